"""``simulate``: run the generalized-alpha integrator over a time interval and record results."""

from __future__ import annotations

import dataclasses
import math
import numbers
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from se3dyn.dynamics import stepcontrol
from se3dyn.dynamics.condense import condensation
from se3dyn.dynamics.integrator import GeneralizedAlpha, energies, interpolate
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
           "energy_warning", "energy_cause", "energy_rows", "SCALARS"]


#: Most steps of one fixed-step run (the compiled loop counts steps in 32-bit integers), and
#: most stored rows of one run; more is refused before anything is allocated.
MAX_STEPS = 10**8
#: Rows allocated at the start; the recorder grows (doubling) as the run goes.
_INITIAL_ROWS = 4096
#: Steps whose times and inputs are tabulated at once by the compiled fixed-step loop.
_BLOCK = 65536

#: Names of the scalar columns of a stored row, in order (see ``on_output`` of :func:`simulate`).
SCALARS = ("kinetic", "potential", "spring", "work_actuators", "work_loads", "dissipation",
           "iterations", "residual", "constraint")


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """A point from which a run continues bit for bit (see ``on_rows`` of :func:`simulate`).

    Attributes
    ----------
    state : State
        The integration state after the last row of the block it comes with.
    steps : int
        Steps from ``t_start`` up to ``state`` (a multiple of the checkpoint interval,
        ``CHECKPOINT_EVERY`` rounded up to a multiple of ``output_every``).
    h_next : float
        The step the run takes next (adaptive runs: the controller's step; fixed: ``step``).
    newton_iterations, rejected : int
        Counters of this call up to ``state``.
    rows : int
        Rows stored by this call up to ``state`` (its row included; the initial one too).
    """

    state: State
    steps: int
    h_next: float
    newton_iterations: int = 0
    rejected: int = 0
    rows: int = 0


#: Steps between checkpoints (a multiple of output_every is taken): states (with the linear
#: solver's memory, ``State.solver``) from which a run continues, in any process, exactly as
#: the uninterrupted run, and whose stored rows are exactly those of that run.
CHECKPOINT_EVERY = 1000
#: Bytes of rows held at most in memory by a streamed run (``store=False``) between blocks.
_STREAM_BYTES = 4 << 20
#: Wall time (s) after which rows computed step by step are passed on to ``on_rows``.
_EMIT_EVERY = 0.2


