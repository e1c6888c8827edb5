"""The import paths of the flat layout (se3dyn 0.1 before the layered packages, issue 29).

``import se3dyn.modelfile`` or ``from se3dyn.system import evaluate`` keep working: a finder at
the end of ``sys.meta_path`` (consulted only when no module of that name exists, so it costs
nothing otherwise) answers for exactly these names with a module that forwards every attribute
to the new places and says once, in a DeprecationWarning, where they are. Two old modules
shared their name with a function of the package face (``se3dyn.simulate``,
``se3dyn.kinematics``): importing them as modules would replace the function on the package, so
they fail with an ImportError naming the new module.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import sys
import types
import warnings

#: old module -> the new modules its names went to (looked up in this order)
MOVED = {
    "se3dyn.model": None,  # now the package se3dyn.model (it re-exports the builder and specs)
    "se3dyn.joints": ("se3dyn.model.joint_types",),
    "se3dyn.timefunc": ("se3dyn.model.timefunc",),
    "se3dyn.sections": ("se3dyn.model.sections",),
    "se3dyn.visuals": ("se3dyn.model.visuals",),
    "se3dyn.examples": ("se3dyn.model.examples",),
    "se3dyn.system": ("se3dyn.engine.system", "se3dyn.engine.inputs", "se3dyn.engine.workspace",
                      "se3dyn.engine.evaluate", "se3dyn.engine.linsolve"),
    "se3dyn.assembly": ("se3dyn.engine.layout",),
    "se3dyn.threads": ("se3dyn.engine.threads",),
    "se3dyn.integrator": ("se3dyn.dynamics.integrator", "se3dyn.dynamics.state",
                          "se3dyn.engine.memory"),
    "se3dyn.stepcontrol": ("se3dyn.dynamics.stepcontrol",),
    "se3dyn.condense": ("se3dyn.dynamics.condense",),
    "se3dyn.statics": ("se3dyn.analysis.statics",),
    "se3dyn.channels": ("se3dyn.results.channels",),
    "se3dyn.modelfile": ("se3dyn.io.modelfile",),
    "se3dyn.h5": ("se3dyn.io.h5",),
}
#: old modules whose name is a function of the face: refused, naming the new module
REFUSED = {"se3dyn.simulate": "se3dyn.dynamics.run",
           "se3dyn.kinematics": "se3dyn.analysis.kinematics (assemble: se3dyn.analysis.assemble)"}


class _Forward(types.ModuleType):
    """An old module: every attribute read from its new modules."""

    def __getattr__(self, name: str):
        for new in self.__new_modules__:
            mod = importlib.import_module(new)
            if hasattr(mod, name):
                return getattr(mod, name)
        raise AttributeError(f"module {self.__name__!r} (moved to "
                             f"{', '.join(self.__new_modules__)}) has no attribute {name!r}")


class _Loader:
    """(importlib's loader protocol; importlib.abc itself costs 15 ms to import)"""

    def create_module(self, spec):
        new = MOVED[spec.name]
        mod = _Forward(spec.name, f"moved to {', '.join(new)}")
        mod.__new_modules__ = new
        return mod

    def exec_module(self, module):
        pass


class _Finder:
    """(importlib's meta path finder protocol)"""

    def find_spec(self, fullname, path=None, target=None):
        if fullname in REFUSED:
            raise ImportError(f"{fullname} is now {REFUSED[fullname]} (the layered packages of "
                              f"se3dyn; see docs/design.md). The function is se3dyn."
                              f"{fullname.rsplit('.', 1)[1]} as before.", name=fullname)
        if MOVED.get(fullname) is None:
            return None
        warnings.warn(f"{fullname} moved to {' and '.join(MOVED[fullname])} (docs/design.md); "
                      "the old path will be removed in a later version",
                      DeprecationWarning, stacklevel=3)
        return importlib.machinery.ModuleSpec(fullname, _Loader())


def install() -> None:
    """Put the finder at the end of ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.append(_Finder())
