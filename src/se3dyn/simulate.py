"""``simulate``: run the generalized-alpha integrator over a time interval and record results."""

from __future__ import annotations

import dataclasses
import math
import numbers
import time
from collections.abc import Callable

import numpy as np

from se3dyn.analysis import equation_name
from se3dyn.errors import ModelError, NewtonError, SimulationError
from se3dyn.integrator import GeneralizedAlpha, State, energies, interpolate, step_inputs
from se3dyn.model import Model
from se3dyn.results import Results
from se3dyn.system import System, Workspace, compile_model

__all__ = ["simulate", "SCALARS"]


#: Names of the scalar columns of a stored row, in order (see ``on_output`` of :func:`simulate`).
SCALARS = ("kinetic", "potential", "spring", "work_actuators", "work_loads", "dissipation",
           "iterations", "residual", "constraint")


class _Recorder:
    def __init__(self, s: System, capacity: int, sink=None):
        self.s = s
        self.sink = sink
        self.n = 0
        self.t = np.zeros(capacity)
        self.H = np.zeros((capacity, s.M, 4, 4))
        self.v = np.zeros((capacity, s.nq))
        self.vd = np.zeros((capacity, s.nq))
        self.lam = np.zeros((capacity, s.nm))
        self.alpha = np.zeros((capacity, s.nq))
        self.scal = np.zeros((capacity, 9))

    def _grow(self):
        for name in ("t", "H", "v", "vd", "lam", "alpha", "scal"):
            arr = getattr(self, name)
            setattr(self, name, np.concatenate([arr, np.zeros_like(arr)]))

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
        if self.sink is not None:
            self.sink(st, dict(zip(SCALARS, self.scal[i].tolist(), strict=True)))

    def results(self, stats: dict) -> Results:
        n = self.n
        c = self.scal[:n]
        return Results(system=self.s, t=self.t[:n].copy(), H=self.H[:n].copy(),
                       v=self.v[:n].copy(), vd=self.vd[:n].copy(), lam=self.lam[:n].copy(),
                       alpha=self.alpha[:n].copy(), kinetic=c[:, 0].copy(),
                       potential=c[:, 1].copy(), spring=c[:, 2].copy(),
                       work_actuators=c[:, 3].copy(), work_loads=c[:, 4].copy(),
                       dissipation=c[:, 5].copy(), iterations=c[:, 6].astype(int),
                       residual=c[:, 7].copy(), constraint=c[:, 8].copy(), stats=stats)


