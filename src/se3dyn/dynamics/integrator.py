"""Lie-group generalized-alpha time integration (Eqs. (38)-(46)) with Newton iterations.

One step from ``t_n`` to ``t_{n+1} = t_n + h`` solves for the increments ``n_{n+1}`` (Eq. (41)):

* ``H_{n+1} = H_n exp(A n_{n+1})`` (Eq. (38)) for every node and joint;
* the equations of motion (39) and the constraints (40) at ``t_{n+1}``;
* ``v_{n+1} = v_n + (1-gamma) h a_n + gamma h a_{n+1}`` (42),
  ``(1-alpha_m) a_{n+1} + alpha_m a_n = (1-alpha_f) vd_{n+1} + alpha_f vd_n`` (43),
  with the parameters of Eq. (44) from the spectral radius ``rho_inf``.

Newton corrections use ``dv = gamma' dn``, ``dvd = beta' dn`` and the scaled iteration matrix
described in :mod:`se3dyn.system`. Converged when the residual is below ``tol_residual`` relative
to the magnitude of the forces entering it and the constraints below ``tol_constraint`` (times the
model's length scale), or when the increment correction reaches round-off with the constraints
satisfied.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from se3dyn import lie
from se3dyn.dynamics.state import State, StepInfo
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.linsolve import LinearSolver
from se3dyn.errors import ModelError, NewtonError, SimulationError

if TYPE_CHECKING:
    from se3dyn.engine.system import System


#: modified Newton: refactorise when more than KMAX further iterations are predicted (a
#: factorisation costs about five iterations on the benchmark models; 5-12 perform alike)
KMAX = 8.0


#: Largest number of unknowns for which a singular start is diagnosed (a dense SVD, as check's).
DIAGNOSE_MAX = 3000


def _singular_start_cause(s: System) -> str:
    """Why the initial acceleration matrix is singular: the motions with no mass found by
    :func:`se3dyn.engine.rank.massless_motions` (the diagnosis of ``se3dyn check``), else the
    typical causes."""
    if s.nq <= DIAGNOSE_MAX:
        from se3dyn.engine.rank import massless_message, massless_motions

        try:
            free = massless_motions(s)
        except (np.linalg.LinAlgError, ValueError):  # a non-finite state: no diagnosis
            free = []
        if free:
            return massless_message(free)
    return ("typical causes: redundant constraints not detected at the start (a mechanism "
            "started in a singular configuration), a free massless node whose motion no joint "
            "determines, or a non-finite state")


def _drive_start(s: System, t0: float, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rates and accelerations (nd,) of the driven coordinates at t0 (from the inputs ``u`` at
    t0), after checking that the position drivers start where the model's joints are
    (``System.alpha0``)."""
    slots = np.array(s.inputs.drive_slots, np.int64).reshape(-1, 3)
    k = 0
    for dr in s.model.drives:
        for jname, i, _ in dr.targets:
            pos = slots[k, 0]
            a0 = float(s.alpha0[s.drive_dof[k]])
            if pos >= 0 and abs(u[pos] - a0) > 1e-9 * max(1.0, abs(a0)):
                raise ModelError(
                    f"drive '{dr.name}'", "position",
                    f"{a0:.9g}, the initial coordinate {i} of joint '{jname}', at t0 = {t0:g}",
                    f"{u[pos]:.9g}",
                    hint="start the function there (add an offset), or give the joint that "
                         "initial value (ModelBuilder.joint initial=) with the bodies placed "
                         "accordingly (se3dyn.assemble(model, coordinates=...) finds them)")
            k += 1
    return u[slots[:, 1]], u[slots[:, 2]]


def _check_couplings(s: System) -> None:
    """Every coupling must hold in the initial configuration: ``alpha_b0 = ratio alpha_a0 +
    offset`` (the joints' ``initial`` values, zero by default)."""
    for c, a, b, r, o in zip(s.model.couplings, s.cpl_lead, s.cpl_follow, s.cpl_ratio,
                             s.cpl_offset, strict=True):
        want = r * s.alpha0[a] + o
        if abs(s.alpha0[b] - want) > 1e-9 * max(1.0, abs(want)):
            raise ModelError(f"coupling '{c.name}'", "offset",
                             f"{s.alpha0[b] - r * s.alpha0[a]:.9g}: the follower's initial "
                             f"coordinate {s.alpha0[b]:.9g} minus ratio times the leader's "
                             f"{s.alpha0[a]:.9g}", f"{o:.9g}",
                             hint="give that offset, or the joints initial values that "
                                  "satisfy the coupling")


