"""``simulate``: run the generalized-alpha integrator over a time interval and record results.

A run goes: its settings, checked once (:class:`~se3dyn.dynamics.settings.RunSettings`), the
plan of the run (:func:`_plan`: fixed or adaptive steps, the compiled loop or the step-by-step
one, the output grid, the sizes), its start (:class:`_Run`: the initial state, the condensed
rigid joints, the recorder, the global error companion), one loop (:func:`_fixed_compiled` or
:func:`_stepwise`), the reports (:mod:`se3dyn.dynamics.reports`) and the results
(:mod:`se3dyn.dynamics.recorder`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from se3dyn.dynamics import stepcontrol
from se3dyn.dynamics.condense import condensation
from se3dyn.dynamics.integrator import GeneralizedAlpha, energies, interpolate
from se3dyn.dynamics.recorder import CHECKPOINT_EVERY as CHECKPOINT_EVERY
from se3dyn.dynamics.recorder import SCALARS, Checkpoint, _Recorder, checkpoint_interval
from se3dyn.dynamics.reports import _balance_and_scale as _balance_and_scale
from se3dyn.dynamics.reports import (
    _energy_check,
    _global_error_check,
    _velocity_report,
    energy_balance_check,
    energy_cause,
    energy_jump,
    energy_rows,
    energy_warning,
)
from se3dyn.dynamics.settings import MAX_STEPS as MAX_STEPS
from se3dyn.dynamics.settings import RunSettings
from se3dyn.dynamics.state import State
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.rank import equation_name
from se3dyn.engine.system import System, system_of
from se3dyn.engine.workspace import Workspace
from se3dyn.errors import ModelError, NewtonError, SimulationError
from se3dyn.results.results import Results

if TYPE_CHECKING:
    from se3dyn.model.specs import Model

__all__ = ["simulate", "check_settings", "energy_balance_check", "energy_jump",
           "energy_warning", "energy_cause", "energy_rows", "SCALARS", "Checkpoint"]


#: Steps whose times and inputs are tabulated at once by the compiled fixed-step loop.
_BLOCK = 65536


def simulate(model: Model | System, t_end: float, step: float, *, rho_inf: float = 0.9,
             t_start: float = 0.0, tol_residual: float = 1e-10, tol_constraint: float = 1e-11,
             max_iter: int = 25, output_every: int = 1, formulation: str = "index2",
             redundant: str = "drop", tol: float | None = None, h_min: float | None = None,
             h_max: float | None = None, output_step: float | None = None,
             engine: str = "auto", newton: str = "modified",
             initial_velocities: str = "project",
             progress: Callable[[float, int], None] | None = None,
             on_output: Callable[[State, dict], None] | None = None,
             on_rows: Callable[[Results, Checkpoint | None], None] | None = None,
             store: bool = True,
             initial_state: State | Checkpoint | None = None,
             condense: bool = True, global_error: bool | str = False,
             _schedule: np.ndarray | None = None) -> Results:
    """Simulate a model from ``t_start`` to ``t_end`` (Eqs. (38)-(46)), with a fixed step or,
    when ``tol`` is given, with adaptive steps.

    Parameters
    ----------
    model : Model or System
        The model (compiled here) or an already compiled system.
    t_end : float
        Final time (s).
    step : float
        Time step h (s); the initial step when ``tol`` is given. With a fixed step, when
        ``(t_end - t_start)/step`` is not an integer the last step is shortened to land on
        ``t_end``. More than ``MAX_STEPS`` (1e8) fixed steps, or stored rows that would not fit
        in the available memory, are refused with a ModelError before the run starts.
    rho_inf : float
        Spectral radius at infinite frequency (Eq. (44)).
    tol_residual, tol_constraint, max_iter :
        Newton settings, see :class:`~se3dyn.dynamics.integrator.GeneralizedAlpha`.
    output_every : int
        Store every k-th step (the initial and the final state are always stored).
    formulation : {"index2", "index3"}
        Stabilized index-2 (default; second order in positions, velocities and multipliers)
        or the paper's index-3 form, see :class:`~se3dyn.dynamics.integrator.GeneralizedAlpha`.
        Under modified Newton the index-2 steps iterate with a split matrix (an index-3-sized
        factorisation and a small one; the same converged steps) until it contracts too
        slowly, then with the full matrix for the rest of the run
        (``stats["full_matrix_steps"]`` counts those steps; ``se3dyn/_core/newton.hpp``).
    redundant : {"drop", "error"}
        Redundant constraint equations are left out with zero multipliers (default; their
        names are in ``stats["redundant"]``) or reported as an error.
    tol : float, optional
        Adaptive time stepping (:mod:`se3dyn.dynamics.stepcontrol`): the local position errors (m)
        add up to ``tol`` over a run of even difficulty. A step's local error estimate
        ``(1/6 - beta - (alpha_m - alpha_f) / 2) h^2 (a_{n+1} - a_n)`` is measured per body as
        the root mean square, over its mass, of the errors of its material points (rotation
        errors weigh by the body's radius of gyration; massless nodes do not count), the
        largest over the bodies, and held to the step's share
        ``tol (h_bar / span) (h_bar / h)^3`` (``span = t_end - t_start``, ``h_bar`` the mean
        step so far): ``tol / N`` for N even steps; where the difficulty varies the steps
        vary as the local error's -1/6th power, half as much as under the classical rule of
        equal error per step, which measured more steps than a fixed step of the same
        accuracy on mechanisms with short violent phases. Rejected steps are repeated with a
        smaller step; while the error stays within ``[1.3^-6, 1]`` of its share the next step
        tracks the state, ``h (c_n / c_{n+1})^(1/6)`` with ``c`` the error coefficient that
        ``a - vd`` of the states at the step's ends give (rho_inf < 1), so that the steps
        follow the motion, not its history (where a step is shorter than 1.2 times the mean
        step so far, a violent phase, errors up to 4 times the share are accepted and the band
        is ``[1.3^-12, 4]``: the share rescales the steps in the quiet phases, where a step
        change costs least); otherwise it is ``h (share / error)^(1/6)``
        (safety 0.9, at most doubled, kept when it would grow by less than 30 %). A step whose
        Newton iterations fail is retried with h / 4. The sum of the accepted estimates is
        ``stats["error_estimate"]``. The global error is a fraction of ``tol`` where errors
        neither grow nor decay along the motion (the undamped pendulum) or decay, and larger
        where the motion amplifies them (an accelerating mechanism, a fast top, a mechanism
        passing singular positions): see ``docs/accuracy.md``; ``global_error`` measures it,
        and ``global_error="bound"`` holds it to ``tol``. ``stats["step_times"]`` holds the
        times the accepted steps reached.
    h_min, h_max : float, optional
        Step bounds for adaptive stepping (default ``1e-12 (t_end - t_start)`` and
        ``(t_end - t_start) / 10``). Falling below ``h_min`` stops the run with a
        :class:`~se3dyn.errors.SimulationError` naming the time and the cause.
    output_step : float, optional
        Store the results on the grid ``t_start + k output_step`` (and ``t_end``) by dense
        output (:func:`~se3dyn.dynamics.integrator.interpolate`), whatever the internal steps;
        without it every (``output_every``-th) step is stored.
    engine : {"auto", "compiled", "numpy"}
        Kept for compatibility: every step runs in the compiled engine (``se3dyn/_core``, C++
        built at install; there is no second implementation, see
        :class:`~se3dyn.dynamics.integrator.GeneralizedAlpha`). With a fixed step and no
        ``progress``, ``on_output`` or ``output_step``, the whole time loop runs compiled.
    newton : {"modified", "full"}
        Reuse of the factorised iteration matrix by the compiled engine, see
        :class:`~se3dyn.dynamics.integrator.GeneralizedAlpha`.
    initial_velocities : {"project", "strict"}
        Initial velocities the joints do not allow are projected (default): every change is
        in ``stats["initial_velocity_changes"]`` (per node: the change of velocity and angular
        velocity, the given and the used values) with the kinetic energy given and used, and
        a :class:`~se3dyn.errors.Se3dynWarning` is issued when it exceeds 1e-6 of the
        velocities; ``"strict"`` refuses them (:class:`~se3dyn.errors.ModelError` naming the
        node).
    progress : callable(t, step_index), optional
        Called after every step.
    on_output : callable(state, scalars), optional
        Called with every stored row as it is computed (the initial state included): the
        :class:`~se3dyn.dynamics.state.State` and a dict of the scalar columns ``SCALARS``
        (energies, works, Newton iterations, residual, constraint violation). Used to stream
        results to a file while the simulation runs.
    on_rows : callable(rows, checkpoint), optional
        Called with the stored rows in blocks as they are computed (the initial state in the
        first): ``rows`` is a :class:`Results` of the new rows (its own arrays), ``checkpoint``
        a :class:`Checkpoint` from which the run continues bit for bit, or None when none was
        reached since the last call. Blocks come about every 0.1-0.2 s of wall time. The
        streaming interface of :class:`se3dyn.io.h5.ResultsWriter` (``writer.add_rows``).
    store : bool
        Keep every stored row in the returned results (default). False for streamed runs:
        rows are only passed on to ``on_output`` / ``on_rows`` and memory stays flat however
        long the run; the returned results then hold the first and the last row, and
        ``stats`` the summary of all of them either way (``rows``, ``energy_balance_error``,
        ``max_energy``, ``max_constraint``, ``max_iterations``).
    initial_state : State or Checkpoint, optional
        Continue from this state (``stats["final_state"]`` of an earlier run, or a
        :class:`Checkpoint` from ``on_rows``, whose ``h_next`` is then an adaptive run's first
        step) instead of the model's initial state, with the same settings: ``t_start`` stays
        the start of the whole run (the fixed steps keep the times ``t_start + k step``, so
        ``initial_state.t`` must be one of them). The first row of the results is
        ``initial_state``. The state carries the linear solver's memory (``State.solver``),
        so the continued run computes exactly what the uninterrupted run computes from that
        state on; its rows are the uninterrupted run's rows when it starts from a
        :class:`Checkpoint` (every ``CHECKPOINT_EVERY`` = 1000 steps, rounded up to a multiple
        of ``output_every``, and the start) or from a final state reached at a step time that
        is a multiple of ``output_every`` (the last step of a run is shortened to land on
        ``t_end`` otherwise). An adaptive run continues to its own ``t_end`` only (``tol``
        and ``h_max`` are per run length).
    condense : bool
        Nodes joined by rigid joints move as one body in the time loop (default): the steps
        run on a reduced model with one node per group (its mass, centre of mass and inertia
        combined, the other elements attached at the same material places), which has the
        paper's discrete motion with the index-3 form and, with the index-2 form, the motion
        of the same bodies built as one node each (``com=``, ``at=``); every stored row is the
        model's own (the frames, velocities and accelerations of every node; the multipliers
        of the condensed joints from the equations of motion of the nodes they carry,
        computed when first asked for). ``stats["condensed"]`` names the condensed joints,
        ``stats["matrix_size"]`` is the size of the matrix solved. A step that fails on the
        reduced model is retried with the rigid joints kept, and the run goes on so
        (``stats["condensed_until"]``: the time of the switch). See :mod:`se3dyn.dynamics.condense`
        for what is kept as a joint.
    global_error : bool or "bound"
        With ``tol``: ``True`` estimates the global position error of the run (m, in the norm
        of ``tol``) by a companion run that takes the run's accepted steps two at a time
        (Richardson: the error is the difference of the two runs over three where both
        meet; :class:`~se3dyn.dynamics.stepcontrol.GlobalEstimate`), at the cost of about half the
        run's steps again. ``stats["global_error"]`` is the largest estimate,
        ``stats["global_error_at"]`` its time, ``stats["global_error_history"]`` the (k, 2)
        times and estimates; where the companion's Newton iterations fail, the estimate stops
        (``stats["global_error_until"]``). The run's own steps do not depend on it, and a
        :class:`~se3dyn.errors.Se3dynWarning` says so when the estimate exceeds ``tol``. A run
        continued from ``initial_state`` estimates the error made from there on.
        ``"bound"`` makes ``tol`` a bound on the estimated global error: when the first
        run's estimate ``E`` exceeds ``tol``, the run is repeated on its own steps each split
        into ``m = ceil(sqrt(E / (0.8 tol)))`` (the error of a second-order scheme falls as
        ``1/m^2`` on steps refined alike), and the repeated run's error estimated from the
        two, ``|y_1 - y_m| / (m^2 - 1)`` over their common rows; at most
        ``BOUND_RUNS`` = 3 runs. The results are those of the last run;
        ``stats["global_error_runs"]`` lists every run (refinement, steps, estimate).
        For results kept in memory only (``store=True``, no ``on_output``/``on_rows``) and
        from the model's initial state.

    Returns
    -------
    Results
        ``stats`` holds steps, rejected steps, Newton iterations, smallest/largest step, the
        summary over all rows (see ``store``), ``final_state`` (the :class:`State` reached),
        initial velocity changes (above), and ``energy_balance_error`` (J: the largest drift
        of kinetic + potential + elastic energy - work of actuators and loads + dissipation)
        beside ``energy_scale`` (J: the energy in play, see :func:`energy_balance_check`); a
        :class:`~se3dyn.errors.Se3dynWarning` says so when the
        error exceeds 10 % of the scale (a step too large for the motion, or ``rho_inf``
        near 1 with the index-3 form).

    Raises
    ------
    NewtonError
        When a step fails (fixed step) or the step falls below ``h_min`` (adaptive); its
        ``result`` attribute holds the results up to the last converged step, and the message
        names the time, the step, the norms and the worst item.
    """
    if isinstance(global_error, str) and global_error == "bound":  # (locals: the arguments)
        return _bound({k: v for k, v in locals().items()
                       if k not in ("global_error", "_schedule")})
    s = system_of(model)
    cfg = RunSettings.of(
        s, t_end=t_end, step=step, rho_inf=rho_inf, t_start=t_start, tol_residual=tol_residual,
        tol_constraint=tol_constraint, max_iter=max_iter, output_every=output_every,
        formulation=formulation, redundant=redundant, tol=tol, h_min=h_min, h_max=h_max,
        output_step=output_step, engine=engine, newton=newton,
        initial_velocities=initial_velocities, progress=progress, on_output=on_output,
        on_rows=on_rows, store=store, initial_state=initial_state, condense=condense,
        global_error=global_error)
    plan = _plan(cfg, _schedule)
    if s.contacts and plan.compiled:  # contact-aware steps (_contact_steps): step by step
        plan = dataclasses.replace(plan, compiled=False)
    run = _Run(s, cfg, plan)
    if plan.compiled:
        _fixed_compiled(run)
    else:
        _stepwise(run)
    run.rec.emit()
    run.final_stats(False)
    res = run.rec.results(run.stats)
    _energy_check(res)
    _global_error_check(res)
    return res


def check_settings(model: Model | System, **settings) -> None:
    """Check simulation settings as :func:`simulate` would before its first step, without
    running: unknown names, types and ranges (``t_start < t_end``, ``h_min <= h_max``,
    ``rho_inf`` in [0, 1], ...), and the size of the run. Raises :class:`ModelError` naming
    the field; ``se3dyn check`` calls it with the model file's settings."""
    import inspect

    try:
        b = inspect.signature(simulate).bind(model, **settings)
    except TypeError as exc:
        raise ModelError("simulation", "settings", "names of simulate's parameters",
                         ", ".join(settings), str(exc)) from None
    b.apply_defaults()
    kw = {k: v for k, v in b.arguments.items() if k not in ("model", "_schedule")}
    RunSettings.of(system_of(model), **kw)