def simulate(model: Model | System, t_end: float, step: float, *, rho_inf: float = 0.9,
             t_start: float = 0.0, tol_residual: float = 1e-10, tol_constraint: float = 1e-11,
             max_iter: int = 25, output_every: int = 1, formulation: str = "index2",
             redundant: str = "drop", tol: float | None = None, h_min: float | None = None,
             h_max: float | None = None, output_step: float | None = None,
             engine: str = "auto", newton: str = "modified",
             progress: Callable[[float, int], None] | None = None,
             on_output: Callable[[State, dict], None] | None = None) -> Results:
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
        ``t_end``.
    rho_inf : float
        Spectral radius at infinite frequency (Eq. (44)).
    tol_residual, tol_constraint, max_iter :
        Newton settings, see :class:`~se3dyn.integrator.GeneralizedAlpha`.
    output_every : int
        Store every k-th step (the initial and the final state are always stored).
    formulation : {"index2", "index3"}
        Stabilized index-2 (default; second order in positions, velocities and multipliers)
        or the paper's index-3 form, see :class:`~se3dyn.integrator.GeneralizedAlpha`.
    redundant : {"drop", "error"}
        Redundant constraint equations are left out with zero multipliers (default; their
        names are in ``stats["redundant"]``) or reported as an error.
    tol : float, optional
        Adaptive time stepping: tolerance on the error of the positions (m for translations,
        rad for rotations and joint angles) over the whole run. Every step's local error
        estimate ``(beta - 1/6) h^2 (a_{n+1} - a_n)`` (max norm over the unknowns) is held
        below ``tol * h / (t_end - t_start)`` (error per unit step), so that the local errors
        add up to at most ``tol``; rejected steps are repeated with a smaller step, the next
        step is ``h (tol_h / err)^(1/2)`` (safety 0.9, change limited to [0.2, 2]). A step
        whose Newton iterations fail is retried with h / 4.
    h_min, h_max : float, optional
        Step bounds for adaptive stepping (default ``1e-12 (t_end - t_start)`` and
        ``(t_end - t_start) / 10``). Falling below ``h_min`` stops the run with a
        :class:`~se3dyn.errors.SimulationError` naming the time and the cause.
    output_step : float, optional
        Store the results on the grid ``t_start + k output_step`` (and ``t_end``) by dense
        output (:func:`~se3dyn.integrator.interpolate`), whatever the internal steps; without
        it every (``output_every``-th) step is stored.
    engine : {"auto", "compiled", "numpy"}
        Compiled kernels (:mod:`se3dyn.fast`) or the numpy implementation, see
        :class:`~se3dyn.integrator.GeneralizedAlpha`. With a fixed step and no ``progress``,
        ``on_output`` or ``output_step``, the whole time loop runs compiled.
    newton : {"modified", "full"}
        Reuse of the factorised iteration matrix by the compiled engine, see
        :class:`~se3dyn.integrator.GeneralizedAlpha`.
    progress : callable(t, step_index), optional
        Called after every step.
    on_output : callable(state, scalars), optional
        Called with every stored row as it is computed (the initial state included): the
        :class:`~se3dyn.integrator.State` and a dict of the scalar columns ``SCALARS``
        (energies, works, Newton iterations, residual, constraint violation). Used to stream
        results to a file while the simulation runs.

    Returns
    -------
    Results
        ``stats`` holds steps, rejected steps, Newton iterations, smallest/largest step, etc.

    Raises
    ------
    NewtonError
        When a step fails (fixed step) or the step falls below ``h_min`` (adaptive); its
        ``result`` attribute holds the results up to the last converged step, and the message
        names the time, the step, the norms and the worst item.
    """
    s = model if isinstance(model, System) else compile_model(model)
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
    if not (isinstance(output_every, int) and output_every >= 1):
        raise ModelError("simulate", "output_every", "a positive integer", output_every)
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
    if opt["h_min"] > opt["h_max"]:
        raise ModelError("simulate", "h_min", f"at most h_max={opt['h_max']:g}", opt["h_min"])
    if isinstance(rho_inf, numbers.Real) and not isinstance(rho_inf, bool):
        rho_inf = float(rho_inf)
    integ = GeneralizedAlpha(rho_inf=rho_inf, tol_residual=tol_residual,
                             tol_constraint=tol_constraint, max_iter=max_iter,
                             formulation=formulation, redundant=redundant, engine=engine,
                             newton=newton)
    adaptive = opt["tol"] is not None
    grid = None
    if opt["output_step"] is not None:
        k = max(1, math.ceil(span / opt["output_step"] - 1e-9))
        grid = np.minimum(t_start + opt["output_step"] * np.arange(k + 1), t_end)
        grid[-1] = t_end
        capacity = len(grid)
    elif adaptive:
        capacity = 1024
    else:
        capacity = max(1, math.ceil(span / step - 1e-9)) // output_every + 2
    rec = _Recorder(s, capacity, on_output)
    wall0 = time.perf_counter()
    ws = Workspace(s)  # this run's engine and steppers, shared with no other run
    st = integ.init(s, t_start, ws=ws)
    solver = integ.solver(s, st)
    e = energies(s, st, step_inputs(s, t_start), ws)
    rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
    gi = 1  # next grid time to fill
    stats = dict(steps=0, rejected=0, newton_iterations=0, rho_inf=rho_inf, step=step,
                 t_start=t_start, t_end=t_end, tol_residual=tol_residual,
                 tol_constraint=tol_constraint, unknowns=s.nq, multipliers=s.nm,
                 matrix_size=solver.N, formulation=formulation,
                 redundant=[equation_name(s, r) for r in st.dropped],
                 linear_solver="dense LU" if solver.dense else "sparse LU (SuperLU)",
                 adaptive=adaptive, tol=opt["tol"], h_min_used=math.inf, h_max_used=0.0)
    nsteps = max(1, math.ceil(span / step - 1e-9))
    h = min(step, opt["h_max"]) if adaptive else step
    i = 0

    def fail(exc: SimulationError):
        stats.update(steps=i, failed=True, wall_time=time.perf_counter() - wall0)
        if grid is None and rec.n and rec.t[rec.n - 1] != st.t:
            e = energies(s, st, step_inputs(s, st.t), ws)
            rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
        exc.result = rec.results(stats)
        raise exc

    stats["linear_solver"] = "sparse LU (se3dyn/_core/sparse_lu.hpp)"
    stats["engine"] = "compiled"
    if not adaptive and grid is None:
        # the whole fixed-step loop in the compiled engine, in chunks between which progress
        # and streamed rows are reported; a failing step is repeated by
        # GeneralizedAlpha.step, which raises the error naming time, norms and item
        times = np.array([t_start + (k + 1) * step if k + 1 < nsteps else t_end
                          for k in range(nsteps)])
        st, i, fac = _run_compiled(s, integ, st, times, output_every, rec, progress, stats, ws)
        stats["factorizations"] = fac
        if i < nsteps:
            try:
                integ.step(s, st, times[i] - st.t, solver, ws)
            except SimulationError as exc:
                fail(exc)
            raise AssertionError("the compiled step failed but GeneralizedAlpha.step converged")
        if nsteps:
            hs = np.diff(np.concatenate([[t_start], times]))
            stats["h_min_used"] = float(hs.min())
            stats["h_max_used"] = float(hs.max())
    while st.t < t_end and (adaptive or i < nsteps):
        if adaptive:
            h = min(h, t_end - st.t)
            if t_end - st.t - h < 1e-9 * h:
                h = t_end - st.t
            try:
                new, info = integ.step(s, st, h, solver, ws)
            except SimulationError as exc:
                if not isinstance(exc, NewtonError):
                    fail(exc)
                if h / 4 < opt["h_min"]:
                    fail(NewtonError(f"{exc}; the step cannot be reduced below h_min="
                                     f"{opt['h_min']:.3g}", **_err_kwargs(exc)))
                stats["rejected"] += 1
                h /= 4
                continue
            tol_h = opt["tol"] * h / span
            err = float(np.abs(info.error).max(initial=0.0)) / tol_h
            if err > 1.0:
                if h <= opt["h_min"] * (1 + 1e-9):
                    worst = int(np.argmax(np.abs(info.error)))
                    fail(SimulationError(
                        f"t={st.t:.9g}: the local error estimate {err * tol_h:.3e} exceeds the "
                        f"tolerance {tol_h:.3e} (tol={opt['tol']:g} per {span:g} s) at the "
                        f"minimum step h_min={opt['h_min']:.3g}; worst: {s.labels[worst]} "
                        "(a discontinuous input, or a tolerance too tight for the model)"))
                stats["rejected"] += 1
                stats["newton_iterations"] += info.iterations
                h = max(opt["h_min"], h * min(0.9, max(0.2, 0.9 * err ** -0.5)))
                continue
            t1 = st.t + h if t_end - st.t - h > 1e-12 * span else t_end
        else:
            t1 = t_start + (i + 1) * step if i + 1 < nsteps else t_end
            h = t1 - st.t
            try:
                new, info = integ.step(s, st, h, solver, ws)
            except SimulationError as exc:
                fail(exc)
        new = dataclasses.replace(new, t=t1)  # exact times, no drift
        i += 1
        stats["newton_iterations"] += info.iterations
        stats["h_min_used"] = min(stats["h_min_used"], h)
        stats["h_max_used"] = max(stats["h_max_used"], h)
        if grid is not None:
            while gi < len(grid) and grid[gi] <= t1 + 1e-12 * span:
                tg = grid[gi]
                if abs(tg - t1) <= 1e-12 * span:
                    out = new
                else:
                    out = dataclasses.replace(
                        interpolate(s, st, new, info.increment, (tg - st.t) / h, ws), t=tg)
                ei = energies(s, out, step_inputs(s, tg), ws)
                out = dataclasses.replace(out, power=ei["power"])
                rec.add(out, ei["kinetic"], ei["potential"], ei["spring"], info.iterations,
                        info.residual, info.constraint)
                gi += 1
        elif i % output_every == 0 or t1 >= t_end:
            e = info.energies
            rec.add(new, e["kinetic"], e["potential"], e["spring"], info.iterations,
                    info.residual, info.constraint)
        st = new
        if progress is not None:
            progress(st.t, i)
        if adaptive:
            h = min(opt["h_max"], h * min(2.0, max(0.2, 0.9 * max(err, 1e-10) ** -0.5)))
    stats.update(steps=i, failed=False, wall_time=time.perf_counter() - wall0, final_state=st)
    return rec.results(stats)


def _run_compiled(s: System, integ: GeneralizedAlpha, st: State, times: np.ndarray,
                  output_every: int, rec: _Recorder, progress, stats: dict, ws: Workspace):
    """Fixed steps to ``times`` in the compiled loop (``Stepper.run``); returns the state
    reached, the number of steps done (less than ``len(times)`` when a step failed) and the
    factorisations. Progress is reported and stored rows are streamed between chunks of
    steps that last about 0.1 s each."""
    from se3dyn.integrator import KMAX, _stepper
    from se3dyn.system import input_table

    nsteps = len(times)
    U, n_ok = input_table(s, times)
    stp = _stepper(s, integ.index2, st.dropped, ws)
    F = s.M + s.m
    H = np.ascontiguousarray(np.concatenate([st.H, st.HJ]).reshape(F, 4, 4), dtype=float)
    c = lambda x: np.array(x, dtype=float)  # noqa: E731
    alpha, v, vd, a, lam = c(st.alpha), c(st.v), c(st.vd), c(st.a), c(st.lam)
    acc = np.array([*st.power, st.work_act, st.work_ext, st.dissipated, st.h_last, st.t])
    am, af, g, b = integ.params
    i = 0
    fac = 0
    chunk = 16
    while i < n_ok:
        i1 = min(n_ok, i + chunk)
        rows_needed = (i1 // output_every - i // output_every) + 1
        while len(rec.t) - rec.n < rows_needed:
            rec._grow()
        n0 = rec.n
        tic = time.perf_counter()
        status, done, its, nf, count, res, con = stp.run(
            times, i, i1, nsteps - 1, U, output_every, am, af, g, b, integ.tol_residual,
            integ.tol_constraint * s.length_scale, float(s.length_scale), integ.max_iter,
            integ.newton == "modified", KMAX, H, alpha, v, vd, a, lam, acc, rec.t,
            rec.H.reshape(-1), rec.v.reshape(-1), rec.vd.reshape(-1), rec.lam.reshape(-1),
            rec.alpha.reshape(-1), rec.scal.reshape(-1), rec.n)
        dt = time.perf_counter() - tic
        rec.n = count
        stats["newton_iterations"] += its
        fac += nf
        i = done
        if rec.sink is not None:
            for r in range(n0, count):
                row = State(t=float(rec.t[r]), H=rec.H[r], HJ=np.zeros((0, 4, 4)), v=rec.v[r],
                            vd=rec.vd[r], a=rec.vd[r], lam=rec.lam[r], alpha=rec.alpha[r])
                # (read-only views of the recorder's rows)
                rec.sink(row, dict(zip(SCALARS, rec.scal[r].tolist(), strict=True)))
        if progress is not None and done > 0:
            progress(float(times[done - 1]), done)
        if status != 0:
            break
        chunk = max(1, min(4 * chunk, int(chunk * 0.1 / max(dt, 1e-6))))
    st = State(t=float(acc[7]), H=H[:s.M].copy(), HJ=H[s.M:].copy(), v=v.copy(), vd=vd.copy(),
               a=a.copy(), lam=lam.copy(), alpha=alpha.copy(), work_act=float(acc[3]),
               work_ext=float(acc[4]), dissipated=float(acc[5]), power=acc[:3].copy(),
               dropped=st.dropped, h_last=float(acc[6]))
    return st, i, fac


def _err_kwargs(exc) -> dict:
    if isinstance(exc, NewtonError):
        return dict(t=exc.t, h=exc.h, iterations=exc.iterations,
                    residual_norm=exc.residual_norm, constraint_norm=exc.constraint_norm,
                    item=exc.item)
    return {}