def _check_drive_velocities(s: System, v: np.ndarray, values: np.ndarray, dropped) -> None:
    """The projected initial velocities must satisfy the velocity constraints with the driven
    rates kept: else the drivers ask for a motion the joints do not allow (a coordinate a
    closed loop locks, or two drivers in conflict)."""
    from se3dyn.engine.rank import equation_name

    if not s.drive_dof.size:
        return
    A = LinearSolver(s, drop=dropped).matrix(values)
    rows = np.setdiff1d(np.arange(s.nm), dropped)
    res = np.abs(np.asarray(A[s.nq:][:, :s.nq] @ v).ravel()[rows])
    scale = np.abs(A[s.nq:][:, :s.nq]) @ np.abs(v)
    scale = np.asarray(scale).ravel()[rows]
    bad = np.flatnonzero(res > 1e-8 * scale + 1e-9 * float(scale.max(initial=0.0)))
    if bad.size:
        names = sorted({s.model.drives[i].name for i in s.drive_of})
        raise ModelError("drives " + ", ".join(repr(n) for n in names), "velocity",
                         "initial rates the joints allow", f"velocity constraint "
                         f"{equation_name(s, int(rows[bad[0]]))} violated by "
                         f"{res[bad[0]]:.3g}", hint="a closed loop locks the driven "
                         "coordinate, or two drivers ask for motions in conflict")


def _velocity_changes(s: System, v: np.ndarray) -> list[dict]:
    """The free nodes with mass whose velocities in ``v`` (nq,) differ from the model's initial
    ones by more than round-off (1e-9 of the largest velocity, linear and angular apart)."""
    given = s.node_v0[s.node_free]
    used = np.asarray(v)[s.node_dofidx]
    d = used - given
    out = []
    if not len(given):
        return out
    sv = max(float(np.abs(given[:, :3]).max()), float(np.abs(used[:, :3]).max()), 1e-300)
    sw = max(float(np.abs(given[:, 3:]).max()), float(np.abs(used[:, 3:]).max()), 1e-300)
    free = np.asarray(s.node_free)
    # (massless nodes: their velocities are the joints' to determine, not the user's)
    massive = (s.node_mass[free] > 0) | np.any(s.node_J[free] != 0, axis=(1, 2))
    dv, dw = np.linalg.norm(d[:, :3], axis=1), np.linalg.norm(d[:, 3:], axis=1)
    for i in np.flatnonzero(massive & ((dv > 1e-9 * sv) | (dw > 1e-9 * sw))):
        node = free[i]
        R = s.node_H0[node, :3, :3]  # material -> inertial components at t0
        out.append(dict(node=s.node_names[node], dv=float(dv[i]), dw=float(dw[i]),
                        given=np.concatenate([R @ given[i, :3], R @ given[i, 3:]]),
                        used=np.concatenate([R @ used[i, :3], R @ used[i, 3:]])))
    return out


def initial_velocity_changes(s: System, st: State) -> list[dict]:
    """What :meth:`GeneralizedAlpha.init` changed in the model's initial velocities to satisfy
    the velocity constraints of the joints.

    Returns
    -------
    list of dict, one per changed node: ``node`` (name), ``dv`` and ``dw`` (norms of the change
    of the velocity, m/s, and of the angular velocity, rad/s), ``given`` and ``used`` (6,) the
    model's and the state's velocity and angular velocity in the inertial frame. Empty when the
    velocities were consistent.
    """
    return _velocity_changes(s, st.v)


def _ws(s: System, ws=None):
    """The workspace ``ws`` or the system's default one."""
    from se3dyn.engine.workspace import workspace

    return ws or workspace(s)


