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

# ruff: noqa: E402  (the interrupt guard goes before the imports that take time)


def _quiet_startup_interrupt() -> None:
    """The ``se3dyn`` command: Ctrl-C while the package loads prints one line and exits with
    130, no traceback (``se3dyn.cli.main`` restores the default handler once it runs)."""
    import os
    import signal
    import sys
    import threading

    if (os.path.basename(sys.argv[0] if sys.argv else "") not in ("se3dyn", "se3dyn.exe")
            or threading.current_thread() is not threading.main_thread()):
        return

    def interrupted(signum, frame):
        os.write(2, b"se3dyn: error: interrupted\n")
        os._exit(130)

    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, interrupted)
    except (ValueError, OSError):  # pragma: no cover - no signals here
        pass


_quiet_startup_interrupt()

from se3dyn import examples, lie
from se3dyn.errors import ModelError, NewtonError, Se3dynError, SimulationError
from se3dyn.integrator import GeneralizedAlpha, State
from se3dyn.joints import JOINT_TYPES
from se3dyn.kinematics import Assembly, AssemblyError, KinematicsResult, assemble, kinematics
from se3dyn.model import PD, JointSpec, LoadSpec, Model, ModelBuilder, NodeSpec
from se3dyn.results import Results
from se3dyn.simulate import simulate
from se3dyn.statics import StaticResult, static_equilibrium
from se3dyn.system import System, compile_model
from se3dyn.timefunc import Callable, Component, Constant, Ramp, Sine, Step, Table

__version__ = "0.1.0"

__all__ = [
    "lie", "examples", "ModelBuilder", "Model", "NodeSpec", "JointSpec", "LoadSpec", "PD",
    "System", "compile_model", "simulate", "Results", "GeneralizedAlpha", "State",
    "Constant", "Step", "Ramp", "Table", "Sine", "Callable", "Component", "JOINT_TYPES",
    "Se3dynError", "ModelError", "SimulationError", "NewtonError", "__version__",
    "static_equilibrium", "StaticResult", "assemble", "Assembly", "AssemblyError",
    "kinematics", "KinematicsResult",
]


def __getattr__(name: str):
    # se3dyn.sweep: the opt-in sweep layer, imported on first use only (PEP 562)
    if name == "sweep":
        import importlib

        return importlib.import_module("se3dyn.sweep")
    raise AttributeError(f"module 'se3dyn' has no attribute {name!r}")
