"""The settings of a run (:class:`RunSettings`): the keywords of
:func:`~se3dyn.dynamics.run.simulate`, checked once (a :class:`~se3dyn.errors.ModelError`
naming the field) and normalised, by :func:`~se3dyn.dynamics.run.simulate` and
:func:`~se3dyn.dynamics.run.check_settings` alike."""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable

import numpy as np

from se3dyn.dynamics.integrator import GeneralizedAlpha
from se3dyn.dynamics.recorder import Checkpoint
from se3dyn.dynamics.state import State
from se3dyn.engine.system import System
from se3dyn.errors import ModelError

#: Most steps of one fixed-step run (the compiled loop counts steps in 32-bit integers), and
#: most stored rows of one run; more is refused before anything is allocated.
MAX_STEPS = 10**8


@dataclasses.dataclass(frozen=True)
class RunSettings:
    """The settings of one run of :func:`~se3dyn.dynamics.run.simulate`, checked and
    normalised (see its parameters); built by :meth:`of`.

    Attributes
    ----------
    t_end, step, t_start, span : float
        The time interval (s), the (initial) step and ``t_end - t_start``.
    output_every : int
        Store every k-th step.
    tol, h_min, h_max, output_step : float or None
        Adaptive stepping (``tol``; ``h_min``, ``h_max`` with their defaults filled in) and
        the output grid.
    rho_inf, tol_residual, tol_constraint, max_iter, formulation, redundant, engine, newton, \
initial_velocities :
        The integrator's settings (``rho_inf`` a float when given as a real number).
    progress, on_output, on_rows : callable or None
        The callbacks.
    store, condense, global_error : bool
        ``global_error="bound"`` is True here (the repetitions are the caller's).
    initial_state : State or None
        The state the run starts from (a :class:`Checkpoint`'s state).
    first_step : float or None
        A :class:`Checkpoint`'s ``h_next``.
    k0 : int
        Steps before the first one of this call (fixed steps from an ``initial_state``, or a
        :class:`Checkpoint`'s steps in an adaptive run).
    integrator : GeneralizedAlpha
        The integrator of these settings.
    """

    t_end: float
    step: float
    t_start: float
    span: float
    output_every: int
    tol: float | None
    h_min: float
    h_max: float
    output_step: float | None
    rho_inf: float
    tol_residual: float
    tol_constraint: float
    max_iter: int
    formulation: str
    redundant: str
    engine: str
    newton: str
    initial_velocities: str
    progress: Callable[[float, int], None] | None
    on_output: Callable | None
    on_rows: Callable | None
    store: bool
    condense: bool
    global_error: bool
    initial_state: State | None
    first_step: float | None
    k0: int
    integrator: GeneralizedAlpha = dataclasses.field(repr=False, compare=False)

    @property
    def adaptive(self) -> bool:
        """Adaptive steps (``tol`` given)."""
        return self.tol is not None

    @classmethod
    def of(cls, s: System, *, t_end, step, rho_inf, t_start, tol_residual, tol_constraint,
           max_iter, output_every, formulation, redundant, tol, h_min, h_max, output_step,
           engine, newton, initial_velocities, progress, on_output, on_rows, store,
           initial_state, condense, global_error) -> RunSettings:
        """The settings of a run of ``s`` from :func:`~se3dyn.dynamics.run.simulate`'s
        keywords (all of them, defaults filled in), checked in this order: the times and
        the output, the callbacks, ``store`` and ``condense``, ``global_error``,
        ``initial_state``, the size of the run, the integrator's settings. Raises
        :class:`~se3dyn.errors.ModelError` naming the first field refused."""
        t_end, step, t_start, output_every, span, opt = _times(
            t_end, step, t_start, output_every, tol, h_min, h_max, output_step)
        for fld, val in (("progress", progress), ("on_output", on_output),
                         ("on_rows", on_rows)):
            if val is not None and not callable(val):
                raise ModelError("simulate", fld, "a callable or None", val)
        for fld, val in (("store", store), ("condense", condense)):
            if not isinstance(val, bool | np.bool_):
                raise ModelError("simulate", fld, "True or False", val)
        adaptive = opt["tol"] is not None
        global_error = _global_error_setting(global_error, adaptive)
        k0 = 0  # steps before the first one of this call (fixed steps from an initial_state)
        first_step = None
        if isinstance(initial_state, Checkpoint):
            first_step = initial_state.h_next
            k0 = int(initial_state.steps) if adaptive else 0
            initial_state = initial_state.state
        if initial_state is not None:
            k0 = _check_initial_state(s, initial_state, t_start, t_end, step, adaptive) or k0
        _check_size(s, span, step, output_every, opt["output_step"], adaptive, bool(store))
        _check_sampled(s, t_start, step, adaptive)
        if getattr(s, "contacts", ()) and not adaptive and opt["output_step"] is not None:
            raise ModelError("simulate", "output_step", "None for fixed steps of a model with "
                             "contact pairs (its steps go in contact-aware substeps, which "
                             "dense output does not follow yet): use output_every, or tol",
                             opt["output_step"])
        if isinstance(rho_inf, numbers.Real) and not isinstance(rho_inf, bool):
            rho_inf = float(rho_inf)
        integ = GeneralizedAlpha(rho_inf=rho_inf, tol_residual=tol_residual,
                                 tol_constraint=tol_constraint, max_iter=max_iter,
                                 formulation=formulation, redundant=redundant, engine=engine,
                                 newton=newton, initial_velocities=initial_velocities)
        return cls(t_end=t_end, step=step, t_start=t_start, span=span,
                   output_every=output_every, **opt, rho_inf=rho_inf,
                   tol_residual=tol_residual, tol_constraint=tol_constraint,
                   max_iter=max_iter, formulation=formulation, redundant=redundant,
                   engine=engine, newton=newton, initial_velocities=initial_velocities,
                   progress=progress, on_output=on_output, on_rows=on_rows, store=bool(store),
                   condense=bool(condense), global_error=global_error,
                   initial_state=initial_state, first_step=first_step, k0=k0,
                   integrator=integ)