def _stepper(s: System, index2: bool, dropped: np.ndarray, ws=None, keep: bool = True,
             split: bool = True):
    """The compiled Newton stepper of a workspace (the system's default one); ``split``
    (modified Newton): see :meth:`se3dyn.engine.workspace.Workspace.stepper`."""
    return _ws(s, ws).stepper(index2, dropped, keep, split)


def energies(s: System, st: State, inputs: dict, ws=None) -> dict:
    """Kinetic, gravity-potential and elastic energy of a state, and the three powers, from
    the element kernels.

    Returns
    -------
    dict with floats ``kinetic`` (Eq. (47)), ``potential`` (gravity), ``spring`` (Eq. (62) and
    the elastic elements), and ``power`` ndarray (3,) = (actuators incl. PD, external loads,
    dissipation).
    """
    z = np.zeros(s.nq)
    ev = evaluate(s, st.H, st.HJ, st.alpha, z, st.v, z, st.lam, inputs, full_alpha=False, ws=ws)
    e = ev.energy
    return dict(kinetic=float(e[0]), potential=float(e[1]), spring=float(e[2]),
                power=e[3:6].copy())


@dataclass(frozen=True)
class GeneralizedAlpha:
    """Lie-group generalized-alpha integrator (Eqs. (38)-(46)), frozen configuration.

    Parameters
    ----------
    rho_inf : float
        Spectral radius at infinite frequency, in [0, 1] (Eq. (44)); 1 means no numerical
        dissipation.
    tol_residual : float
        Newton tolerance on ``||r||_inf`` relative to the magnitude of the forces in Eq. (39).
    tol_constraint : float
        Newton tolerance on ``||Phi||_inf`` (Eq. (40)), in units of the model's length scale.
    max_iter : int
        Maximum Newton iterations per step.
    formulation : {"index2", "index3"}
        ``"index2"`` (default): the stabilized index-2 formulation of Arnold, Brüls & Cardona
        (Numer. Math. 129 (2015) 149-179), which adds the velocity constraints
        ``Phi_q(q_{n+1}) v_{n+1} = 0`` and corrects the increment by ``B_n^T xi``::

            n_{n+1} = h v_n + h^2 (1/2 - beta) a_n + h^2 beta a_{n+1} + B_n^T xi_{n+1}

        (``B_n = Phi_q(q_n)``, Eq. (58); ``xi`` a new multiplier with the units of an
        increment). Positions, velocities, accelerations and multipliers are then all second
        order accurate, without the O(h) transients of the index-3 form, and the multipliers
        stay bounded for ``rho_inf = 1``. ``"index3"``: the paper's Eqs. (38)-(46) as written.
    redundant : {"drop", "error"}
        What to do with redundant constraint equations found at the initial configuration
        (:func:`se3dyn.engine.rank.redundant_equations`): leave them out with zero multipliers
        (default) or raise :class:`ModelError` naming them.
    engine : {"auto", "compiled", "numpy"}
        Kept for compatibility: every evaluation and Newton iteration runs in the compiled
        engine (``se3dyn/_core``, C++ built at install); there is no second implementation.
    initial_velocities : {"project", "strict"}
        Initial velocities that violate the velocity constraints of the joints (a body given
        only part of its motion, a velocity out of a hinge's plane): ``"project"`` (default)
        makes them consistent, keeping consistent body velocities exactly (see
        :meth:`init`; :func:`initial_velocity_changes` and ``simulate``'s stats and warning
        report every change); ``"strict"`` refuses them with a :class:`ModelError` naming the
        nodes.
    newton : {"modified", "full"}
        ``"modified"`` (default) factorises the iteration matrix at the
        predictor of each step and keeps it over the iterations while Newton contracts fast
        enough to converge within a few more iterations, refactorising at the current iterate
        otherwise (see ``se3dyn/_core/newton.hpp``); ``"full"`` refactorises at every
        iteration. Both converge to the same tolerances.
    """

    rho_inf: float = 0.9
    tol_residual: float = 1e-10
    tol_constraint: float = 1e-11
    max_iter: int = 25
    formulation: str = "index2"
    redundant: str = "drop"
    engine: str = "auto"
    newton: str = "modified"
    initial_velocities: str = "project"

    def __post_init__(self):
        r = self.rho_inf
        if not (isinstance(r, int | float) and 0.0 <= r <= 1.0):
            raise ModelError("integrator", "rho_inf", "a number in [0, 1]", r)
        for fld in ("tol_residual", "tol_constraint"):
            v = getattr(self, fld)
            if not (isinstance(v, int | float) and 0 < v < 1):
                raise ModelError("integrator", fld, "a positive tolerance below 1", v)
        if not (isinstance(self.max_iter, int) and not isinstance(self.max_iter, bool)
                and 1 <= self.max_iter <= 10**6):
            raise ModelError("integrator", "max_iter", "a positive integer (at most 1e6)",
                             self.max_iter)
        if self.formulation not in ("index2", "index3"):
            raise ModelError("integrator", "formulation", "'index2' or 'index3'",
                             self.formulation)
        if self.redundant not in ("drop", "error"):
            raise ModelError("integrator", "redundant", "'drop' or 'error'", self.redundant)
        if self.newton not in ("modified", "full"):
            raise ModelError("integrator", "newton", "'modified' or 'full'", self.newton)
        if self.initial_velocities not in ("project", "strict"):
            raise ModelError("integrator", "initial_velocities", "'project' or 'strict'",
                             self.initial_velocities)
        if self.engine not in ("auto", "compiled", "numpy"):
            raise ModelError("integrator", "engine", "'auto', 'compiled' or 'numpy'",
                             self.engine)

    def compiled(self, s: System) -> bool:
        """Whether steps of this system run in the compiled engine: always."""
        return True

    @property
    def index2(self) -> bool:
        return self.formulation == "index2"

    def solver(self, s: System, st: State) -> LinearSolver:
        """A linear solver for the steps of this integrator from state ``st``."""
        return LinearSolver(s, index2=self.index2, drop=st.dropped)

    def _solver_for(self, s: System, st: State, solver: LinearSolver | None) -> LinearSolver:
        if (solver is None or solver.index2 != self.index2
                or not np.array_equal(solver.drop, st.dropped)):
            return self.solver(s, st)
        return solver

    @property
    def params(self) -> tuple[float, float, float, float]:
        """(alpha_m, alpha_f, gamma, beta) of Eq. (44)."""
        r = self.rho_inf
        am = (2 * r - 1) / (r + 1)
        af = r / (r + 1)
        g = 0.5 + af - am
        b = 0.25 * (g + 0.5) ** 2
        return am, af, g, b

    # -----------------------------------------------------------------------------------------
    def init(self, s: System, t0: float = 0.0, solver: LinearSolver | None = None,
             ws=None) -> State:
        """Initial state: frames from the model, velocities made consistent with the velocity
        constraints, consistent accelerations and multipliers at t0 (Eqs. (36)-(37)).

        Redundant constraint equations are found first by rank analysis of the loop joints
        (:func:`se3dyn.engine.rank.redundant_equations`) and left out (``State.dropped``), so
        overconstrained mechanisms simulate with well-defined multipliers: those of the left-out
        equations are zero, the others unique. ``solver`` is accepted for compatibility and
        not used (the initial solve needs the index-3 layout)."""
        from se3dyn.engine.rank import equation_name, redundant_equations

        nq, nm = s.nq, s.nm
        dropped = redundant_equations(s) if nm else np.zeros(0, np.int64)
        if dropped.size and self.redundant == "error":
            names = [equation_name(s, r) for r in dropped]
            raise ModelError("model", "joints", "independent constraint equations",
                             f"{len(names)} redundant: " + ", ".join(names[:12])
                             + (" ..." if len(names) > 12 else ""),
                             hint="remove the duplicated freedom or use redundant='drop'")
        _check_couplings(s)
        v = np.zeros(nq)
        v[s.node_dofidx] = s.node_v0[s.node_free]
        H, HJ = s.node_H0.copy(), s.joint_H0.copy()
        inputs = step_inputs(s, t0)
        dd = s.drive_dof
        vd0 = np.zeros(nq)
        v[dd], vd0[dd] = _drive_start(s, t0, inputs["u"])
        zero = np.zeros(nq)
        lam0 = np.zeros(nm)
        ev = evaluate(s, H, HJ, s.alpha0, zero, v, vd0, lam0, inputs, (1.0, 0.0, 0.0),
                      accel=True, ws=ws)
        if nm and (np.any(v != 0) or s.cpl_follow.size):
            rates = v[dd].copy()
            v = self._project_velocity(s, LinearSolver(s, drop=dropped), ev.values, v)
            v[dd] = rates  # (exactly: the projection holds them to its round-off)
            v[s.cpl_follow] = s.cpl_ratio * v[s.cpl_lead]  # (exactly, as the steps keep it)
            _check_drive_velocities(s, v, ev.values, dropped)
            if self.initial_velocities == "strict":
                changed = _velocity_changes(s, v)
                if changed:
                    c = changed[0]
                    raise ModelError(
                        f"node {c['node']!r}", "velocity",
                        "initial velocities that satisfy the velocity constraints of the joints",
                        f"velocity changed by {c['dv']:.3g} m/s and angular velocity by "
                        f"{c['dw']:.3g} rad/s to satisfy them"
                        + (f" ({len(changed) - 1} more nodes)" if len(changed) > 1 else ""),
                        hint="give consistent velocities, or initial_velocities='project' "
                             "to have them projected (reported)")
            ev = evaluate(s, H, HJ, s.alpha0, zero, v, vd0, lam0, inputs, (1.0, 0.0, 0.0),
                          accel=True, ws=ws)
        # the index-3 layout; kept only when the steps use it too
        keep = not self.index2
        stp = _stepper(s, False, dropped, ws, keep=keep)
        ctrl = np.zeros(s.inputs.nctrl)
        if ctrl.size:  # PID laws: their states at t0 (a sampled law's first sample), in force
            stp.controller_inputs(ctrl, 0.0, float(t0), inputs["u"])
            ctrl = evaluate(s, H, HJ, s.alpha0, zero, v, vd0, lam0, inputs, ws=ws).ctrl
            stp.controller_inputs(ctrl, 0.0, float(t0), inputs["u"])
            ev = evaluate(s, H, HJ, s.alpha0, zero, v, vd0, lam0, inputs, (1.0, 0.0, 0.0),
                          accel=True, ws=ws)
        # [M Phi_q^T; Phi_q 0][vd; lam] = [-r; arhs] with the acceleration-level constraints
        # Phi_q vd = arhs (the time derivative of Phi_q v = 0), by the compiled sparse LU; the
        # driven accelerations given (vd0: their rows and columns the identity's, their terms
        # in the residual and on the right-hand side)
        rhs = np.concatenate([-ev.r, ev.arhs])
        ca, cb, cr = s.cpl_lead, s.cpl_follow, s.cpl_ratio
        np.add.at(rhs, ca, cr * rhs[cb])  # (a follower's equation on its leader's: engine.hpp)
        rhs[cb] = 0.0
        if dd.size:
            A0 = LinearSolver(s, drop=dropped).matrix(ev.values)
            rhs[nq:] -= np.asarray(A0[nq:][:, dd] @ vd0[dd]).ravel()
            rhs[dd] = 0.0
        rhs[nq + dropped] = 0.0
        code = stp.solve_values(ev.values, rhs)
        if code != 0 or not np.all(np.isfinite(rhs)):
            raise SimulationError(f"t={t0:.6g} (initial accelerations): the iteration matrix "
                                  f"is singular: {_singular_start_cause(s)}")
        vd = rhs[:nq] + vd0 if dd.size else rhs[:nq].copy()  # (-0.0 stays -0.0 without drives)
        vd[cb] = cr * vd[ca]
        power = ev.energy[3:6].copy()  # powers at t0 (velocity-level: vd does not enter)
        if dd.size:  # and the drivers' (their forces at the consistent state, as newton.hpp)
            ev1 = evaluate(s, H, HJ, s.alpha0, zero, v, vd, rhs[nq:], inputs, ws=ws)
            power[0] += float(ev1.r[dd] @ v[dd])
        return State(t=t0, H=H, HJ=HJ, v=v, vd=vd, a=vd.copy(),
                     lam=rhs[nq:].copy(), alpha=s.alpha0.copy(), power=power,
                     dropped=dropped, solver=_ws(s, ws).memory(stp) if keep else None,
                     ctrl=ctrl)

    @staticmethod
    def _project_velocity(s: System, solver: LinearSolver, values: np.ndarray,
                          v0: np.ndarray) -> np.ndarray:
        """Velocities satisfying the velocity constraints ``Phi_q v = 0`` with the given speeds
        kept (:func:`se3dyn.engine.projection.project_velocities`; the redundant equations
        ``solver.drop`` left out); the changes are reported by the caller per node."""
        import scipy.sparse as sp

        from se3dyn.engine.projection import project_velocities

        A = solver.matrix(values)
        A = sp.csr_matrix(A) if sp.issparse(A) else A
        nq = s.nq
        return project_velocities(s, A[:nq, :nq], A[nq:, :nq], v0, dropped=solver.drop,
                                  prescribed=s.drive_dof, couplings=(
                                      s.cpl_lead, s.cpl_follow, s.cpl_ratio))[0]

    # -----------------------------------------------------------------------------------------
    def step(self, s: System, st: State, h: float, solver: LinearSolver | None = None,
             ws=None, inputs: dict | None = None) -> tuple[State, StepInfo]:
        """Advance one step of size h; raises :class:`NewtonError` when Newton fails.

        The Newton iterations run in the compiled engine (``se3dyn/_core/newton.hpp``, one
        Newton loop for every kind of run): unknowns the increment n (nq), the scaled
        multipliers ``lambda / beta'`` (nm) and, for the index-2 formulation, ``xi`` (nm).
        Velocities and accelerations follow the part ``m = n - B_n^T xi`` of the increment:
        ``dv = gamma' dm``, ``dvd = beta' dm``. Rows: dynamics / beta' (Eq. (39)), constraints
        (Eq. (40)) and, for index 2, velocity constraints / gamma'; all O(1) whatever h.
        ``solver`` is accepted for compatibility and not used; ``ws`` is the
        :class:`~se3dyn.engine.workspace.Workspace` of the run (the system's default one otherwise);
        ``inputs``: those of the step (:func:`~se3dyn.engine.inputs.step_inputs`; the model's
        at ``t + h`` by default, others from :class:`~se3dyn.dynamics.simulator.Simulator`).
        """
        am, af, g, b = self.params
        t1 = st.t + h
        try:
            inputs = step_inputs(s, t1) if inputs is None else inputs
        except SimulationError as exc:
            raise SimulationError(f"step h={h:.6g} to {exc}") from None
        # a_n approximates vd(t_n + (alpha_m - alpha_f) h) (Arnold & Brüls 2007): after a
        # change of step size it is moved to the new h, a_n = vd_n + (h / h_last)(a_n - vd_n),
        # which keeps variable steps second order
        a_n = st.a
        if st.h_last > 0 and h != st.h_last:
            a_n = st.vd + (h / st.h_last) * (st.a - st.vd)
        stp = _stepper(s, self.index2, st.dropped, ws, split=self.newton == "modified")
        w = _ws(s, ws)
        w.adopt(stp, st.solver)
        F = s.M + s.m
        Hall = np.ascontiguousarray(np.concatenate([st.H, st.HJ]).reshape(F, 4, 4))
        Hout = np.empty_like(Hall)
        nq, nm = s.nq, s.nm
        alpha, v, vd, a, n = (np.zeros(nq) for _ in range(5))
        lam = np.zeros(nm)
        c = np.ascontiguousarray
        u = inputs["u"]
        ctrl = np.array(st.ctrl, dtype=float)
        if ctrl.size:  # the PID states of the step's start in their input slots
            stp.controller_inputs(ctrl, float(h), float(t1), u)
        status, it, er, ep, nfac, en = stp.step(
            Hall, c(st.alpha, float), c(st.v, float), c(st.vd, float), c(a_n, float),
            c(st.lam, float), u, float(h), am, af, g, b, self.tol_residual,
            self.tol_constraint * s.length_scale, float(s.length_scale), self.max_iter,
            self.newton == "modified", KMAX, Hout, alpha, v, vd, a, lam, n)
        if status != 0:
            stab = dict(cv=b * h / g) if (self.index2 and nm) else None
            ev = evaluate(s, st.H, st.HJ, st.alpha, n, v, vd, lam, inputs, full_alpha=False,
                          velocity=stab is not None, ws=ws)
            why = {1: "the iterate became non-finite",
                   2: f"no convergence within max_iter={self.max_iter} iterations",
                   3: "Newton is diverging (try a smaller step or rho_inf < 1)",
                   4: "the iteration matrix is singular (a mechanism in a singular "
                      "configuration, a massless node no joint determines, or a diverged "
                      "iterate)"}[status]
            self._fail(s, t1, h, it, ev, why, w.law_error())
        H, HJ = Hout[:s.M], Hout[s.M:]
        # local truncation error of the increment: a_n approximates vd(t_n + (alpha_m -
        # alpha_f) h), so the position update n = h v + h^2 ((1/2 - beta) a_n + beta a_{n+1})
        # reproduces the Taylor term h^3 q^(3) / 6 as (beta + (alpha_m - alpha_f) / 2) h^3 q^(3),
        # leaving (1/6 - beta - (alpha_m - alpha_f) / 2) h^3 q^(3), with h q^(3) measured by
        # a_{n+1} - a_n (0.084 h^3 q^(3) at rho_inf = 0.9, 1/12 at 1)
        err = (1.0 / 6.0 - b - 0.5 * (am - af)) * h * h * (a - a_n)
        jump = 0.0
        if ctrl.size:  # (the state after the switch of sampled laws at t1: newton.hpp)
            old = ctrl.copy()
            stp.ctrl_into(ctrl)
            jump = stp.sample_jump(old, v, vd, a, lam)
        new = State(t=t1, H=H, HJ=HJ, v=v, vd=vd, a=a, lam=lam, alpha=alpha,
                    dropped=st.dropped, h_last=h, solver=w.memory(stp), ctrl=ctrl)
        # energies and powers of the converged iterate (the compiled loop's too)
        e = dict(kinetic=en[0], potential=en[1], spring=en[2], power=np.array(en[3:6]))
        p = e["power"]
        # trapezoidal accumulation of the powers (second order, like the integrator)
        new = dataclasses.replace(new, power=p + np.array([jump, 0.0, 0.0]),
                                  work_act=st.work_act + 0.5 * h * (st.power[0] + p[0]),
                                  work_ext=st.work_ext + 0.5 * h * (st.power[1] + p[1]),
                                  dissipated=st.dissipated + 0.5 * h * (st.power[2] + p[2]))
        return new, StepInfo(int(it), float(er), float(ep), e, n, err)

    def _fail(self, s: System, t: float, h: float, it: int, ev, why: str,
              law: str | None = None):
        # non-finite entries (an overflow) count as the largest: never a crash here
        with np.errstate(all="ignore"):
            big = dict(nan=np.inf, posinf=np.inf)
            r = np.nan_to_num(np.abs(np.asarray(ev.r, dtype=float)), **big)
            phi = np.nan_to_num(np.abs(np.asarray(ev.phi, dtype=float)), **big)
            scale = float(ev.f_scale) if np.isfinite(ev.f_scale) else 1.0
            rs = r / max(scale, 1e-300)
            rmax = float(rs.max(initial=0.0))
            pmax = float(phi.max(initial=0.0))
            ptol = self.tol_constraint * s.length_scale
            if phi.size and (pmax / ptol > rmax / self.tol_residual
                             or (np.isinf(pmax) and not np.isinf(rmax))):
                i = int(np.argmax(phi))
                where = s.labels[s.nq + i]
                item = s.items[s.nq + i]
            elif r.size:
                i = int(np.argmax(rs))
                where = s.labels[i]
                item = s.items[i]
            else:  # pragma: no cover
                where = item = "?"
        if law is not None:  # (the non-finite values are the failed law's)
            why = f"the law of {law}"
        if not (np.isfinite(rmax) and np.isfinite(pmax)) and law is None:
            why += " (non-finite values: an overflow; check the magnitudes of the model's numbers)"
        msg = (f"Newton failed at t={t:.9g} (step h={h:.3g}) after {it} iterations: {why}; "
               f"residual {rmax:.3e} (relative, tol {self.tol_residual:.1e}), constraint "
               f"violation {pmax:.3e} (tol {ptol:.1e}); worst: {where}")
        raise NewtonError(msg, t=t, h=h, iterations=it, residual_norm=rmax,
                          constraint_norm=pmax, item=item)