class _Recorder:
    """The stored rows of one run.

    With ``store`` every row is kept: the arrays grow in place (``ndarray.resize``, which
    reallocates without a copy where the C library can, doubling up to the rows expected) and
    are trimmed in place at the end, so the results cost their own size. Without ``store``
    (streamed runs) rows are held only until they are passed on to ``on_rows``: memory stays
    flat whatever the length of the run, and the results keep the first and the last row.
    The summary statistics (energy balance error, largest energy, constraint violation and
    Newton iterations) cover every row either way.
    """

    _FIELDS = ("t", "H", "v", "vd", "lam", "alpha", "scal")

    def __init__(self, s: System, capacity: int, sink=None, limit: int | None = None, *,
                 store: bool = True, on_rows=None, cond=None, full_ws=None):
        self.s = s
        self.cond = cond  # rows of cond.reduced, passed on as rows of cond.full (condense)
        self.full_ws = full_ws  # the run's workspace of cond.full (its rigid reactions)
        self.out_system = s if cond is None else cond.full
        self.sink = sink
        self.on_rows = on_rows
        self.store = store
        self.limit = limit  # rows expected in all (fixed steps): growth stops there
        self.row_bytes = 8 * (1 + 16 * s.M + 3 * s.nq + s.nm + 9)
        if not store:
            capacity = max(16, min(capacity, _STREAM_BYTES // self.row_bytes))
        self.n = 0  # rows in the buffer
        self.sent = 0  # rows of the buffer already passed on to on_rows
        self.summarized = 0  # rows of the buffer already in the summary
        self.total = 0  # rows recorded in all
        self.first = None  # (store=False) the first row, kept for the results
        self.pending = None  # the latest checkpoint not yet passed on
        self.last_emit = time.perf_counter()
        self.summary = dict(e0=None, balance=0.0, energy=0.0, constraint=0.0, iterations=0)
        # (np.empty: every row below self.n is written before it is read, by add() or the
        # compiled loop, and nothing reads beyond; a 1000-link chain's 1001 rows are 390 MB,
        # and the first call in a fresh process took 3.92 s with np.zeros against 3.76 s with
        # np.empty, means of 7 alternated fresh-process pairs: docs/performance.md)
        self.t = np.empty(capacity)
        self.H = np.empty((capacity, s.M, 4, 4))
        self.v = np.empty((capacity, s.nq))
        self.vd = np.empty((capacity, s.nq))
        self.lam = np.empty((capacity, s.nm))
        self.alpha = np.empty((capacity, s.nq))
        self.scal = np.empty((capacity, 9))

    def _resize(self, rows: int) -> None:
        for name in self._FIELDS:
            shape = (rows,) + getattr(self, name).shape[1:]
            try:
                # in place (realloc), zero-filled; refused while anything else references the
                # array (so no local name for it here)
                getattr(self, name).resize(shape)
            except ValueError:
                old = getattr(self, name)
                new = np.zeros(shape)
                k = min(rows, len(old))
                new[:k] = old[:k]
                setattr(self, name, new)
                del old

    def _grow(self):
        n = len(self.t)
        if not self.store:
            self._resize(2 * n)  # rows of one step beyond the buffer (dense output)
            return
        extra = n if self.limit is None or self.limit <= n else min(n, self.limit - n)
        self._resize(n + max(extra, 1))

    def free(self) -> int:
        """Rows that fit in the buffer without growing it."""
        return len(self.t) - self.n

    def add(self, st: State, kin: float, pot: float, spring: float, iters: int, res: float,
            con: float):
        if self.n == len(self.t):
            self._grow()
        i = self.n
        self.t[i] = st.t
        self.H[i] = st.H
        self.v[i] = st.v
        self.vd[i] = st.vd
        self.lam[i] = st.lam
        self.alpha[i] = st.alpha
        self.scal[i] = (kin, pot, spring, st.work_act, st.work_ext, st.dissipated, iters, res,
                        con)
        self.n += 1
        self.total += 1
        if self.sink is not None:
            self.sink_row(st, self.scal[i])

    def sink_row(self, st: State, scal: np.ndarray) -> None:
        """Pass a stored row on to ``on_output`` (as a state of the model's own system)."""
        self.sink(st if self.cond is None else self.cond.expand(st, self.full_ws),
                  dict(zip(SCALARS, scal.tolist(), strict=True)))

    def added(self, count: int) -> None:
        """``count`` rows were written into the buffer by the compiled loop."""
        self.total += count - self.n
        self.n = count

    def _summarize(self) -> None:
        lo, hi = self.summarized, self.n
        if hi <= lo:
            return
        c = self.scal[lo:hi]
        sm = self.summary
        if sm["e0"] is None:  # the first row: the references of the balance and the scale
            sm["e0"] = c[0, :6].copy()
        err, scale = _balance_and_scale(c, sm["e0"])
        sm["balance"] = max(sm["balance"], err)
        sm["scale"] = max(sm.get("scale", 0.0), scale)
        sm["energy"] = max(sm["energy"], float(np.abs(c[:, 0] + c[:, 1] + c[:, 2]).max()))
        sm["constraint"] = max(sm["constraint"], float(c[:, 8].max()))
        sm["iterations"] = max(sm["iterations"], int(c[:, 6].max()))
        self.summarized = hi

    def _block(self, lo: int, hi: int, stats: dict | None = None, copy: bool = True
               ) -> Results:
        c = self.scal[lo:hi]
        cp = (lambda x: x[lo:hi].copy()) if copy else (lambda x: x[lo:hi])  # noqa: E731
        rows = dict(t=cp(self.t), H=cp(self.H), v=cp(self.v), vd=cp(self.vd),
                    lam=cp(self.lam), alpha=cp(self.alpha))
        if self.cond is not None:
            rows["H"], rows["v"], rows["vd"], rows["alpha"], rows["lam"] = (
                self.cond.expand_rows(rows["H"], rows["v"], rows["vd"], rows["alpha"],
                                      rows["lam"]))
        out = Results(system=self.out_system, **rows,
                      kinetic=c[:, 0].copy(), potential=c[:, 1].copy(), spring=c[:, 2].copy(),
                      work_actuators=c[:, 3].copy(), work_loads=c[:, 4].copy(),
                      dissipation=c[:, 5].copy(), iterations=c[:, 6].astype(int),
                      residual=c[:, 7].copy(), constraint=c[:, 8].copy(),
                      stats=stats if stats is not None else {})
        if self.cond is not None and len(self.cond.rigid):
            out.defer_multipliers(self.cond.fill_multipliers)
        return out

    def emit(self, checkpoint: Checkpoint | None = None, force: bool = True) -> None:
        """Pass the new rows (and the checkpoint reached after them) on to ``on_rows``; in a
        streamed run, drop them from the buffer. Without ``force``, only when the buffer is
        nearly full or ``_EMIT_EVERY`` seconds have passed."""
        if checkpoint is not None:
            self.pending = checkpoint  # passed on with the next block
        if not force and self.free() > 1 and time.perf_counter() - self.last_emit < _EMIT_EVERY:
            return
        self._summarize()
        checkpoint, self.pending = self.pending, None
        if checkpoint is not None and self.cond is not None and self.on_rows is not None:
            checkpoint = dataclasses.replace(checkpoint,
                                             state=self.cond.expand(checkpoint.state,
                                                                    self.full_ws))
        if self.on_rows is not None and (self.n > self.sent or checkpoint is not None):
            self.on_rows(self._block(self.sent, self.n), checkpoint)
        self.sent = self.n
        self.last_emit = time.perf_counter()
        if not self.store and self.n:
            if self.first is None:
                self.first = self._block(0, 1)
            self._move_last_to_front()

    def uncondense(self) -> None:
        """The run goes on with the rigid joints kept: the rows held become the model's own
        (their rigid joints' multipliers computed now), and so will the next ones."""
        c, n, cap = self.cond, self.n, len(self.t)
        rows = c.expand_rows(self.H[:n], self.v[:n], self.vd[:n], self.alpha[:n], self.lam[:n])
        c.fill_rows(self.t[:n], rows[0], rows[3], rows[1], rows[2], rows[4], self.full_ws)
        for name, arr in zip(("H", "v", "vd", "alpha", "lam"), rows, strict=True):
            new = np.zeros((cap,) + arr.shape[1:])
            new[:n] = arr
            setattr(self, name, new)
        if self.pending is not None:
            self.pending = dataclasses.replace(self.pending,
                                               state=c.expand(self.pending.state,
                                                              self.full_ws))
        self.s = self.out_system = c.full
        self.cond = None
        s = self.s
        self.row_bytes = 8 * (1 + 16 * s.M + 3 * s.nq + s.nm + 9)

    def _move_last_to_front(self) -> None:
        """(store=False) Keep only the last row, at the front of the buffer."""
        for name in self._FIELDS:
            arr = getattr(self, name)
            arr[0] = arr[self.n - 1]
        self.n = self.sent = self.summarized = 1

    def last_time(self) -> float | None:
        return float(self.t[self.n - 1]) if self.n else None

    def stats(self) -> dict:
        """The summary statistics over every row recorded."""
        self._summarize()
        sm = self.summary
        return dict(rows=self.total, energy_balance_error=sm["balance"],
                    energy_scale=sm.get("scale", 0.0), max_energy=sm["energy"],
                    max_constraint=sm["constraint"], max_iterations=sm["iterations"])

    def results(self, stats: dict) -> Results:
        stats.update(self.stats())
        n = self.n
        if not self.store:
            first = self.first if self.first is not None else (
                self._block(0, 1) if n else None)
            last = self._block(n - 1, n) if n else None
            if self.total <= 1 or first is None or last is None:
                out = first if first is not None else last
                out.stats = stats
                return out
            return Results(system=self.out_system, stats=stats, **{
                f.name: np.concatenate([getattr(first, f.name), getattr(last, f.name)])
                for f in dataclasses.fields(Results) if f.name not in ("system", "stats")})
        # in place: the trimmed arrays become the results (no copy of the rows)
        self._resize(n)
        return self._block(0, n, stats, copy=False)


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
        output (:func:`~se3dyn.dynamics.integrator.interpolate`), whatever the internal steps; without
        it every (``output_every``-th) step is stored.
    engine : {"auto", "compiled", "numpy"}
        Compiled kernels (:mod:`se3dyn.fast`) or the numpy implementation, see
        :class:`~se3dyn.dynamics.integrator.GeneralizedAlpha`. With a fixed step and no ``progress``,
        ``on_output`` or ``output_step``, the whole time loop runs compiled.
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
    t_end, step, t_start, output_every, span, opt = _settings(
        t_end, step, t_start, output_every, tol, h_min, h_max, output_step)
    for fld, val in (("progress", progress), ("on_output", on_output), ("on_rows", on_rows)):
        if val is not None and not callable(val):
            raise ModelError("simulate", fld, "a callable or None", val)
    for fld, val in (("store", store), ("condense", condense)):
        if not isinstance(val, bool | np.bool_):
            raise ModelError("simulate", fld, "True or False", val)
    store, condense = bool(store), bool(condense)
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
    _check_size(s, span, step, output_every, opt["output_step"], adaptive, store)
    if isinstance(rho_inf, numbers.Real) and not isinstance(rho_inf, bool):
        rho_inf = float(rho_inf)
    integ = GeneralizedAlpha(rho_inf=rho_inf, tol_residual=tol_residual,
                             tol_constraint=tol_constraint, max_iter=max_iter,
                             formulation=formulation, redundant=redundant, engine=engine,
                             newton=newton, initial_velocities=initial_velocities)
    grid = None  # the output times t_start + j output_step, the last moved to t_end
    gi = 1  # next grid time to fill
    if opt["output_step"] is not None:
        k = max(1, math.ceil(span / opt["output_step"] - 1e-9))
        dt_out = opt["output_step"]

        def grid(j: int) -> float:  # computed when needed: nothing allocated per row
            return t_end if j >= k else min(t_start + dt_out * j, t_end)

        n_grid = k + 1
        capacity = n_grid
        if initial_state is not None:
            gi = min(n_grid, max(1, int((initial_state.t - t_start) / dt_out) - 1))
            while gi < n_grid and grid(gi) <= initial_state.t + 1e-12 * span:
                gi += 1
            capacity = n_grid - gi + 1
    elif adaptive:
        capacity = 1024
    else:
        capacity = (max(1, math.ceil(span / step - 1e-9)) // output_every + 2
                    - k0 // output_every)
    wall0 = time.perf_counter()
    ws = Workspace(s)  # this run's engine and steppers, shared with no other run
    if initial_state is None:
        st = integ.init(s, t_start, ws=ws)
    else:
        st = initial_state
    e = energies(s, st, step_inputs(s, st.t), ws)
    # (a continued run starts from a state, not from the model's velocities)
    v_report = _velocity_report(s, st, e["kinetic"], ws) if initial_state is None else {}
    model_system, redundant_names = s, [equation_name(s, r) for r in st.dropped]
    ws_full = ws  # the model's own system: its state at t0, the condensed rows expanded
    # rigid joints condensed for the time loop (se3dyn.dynamics.condense): the steps run on the
    # reduced system, the stored rows are the model's own
    cond = condensation(s) if condense else None
    if cond is not None:
        reduced = cond.restrict(st if initial_state is not None
                                else dataclasses.replace(st, solver=None))
        if reduced is None:  # a redundant equation of a rigid joint: kept as it is
            cond = None
        else:
            s, st = cond.reduced, reduced
            ws = Workspace(s)
    run_ws = [ws_full] + ([ws] if ws is not ws_full else [])  # (their steppers' counters)
    # storage grows as the run goes (doubling, up to the rows expected)
    rec = _Recorder(s, min(capacity, _INITIAL_ROWS), on_output,
                    None if adaptive and grid is None else capacity, store=store,
                    on_rows=on_rows, cond=cond, full_ws=ws_full)
    solver = integ.solver(s, st)
    rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
    stats = dict(steps=0, rejected=0, newton_iterations=0, rho_inf=rho_inf, step=step,
                 t_start=t_start, t_end=t_end, tol_residual=tol_residual,
                 tol_constraint=tol_constraint, unknowns=model_system.nq,
                 multipliers=model_system.nm, matrix_size=solver.N, formulation=formulation,
                 redundant=redundant_names,
                 condensed=[] if cond is None else [model_system.joint_names[j]
                                                     for j in cond.rigid],
                 linear_solver="dense LU" if solver.dense else "sparse LU (SuperLU)",
                 adaptive=adaptive, tol=opt["tol"], h_min_used=math.inf, h_max_used=0.0,
                 **v_report)
    if initial_state is not None:
        stats["resumed_at"] = st.t
    gest = None  # the companion run of the global error estimate
    step_times = [st.t]  # of an adaptive run: the times its accepted steps reached
    c_st = None  # the error coefficient of the state st, once computed (stepcontrol)
    if adaptive:
        norm = stepcontrol.ErrorNorm(s)
        stats["error_estimate"] = 0.0
        if global_error:
            gest = stepcontrol.GlobalEstimate(norm, st, _companion(integ, s))
    nsteps = 0 if adaptive else max(1, math.ceil(span / step - 1e-9))
    h = min(step, opt["h_max"]) if adaptive else step
    if adaptive and first_step is not None:
        h = min(first_step, opt["h_max"])
    i = k0
    cpe = output_every * math.ceil(CHECKPOINT_EVERY / output_every)  # checkpoint interval
    if k0 % cpe == 0:  # the start is a checkpoint too
        rec.pending = Checkpoint(st, k0, h, 0, 0, 1)

    def uncondense() -> None:
        # a step of the reduced system failed: the run goes on with the rigid joints kept
        # (a condensed run never fails where the model itself goes on; stats say from when)
        nonlocal s, st, ws, solver, cond, norm, c_st
        c_st = None  # (another norm from here)
        stats["condensed_until"] = st.t
        full = dataclasses.replace(cond.expand(st, ws_full), solver=None)
        rec.uncondense()
        if gest is not None:
            gest.replace(stepcontrol.ErrorNorm(model_system),
                         dataclasses.replace(cond.expand(gest.coarse, ws_full), solver=None),
                         _companion(integ, model_system))
        s, st, cond, ws = model_system, full, None, ws_full
        solver = integ.solver(s, st)
        if adaptive:
            norm = stepcontrol.ErrorNorm(s)

    def final_stats(failed: bool) -> None:  # (the run's end, or where it failed)
        if gest is not None:
            stats.update(gest.stats())
        if adaptive:
            stats["step_times"] = np.asarray(step_times)
        if integ.index2:  # (split index-2 steps that fell back to the full matrix)
            stats["full_matrix_steps"] = sum(w.full_matrix_steps() for w in run_ws)
        stats.update(steps=i - k0, failed=failed, wall_time=time.perf_counter() - wall0,
                     final_state=st if cond is None else cond.expand(st, ws_full))

    def fail(exc: SimulationError):
        final_stats(True)
        if grid is None and rec.n and rec.last_time() != st.t:
            e = energies(s, st, step_inputs(s, st.t), ws)
            rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
        rec.emit()
        exc.result = rec.results(stats)
        raise exc

    stats["linear_solver"] = ("sparse LU (se3dyn/_core/sparse_lu.hpp)"
                              + (" and LDL^T (sparse_ldlt.hpp) of the split index-2 iteration's "
                                 "xi block" if integ.index2 and integ.newton == "modified" and s.nm
                                 else ""))
    stats["engine"] = "compiled"
    if not adaptive and grid is None:
        # the whole fixed-step loop in the compiled engine, in chunks between which progress
        # and streamed rows are reported; a failing step is repeated by
        # GeneralizedAlpha.step, which raises the error naming time, norms and item
        def times(k0: int, k1: int) -> np.ndarray:  # the times of steps k0 <= k < k1
            out = t_start + np.arange(k0 + 1, k1 + 1, dtype=np.int64).astype(float) * step
            if k1 == nsteps:
                out[-1] = t_end
            return out

        st, i, fac, hs = _run_compiled(s, integ, st, times, k0, nsteps, output_every, cpe,
                                       rec, progress, stats, ws)
        if i < nsteps and cond is not None:
            uncondense()
            st, i, fac2, hs2 = _run_compiled(s, integ, st, times, i, nsteps, output_every,
                                             cpe, rec, progress, stats, ws)
            fac += fac2
            hs = (min(hs[0], hs2[0]), max(hs[1], hs2[1]))
        stats["factorizations"] = fac
        if i < nsteps:
            try:
                integ.step(s, st, float(times(i, i + 1)[0]) - st.t, solver, ws)
            except SimulationError as exc:
                fail(exc)
            raise AssertionError("the compiled step failed but GeneralizedAlpha.step converged")
        if nsteps > k0:
            stats["h_min_used"], stats["h_max_used"] = hs
    while st.t < t_end and (adaptive or i < nsteps):
        if adaptive and _schedule is None:
            h = min(h, t_end - st.t)
            if t_end - st.t - h < 1e-9 * h:
                h = t_end - st.t
            try:
                new, info = integ.step(s, st, h, solver, ws)
            except SimulationError as exc:
                if cond is not None and isinstance(exc, NewtonError):
                    uncondense()
                    continue
                if not isinstance(exc, NewtonError):
                    fail(exc)
                if h / 4 < opt["h_min"]:
                    fail(NewtonError(f"{exc}; the step cannot be reduced below h_min="
                                     f"{opt['h_min']:.3g}", **_err_kwargs(exc)))
                stats["rejected"] += 1
                h /= 4
                continue
            tol_h = stepcontrol.share(opt["tol"], span, st.t, t_start, i, h)
            est = norm(info.error)
            err = est / tol_h
            lim = stepcontrol.allowance(st.t, t_start, i, h)
            if not err <= lim:
                if h <= opt["h_min"] * (1 + 1e-9):
                    worst = norm.worst(info.error)
                    fail(SimulationError(
                        f"t={st.t:.9g}: the local error estimate {est:.3e} m exceeds the step's "
                        f"share {tol_h:.3e} m of tol={opt['tol']:g} at the minimum step "
                        f"h_min={opt['h_min']:.3g}; worst: {s.labels[worst]} "
                        "(a discontinuous input, or a tolerance too tight for the model)"))
                stats["rejected"] += 1
                stats["newton_iterations"] += info.iterations
                h = max(opt["h_min"], stepcontrol.next_step(h, err, accepted=False))
                continue
            stats["error_estimate"] += est
            t1 = st.t + h if t_end - st.t - h > 1e-12 * span else t_end
            regular = True  # (an adaptive run continues to its own t_end only)
        else:  # prescribed times: fixed steps, or the refined repetition of global_error="bound"
            if _schedule is not None:
                t1, regular = float(_schedule[i + 1]), True
            else:
                t1 = t_start + (i + 1) * step if i + 1 < nsteps else t_end
                regular = t1 == t_start + (i + 1) * step
            h = t1 - st.t
            try:
                new, info = integ.step(s, st, h, solver, ws)
            except SimulationError as exc:
                if cond is not None and isinstance(exc, NewtonError):
                    uncondense()
                    continue
                fail(exc)
            if _schedule is not None:
                stats["error_estimate"] += norm(info.error)
        new = dataclasses.replace(new, t=t1)  # exact times, no drift
        i += 1
        if adaptive:
            step_times.append(t1)
        if gest is not None:
            gest.accepted(new, final=t1 >= t_end)
        stats["newton_iterations"] += info.iterations
        stats["h_min_used"] = min(stats["h_min_used"], h)
        stats["h_max_used"] = max(stats["h_max_used"], h)
        stored = False
        if grid is not None:
            stored = True  # every grid time up to t1 is filled
            while gi < n_grid and grid(gi) <= t1 + 1e-12 * span:
                tg = grid(gi)
                if abs(tg - t1) <= 1e-12 * span:
                    out = new
                else:
                    out = dataclasses.replace(
                        interpolate(s, st, new, info.increment, (tg - st.t) / h, ws), t=tg)
                ei = energies(s, out, step_inputs(s, tg), ws)
                out = dataclasses.replace(out, power=ei["power"])
                rec.add(out, ei["kinetic"], ei["potential"], ei["spring"], info.iterations,
                        info.residual, info.constraint)
                if tg != t_start + opt["output_step"] * gi:
                    regular = False  # the last grid time, moved to t_end
                gi += 1
        elif i % output_every == 0 or t1 >= t_end:
            e = info.energies
            rec.add(new, e["kinetic"], e["potential"], e["spring"], info.iterations,
                    info.residual, info.constraint)
            stored = i % output_every == 0 or adaptive
        prev, st = st, new
        if progress is not None:
            progress(st.t, i)
        if adaptive and _schedule is None:
            c0 = c_st if c_st is not None else stepcontrol.coefficient(norm, prev, integ.params)
            c_st = stepcontrol.coefficient(norm, st, integ.params)
            cs = (c0, c_st)
            h = min(opt["h_max"],
                    stepcontrol.next_step(h, err, accepted=True, c=cs, limit=lim))
        cp = None
        if stored and regular and i % cpe == 0:
            cp = Checkpoint(st, i, h, stats["newton_iterations"], stats["rejected"], rec.total)
        rec.emit(cp, force=st.t >= t_end or (not adaptive and i >= nsteps))
    rec.emit()
    final_stats(False)
    res = rec.results(stats)
    _energy_check(res)
    _global_error_check(res)
    return res


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


def _global_error_setting(val, adaptive: bool) -> bool:
    """``global_error`` checked: True or False, True with ``tol`` only ("bound" is handled
    by :func:`_bound`)."""
    on = True if isinstance(val, str) and val == "bound" else val
    if not isinstance(on, bool | np.bool_):
        raise ModelError("simulate", "global_error", "True, False or 'bound'", val)
    if on and not adaptive:
        raise ModelError("simulate", "global_error", "an adaptive run (tol given): the "
                         "estimate follows the run's own steps", val)
    return bool(on)


def _companion(integ: GeneralizedAlpha, s: System):
    """The step of the companion run of a global error estimate: from a state to a time, in a
    workspace of its own (:class:`~se3dyn.dynamics.stepcontrol.GlobalEstimate`)."""
    ws = Workspace(s)

    def step(st: State, t: float) -> State:
        new, _ = integ.step(s, st, t - st.t, None, ws)
        return dataclasses.replace(new, t=t)

    return step


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


def _settings(t_end, step, t_start, output_every, tol, h_min, h_max, output_step):
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
    a = b.arguments
    s = system_of(model)
    t_end, step, t_start, output_every, span, opt = _settings(
        a["t_end"], a["step"], a["t_start"], a["output_every"], a["tol"], a["h_min"],
        a["h_max"], a["output_step"])
    _check_size(s, span, step, output_every, opt["output_step"], opt["tol"] is not None)
    _global_error_setting(a["global_error"], opt["tol"] is not None)
    GeneralizedAlpha(rho_inf=a["rho_inf"], tol_residual=a["tol_residual"],
                     tol_constraint=a["tol_constraint"], max_iter=a["max_iter"],
                     formulation=a["formulation"], redundant=a["redundant"],
                     engine=a["engine"], newton=a["newton"],
                     initial_velocities=a["initial_velocities"])


def _velocity_report(s: System, st: State, kinetic: float, ws) -> dict:
    """Stats entries on the initial velocities init changed (and a warning when they matter)."""
    import warnings

    from se3dyn.dynamics.integrator import initial_velocity_changes
    from se3dyn.errors import Se3dynWarning

    changes = initial_velocity_changes(s, st)
    if not changes:
        return dict(initial_velocity_changes=[])
    v0 = np.zeros(s.nq)
    v0[s.node_dofidx] = s.node_v0[s.node_free]
    given = energies(s, dataclasses.replace(st, v=v0), step_inputs(s, st.t), ws)["kinetic"]
    rows = [dict(node=c["node"], dv=c["dv"], dw=c["dw"], given=c["given"].tolist(),
                 used=c["used"].tolist()) for c in changes]
    scale = max(float(np.abs(s.node_v0).max()), 1e-300)
    worst = max(changes, key=lambda c: max(c["dv"], c["dw"]))
    if max(worst["dv"], worst["dw"]) > 1e-6 * scale:
        names = ", ".join(repr(c["node"]) for c in changes[:5]) + (
            f" and {len(changes) - 5} more" if len(changes) > 5 else "")
        warnings.warn(Se3dynWarning(
            f"initial velocities projected onto the joints' velocity constraints: {names} "
            f"changed (largest: node {worst['node']!r}, velocity by {worst['dv']:.3g} m/s, "
            f"angular velocity by {worst['dw']:.3g} rad/s); kinetic energy {given:.6g} J "
            f"given, {kinetic:.6g} J used (stats['initial_velocity_changes']; "
            "initial_velocities='strict' refuses them)"), stacklevel=3)
    return dict(initial_velocity_changes=rows, initial_kinetic_energy_given=float(given),
                initial_kinetic_energy_used=float(kinetic))


def energy_balance_check(res: Results) -> tuple[float, float]:
    """The largest energy balance error of a run and the energy scale it compares with (J).

    The error is the largest drift of kinetic + potential + elastic energy - work of actuators
    and loads + dissipation from its initial value. The scale is the largest of the kinetic and
    the elastic energy (absolute quantities) and of the changes of the gravity potential (its
    zero is arbitrary), of the works and of the dissipation over the run: the energy in play (a
    pendulum released from rest has no energy at t0, a free spinning body exchanges none).
    """
    if not len(res.t):
        return 0.0, 0.0
    c = energy_rows(res)
    return _balance_and_scale(c, c[0])


def _balance_and_scale(c: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(largest energy balance drift, energy in play) of scalar rows ``c`` (n, >= 6) in the
    order of SCALARS (kinetic, potential, spring, actuator work, load work, dissipated),
    measured from the first row of the run ``ref`` (6,); see :func:`energy_balance_check`."""
    def bal(x):  # energy - works + dissipation
        return x[..., 0] + x[..., 1] + x[..., 2] - x[..., 3] - x[..., 4] + x[..., 5]

    err = float(np.abs(bal(c[:, :6]) - bal(ref)).max())
    rel = [1, 3, 4, 5]  # the gravity potential's zero is arbitrary; works start at ref
    scale = max(float(np.abs(c[:, 0]).max()), float(np.abs(c[:, 2]).max()),
                float(np.abs(c[:, rel] - ref[rel]).max()))
    return err, scale


def energy_jump(t: np.ndarray, c: np.ndarray) -> dict | None:
    """Where the energy balance changed most between two consecutive stored rows.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Stored times.
    c : ndarray, shape (n, >= 6)
        Energies and works in the order of :data:`SCALARS` (kinetic, potential, spring,
        actuator work, load work, dissipated).

    Returns
    -------
    dict or None
        ``t0``, ``t1`` (s): the rows around the largest change; ``jump`` (J): the change of
        ``E - W_actuators - W_loads + dissipation`` between them; ``first``: whether they are the
        run's first two rows. None with fewer than two rows.
    """
    c = np.asarray(c, dtype=float)
    if len(c) < 2:
        return None
    b = c[:, 0] + c[:, 1] + c[:, 2] - c[:, 3] - c[:, 4] + c[:, 5]
    d = np.diff(b)
    k = int(np.argmax(np.abs(d)))
    return dict(t0=float(t[k]), t1=float(t[k + 1]), jump=float(d[k]), first=k == 0)


def energy_warning(err: float, scale: float, jump: dict | None = None) -> str | None:
    """The warning on a large energy balance error (above 10 % of the energy in play), with
    when and how large its largest jump between stored rows was (:func:`energy_jump`); None
    when the balance is fine."""
    if not (err > 0.1 * scale and err > 1e-12):
        return None
    return (f"energy balance error {err:.3g} J is {100 * err / max(scale, 1e-300):.3g} % of "
            f"the energy in play in the run ({scale:.3g} J)" + energy_cause(err, jump))


def energy_cause(err: float, jump: dict | None) -> str:
    """The end of :func:`energy_warning`: the largest jump (when known) and the likely cause,
    starting with ``"; "`` or ``": "``."""
    text = ""
    if jump is not None:
        share = abs(jump["jump"]) / max(err, 1e-300)
        text = (f"; its largest jump, {jump['jump']:+.3g} J ({100 * share:.3g} % of the "
                f"error), between t = {jump['t0']:.6g} and {jump['t1']:.6g} s")
        if jump["first"] and share >= 0.5:
            return text + (" (the first step): a start the step does not resolve, e.g. "
                           "velocities or forces switched on at t0 (an impulsive start), rather "
                           "than a step too large for the motion after it")
    return text + (": the step is probably too large for the motion (the results may be far "
                   "from the true motion; try a smaller step, or rho_inf < 1 with the index-3 "
                   "form)")


def energy_rows(res: Results) -> np.ndarray:
    """The energies and works of a result's rows, (n, 6) in the order of :data:`SCALARS`."""
    return np.stack([res.kinetic, res.potential, res.spring, res.work_actuators,
                     res.work_loads, res.dissipation], axis=1)


def _energy_check(res: Results) -> None:
    import warnings

    from se3dyn.errors import Se3dynWarning

    if "energy_scale" in res.stats:  # over every row, streamed ones included (_Recorder)
        err, scale = res.stats["energy_balance_error"], res.stats["energy_scale"]
    else:
        err, scale = energy_balance_check(res)
        res.stats.update(energy_balance_error=err, energy_scale=scale)
    if energy_warning(err, scale) is None:
        return
    jump = None
    if len(res.t) == res.stats.get("rows", len(res.t)):  # every row held (not streamed)
        jump = energy_jump(res.t, energy_rows(res))
        if jump is not None:
            res.stats["energy_jump"] = jump
    warnings.warn(Se3dynWarning(energy_warning(err, scale, jump)), stacklevel=3)


def _global_error_check(res: Results) -> None:
    import warnings

    from se3dyn.errors import Se3dynWarning

    ge, tol = res.stats.get("global_error"), res.stats.get("tol")
    if ge is not None and tol is not None and ge > tol:
        warnings.warn(Se3dynWarning(
            f"global error estimate {ge:.3g} m is {ge / tol:.3g} times tol = {tol:g} m (largest "
            f"at t = {res.stats['global_error_at']:.6g} s): the motion amplifies the local "
            "errors; a smaller tol brings it down (docs/accuracy.md)"), stacklevel=3)


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
                     solver=ws.memory(stp))

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
            rec.lam.reshape(-1), rec.alpha.reshape(-1), rec.scal.reshape(-1), rec.n)
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