def _check_sampled(s: System, t_start: float, step: float, adaptive: bool) -> None:
    """Sampled PID laws (``PID(sample_time=T)``) sample at the times ``k T``, which must be
    ends of steps: fixed steps that divide T, from a start on that grid."""
    ts = np.asarray(getattr(s, "dof_ts", np.zeros(0)))
    for d in np.flatnonzero(ts > 0):
        T = float(ts[d])
        item = f"the sampled PID law on {s.labels[d]}"
        if adaptive:
            raise ModelError("simulate", "tol", "fixed steps (no tol): " + item + " samples at "
                             f"multiples of {T:g} s, which adaptive steps do not land on",
                             "adaptive steps")
        for fld, val, what in (("step", T, step), ("t_start", t_start, T)):
            q = val / what
            if abs(q - round(q)) > 1e-9 * max(1.0, abs(q)):
                raise ModelError("simulate", fld, (f"a step that divides the sample time "
                                 f"{T:g} s of {item}" if fld == "step" else
                                 f"a start at a multiple of the sample time {T:g} s of {item}"),
                                 step if fld == "step" else t_start)


def _global_error_setting(val, adaptive: bool) -> bool:
    """``global_error`` checked: True or False, True with ``tol`` only ("bound" is handled
    by :func:`se3dyn.dynamics.run._bound`)."""
    on = True if isinstance(val, str) and val == "bound" else val
    if not isinstance(on, bool | np.bool_):
        raise ModelError("simulate", "global_error", "True, False or 'bound'", val)
    if on and not adaptive:
        raise ModelError("simulate", "global_error", "an adaptive run (tol given): the "
                         "estimate follows the run's own steps", val)
    return bool(on)



def _check_initial_state(s: System, st, t_start: float, t_end: float, step: float,
                         adaptive: bool) -> int:
    """Validate ``initial_state``; the number of fixed steps before it (0 when adaptive)."""
    if not isinstance(st, State):
        raise ModelError("simulate", "initial_state", "a State (stats['final_state'] of an "
                         "earlier run) or None", st)
    F = {"H": (s.M, 4, 4), "HJ": (s.m, 4, 4), "v": (s.nq,), "vd": (s.nq,), "a": (s.nq,),
         "lam": (s.nm,), "alpha": (s.nq,)}
    for name, shape in F.items():
        arr = np.asarray(getattr(st, name))
        if arr.shape != shape:
            raise ModelError("simulate", "initial_state", f"a state of this model ({name} of "
                             f"shape {shape})", f"{name} of shape {arr.shape}")
    t = float(st.t)
    if not (math.isfinite(t) and t_start <= t < t_end):
        raise ModelError("simulate", "initial_state", f"a state at a time in [t_start, t_end) ="
                         f" [{t_start:g}, {t_end:g})", f"t = {t!r}")
    if adaptive:
        return 0
    k = round((t - t_start) / step)
    if abs(t_start + k * step - t) > 1e-9 * step:
        raise ModelError("simulate", "initial_state", f"a state at a step time t_start + k "
                         f"step ({t_start:g} + k {step:g})", f"t = {t!r}",
                         "give the t_start of the run that computed it, or t_start=t")
    return int(k)