def interpolate(s: System, st0: State, st1: State, n: np.ndarray, theta: float,
                ws=None) -> State:
    """State at ``t0 + theta h`` inside a converged step (dense output), ``0 <= theta <= 1``.

    Positions: a cubic Hermite curve in the increment space of each node and joint,
    ``H(theta) = H_0 exp(Delta(theta))`` with ``Delta(0) = 0``, ``Delta'(0) = h v_0``,
    ``Delta(1) = n`` (the step's increment, Eq. (38)) and ``Delta'(1) = h T(n)^-1 v_1``
    (Eq. (21)), so frames and their velocities match both ends; third-order accurate, like the
    step itself. Relative coordinates of abelian joints by the same Hermite curve (Eq. (60)),
    of non-abelian joints as log coordinates of the interpolated H_J. Velocities: cubic
    Hermite with the accelerations as slopes; accelerations, multipliers and accumulated works:
    linear.

    Parameters
    ----------
    s : System
    st0, st1 : State
        The states at the start and the end of the step.
    n : ndarray (nq,)
        The step's converged increment (``StepInfo.increment``).
    theta : float
    """
    h = st1.t - st0.t
    th = float(theta)
    h10 = th ** 3 - 2 * th ** 2 + th
    h01 = -2 * th ** 3 + 3 * th ** 2
    h11 = th ** 3 - th ** 2
    h00 = 2 * th ** 3 - 3 * th ** 2 + 1
    H = st0.H.copy()
    if len(s.node_free):
        nI = n[s.node_dofidx]
        v0 = st0.v[s.node_dofidx]
        v1 = np.einsum("nij,nj->ni", lie.tangent_se3_inv(nI), st1.v[s.node_dofidx])
        D = h10 * h * v0 + h01 * nI + h11 * h * v1
        H[s.node_free] = st0.H[s.node_free] @ lie.exp_se3(D)
    HJ = st0.HJ.copy()
    alpha = st0.alpha.copy()
    for g in s.groups:
        if not g.k:
            continue
        jd = g.jdof
        nJ = np.einsum("jik,jk->ji", g.A, n[jd])
        vJ0 = np.einsum("jik,jk->ji", g.A, st0.v[jd])
        vJ1 = np.einsum("jil,jl->ji", lie.tangent_se3_inv(nJ),
                        np.einsum("jik,jk->ji", g.A, st1.v[jd]))
        D = h10 * h * vJ0 + h01 * nJ + h11 * h * vJ1
        HJ[g.ids] = st0.HJ[g.ids] @ lie.exp_se3(D)
        alpha[jd] = st0.alpha[jd] + h10 * h * st0.v[jd] + h01 * n[jd] + h11 * h * st1.v[jd]
    # coordinates of non-abelian joints: log coordinates of the interpolated H_J (the kernels'
    # coordinates at n = 0 from the interpolated frames; abelian ones are kept)
    z = np.zeros(s.nq)
    alpha = evaluate(s, H, HJ, alpha, z, z, z, np.zeros(s.nm), dict(u=np.zeros(s.inputs.nu)),
                     full_alpha=True, ws=ws).alpha
    v = h00 * st0.v + h10 * h * st0.vd + h01 * st1.v + h11 * h * st1.vd
    lin = lambda x0, x1: (1 - th) * x0 + th * x1  # noqa: E731
    return State(t=st0.t + th * h, H=H, HJ=HJ, v=v, vd=lin(st0.vd, st1.vd),
                 a=lin(st0.a, st1.a), lam=lin(st0.lam, st1.lam), alpha=alpha,
                 work_act=lin(st0.work_act, st1.work_act),
                 work_ext=lin(st0.work_ext, st1.work_ext),
                 dissipated=lin(st0.dissipated, st1.dissipated),
                 power=lin(st0.power, st1.power), dropped=st1.dropped,
                 ctrl=lin(st0.ctrl, st1.ctrl))
