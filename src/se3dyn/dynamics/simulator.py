"""``Simulator``: the fixed-step time loop of :func:`~se3dyn.dynamics.run.simulate`, stepped
by the user's own control loop (``docs/control.md``, "Stepping simulator").

A Simulator is a run of ``simulate`` held open: the same settings checked the same way, the same
start (:class:`~se3dyn.dynamics.run._Run`: the initial state, the condensed rigid joints, the
recorder) and the same compiled fixed-step loop (``Stepper.run``, ``se3dyn/_core/newton.hpp``),
called for the steps asked for. The compiled loop carries its state in arrays between calls and
``simulate`` itself calls it in chunks of any length, so stepping in pieces computes the numbers
of one ``simulate`` over the whole interval, bit for bit.

Inputs are the model's time-dependent inputs (:class:`se3dyn.engine.inputs._Inputs`): a value
set by :meth:`Simulator.set_input` replaces the model's time function from the next step on and
is held (zero-order hold) until set again or cleared.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import warnings
from typing import TYPE_CHECKING

import numpy as np

from se3dyn.dynamics.integrator import KMAX, _stepper, energies
from se3dyn.dynamics.reports import _balance_and_scale
from se3dyn.dynamics.run import _plan, _Run
from se3dyn.dynamics.settings import RunSettings, _check_initial_state
from se3dyn.dynamics.state import State
from se3dyn.engine.inputs import _DERIV, _sample, input_table, step_inputs
from se3dyn.engine.system import System, system_of
from se3dyn.engine.workspace import Workspace
from se3dyn.errors import ModelError, NewtonError, SimulationError, close_matches
from se3dyn.results.channels import escape_name, get_channel
from se3dyn.results.results import Results

if TYPE_CHECKING:
    from se3dyn.model.specs import Model

__all__ = ["Simulator", "SimulatorState"]

#: Steps whose times and model inputs are tabulated at once (a multiple of ``output_every`` is
#: taken, blocks start at multiples of it, as in ``simulate``).
_TABLE = 1024

#: Channels that are stored scalars of a row: their column of the recorder's ``scal``
#: (``se3dyn.dynamics.recorder.SCALARS``; -1: the time).
_STORED = {"time": -1, "energy/kinetic": 0, "energy/potential": 1, "energy/spring": 2,
           "energy/work_actuators": 3, "energy/work_loads": 4, "energy/dissipation": 5,
           "solver/iterations": 6, "solver/residual": 7, "solver/constraint": 8}



@dataclasses.dataclass(frozen=True)
class SimulatorState:
    """Everything a :class:`Simulator` needs to continue from a point, bit for bit
    (:attr:`Simulator.state`, :meth:`Simulator.restore`); immutable.

    Attributes
    ----------
    state : State
        The integration state (frames, velocities, accelerations, the generalized-alpha
        variable, multipliers, coordinates, works, powers, the linear solver's memory) of the
        system stepped: the condensed one while rigid joints are condensed.
    steps : int
        Steps from ``t_start`` (``state.t = t_start + steps * step``).
    condensed : bool
        Whether the rigid joints were condensed (a run that kept them after a failing
        condensed step continues so).
    held : tuple of (name, ndarray)
        The inputs held by :meth:`Simulator.set_input`.
    row : ndarray (9,)
        The scalars of the state's stored row (energies, works, Newton iterations, residual,
        constraint violation; ``se3dyn.dynamics.recorder.SCALARS``).
    u : ndarray (nu,)
        The inputs of the step that reached the state (the multipliers of condensed rigid
        joints are computed from them).
    t_start, step : float
        The time grid of the simulator that made it.
    """

    state: State
    steps: int
    condensed: bool
    held: tuple
    row: np.ndarray
    u: np.ndarray
    t_start: float
    step: float

    def __post_init__(self):
        for x in (self.row, self.u, *(v for _, v in self.held)):
            x.flags.writeable = False

    @property
    def t(self) -> float:
        return self.state.t


def _input_specs(s: System) -> dict:
    """name -> (slot, k, slot of the rate a held target holds at zero or -1) of the inputs a
    user may set (see :class:`Simulator`)."""
    out, rates = {}, {}
    for kind, item, fld, slot, k in s.inputs.names:
        name = kind if item is None else f"{kind}/{escape_name(item)}/{fld}"
        out[name] = [slot, k, -1]
        if fld == "target_rate":
            rates[f"{kind}/{escape_name(item)}/target"] = slot
    for name, slot in rates.items():
        out[name][2] = slot
    return {n: tuple(v) for n, v in out.items()}


class Simulator:
    """The time loop of :func:`~se3dyn.dynamics.run.simulate` (fixed steps), stepped by the
    caller: for controllers written in Python, co-simulation and anything that decides the
    next inputs from the state reached.

    >>> sim = sd.Simulator(model, step=1e-3)             # doctest: +SKIP
    >>> while sim.t < 2.0:                                # doctest: +SKIP
    ...     q, w = sim.read("joint/j1/alpha/0"), sim.read("joint/j1/velocity/0")
    ...     sim.set_input("joint/j1/actuator", -kp * q - kd * w)
    ...     sim.step()
    >>> res = sim.results()                               # doctest: +SKIP

    Parameters
    ----------
    model : Model or System
    step : float
        The time step h (s); the steps reach the times ``t_start + k h``.
    rho_inf, t_start, tol_residual, tol_constraint, max_iter, output_every, formulation, \