def _check_size(s: System, span: float, step: float, output_every: int,
                output_step: float | None, adaptive: bool, store: bool = True) -> None:
    """Refuse, before anything is allocated, a run of more than MAX_STEPS fixed steps or more
    than MAX_STEPS stored rows, or whose stored rows would not fit in the available memory
    (streamed runs, ``store=False``, keep no rows)."""
    what = f"(t_end - t_start) / step = {span:g} / {step:g}"
    n = span / step  # may be inf
    if not adaptive and not n <= MAX_STEPS:
        raise ModelError("simulate", "step", f"at most {MAX_STEPS:.0e} steps", step,
                         f"{what} = {n:.3g} steps; use a larger step")
    rows = span / output_step + 1 if output_step is not None else (
        None if adaptive else n / output_every + 2)
    if rows is None:
        return
    if not rows <= MAX_STEPS:
        raise ModelError("simulate", "output_step" if output_step is not None else
                         "output_every", f"at most {MAX_STEPS:.0e} stored rows", rows,
                         "store fewer rows: a larger output_step or output_every")
    if not store:
        return
    per_row = 8 * (1 + 16 * s.M + 3 * s.nq + s.nm + 9)
    need = rows * per_row
    avail = _available_memory()
    if avail is not None and need > avail:
        raise ModelError(
            "simulate", "output_step" if output_step is not None else "step",
            "results that fit in memory", f"{rows:.3g} stored rows of {per_row} bytes = "
            f"{need / 2**30:.1f} GiB", f"{avail / 2**30:.1f} GiB available; store fewer rows "
            "with output_every or output_step (CLI: --output-step), or use a larger step")


def _times(t_end, step, t_start, output_every, tol, h_min, h_max, output_step):
    """The time settings of a run, checked (ModelError naming the field) and normalised:
    (t_end, step, t_start, output_every, span, dict of tol, h_min, h_max, output_step)."""
    for fld, val in (("t_end", t_end), ("step", step), ("t_start", t_start)):
        if (not isinstance(val, numbers.Real) or isinstance(val, bool)
                or not math.isfinite(float(val))):
            raise ModelError("simulate", fld, "a finite number (s)", val)
    t_end, step, t_start = float(t_end), float(step), float(t_start)
    if not step > 0:
        raise ModelError("simulate", "step", "a positive time step (s)", step)
    if not t_end > t_start:
        raise ModelError("simulate", "t_end", f"a time after t_start={t_start}", t_end)
    if isinstance(output_every, numbers.Integral) and not isinstance(output_every, bool):
        output_every = int(output_every)
    if not (isinstance(output_every, int) and 1 <= output_every <= MAX_STEPS):
        raise ModelError("simulate", "output_every", f"a positive integer of at most "
                         f"{MAX_STEPS:.0e} (the most steps a run takes)", output_every)
    span = t_end - t_start
    opt = {}
    for fld, val, default in (("tol", tol, None), ("h_min", h_min, 1e-12 * span),
                              ("h_max", h_max, span / 10), ("output_step", output_step, None)):
        if val is None:
            opt[fld] = default
            continue
        if (not isinstance(val, numbers.Real) or isinstance(val, bool)
                or not (math.isfinite(float(val)) and float(val) > 0)):
            raise ModelError("simulate", fld, "a positive number", val)
        opt[fld] = float(val)
    if opt["tol"] is not None and opt["tol"] < 1e-15:
        raise ModelError("simulate", "tol", "a tolerance of at least 1e-15 (m, rad)", opt["tol"])
    if opt["h_min"] > opt["h_max"]:
        raise ModelError("simulate", "h_min", f"at most h_max={opt['h_max']:g}", opt["h_min"])
    return t_end, step, t_start, output_every, span, opt



def _available_memory() -> float | None:
    """Available memory in bytes (Linux: MemAvailable), None when unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None
