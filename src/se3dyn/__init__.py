"""se3dyn: multibody dynamics on the special Euclidean group SE(3).

The method is the finite-element formulation of multibody systems on SE(3) with a Lie-group
generalized-alpha integrator. Conventions are written once in :mod:`se3dyn.lie`.

>>> import se3dyn as sd
>>> model = sd.examples.slider_crank()
>>> result = sd.simulate(model, t_end=5.0, step=1e-2, rho_inf=0.9)  # doctest: +SKIP

Beyond dynamics: :func:`static_equilibrium` (load stepping), :func:`assemble` (inconsistent
initial configurations), :func:`kinematics` (driven mechanisms, inverse dynamics).
Parameter studies on dask.distributed: ``se3dyn.sweep(...)`` (:mod:`se3dyn.sweep`, imported on
first use; the core never imports it).
"""

# ruff: noqa: E402  (the command's start-up settings go before the imports that take time)


def _command_startup() -> None:
    """The ``se3dyn`` command only (not ``import se3dyn`` in a program), before numpy loads:

    * numpy's OpenBLAS starts its worker threads at import, and each spins (``sched_yield``)
      for 2^28 cycles, ~0.1 s, before it sleeps: on a machine whose cores are busy that cost
      the command's start-up 30-40 ms of CPU and up to 0.15 s of wall time (numpy's import
      0.07 -> 0.23 s at load 3 on 2 cores). ``OPENBLAS_THREAD_TIMEOUT=4`` (2^4 cycles, unless
      set) puts them to sleep at once; the number of threads, and so every result, is the
      same, and a BLAS call that uses them wakes them (the engine does not use BLAS). The
      processes the command starts (sweep workers) inherit the setting.
    * The cyclic garbage collector pauses while the modules load (their objects all live
      on: the collections of the start-up only walked them, 10-15 ms of CPU); once they are
      loaded, ``se3dyn.cli`` freezes what exists (``gc.freeze``: never walked again) and
      resumes it, before the simulation. At exit, the interpreter's last collections walk
      every object (50-80 ms of wall time): the objects are frozen first (the last atexit
      handler; all of them go with the process). The handlers registered later, the
      teardown of the modules and the finalizers of the objects that no cycle holds run as
      before. Not for ``sweep``: dask shuts its machinery down as usual.
    * Ctrl-C while the package loads prints one line and exits with 130, no traceback, and
      SIGTERM likewise with 143 (``se3dyn.cli.main`` installs its own handlers once it runs).
    """
    import os
    import sys

    if os.path.basename(sys.argv[0] if sys.argv else "") not in ("se3dyn", "se3dyn.exe"):
        return
    os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")
    if "sweep" not in sys.argv[1:2]:
        import atexit
        import gc

        global _GC_PAUSED
        _GC_PAUSED = gc.isenabled()
        gc.disable()  # se3dyn.cli resumes it
        atexit.register(gc.freeze)  # registered first: runs last

    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def interrupted(signum, frame):
        if signum == signal.SIGTERM:
            os.write(2, b"se3dyn: error: terminated\n")
            os._exit(143)
        os.write(2, b"se3dyn: error: interrupted\n")
        os._exit(130)

    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, interrupted)
        if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
            signal.signal(signal.SIGTERM, interrupted)
    except (ValueError, OSError):  # pragma: no cover - no signals here
        pass


_GC_PAUSED = False  # by _command_startup, until se3dyn.cli resumes the collector
_command_startup()

from se3dyn import examples, lie
from se3dyn.errors import ModelError, NewtonError, Se3dynError, SimulationError
from se3dyn.integrator import GeneralizedAlpha, State
from se3dyn.joints import JOINT_TYPES
from se3dyn.kinematics import Assembly, AssemblyError, KinematicsResult, assemble, kinematics
from se3dyn.model import PD, JointSpec, LoadSpec, Model, ModelBuilder, NodeSpec
from se3dyn.results import Results
from se3dyn.simulate import simulate
from se3dyn.system import System, compile_model
from se3dyn.threads import get_threads, set_threads
from se3dyn.timefunc import Callable, Component, Constant, Ramp, Sine, Step, Table

__version__ = "0.1.0"

__all__ = [
    "lie", "examples", "ModelBuilder", "Model", "NodeSpec", "JointSpec", "LoadSpec", "PD",
    "System", "compile_model", "simulate", "Results", "GeneralizedAlpha", "State",
    "Constant", "Step", "Ramp", "Table", "Sine", "Callable", "Component", "JOINT_TYPES",
    "Se3dynError", "ModelError", "SimulationError", "NewtonError", "__version__",
    "static_equilibrium", "StaticResult", "assemble", "Assembly", "AssemblyError",
    "kinematics", "KinematicsResult", "set_threads", "get_threads",
]


# imported on first use (PEP 562): statics, which a run does not need, and se3dyn.sweep, the
# opt-in sweep layer. (kinematics stays eager: its function shares the module's name)
_LAZY = {"static_equilibrium": "se3dyn.statics", "StaticResult": "se3dyn.statics",
         "sweep": "se3dyn.sweep"}


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module 'se3dyn' has no attribute {name!r}")
    import importlib

    mod = importlib.import_module(_LAZY[name])
    return mod if name == "sweep" else getattr(mod, name)