redundant, newton, initial_velocities, condense :
        As for :func:`~se3dyn.dynamics.run.simulate` (checked alike; a
        :class:`~se3dyn.errors.ModelError` names the field). ``output_every``: keep every
        k-th step's row in :meth:`results` (the current state's row is always there).

    Inputs (:attr:`inputs`; names as the results channels write them, ``/`` and ``%`` in item
    names escaped):

    ``joint/<joint>/actuator`` (k)
        the actuator force or torque of a joint that has one in the model (``actuator=``,
        ``torque=``, ``force=``; give ``actuator=0.0`` to a joint to be driven from here);
    ``joint/<joint>/target``, ``joint/<joint>/target_rate`` (k)
        the target and target rate of a joint's PD law (``control=sd.PD(...)``); a held
        target holds the target rate at 0 unless ``target_rate`` is held too;
    ``load/<load>/force``, ``load/<load>/torque`` (3)
        a load's force and torque (each one the load has), in the load's frames;
    ``gravity`` (3)
        the gravitational acceleration.

    A value set by :meth:`set_input` is used from the next step on, for every step until it
    is set again or :meth:`clear_input` returns the input to the model's time function: a
    zero-order hold, as a sampled controller drives its plant. Steps taken with the model's
    own inputs compute exactly what ``simulate`` computes.
    """

    def __init__(self, model: Model | System, step: float, *, rho_inf: float = 0.9,
                 t_start: float = 0.0, tol_residual: float = 1e-10,
                 tol_constraint: float = 1e-11, max_iter: int = 25, output_every: int = 1,
                 formulation: str = "index2", redundant: str = "drop",
                 newton: str = "modified", initial_velocities: str = "project",
                 condense: bool = True):
        s = system_of(model)
        if s.contacts:  # (its compiled loop has no contact-aware substeps: docs/contact.md)
            raise ModelError("Simulator", "model", "a model without contact pairs (the "
                             "contact-aware substeps run in simulate only, for now)",
                             f"{len(s.contacts)} contact pairs")
        for fld, val in (("step", step), ("t_start", t_start)):
            if (not isinstance(val, numbers.Real) or isinstance(val, bool)
                    or not math.isfinite(float(val))):
                raise ModelError("Simulator", fld, "a finite number (s)", val)
        try:
            cfg = RunSettings.of(
                s, t_end=float(t_start) + float(step), step=step, rho_inf=rho_inf,
                t_start=t_start, tol_residual=tol_residual, tol_constraint=tol_constraint,
                max_iter=max_iter, output_every=output_every, formulation=formulation,
                redundant=redundant, tol=None, h_min=None, h_max=None, output_step=None,
                engine="auto", newton=newton, initial_velocities=initial_velocities,
                progress=None, on_output=None, on_rows=None, store=True, initial_state=None,
                condense=condense, global_error=False)
        except ModelError as exc:
            if exc.item != "simulate":
                raise
            raise ModelError("Simulator", exc.field, exc.expected, exc.got) from None
        plan = dataclasses.replace(_plan(cfg, None), capacity=1024, limit=None)
        self._cfg = dataclasses.replace(cfg, t_end=math.inf)
        self._plan = plan
        self._model_system = s
        self.h, self.t_start = cfg.step, cfg.t_start
        self._oe = cfg.output_every
        self._B = self._oe * max(1, _TABLE // self._oe)
        self._inputs = _input_specs(s)
        self._held: dict[str, object] = {}
        self._hold = np.zeros(s.inputs.nu)
        self._mask = np.zeros(s.inputs.nu, bool)
        self._iterations = self._factorizations = 0
        self._start(stacklevel_warnings=True)

    # -- set-up -----------------------------------------------------------------------------
    def _start(self, stacklevel_warnings: bool = False) -> None:
        """A new run from the model's initial state (the constructor, or a restore that needs
        the rigid joints condensed again)."""
        with warnings.catch_warnings():
            if not stacklevel_warnings:  # (said once, by the constructor)
                warnings.simplefilter("ignore")
            run = self._run = _Run(self._model_system, self._cfg, self._plan)
        if run.cond is not None and not np.array_equal(run.s.inputs.kind,
                                                       self._model_system.inputs.kind):
            raise AssertionError("the condensed model's inputs differ from the model's")
        self._k = 0
        self._b0 = -(1 << 62)  # the first step of the tabulated block (none yet)
        self._u_cur = step_inputs(self._model_system, self.t_start)["u"]
        self._U_rows = np.zeros((len(run.rec.t), self._hold.size))
        self._U_rows[0] = self._u_cur
        self._cur = 0  # the recorder's row of the current state
        self._load(run.st)

    def _load(self, st: State) -> None:
        """Make ``st`` (a state of the system stepped) the current state: the compiled loop's
        arrays and the stepper holding the state's solver memory."""
        run = self._run
        s, integ = run.s, run.integ
        self._stp = _stepper(s, integ.index2, st.dropped, run.ws,
                             split=integ.newton == "modified")
        run.ws.adopt(self._stp, st.solver)
        F = s.M + s.m
        self._H = np.ascontiguousarray(np.concatenate([st.H, st.HJ]).reshape(F, 4, 4),
                                       dtype=float)
        c = lambda x: np.array(x, dtype=float)  # noqa: E731
        self._alpha, self._v, self._vd, self._a, self._lam, self._ctrl = (
            c(st.alpha), c(st.v), c(st.vd), c(st.a), c(st.lam), c(st.ctrl))
        self._acc = np.array([*st.power, st.work_act, st.work_ext, st.dissipated, st.h_last,
                              st.t])
        self._dropped = st.dropped
        am, af, g, b = integ.params
        self._consts = (am, af, g, b, integ.tol_residual, integ.tol_constraint * s.length_scale,
                        float(s.length_scale), integ.max_iter, integ.newton == "modified", KMAX)
        self._readers: dict = {}
        self._rows = None  # the two-row results of read(), made when first needed
        self._read_ws = None

    def _table_row(self, t: float) -> np.ndarray:
        """The inputs of a step to ``t`` one by one (where the block's table could not be
        made): the held values and the model's time functions of the others, a
        :class:`SimulationError` naming the function that fails."""
        s = self._model_system
        u = np.where(self._mask, self._hold, 0.0)
        u[:3] = self._hold[:3] if self._mask[0] else s.inputs.gravity
        for slot, k, tf, item, what, order in s.inputs.sources:
            if not self._mask[slot]:
                u[slot:slot + k] = _sample(_DERIV[order](tf), t, (k,), item, what)
        return u

    def _tabulate(self, k: int) -> None:
        """The times and model inputs of the block of steps containing step ``k + 1``."""
        B = self._B
        b0 = (k // B) * B
        tb = self.t_start + np.arange(b0 + 1, b0 + B + 1, dtype=np.int64).astype(float) * self.h
        self._U0, self._ok = input_table(self._run.s, tb)
        self._tb, self._U, self._b0 = tb, self._U0.copy(), b0

    # -- the public face --------------------------------------------------------------------
    @property
    def t(self) -> float:
        """The time of the current state (s)."""
        return float(self._acc[7])

    @property
    def steps(self) -> int:
        """Steps taken from ``t_start``."""
        return self._k

    @property
    def inputs(self) -> dict[str, int]:
        """The inputs that :meth:`set_input` takes: name -> number of values."""
        return {n: v[1] for n, v in self._inputs.items()}

    @property
    def held(self) -> dict[str, np.ndarray]:
        """The inputs held now (name -> value)."""
        return {n: np.array(v, dtype=float).reshape(self._inputs[n][1])
                for n, v in self._held.items()}

    def input_value(self, name: str) -> np.ndarray:
        """The values (k,) of the input ``name`` with which the current state was computed (the
        held value or the model's time function at its time; at the start the model's)."""
        if name not in self._inputs:
            raise self._unknown_input(name)
        slot, k, _ = self._inputs[name]
        return self._u_cur[slot:slot + k].copy()

    def step(self) -> None:
        """Take one step (to ``t + step``)."""
        self._go(self._k + 1)

    def advance(self, t: float) -> None:
        """Step to the time ``t``, a time of the step grid ``t_start + k step`` (to round-off)
        not before the current time; the state then is at ``t_start + k step`` exactly (the
        grid's own number, as in ``simulate``'s steps)."""
        if (not isinstance(t, numbers.Real) or isinstance(t, bool)
                or not math.isfinite(float(t))):
            raise ModelError("Simulator.advance", "t", "a finite time (s)", t)
        t = float(t)
        k = round((t - self.t_start) / self.h)
        if abs(self.t_start + k * self.h - t) > 1e-9 * self.h:
            lo = math.floor((t - self.t_start) / self.h)
            raise ModelError(
                "Simulator.advance", "t", f"a time on the step grid t_start + k step "
                f"({self.t_start:g} + k {self.h:g})", t,
                f"the nearest are {self.t_start + lo * self.h!r} and "
                f"{self.t_start + (lo + 1) * self.h!r}")
        if k < self._k:
            raise ModelError("Simulator.advance", "t", f"a time not before the current time "
                             f"t={self.t!r} (restore a saved state to go back)", t)
        self._go(k)

    def set_input(self, name: str, value) -> None:
        """Hold the input ``name`` (see :attr:`inputs`) at ``value`` from the next step on:
        k numbers (a number for k = 1). A :class:`~se3dyn.errors.ModelError` names the input
        when the name is unknown, the shape wrong or a value not finite."""
        spec = self._inputs.get(name)
        if spec is None:
            raise self._unknown_input(name)
        slot, k, rate = spec
        if k == 1 and isinstance(value, float) and math.isfinite(value):  # (a controller's)
            self._hold[slot] = value
            self._mask[slot] = True
        else:
            value = self._check_value(name, value, k)
            self._hold[slot:slot + k] = value
            self._mask[slot:slot + k] = True
        self._held[name] = value
        if rate >= 0 and name + "_rate" not in self._held:  # a held target: its rate is 0
            self._hold[rate:rate + k] = 0.0
            self._mask[rate:rate + k] = True

    def clear_input(self, name: str) -> None:
        """Return the input ``name`` to the model's time function from the next step on."""
        if name not in self._inputs:
            raise self._unknown_input(name)
        self._held.pop(name, None)
        self._set_holds(dict(self._held))

    def read(self, channel: str) -> float:
        """The value of a results channel (``se3dyn.results.channels``: ``"joint/j/alpha/0"``,
        ``"marker/m/position/x"``, ``"joint/j/torque/0"``, ``"energy/kinetic"``, ...) at the
        current state, as :meth:`results` would give it."""
        f = self._readers.get(channel)
        if f is None:
            f = self._readers[channel] = self._reader(channel)
        return f()

    @property
    def state(self) -> SimulatorState:
        """The current state, with everything the steps from it need (see
        :class:`SimulatorState`); :meth:`restore` continues from it bit for bit."""
        rec = self._run.rec
        return SimulatorState(
            state=self._state(), steps=self._k, condensed=self._run.cond is not None,
            held=tuple((n, np.array(v, dtype=float).reshape(self._inputs[n][1]))
                       for n, v in self._held.items()),
            row=rec.scal[self._cur].copy(), u=self._u_cur.copy(), t_start=self.t_start,
            step=self.h)

    def restore(self, state: SimulatorState) -> None:
        """Continue from ``state`` (of this simulator or another one of the same model and
        time grid): the following steps compute what they computed after it, bit for bit.
        The inputs held are the state's. The rows recorded up to the state are kept when this
        simulator recorded it; otherwise the record starts again at the state."""
        if not isinstance(state, SimulatorState):
            raise ModelError("Simulator.restore", "state", "a SimulatorState (sim.state)",
                             state)
        if state.t_start != self.t_start or state.step != self.h:
            raise ModelError("Simulator.restore", "state", f"a state of the time grid "
                             f"t_start={self.t_start!r}, step={self.h!r}",
                             f"t_start={state.t_start!r}, step={state.step!r}")
        if state.condensed and self._run.cond is None:
            self._start()  # (a run that kept its rigid joints: begin again, condensed)
            if self._run.cond is None:
                raise ModelError("Simulator.restore", "state", "a state of this model (its "
                                 "rigid joints not condensed)", "a condensed state")
        elif not state.condensed and self._run.cond is not None:
            self._uncondense()
        run = self._run
        st = state.state
        k = _check_initial_state(run.s, st, self.t_start, math.inf, self.h, False)
        if k != state.steps:
            raise ModelError("Simulator.restore", "state", "a state at t_start + steps step",
                             f"steps={state.steps}, t={st.t!r}")
        self._load(st)
        self._k = k
        self._set_holds({n: v.copy() for n, v in state.held})
        self._u_cur = np.array(state.u)
        self._restore_rows(state)

    def results(self) -> Results:
        """The rows recorded so far (every ``output_every``-th step's and the current
        state's), as :func:`~se3dyn.dynamics.run.simulate` returns them: ``stats`` holds the
        steps, Newton iterations, energy balance error and ``final_state`` (the current
        state of the model)."""
        rec = self._run.rec
        n = self._cur + 1
        res = self._block(0, n)
        c = rec.scal[:n]
        err, scale = _balance_and_scale(c, c[0, :6])
        stats = dict(self._run.stats)
        stats.update(
            steps=self._k, newton_iterations=self._iterations,
            factorizations=self._factorizations, t_end=self.t, failed=False,
            final_state=self._model_state(), rows=n, energy_balance_error=err,
            energy_scale=scale, max_energy=float(np.abs(c[:, 0] + c[:, 1] + c[:, 2]).max()),
            max_constraint=float(c[:, 8].max()), max_iterations=int(c[:, 6].max()),
            held=self.held)
        res.stats = stats
        return res

    # -- stepping ---------------------------------------------------------------------------
    def _go(self, k1: int) -> None:
        """Steps to step number ``k1`` in the compiled loop, a block of the table at a time."""
        rec, oe = self._run.rec, self._oe
        while self._k < k1:
            k = self._k
            if not 0 <= k - self._b0 < self._B:
                self._tabulate(k)
            b0, U = self._b0, self._U
            j = k - b0
            if j >= self._ok:  # a time function failed in the block: step by step, named
                U[j] = self._table_row(float(self._tb[j]))
                j1 = j + 1
            else:
                j1 = min(k1 - b0, self._B, self._ok)
                U[j:j1] = self._U0[j:j1]
                if self._held:
                    np.copyto(U[j:j1], self._hold, where=self._mask)
            need = (b0 + j1) // oe - (b0 + j) // oe + 2
            while rec.free() < need:
                rec._grow()
            n0 = rec.n
            status, done, its, nf, count, _, _ = self._stp.run(
                self._tb, j, j1, j1 - 1, U, oe, *self._consts, self._H, self._alpha, self._v,
                self._vd, self._a, self._lam, self._acc, rec.t, rec.H.reshape(-1),
                rec.v.reshape(-1), rec.vd.reshape(-1), rec.lam.reshape(-1),
                rec.alpha.reshape(-1), rec.scal.reshape(-1), n0, self._ctrl)
            self._iterations += its
            self._factorizations += nf
            self._rows = None
            if done > j:
                self._u_cur = U[done - 1].copy()
            self._k = b0 + done
            self._store_inputs(U, b0, j, done, n0, count, last=status == 0)
            if status == 0:
                rec.added(count if self._k % oe == 0 else count - 1)
                self._cur = count - 1
            else:
                rec.added(count)
                self._failed(U[done], count, progressed=done > j)

    def _store_inputs(self, U: np.ndarray, b0: int, j: int, done: int, n0: int, count: int,
                      last: bool) -> None:
        """The inputs of the rows ``n0 <= r < count`` the compiled loop stored (the steps at
        multiples of ``output_every`` and, ``last``, the step ``done``), kept beside them for
        the multipliers of condensed rigid joints."""
        if count == n0 or self._run.cond is None or not len(self._run.cond.rigid):
            return  # (nothing reads them)
        if len(self._U_rows) < len(self._run.rec.t):
            self._U_rows = np.resize(self._U_rows, (len(self._run.rec.t), self._hold.size))
        if last and count - n0 == 1:  # (one step: its row)
            self._U_rows[n0] = U[done - 1]
            return
        oe = self._oe
        g = np.arange(((b0 + j) // oe + 1) * oe, b0 + done + 1, oe)
        if last and (b0 + done) % oe:
            g = np.append(g, b0 + done)
        self._U_rows[n0:count] = U[g - b0 - 1]

    def _failed(self, u: np.ndarray, count: int, progressed: bool) -> None:
        """A step failed in the compiled loop (the arrays hold the last converged state): a
        condensed run goes on with the rigid joints kept, as ``simulate`` does; otherwise the
        step is repeated by :meth:`GeneralizedAlpha.step`, which raises the error naming time,
        norms and item, with the results so far (``exc.result``)."""
        rec = self._run.rec
        if progressed:  # (otherwise the current row is where it was)
            if self._k % self._oe == 0 and count > 0 and rec.t[count - 1] == self.t:
                self._cur = count - 1
            else:
                self._scratch_row()
        if self._run.cond is not None:
            self._uncondense()
            return
        run, st = self._run, self._state()
        t1 = self.t_start + (self._k + 1) * self.h
        try:
            run.integ.step(run.s, st, t1 - st.t, None, run.ws, inputs=dict(u=u.copy()))
            exc = NewtonError(f"Newton failed at t={t1:.9g} (step h={self.h:.3g})", t=t1,
                              h=self.h)
        except SimulationError as e:
            exc = e
        self._load(st)  # (the stepper's memory as before the failed step)
        exc.result = self.results()
        raise exc

    def _uncondense(self) -> None:
        """Go on with the rigid joints kept (:meth:`_Run.uncondense`), with the inputs the
        rows were computed with."""
        run, rec = self._run, self._run.rec
        run.st = self._state()
        scratch = self._cur == rec.n
        run.uncondense(U=self._U_rows, inputs=dict(u=self._u_cur.copy()))
        self._load(run.st)
        if scratch:
            self._scratch_row()

    def _scratch_row(self) -> None:
        """The current state's row after the kept ones, from its energies (where the compiled
        loop did not store it)."""
        rec = self._run.rec
        st = self._state()
        e = energies(self._run.s, st, dict(u=self._u_cur), self._run.ws)
        rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
        rec.n -= 1
        rec.total -= 1
        self._cur = rec.n
        self._U_rows = np.resize(self._U_rows, (len(rec.t), self._hold.size))
        self._U_rows[rec.n] = self._u_cur
        self._rows = None

    # -- states, rows, inputs ---------------------------------------------------------------
    def _state(self) -> State:
        """The current state of the system stepped, from the compiled loop's arrays."""
        M, H, acc = self._run.s.M, self._H, self._acc
        return State(t=float(acc[7]), H=H[:M].copy(), HJ=H[M:].copy(), v=self._v.copy(),
                     vd=self._vd.copy(), a=self._a.copy(), lam=self._lam.copy(),
                     alpha=self._alpha.copy(), work_act=float(acc[3]), work_ext=float(acc[4]),
                     dissipated=float(acc[5]), power=acc[:3].copy(), dropped=self._dropped,
                     h_last=float(acc[6]), solver=self._run.ws.memory(self._stp),
                     ctrl=self._ctrl.copy())

    def _model_state(self) -> State:
        """The current state of the model (expanded when rigid joints are condensed)."""
        run, st = self._run, self._state()
        if run.cond is None:
            return st
        return run.cond.expand(st, None, dict(u=self._u_cur.copy()))

    def _block(self, lo: int, hi: int, rows: np.ndarray | None = None, ws=None) -> Results:
        """Rows ``lo <= r < hi`` (or ``rows``) of the recorder as the model's own, the
        multipliers of the condensed rigid joints computed with the rows' own inputs when
        first asked for (in the workspace ``ws`` of the model's system, a new one if None)."""
        rec = self._run.rec
        out = rec._block(lo, hi, rows=rows)
        cond = rec.cond
        if cond is not None and len(cond.rigid):
            U = self._U_rows[lo:hi].copy() if rows is None else self._U_rows[rows]
            out.defer_multipliers(lambda r: cond.fill_rows(r.t, r.H, r.alpha, r.v, r.vd,
                                                           r.__dict__["_lam"], ws, U=U))
        return out

    def _reader(self, channel: str):
        """A function returning the channel's value at the current state: the results
        channel of the first and the current row, or for joint coordinates and rates the
        entry of the state (the same number) found once through the same channel."""
        get_channel(self._two_rows(), channel)  # (an unknown name: its error, here)
        parts = str(channel).split("/")
        col = _STORED.get(channel)
        if col is not None:  # a stored scalar of the row: the number itself
            rec = self._run.rec
            if col < 0:
                return lambda: float(self._acc[7])
            return lambda: float(rec.scal[self._cur, col])
        if len(parts) == 4 and parts[0] == "joint" and parts[2] in ("alpha", "velocity"):
            s = self._model_system
            idx = np.arange(s.nq, dtype=float)[None]
            z = np.zeros(1)
            probe = Results(system=s, t=z, H=np.zeros((1, s.M, 4, 4)), v=idx, vd=idx,
                            lam=np.zeros((1, s.nm)), alpha=idx, kinetic=z, potential=z,
                            spring=z, work_actuators=z, work_loads=z, dissipation=z,
                            iterations=np.zeros(1, int), residual=z, constraint=z)
            i = int(get_channel(probe, channel)[0])
            cond = self._run.cond
            if cond is not None:
                hit = np.flatnonzero(cond.dof_full == i)
                i = int(hit[0]) if len(hit) else -1
            if i >= 0:
                arr = self._alpha if parts[2] == "alpha" else self._v
                return lambda: float(arr[i])
        return lambda: float(get_channel(self._two_rows(), channel)[-1])

    def _two_rows(self) -> Results:
        """The first row and the current one (channels relative to the first row, as
        displacements, read as in :meth:`results`)."""
        if self._rows is None:
            if self._read_ws is None:  # (the reads' own: results() may go to other threads)
                self._read_ws = Workspace(self._model_system)
            self._rows = self._block(0, 0, rows=np.array(sorted({0, self._cur})),
                                     ws=self._read_ws)
        return self._rows

    def _restore_rows(self, state: SimulatorState) -> None:
        """The record after :meth:`restore`: this simulator's rows up to the state when it
        recorded the state itself, otherwise the state's row alone."""
        rec, st = self._run.rec, state.state
        r = int(np.searchsorted(rec.t[:self._cur + 1], st.t, side="right")) - 1
        same = (r >= 0 and rec.t[r] == st.t
                and all(np.array_equal(getattr(rec, f)[r], getattr(st, f))
                        for f in ("v", "vd", "lam", "alpha"))
                and np.array_equal(rec.H[r], st.H) and np.array_equal(rec.scal[r], state.row))
        if same:
            rec.truncate(min(r + 1, rec.n))  # (r: a kept row, or the current one after them)
            self._cur = r
        else:
            rec.truncate(0)
            row = state.row
            rec.add(st, row[0], row[1], row[2], int(row[6]), row[7], row[8])
            self._cur = 0
            self._U_rows[0] = state.u
        self._rows = None

    def _set_holds(self, held: dict) -> None:
        """Hold exactly the inputs of ``held`` (name -> value)."""
        self._held = {}
        self._hold[:] = 0.0
        self._mask[:] = False
        for name in sorted(held, key=lambda n: n.endswith("_rate")):  # (rates after targets)
            self.set_input(name, held[name])

    def _check_value(self, name: str, value, k: int) -> np.ndarray:
        """``value`` as k finite numbers, or a ModelError naming the input."""
        try:
            val = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise ModelError(f"input {name!r}", "value", f"{k} number(s)", value) from None
        if val.shape not in ((k,),) and not (k == 1 and val.shape == ()):
            raise ModelError(f"input {name!r}", "value", f"{k} number(s)" if k > 1
                             else "a number", value, f"shape {val.shape}")
        if not np.all(np.isfinite(val)):
            raise ModelError(f"input {name!r}", "value", "finite numbers", value)
        return val.reshape(k)

    def _unknown_input(self, name) -> ModelError:
        """The error of an input name that does not exist, with the close ones."""
        names = list(self._inputs)
        close = close_matches(str(name), names, n=3, cutoff=0.5)
        hint = ("did you mean " + ", ".join(repr(c) for c in close) + "?") if close else (
            "the inputs: " + ", ".join(repr(c) for c in names[:6])
            + (", ..." if len(names) > 6 else ""))
        parts = str(name).split("/")
        s = self._model_system
        if (len(parts) == 3 and parts[0] == "joint" and parts[2] == "actuator"
                and parts[1] in [escape_name(j) for j in s.joint_names]):
            hint = (f"joint {parts[1]!r} has no actuator: give it one in the model "
                    "(actuator=0.0) to drive it from here")
        return ModelError("Simulator", "input", "the name of an input (sim.inputs)", name, hint)
