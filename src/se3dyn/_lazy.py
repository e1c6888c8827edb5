"""Deferred imports: scipy costs ~0.2 s at import and most runs never need it (the engine's
linear algebra is compiled), so the modules that use it for statics, kinematics and analysis
import it on first use."""

from __future__ import annotations

import importlib
from types import ModuleType


class LazyModule:
    """A module imported on first attribute access, e.g. ``sla = LazyModule("scipy.linalg")``."""

    def __init__(self, name: str) -> None:
        self._name = name
        self._mod: ModuleType | None = None

    def __getattr__(self, attr: str):
        if self._mod is None:
            self._mod = importlib.import_module(self._name)
        return getattr(self._mod, attr)
