"""The compiled engine (:mod:`se3dyn._core._engine`, C++ built at install), prepared once before its
first use: the Taylor-series coefficients of :mod:`se3dyn.lie` handed over (one set of cut-offs
for both languages) and the thread count of :func:`se3dyn.set_threads` or ``SE3DYN_THREADS``."""

from __future__ import annotations

from se3dyn import lie
from se3dyn.engine.threads import pool

_CORE = None


def compiled():
    """The compiled module, prepared (series and threads) on the first call."""
    global _CORE
    if _CORE is None:
        core = pool()  # the module, its threads started
        core.set_series(lie._C2, lie._C3, lie._C4, lie._C5, float(lie.SERIES_CUTOFF))
        _CORE = core
    return _CORE