@dataclasses.dataclass(frozen=True)
class _Plan:
    """What a run decides before its first step (:func:`_plan`).

    Attributes
    ----------
    adaptive : bool
        Adaptive steps (``tol`` given).
    compiled : bool
        The whole fixed-step loop runs in the compiled engine (:func:`_fixed_compiled`);
        otherwise step by step (:func:`_stepwise`).
    grid : callable(j) -> float, or None
        The output times ``t_start + j output_step``, the last moved to ``t_end``.
    n_grid, gi : int
        Grid times in all; the first one this run fills.
    capacity : int
        Rows expected (a first guess of 1024 for an adaptive run without a grid).
    limit : int or None
        Rows the recorder grows to at most (None: no limit known).
    nsteps : int
        Fixed steps of the whole run (0 when adaptive).
    h0 : float
        The first step.
    cpe : int
        Steps between checkpoints.
    schedule : ndarray or None
        Prescribed step times (the refined repetition of ``global_error="bound"``).
    """

    adaptive: bool
    compiled: bool
    grid: Callable[[int], float] | None
    n_grid: int
    gi: int
    capacity: int
    limit: int | None
    nsteps: int
    h0: float
    cpe: int
    schedule: np.ndarray | None


def _plan(cfg: RunSettings, schedule: np.ndarray | None) -> _Plan:
    """The plan of a run with the settings ``cfg``."""
    adaptive = cfg.adaptive
    t_start, t_end, span = cfg.t_start, cfg.t_end, cfg.span
    grid = None  # the output times t_start + j output_step, the last moved to t_end
    gi = 1  # next grid time to fill
    n_grid = 0
    if cfg.output_step is not None:
        k = max(1, math.ceil(span / cfg.output_step - 1e-9))
        dt_out = cfg.output_step

        def grid(j: int) -> float:  # computed when needed: nothing allocated per row
            return t_end if j >= k else min(t_start + dt_out * j, t_end)

        n_grid = k + 1
        capacity = n_grid
        if cfg.initial_state is not None:
            gi = min(n_grid, max(1, int((cfg.initial_state.t - t_start) / dt_out) - 1))
            while gi < n_grid and grid(gi) <= cfg.initial_state.t + 1e-12 * span:
                gi += 1
            capacity = n_grid - gi + 1
    elif adaptive:
        capacity = 1024
    else:
        capacity = (max(1, math.ceil(span / cfg.step - 1e-9)) // cfg.output_every + 2
                    - cfg.k0 // cfg.output_every)
    h = min(cfg.step, cfg.h_max) if adaptive else cfg.step
    if adaptive and cfg.first_step is not None:
        h = min(cfg.first_step, cfg.h_max)
    return _Plan(adaptive=adaptive, compiled=not adaptive and grid is None, grid=grid,
                 n_grid=n_grid, gi=gi, capacity=capacity,
                 limit=None if adaptive and grid is None else capacity,
                 nsteps=0 if adaptive else max(1, math.ceil(span / cfg.step - 1e-9)), h0=h,
                 cpe=checkpoint_interval(cfg.output_every), schedule=schedule)


class _Run:
    """One run as it goes: the system stepped (the reduced one while rigid joints are
    condensed), its state, workspace and linear solver, the recorder, the stats, the global
    error companion and the steps done (``i``, from the start of the whole run)."""

    def __init__(self, s: System, cfg: RunSettings, plan: _Plan):
        self.cfg, self.plan = cfg, plan
        integ = self.integ = cfg.integrator
        initial = cfg.initial_state
        self.wall0 = time.perf_counter()
        ws = Workspace(s)  # this run's engine and steppers, shared with no other run
        st = integ.init(s, cfg.t_start, ws=ws) if initial is None else initial
        e = energies(s, st, step_inputs(s, st.t), ws)
        # (a continued run starts from a state, not from the model's velocities)
        v_report = ({} if initial is not None
                    else _velocity_report(s, st, e["kinetic"], ws, stacklevel=4))
        model_system, redundant_names = s, [equation_name(s, r) for r in st.dropped]
        ws_full = ws  # the model's own system: its state at t0, the condensed rows expanded
        # rigid joints condensed for the time loop (se3dyn.dynamics.condense): the steps run on
        # the reduced system, the stored rows are the model's own
        cond = condensation(s) if cfg.condense else None
        if cond is not None:
            reduced = cond.restrict(st if initial is not None
                                    else dataclasses.replace(st, solver=None))
            if reduced is None:  # a redundant equation of a rigid joint: kept as it is
                cond = None
            else:
                s, st = cond.reduced, reduced
                ws = Workspace(s)
        self.run_ws = [ws_full] + ([ws] if ws is not ws_full else [])  # (steppers' counters)
        # storage grows as the run goes (doubling, up to the rows expected)
        rec = _Recorder(s, plan.capacity, cfg.on_output, plan.limit, store=cfg.store,
                        on_rows=cfg.on_rows, cond=cond, full_ws=ws_full)
        solver = integ.solver(s, st)
        rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
        stats = dict(steps=0, rejected=0, newton_iterations=0, rho_inf=cfg.rho_inf,
                     step=cfg.step, t_start=cfg.t_start, t_end=cfg.t_end,
                     tol_residual=cfg.tol_residual, tol_constraint=cfg.tol_constraint,
                     unknowns=model_system.nq, multipliers=model_system.nm,
                     matrix_size=solver.N, formulation=cfg.formulation,
                     redundant=redundant_names,
                     condensed=[] if cond is None else [model_system.joint_names[j]
                                                         for j in cond.rigid],
                     linear_solver="dense LU" if solver.dense else "sparse LU (SuperLU)",
                     adaptive=plan.adaptive, tol=cfg.tol, h_min_used=math.inf,
                     h_max_used=0.0, **v_report)
        if initial is not None:
            stats["resumed_at"] = st.t
        self.gest = None  # the companion run of the global error estimate
        self.step_times = [st.t]  # of an adaptive run: the times its accepted steps reached
        self.c_st = None  # the error coefficient of the state st, once computed (stepcontrol)
        self.norm = None
        if plan.adaptive:
            self.norm = stepcontrol.ErrorNorm(s)
            stats["error_estimate"] = 0.0
            if cfg.global_error:
                self.gest = stepcontrol.GlobalEstimate(self.norm, st, _companion(integ, s))
        self.i = cfg.k0
        self.gi = plan.gi
        if cfg.k0 % plan.cpe == 0:  # the start is a checkpoint too
            rec.pending = Checkpoint(st, cfg.k0, plan.h0, 0, 0, 1)
        stats["linear_solver"] = (
            "sparse LU (se3dyn/_core/sparse_lu.hpp)"
            + (" and LDL^T (sparse_ldlt.hpp) of the split index-2 iteration's xi block"
               if integ.index2 and integ.newton == "modified" and s.nm else ""))
        stats["engine"] = "compiled"
        self.s, self.st, self.ws, self.solver, self.cond = s, st, ws, solver, cond
        self.model_system, self.ws_full, self.rec, self.stats = model_system, ws_full, rec, stats

    def uncondense(self, U: np.ndarray | None = None, inputs: dict | None = None) -> None:
        """A step of the reduced system failed: the run goes on with the rigid joints kept (a
        condensed run never fails where the model itself goes on; stats say from when).
        ``U``, ``inputs``: the inputs of the stored rows and of the state when they are not
        the model's (:class:`~se3dyn.dynamics.simulator.Simulator`)."""
        cond, ws_full, model_system = self.cond, self.ws_full, self.model_system
        self.c_st = None  # (another norm from here)
        self.stats["condensed_until"] = self.st.t
        full = dataclasses.replace(cond.expand(self.st, ws_full, inputs), solver=None)
        self.rec.uncondense(U, inputs)
        if self.gest is not None:
            self.gest.replace(stepcontrol.ErrorNorm(model_system),
                              dataclasses.replace(cond.expand(self.gest.coarse, ws_full),
                                                  solver=None),
                              _companion(self.integ, model_system))
        self.s, self.st, self.cond, self.ws = model_system, full, None, ws_full
        self.solver = self.integ.solver(self.s, self.st)
        if self.plan.adaptive:
            self.norm = stepcontrol.ErrorNorm(self.s)

    def final_stats(self, failed: bool) -> None:
        """The stats of the run's end, or of where it failed."""
        stats = self.stats
        if self.gest is not None:
            stats.update(self.gest.stats())
        if self.plan.adaptive:
            stats["step_times"] = np.asarray(self.step_times)
        if self.integ.index2:  # (split index-2 steps that fell back to the full matrix)
            stats["full_matrix_steps"] = sum(w.full_matrix_steps() for w in self.run_ws)
        stats.update(steps=self.i - self.cfg.k0, failed=failed,
                     wall_time=time.perf_counter() - self.wall0,
                     final_state=self.st if self.cond is None
                     else self.cond.expand(self.st, self.ws_full))

    def fail(self, exc: SimulationError):
        """Raise ``exc`` with the results up to the last converged step (``exc.result``)."""
        self.final_stats(True)
        rec, st = self.rec, self.st
        if self.plan.grid is None and rec.n and rec.last_time() != st.t:
            e = energies(self.s, st, step_inputs(self.s, st.t), self.ws)
            rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
        rec.emit()
        exc.result = rec.results(self.stats)
        raise exc


def _fixed_compiled(run: _Run) -> None:
    """The whole fixed-step loop in the compiled engine (:func:`_run_compiled`), in chunks
    between which progress and streamed rows are reported; a failing step is repeated by
    :meth:`GeneralizedAlpha.step`, which raises the error naming time, norms and item. A run
    on condensed rigid joints whose step fails goes on with the joints kept."""
    cfg, stats, nsteps = run.cfg, run.stats, run.plan.nsteps
    t_start, step, t_end = cfg.t_start, cfg.step, cfg.t_end

    def times(k0: int, k1: int) -> np.ndarray:  # the times of steps k0 <= k < k1
        out = t_start + np.arange(k0 + 1, k1 + 1, dtype=np.int64).astype(float) * step
        if k1 == nsteps:
            out[-1] = t_end
        return out

    rest = (cfg.output_every, run.plan.cpe, run.rec, cfg.progress, stats)
    run.st, run.i, fac, hs = _run_compiled(run.s, run.integ, run.st, times, cfg.k0, nsteps,
                                           *rest, run.ws)
    if run.i < nsteps and run.cond is not None:
        run.uncondense()
        run.st, run.i, fac2, hs2 = _run_compiled(run.s, run.integ, run.st, times, run.i,
                                                 nsteps, *rest, run.ws)
        fac += fac2
        hs = (min(hs[0], hs2[0]), max(hs[1], hs2[1]))
    stats["factorizations"] = fac
    if run.i < nsteps:
        try:
            run.integ.step(run.s, run.st, float(times(run.i, run.i + 1)[0]) - run.st.t,
                           run.solver, run.ws)
        except SimulationError as exc:
            run.fail(exc)
        raise AssertionError("the compiled step failed but GeneralizedAlpha.step converged")
    if nsteps > cfg.k0:
        stats["h_min_used"], stats["h_max_used"] = hs


def _stepwise(run: _Run) -> None:
    """The step-by-step loop: adaptive steps (:func:`_adaptive_step`), or prescribed times
    (:func:`_prescribed_step`: fixed steps with an output grid, or the refined repetition of
    ``global_error="bound"``); the rows stored by :func:`_store`."""
    cfg, plan, stats, rec = run.cfg, run.plan, run.stats, run.rec
    t_end, adaptive = cfg.t_end, plan.adaptive
    h, err, lim = plan.h0, None, None
    while run.st.t < t_end and (adaptive or run.i < plan.nsteps):
        if adaptive and plan.schedule is None:
            new, info, h, err, lim = _adaptive_step(run, h)
            if new is None:
                continue
            st = run.st
            t1 = st.t + h if t_end - st.t - h > 1e-12 * cfg.span else t_end
            regular = True  # (an adaptive run continues to its own t_end only)
        else:
            took = _prescribed_step(run)
            if took is None:
                continue
            new, info, h, t1, regular = took
        st = run.st
        new = dataclasses.replace(new, t=t1)  # exact times, no drift
        run.i += 1
        i = run.i
        if adaptive:
            run.step_times.append(t1)
        if run.gest is not None:
            run.gest.accepted(new, final=t1 >= t_end)
        stats["newton_iterations"] += info.iterations
        stats["h_min_used"] = min(stats["h_min_used"], h)
        stats["h_max_used"] = max(stats["h_max_used"], h)
        stored, regular = _store(run, st, new, info, h, t1, regular)
        prev, run.st = st, new
        if cfg.progress is not None:
            cfg.progress(new.t, i)
        if adaptive and plan.schedule is None:
            c0 = (run.c_st if run.c_st is not None
                  else stepcontrol.coefficient(run.norm, prev, run.integ.params))
            run.c_st = stepcontrol.coefficient(run.norm, new, run.integ.params)
            cs = (c0, run.c_st)
            h = min(cfg.h_max, stepcontrol.next_step(h, err, accepted=True, c=cs, limit=lim))
        cp = None
        if stored and regular and i % plan.cpe == 0:
            cp = Checkpoint(new, i, h, stats["newton_iterations"], stats["rejected"], rec.total)
        rec.emit(cp, force=new.t >= t_end or (not adaptive and i >= plan.nsteps))


def _adaptive_step(run: _Run, h: float):
    """One adaptive step of at most ``h`` from ``run.st``: ``(new, info, h, err, lim)`` when
    accepted (``err``: the local error estimate over its share, ``lim``: the allowance,
    :mod:`se3dyn.dynamics.stepcontrol`), ``(None, None, h_retry, None, None)`` when it is to be
    retried with ``h_retry`` (a rejected step, a failed Newton iteration, or the rigid joints
    kept from now on)."""
    cfg, stats, st = run.cfg, run.stats, run.st
    h = min(h, cfg.t_end - st.t)
    if cfg.t_end - st.t - h < 1e-9 * h:
        h = cfg.t_end - st.t
    try:
        new, info = run.integ.step(run.s, st, h, run.solver, run.ws)
    except SimulationError as exc:
        if run.cond is not None and isinstance(exc, NewtonError):
            run.uncondense()
            return None, None, h, None, None
        if not isinstance(exc, NewtonError):
            run.fail(exc)
        if h / 4 < cfg.h_min:
            run.fail(NewtonError(f"{exc}; the step cannot be reduced below h_min="
                                 f"{cfg.h_min:.3g}", **_err_kwargs(exc)))
        stats["rejected"] += 1
        return None, None, h / 4, None, None
    tol_h = stepcontrol.share(cfg.tol, cfg.span, st.t, cfg.t_start, run.i, h)
    est = run.norm(info.error)
    err = est / tol_h
    lim = stepcontrol.allowance(st.t, cfg.t_start, run.i, h)
    if not err <= lim:
        if h <= cfg.h_min * (1 + 1e-9):
            worst = run.norm.worst(info.error)
            run.fail(SimulationError(
                f"t={st.t:.9g}: the local error estimate {est:.3e} m exceeds the step's "
                f"share {tol_h:.3e} m of tol={cfg.tol:g} at the minimum step "
                f"h_min={cfg.h_min:.3g}; worst: {run.s.labels[worst]} "
                "(a discontinuous input, or a tolerance too tight for the model)"))
        stats["rejected"] += 1
        stats["newton_iterations"] += info.iterations
        return None, None, max(cfg.h_min, stepcontrol.next_step(h, err, accepted=False)), \
            None, None
    q = stepcontrol.contact_ratio(run.s, st, new, h)
    if q > 1 and h > cfg.h_min * (1 + 1e-9):  # a contact not resolved: shrink (docs/contact.md)
        stats["rejected"] += 1
        stats["newton_iterations"] += info.iterations
        return None, None, max(cfg.h_min, h * max(0.2, 0.9 / q)), None, None
    new = stepcontrol.contact_restart(run.s, st, new)
    stats["error_estimate"] += est
    return new, info, h, err, lim


def _contact_steps(run: _Run, st: State, h: float):
    """A prescribed step of size ``h`` from ``st`` in as many substeps as its contacts need
    (:func:`se3dyn.dynamics.stepcontrol.contact_ratio` <= 1; a failed Newton iteration also
    shrinks the substep): ``(new, info)``, info that of the last substep with the iterations
    of all. The substep carries over to the next prescribed step while a contact is on."""
    t1 = st.t + h
    hs = min(getattr(run, "h_contact", h), h)
    cur, its, floor = st, 0, 1e-9 * h
    while True:
        left = t1 - cur.t
        if hs >= left * (1 - 1e-9):
            hs = left
        try:
            new, info = run.integ.step(run.s, cur, hs, run.solver, run.ws)
            q = stepcontrol.contact_ratio(run.s, cur, new, hs)
        except NewtonError:
            if hs / 4 < floor:
                raise
            new, q = None, 4.0
        if q > 1 and hs > floor:
            run.stats["rejected"] += 1
            hs *= max(0.2, 0.9 / q)
            continue
        its += info.iterations
        new = stepcontrol.contact_restart(run.s, cur, new)
        if hs == left:
            cur = dataclasses.replace(new, t=t1)
            break
        cur = new
        if q == 0:  # apart: a restart (contact_restart), no history to grow the step from
            hs = h
        elif q < 0.5:
            hs = min(2 * hs, h)
    run.h_contact = hs if q > 0 else h
    return cur, dataclasses.replace(info, iterations=its)


def _prescribed_step(run: _Run):
    """One step to a prescribed time (a fixed step, or a time of the refined repetition of
    ``global_error="bound"``): ``(new, info, h, t1, regular)``, with ``regular`` whether
    ``t1`` is its regular time ``t_start + k step``; None when the step is to be repeated with
    the rigid joints kept."""
    cfg, plan, st, i = run.cfg, run.plan, run.st, run.i
    if plan.schedule is not None:
        t1, regular = float(plan.schedule[i + 1]), True
    else:
        t1 = cfg.t_start + (i + 1) * cfg.step if i + 1 < plan.nsteps else cfg.t_end
        regular = t1 == cfg.t_start + (i + 1) * cfg.step
    h = t1 - st.t
    try:
        if run.s.contacts:
            new, info = _contact_steps(run, st, h)
        else:
            new, info = run.integ.step(run.s, st, h, run.solver, run.ws)
    except SimulationError as exc:
        if run.cond is not None and isinstance(exc, NewtonError):
            run.uncondense()
            return None
        run.fail(exc)
    if plan.schedule is not None:
        run.stats["error_estimate"] += run.norm(info.error)
    return new, info, h, t1, regular


def _store(run: _Run, st: State, new: State, info, h: float, t1: float, regular: bool):
    """Store the rows of the step from ``st`` to ``new`` (every ``output_every``-th step and
    the last, or the grid times up to ``t1`` by dense output); ``(stored, regular)``: whether
    the step's row is stored (a checkpoint may follow) and whether its time is regular (the
    last grid time moved to ``t_end`` is not)."""
    cfg, plan, rec = run.cfg, run.plan, run.rec
    if plan.grid is None:
        if run.i % cfg.output_every == 0 or t1 >= cfg.t_end:
            e = info.energies
            rec.add(new, e["kinetic"], e["potential"], e["spring"], info.iterations,
                    info.residual, info.constraint)
            return run.i % cfg.output_every == 0 or plan.adaptive, regular
        return False, regular
    span = cfg.span
    while run.gi < plan.n_grid and plan.grid(run.gi) <= t1 + 1e-12 * span:  # every one to t1
        tg = plan.grid(run.gi)
        if abs(tg - t1) <= 1e-12 * span:
            out = new
        else:
            out = dataclasses.replace(
                interpolate(run.s, st, new, info.increment, (tg - st.t) / h, run.ws), t=tg)
        ei = energies(run.s, out, step_inputs(run.s, tg), run.ws)
        out = dataclasses.replace(out, power=ei["power"])
        rec.add(out, ei["kinetic"], ei["potential"], ei["spring"], info.iterations,
                info.residual, info.constraint)
        if tg != cfg.t_start + cfg.output_step * run.gi:
            regular = False  # the last grid time, moved to t_end
        run.gi += 1
    return True, regular


def _run_compiled(s: System, integ: GeneralizedAlpha, st: State, times, k0: int, nsteps: int,
                  output_every: int, cpe: int, rec: _Recorder, progress, stats: dict,
                  ws: Workspace):
    """Fixed steps ``k0 <= k < nsteps`` to the times ``times(k, k1)`` in the compiled loop
    (``Stepper.run``); returns the state reached, the number of steps done (less than
    ``nsteps`` when a step failed), the factorisations and the smallest and largest step.
    Times and inputs are tabulated in blocks of about _BLOCK steps (a multiple of
    ``output_every``, starting at multiples of the block, so the stored rows are those of one
    table). Progress is reported and stored rows are passed on between chunks of steps that
    last about 0.1 s each (and fill at most the recorder's buffer in a streamed run); a chunk
    ending at a multiple ``cpe`` of steps at its regular time ends with a :class:`Checkpoint`."""
    from se3dyn.dynamics.integrator import KMAX, _stepper
    from se3dyn.engine.inputs import input_table

    block = output_every * max(1, _BLOCK // output_every)
    stp = _stepper(s, integ.index2, st.dropped, ws, split=integ.newton == "modified")
    ws.adopt(stp, st.solver)
    F = s.M + s.m
    H = np.ascontiguousarray(np.concatenate([st.H, st.HJ]).reshape(F, 4, 4), dtype=float)
    c = lambda x: np.array(x, dtype=float)  # noqa: E731
    alpha, v, vd, a, lam = c(st.alpha), c(st.v), c(st.vd), c(st.a), c(st.lam)
    acc = np.array([*st.power, st.work_act, st.work_ext, st.dissipated, st.h_last, st.t])
    ctrl = c(st.ctrl)
    am, af, g, b = integ.params
    i = k0
    fac = 0
    chunk = 16
    n_ok = nsteps
    b0 = b1 = 0
    tb = U = None
    h_lo, h_hi, t_prev = math.inf, 0.0, st.t
    t_last = float(times(nsteps - 1, nsteps)[0])
    # the last step lands on t_end: a checkpoint only if that is its regular time too
    regular_end = (nsteps % cpe == 0
                   and t_last == stats["t_start"] + float(nsteps) * stats["step"])

    def state() -> State:
        return State(t=float(acc[7]), H=H[:s.M].copy(), HJ=H[s.M:].copy(), v=v.copy(),
                     vd=vd.copy(), a=a.copy(), lam=lam.copy(), alpha=alpha.copy(),
                     work_act=float(acc[3]), work_ext=float(acc[4]), dissipated=float(acc[5]),
                     power=acc[:3].copy(), dropped=st.dropped, h_last=float(acc[6]),
                     solver=ws.memory(stp), ctrl=ctrl.copy())

    while i < n_ok:
        if i >= b1:  # the next block of times and inputs
            b0 = (i // block) * block
            b1 = min(nsteps, b0 + block)
            tb = times(b0, b1)
            U, ok = input_table(s, tb)
            if ok < len(tb):
                n_ok = b0 + ok
            hs = np.diff(np.concatenate([[t_prev], tb[i - b0:]]))
            if hs.size:
                h_lo, h_hi = min(h_lo, float(hs.min())), max(h_hi, float(hs.max()))
            t_prev = float(tb[-1])
            if i >= n_ok:
                break
        if not rec.store:  # at most a buffer of rows per chunk
            chunk = min(chunk, (rec.free() - 1) * output_every)
        i1 = min(n_ok, b1, (i // cpe + 1) * cpe,
                 max(i + 1, ((i + max(chunk, 1)) // output_every) * output_every))
        rows_needed = (i1 // output_every - i // output_every) + 1
        while rec.free() < rows_needed:
            rec._grow()
        n0 = rec.n
        tic = time.perf_counter()
        status, done, its, nf, count, res, con = stp.run(
            tb, i - b0, i1 - b0, nsteps - 1 - b0, U, output_every, am, af, g, b,
            integ.tol_residual, integ.tol_constraint * s.length_scale, float(s.length_scale),
            integ.max_iter, integ.newton == "modified", KMAX, H, alpha, v, vd, a, lam, acc,
            rec.t, rec.H.reshape(-1), rec.v.reshape(-1), rec.vd.reshape(-1),
            rec.lam.reshape(-1), rec.alpha.reshape(-1), rec.scal.reshape(-1), rec.n, ctrl)
        dt = time.perf_counter() - tic
        rec.added(count)
        stats["newton_iterations"] += its
        fac += nf
        i = b0 + done
        if rec.sink is not None:
            for r in range(n0, count):
                row = State(t=float(rec.t[r]), H=rec.H[r], HJ=np.zeros((0, 4, 4)), v=rec.v[r],
                            vd=rec.vd[r], a=rec.vd[r], lam=rec.lam[r], alpha=rec.alpha[r])
                # (read-only views of the recorder's rows)
                rec.sink_row(row, rec.scal[r])
        cp = None
        if status == 0 and i > k0 and i % cpe == 0 and (i < nsteps or regular_end):
            cp = Checkpoint(state(), i, stats["step"], stats["newton_iterations"], 0, rec.total)
        rec.emit(cp)
        if progress is not None and i > k0:
            progress(float(tb[i - 1 - b0]), i)
        if status != 0:
            break
        chunk = max(1, min(4 * chunk, int(chunk * 0.1 / max(dt, 1e-6))))
    return state(), i, fac, (h_lo, h_hi)



def _err_kwargs(exc) -> dict:
    if isinstance(exc, NewtonError):
        return dict(t=exc.t, h=exc.h, iterations=exc.iterations,
                    residual_norm=exc.residual_norm, constraint_norm=exc.constraint_norm,
                    item=exc.item)
    return {}


#: Runs of ``simulate(..., global_error="bound")`` at most (the first and its refinements),
#: and the fraction of ``tol`` a refinement aims at.
BOUND_RUNS, BOUND_AIM = 3, 0.8


def _bound(call: dict) -> Results:
    """``simulate(..., global_error="bound")``: the run, repeated on its own steps refined
    until the estimated global error is within ``tol`` (see :func:`simulate`)."""
    import warnings

    from se3dyn.errors import Se3dynWarning

    why = None
    if call["tol"] is None:
        why = "an adaptive run (tol given)"
    elif call["on_output"] is not None or call["on_rows"] is not None or call["store"] is not True:
        why = ("results kept in memory (store=True, no on_output or on_rows): a run may be "
               "repeated")
    elif call["initial_state"] is not None:
        why = "a run from the model's initial state (no initial_state)"
    if why:
        raise ModelError("simulate", "global_error", f"'bound' with {why}", "bound")
    tol = float(call["tol"])
    with warnings.catch_warnings():  # (the first run's estimate above tol is what follows)
        warnings.filterwarnings("ignore", "global error estimate", Se3dynWarning)
        res = simulate(**call, global_error=True)
    est = res.stats["global_error"]
    times = res.stats["step_times"]
    runs = [dict(refine=1, steps=res.stats["steps"], rejected=res.stats["rejected"],
                 global_error=est)]
    norm = stepcontrol.ErrorNorm(system_of(call["model"]))
    refine = 1
    while (est is not None and est > tol and len(runs) < BOUND_RUNS
           and res.stats.get("global_error_until") is None):
        m = max(2, math.ceil(math.sqrt(est / (BOUND_AIM * tol))))
        refine *= m
        frac = np.arange(refine) / refine  # every step of the first run split in `refine`
        sched = np.append((times[:-1, None] + frac * np.diff(times)[:, None]).ravel(),
                          times[-1])
        sched[::refine] = times  # (the first run's times exactly)
        try:
            new = simulate(**call, global_error=False, _schedule=sched)
        except SimulationError as exc:  # the refined run failed: the last run is kept
            runs.append(dict(refine=refine, steps=0, rejected=0, global_error=None,
                             failure=str(exc).split(";")[0]))
            break
        common, ia, ib = np.intersect1d(res.t, new.t, return_indices=True)
        est = float(norm.frames(new.H[ib], res.H[ia]).max(initial=0.0)) / (m * m - 1)
        runs.append(dict(refine=refine, steps=new.stats["steps"], rejected=0,
                         global_error=est))
        res = new
    if runs[-1].get("failure"):  # the results and estimate are the run before's
        refine = runs[-2]["refine"]
    res.stats.update(global_error=est, global_error_runs=runs, global_error_refine=refine)
    if len(runs) > 1:
        for k in ("global_error_at", "global_error_final", "global_error_history",
                  "global_error_steps"):
            res.stats.pop(k, None)
    if est is not None and est > tol:
        warnings.warn(Se3dynWarning(
            f"global_error='bound': the estimated global error {est:.3g} m is still above "
            f"tol = {tol:g} m after {len(runs)} runs (steps refined {refine} times)"
            + (f"; the refinement of the last failed: {runs[-1]['failure']}"
               if runs[-1].get("failure") else "")
            + (f"; the estimate stopped at t = {res.stats['global_error_until']:.6g} s"
               if res.stats.get("global_error_until") is not None else "")),
            stacklevel=3)
    return res



def _companion(integ: GeneralizedAlpha, s: System):
    """The step of the companion run of a global error estimate: from a state to a time, in a
    workspace of its own (:class:`~se3dyn.dynamics.stepcontrol.GlobalEstimate`)."""
    ws = Workspace(s)

    def step(st: State, t: float) -> State:
        new, _ = integ.step(s, st, t - st.t, None, ws)
        return dataclasses.replace(new, t=t)

    return step

