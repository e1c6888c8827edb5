"""``simulate``: run the generalized-alpha integrator over a time interval and record results."""

from __future__ import annotations

import math
import numbers
import time
from collections.abc import Callable

import numpy as np

from se3dyn.analysis import equation_name
from se3dyn.errors import ModelError, SimulationError
from se3dyn.integrator import GeneralizedAlpha, State, energies, step_inputs
from se3dyn.model import Model
from se3dyn.results import Results
from se3dyn.system import System, compile_model

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

    def add(self, st: State, kin: float, pot: float, spring: float, iters: int, res: float,
            con: float):
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
             redundant: str = "drop",
             progress: Callable[[float, int], None] | None = None,
             on_output: Callable[[State, dict], None] | None = None) -> Results:
    """Simulate a model from ``t_start`` to ``t_end`` with a fixed step (Eqs. (38)-(46)).

    Parameters
    ----------
    model : Model or System
        The model (compiled here) or an already compiled system.
    t_end : float
        Final time (s).
    step : float
        Time step h (s). When ``(t_end - t_start)/step`` is not an integer the last step is
        shortened to land on ``t_end``.
    rho_inf : float
        Spectral radius at infinite frequency (Eq. (44)).
    tol_residual, tol_constraint, max_iter :
        Newton settings, see :class:`~se3dyn.integrator.GeneralizedAlpha`.
    formulation : {"index2", "index3"}
        Stabilized index-2 (default; second order in positions, velocities and multipliers)
        or the paper's index-3 form, see :class:`~se3dyn.integrator.GeneralizedAlpha`.
    redundant : {"drop", "error"}
        Redundant constraint equations are left out with zero multipliers (default; their
        names are in ``stats["redundant"]``) or reported as an error.
    output_every : int
        Store every k-th step (the initial and the final state are always stored).
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

    Raises
    ------
    NewtonError
        When a step fails; its ``result`` attribute holds the results up to the last converged
        step, and the message names the time, the step, the norms and the worst item.
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
    if isinstance(rho_inf, numbers.Real) and not isinstance(rho_inf, bool):
        rho_inf = float(rho_inf)
    integ = GeneralizedAlpha(rho_inf=rho_inf, tol_residual=tol_residual,
                             tol_constraint=tol_constraint, max_iter=max_iter,
                             formulation=formulation, redundant=redundant)
    nsteps = max(1, math.ceil((t_end - t_start) / step - 1e-9))
    rec = _Recorder(s, nsteps // output_every + 2, on_output)
    wall0 = time.perf_counter()
    st = integ.init(s, t_start)
    solver = integ.solver(s, st)
    e = energies(s, st, step_inputs(s, t_start))
    rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
    total_it = 0
    stats = dict(steps=0, newton_iterations=0, rho_inf=rho_inf, step=step, t_start=t_start,
                 t_end=t_end, tol_residual=tol_residual, tol_constraint=tol_constraint,
                 unknowns=s.nq, multipliers=s.nm, matrix_size=solver.N,
                 formulation=formulation,
                 redundant=[equation_name(s, r) for r in st.dropped],
                 linear_solver="dense LU" if solver.dense else "sparse LU (SuperLU)")
    for i in range(1, nsteps + 1):
        t1 = t_start + i * step if i < nsteps else t_end
        h = t1 - st.t
        try:
            st, info = integ.step(s, st, h, solver)
        except SimulationError as exc:
            stats.update(steps=i - 1, newton_iterations=total_it, failed=True,
                         wall_time=time.perf_counter() - wall0)
            if rec.n and rec.t[rec.n - 1] != st.t:
                e = energies(s, st, step_inputs(s, st.t))
                rec.add(st, e["kinetic"], e["potential"], e["spring"], 0, 0.0, 0.0)
            exc.result = rec.results(stats)
            raise
        st.t = t1  # exact grid times, no drift
        total_it += info.iterations
        if i % output_every == 0 or i == nsteps:
            e = info.energies
            rec.add(st, e["kinetic"], e["potential"], e["spring"], info.iterations,
                    info.residual, info.constraint)
        if progress is not None:
            progress(st.t, i)
    stats.update(steps=nsteps, newton_iterations=total_it, failed=False,
                 wall_time=time.perf_counter() - wall0, final_state=st)
    return rec.results(stats)
