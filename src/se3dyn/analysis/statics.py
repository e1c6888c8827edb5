"""Static equilibrium by Newton iterations on the group, with load stepping.

At rest (``v = vd = 0``) the equations of motion (36)-(37) reduce to

    r(H, lambda) = g_int(H) + g_ext(H) + Phi_q^T lambda = 0,      Phi(H) = 0,

with the spring forces of Eq. (62) (references included), PD laws ``kp (alpha - target(t))``
(their derivative part vanishes at rest: the target rate is ignored), the actuator efforts, the
nodal loads and gravity of Eq. (66), and the constraints of Eq. (55). The unknowns are the
increments ``n`` of the free nodes and of the joint coordinates, ``H = H_0 exp(n)`` (Eq. (38)),
``alpha = alpha_0 + n`` (Eq. (60)); the Newton matrix is the static tangent

    [[K_T T + geometric stiffness, Phi_q^T], [Phi_q T, 0]]

(Eq. (46) without the inertia and damping terms, the load tangent of Eq. (67), the joint
stiffness of Eq. (63)), evaluated by :func:`se3dyn.engine.evaluate.matrix_values` with coefficients
``(0, 0, 1)``. After each converged load step the frames are re-based (``T = I``).

Load stepping: gravity, nodal loads and actuator efforts are multiplied by a load factor that goes
from 0 to 1 in ``load_steps`` equal increments; a step whose Newton iterations fail is halved
(bisection) up to ``max_cuts`` times, and grown back after two successes. Spring references and
PD targets are not scaled.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.analysis.assemble import _model_at
from se3dyn.analysis.common import _as_system, _Blocks, _OneConfiguration, _unknown_name
from se3dyn.analysis.reduced import held_rows
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.scaling import (
    _RCOND,
    _char_length,
    _describe,
    _null_space,
    _row_scale,
    _svd,
    _unknown_scale,
)
from se3dyn.errors import ModelError, SimulationError

if TYPE_CHECKING:
    from se3dyn.engine.system import System
    from se3dyn.model.specs import Model

sla = LazyModule("scipy.linalg")

__all__ = ["StaticResult", "static_equilibrium"]


@dataclass(eq=False)
class StaticResult(_OneConfiguration):
    """Outcome of :func:`static_equilibrium`.

    Attributes
    ----------
    system : System
    H : ndarray (M, 4, 4)        node frames at equilibrium
    HJ : ndarray (m, 4, 4)       joint transformations
    alpha : ndarray (nq,)        joint coordinates (Eq. (60), from the model's initial
                                 configuration; 0 on node unknowns)
    lam : ndarray (nm,)          multipliers: the reaction wrench of every joint on its node B,
                                 material frame (attachment frame ``H_B X_B`` for a joint
                                 with ``at``), sign of Eq. (36)
    load_factors : ndarray (s,)  load factor reached after every accepted load step (last: 1)
    iterations : ndarray (s,)    Newton iterations of every accepted load step
    cuts : int                   number of step halvings
    residual : float             final ``|r|_inf`` relative to the forces in it
    constraint : float           final scaled ``|Phi|_inf`` (translation rows divided by L)
    min_stiffness : float or None
        Smallest eigenvalue of the reduced stiffness ``N^T K N`` (N: orthonormal basis of the
        free motions, ``B N = 0``, in scaled unknowns: translations divided by L), in units of a
        moment (N m); ``None`` when the model has no free motion or is too large (nq > 1500).
    stable : bool or None
        ``min_stiffness > 0`` (up to round-off): the equilibrium is a local minimum of the
        potential energy when the loads are conservative.
    efforts : ndarray (nd + npid,) or None
        Drives (``ModelBuilder.drive``) and PID laws: the force or torque holding each driven
        or PID-controlled coordinate (:meth:`drive_effort` by drive name,
        :meth:`control_effort` by joint).
    """

    system: System
    H: np.ndarray
    HJ: np.ndarray
    alpha: np.ndarray
    lam: np.ndarray
    load_factors: np.ndarray
    iterations: np.ndarray
    cuts: int
    residual: float
    constraint: float
    min_stiffness: float | None
    stable: bool | None
    #: (nd + npid,) the force or torque holding every driven coordinate (System.drive_dof), then
    #: every PID-controlled one (``System.inputs.pid_ref``), at equilibrium
    efforts: np.ndarray | None = None
    _squeeze: bool = field(default=True, repr=False)

    def drive_effort(self, name: str) -> np.ndarray:
        """Force or torque a driver supplies to hold its coordinates, shape (c,): the residual
        of their rows of Eq. (36) at equilibrium (N m or N, positive along the coordinate)."""
        s = self.system
        names = [d.name for d in s.model.drives]
        if name not in names:
            raise KeyError(_unknown_name("drive", name, names))
        return self.efforts[:len(s.drive_of)][s.drive_of == names.index(name)].copy()

    def control_effort(self, joint: str) -> np.ndarray:
        """Force or torque of a joint's PID law at equilibrium, shape (k,): its integral part
        (the proportional and derivative parts vanish there, the coordinate at its target)."""
        s = self.system
        dofs = [d for _, d in s.inputs.pid_ref]
        if joint not in s.joint_names and joint not in s.composites:
            raise KeyError(_unknown_name("joint", joint, list(s.joint_names)))
        parts = s.composites.get(joint, (joint,))
        out = []
        for p in parts:
            j = s.joint_names.index(p)
            for c in range(int(s.joint_k[j])):
                d = int(s.joint_dofadr[j]) + c
                if d not in dofs:
                    raise KeyError(f"joint {joint!r} has no PID law")
                out.append(self.efforts[len(s.drive_of) + dofs.index(d)])
        return np.array(out)

    @property
    def _lam(self):
        return self.lam[None]

    @property
    def model(self) -> Model:
        """A new Model starting at rest in this equilibrium (joint coordinates restart at 0;
        spring references and PD targets shifted accordingly)."""
        return _model_at(self.system, self.H, self.alpha, np.zeros(self.system.nq))

    def __str__(self) -> str:
        st = ("unknown" if self.stable is None else "stable" if self.stable else "UNSTABLE")
        return (f"static equilibrium of {self.system.model.name!r}: {len(self.load_factors)} "
                f"load step(s), {int(np.sum(self.iterations))} Newton iterations, {self.cuts} "
                f"cut(s); residual {self.residual:.2e}, constraint {self.constraint:.2e}; "
                f"{st} (smallest reduced stiffness {self.min_stiffness})")


class _StepFailure(Exception):
    def __init__(self, why: str, worst: str, residual: float, constraint: float,
                 mechanism: str | None = None):
        super().__init__(why)
        self.why = why
        self.worst = worst
        self.residual = residual
        self.constraint = constraint
        self.mechanism = mechanism


def _scaled_inputs(full: dict, lf: float) -> dict:
    """Inputs at the load factor lf: gravity, loads and actuators scaled, PD targets kept,
    target rates zero (slots of :class:`se3dyn.engine.inputs._Inputs`)."""
    kind = full["kind"]
    scale = np.where(kind == 3, 1.0, np.where(kind == 4, 0.0, lf))
    return dict(u=scale * full["u"])


class _Newton:
    """Newton iterations of one load step (state re-based at the start)."""

    def __init__(self, s: System, tol: float, max_iter: int):
        self.s = s
        self.tol = tol
        self.max_iter = max_iter
        self.blocks = _Blocks(s)
        self.L = _char_length(s)
        self.cs = _unknown_scale(s, self.L)
        self.rs = _row_scale(s, self.L)
        self.redundant = False
        self.mechanism: str | None = None
        #: driven and PID-controlled coordinates and the values they are held at
        self.held = (s.drive_dof, s.alpha0[s.drive_dof])

    def _worst(self, ev, er_vec, ep_vec) -> str:
        s = self.s
        if ep_vec.size and ep_vec.max() / self.tol > er_vec.max(initial=0.0) / self.tol:
            return s.labels[s.nq + int(np.argmax(ep_vec))]
        if er_vec.size:
            return s.labels[int(np.argmax(er_vec))]
        return "?"  # pragma: no cover

    def solve(self, H, HJ, alpha, lam, inputs):
        s = self.s
        nq, nm = s.nq, s.nm
        n = np.zeros(nq)
        z = np.zeros(nq)
        cs, rs = self.cs, self.rs
        self.mechanism = None
        it = 0
        er0 = None
        while True:
            ev = evaluate(s, H, HJ, alpha, n, z, z, lam, inputs, None, full_alpha=True)
            dd, at = self.held
            r = ev.r.copy()
            ca, cb, cr = s.cpl_lead, s.cpl_follow, s.cpl_ratio
            np.add.at(r, ca, cr * r[cb])  # (a coupling's follower on its leader: engine.hpp)
            r[cb] = 0.0
            effort = r[dd].copy()
            r[dd] = 0.0  # (a driven coordinate's row: its value, the driver's force)
            fs = max(ev.f_scale, 1e-300)
            er_vec = np.abs(r) / fs
            ep_vec = np.abs(rs * ev.phi)
            er = float(er_vec.max(initial=0.0))
            ep = float(ep_vec.max(initial=0.0))
            if not (np.isfinite(er) and np.isfinite(ep)):
                raise _StepFailure("the iterate became non-finite", "?", er, ep,
                                   self.mechanism)
            miss = at - (alpha[dd] + n[dd])
            if er <= self.tol and ep <= self.tol and not np.any(miss):
                return ev, lam, it, er, ep, effort
            if it >= self.max_iter:
                raise _StepFailure(f"no convergence within max_iter={self.max_iter}",
                                   self._worst(ev, er_vec, ep_vec), er, ep, self.mechanism)
            if er0 is None:
                er0 = max(er, ep)
            elif it >= 3 and max(er, ep) > 1e6 * max(er0, 1e-8):
                raise _StepFailure("Newton is diverging", self._worst(ev, er_vec, ep_vec), er,
                                   ep, self.mechanism)
            K, PT, B = self.blocks(ev, (0.0, 0.0, 1.0))
            # scaled matrix: unknowns n = cs * x, multipliers lam = rs * y (moment units),
            # equation rows times cs (moments) and constraint rows times rs (dimensionless)
            S = np.block([[cs[:, None] * K * cs, cs[:, None] * PT * rs],
                          [rs[:, None] * B * cs, np.zeros((nm, nm))]])
            rhs = -np.concatenate([cs * r, rs * ev.phi])
            _eliminate_followers(s, S, cs)
            S[dd] = 0.0  # driven coordinates: their rows the identity's, their values given
            S[dd, dd] = 1.0
            rhs[dd] = miss / cs[dd]
            d = self._linear_solve(S, rhs, it)
            dn = cs * d[:nq]
            dn[cb] = cr * dn[ca]
            dl = rs * d[nq:]
            # a crude trust region: at most 1 rad (or L) per iteration
            big = float(np.abs(d[:nq]).max(initial=0.0))
            if big > 1.0:
                dn /= big
                dl /= big
            n = n + dn
            lam = lam + dl
            it += 1

    def _linear_solve(self, S: np.ndarray, rhs: np.ndarray, it: int) -> np.ndarray:
        nq = self.s.nq
        if not self.redundant:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore")
                lu, piv = sla.lu_factor(S, check_finite=False)
            p = np.abs(np.diag(lu))
            if np.all(np.isfinite(p)) and p.min(initial=1.0) > 1e-12 * max(p.max(initial=0.0),
                                                                              1e-300):
                return sla.lu_solve((lu, piv), rhs, check_finite=False)
        U, sv, Vt = _svd(S, full=True)
        r = int(np.sum(sv > 1e-11 * sv[0])) if sv.size and sv[0] > 0 else 0
        Nn = Vt[r:, :nq]  # unknown part of the null vectors
        if r < S.shape[0] and np.abs(Nn).max(initial=0.0) > 1e-6:
            # a free motion without stiffness here: remember it, and take a regularised
            # (Levenberg-Marquardt) step; the trust region limits it. If the equilibrium is
            # isolated, the next iterates have a regular tangent.
            k = int(np.argmax(np.linalg.norm(Nn, axis=1)))
            self.mechanism = _describe(Nn[k] * self.cs, self.s.labels)
            Sr = S.copy()
            mu = 1e-6 * float(sv[0])
            Sr[np.arange(nq), np.arange(nq)] += mu
            return sla.lstsq(Sr, rhs, cond=1e-14, lapack_driver="gelsy")[0]
        # null space in the multipliers only: redundant constraints, minimum-norm multipliers
        self.redundant = True
        return Vt[:r].T @ ((U[:, :r].T @ rhs) / sv[:r])


def static_equilibrium(model_or_system: Model | System, *, load_steps: int = 1,
                       tol: float = 1e-10, max_iter: int = 30, t: float = 0.0,
                       max_cuts: int = 10) -> StaticResult:
    """Static equilibrium under gravity, joint springs, actuators, PD laws and nodal loads.

    Newton iterations on the group (see the module docstring for the equations) from the model's
    initial configuration, with load stepping: the loads (gravity, nodal forces and torques,
    actuator efforts at time ``t``) are applied with a load factor increasing from 0 to 1 in
    ``load_steps`` increments; when Newton fails the increment is halved (at most ``max_cuts``
    times in a row). Redundant constraints are handled by least squares (the multipliers are then
    the minimum-norm ones, in moment units).

    Parameters
    ----------
    model_or_system : Model or System
    load_steps : int
        Number of equal load increments (more for large displacements).
    tol : float
        Tolerance on ``|r|_inf`` relative to the largest force in r and on the scaled constraint
        violation ``|Phi|_inf`` (translation rows divided by the characteristic length L).
    max_iter : int
        Maximum Newton iterations per load step.
    t : float
        Time at which actuators, loads and PD targets are evaluated.
    max_cuts : int
        Maximum number of successive halvings of a load increment.

    Returns
    -------
    StaticResult

    Raises
    ------
    ModelError
        Bad arguments.
    SimulationError
        The static tangent is singular: a free motion without stiffness (the equilibrium is not
        unique, or is unstable), naming the unknowns involved; or Newton cannot proceed even with
        the smallest load increment: the message gives the load factor reached, the one tried and
        the worst residual or constraint entry (a limit point, e.g. snap-through or buckling, or
        no equilibrium within reach); its ``result`` is then the StaticResult at the last
        load factor reached.
    """
    s = _as_system(model_or_system, "static_equilibrium")
    from se3dyn.dynamics.settings import MAX_STEPS

    for name, val, lo in (("load_steps", load_steps, 1), ("max_iter", max_iter, 1),
                          ("max_cuts", max_cuts, 0)):
        if not (isinstance(val, int) and not isinstance(val, bool) and lo <= val <= MAX_STEPS):
            raise ModelError("static_equilibrium", name, f"an integer from {lo} to "
                             f"{MAX_STEPS:.0e} (the most steps of a run)", val)
    if not (isinstance(tol, int | float) and 0 < tol < 1):
        raise ModelError("static_equilibrium", "tol", "a positive tolerance below 1", tol)
    if not (isinstance(t, int | float) and math.isfinite(t)):
        raise ModelError("static_equilibrium", "t", "a finite time", t)
    if len(s.sensor_dof):
        d = int(s.sensor_dof[0])
        raise ModelError("static_equilibrium", "model", "PID laws on their joints' own "
                         "coordinates (held at their targets at equilibrium)",
                         f"a sampled law on {s.labels[d]} reading a sensor",
                         hint="the equilibrium a law on a sensor holds is not solved for; "
                              "simulate to rest, or use a drive")
    full = dict(step_inputs(s, float(t)), kind=s.inputs.kind)
    newton = _Newton(s, tol, max_iter)
    # drives hold their coordinates: a position driver at f(t) (reached by the load steps
    # from the initial coordinate), a velocity driver where the model starts; the integral
    # action of a PID law holds its coordinate at the target (its steady state: e = 0)
    slots = np.array(s.inputs.drive_slots, np.int64).reshape(-1, 3)
    pid = np.array(s.inputs.pid_ref, np.int64).reshape(-1, 2)
    held = np.concatenate([s.drive_dof, pid[:, 1]])
    a0 = s.alpha0[held]
    goal = np.concatenate([np.where(slots[:, 0] >= 0, full["u"][np.maximum(slots[:, 0], 0)],
                                    a0[:len(slots)]), full["u"][pid[:, 0]]])
    efforts = np.zeros(len(a0))
    H, HJ = s.node_H0.copy(), s.joint_H0.copy()
    alpha = s.alpha0.copy()
    lam = np.zeros(s.nm)
    lf = 0.0
    nominal = 1.0 / load_steps
    dlf = nominal
    factors, iters = [], []
    cuts = 0
    run = 0  # consecutive successes since the last cut
    level = 0  # halvings of the current increment
    er = ep = 0.0
    while lf < 1.0:
        target = min(1.0, lf + dlf)
        if 1.0 - target < 1e-12:
            target = 1.0
        newton.held = (held, goal if target == 1.0 else a0 + target * (goal - a0))
        try:
            ev, lam_new, it, er, ep, effort = newton.solve(H, HJ, alpha, lam,
                                                   _scaled_inputs(full, target))
        except _StepFailure as fail:
            if level >= max_cuts:
                part = StaticResult(
                    system=s, H=H, HJ=HJ, alpha=alpha, lam=lam,
                    load_factors=np.array(factors), iterations=np.array(iters, dtype=int),
                    cuts=cuts, residual=er, constraint=ep, min_stiffness=None, stable=None)
                if fail.mechanism is not None:
                    raise SimulationError(_mechanism_message(
                        f"Newton cannot proceed beyond load factor {lf:.6g} (tried {target:.6g}:"
                        f" {fail.why}; worst: {fail.worst})", fail.mechanism,
                        "or has no equilibrium along it"), part) from None
                raise SimulationError(
                    f"static_equilibrium: Newton cannot proceed beyond load factor {lf:.6g} "
                    f"(tried {target:.6g} after {cuts} cut(s), increment {dlf:.3g}): "
                    f"{fail.why}; relative residual {fail.residual:.3e}, scaled constraint "
                    f"violation {fail.constraint:.3e} (tol {tol:.1e}); worst: {fail.worst}. "
                    "Likely a limit point (snap-through, buckling) or no equilibrium within "
                    "reach; try more load_steps or check the loads", part) from None
            dlf *= 0.5
            cuts += 1
            level += 1
            run = 0
            continue
        H, HJ, alpha, lam = ev.H, ev.HJ, ev.alpha, lam_new
        efforts = effort
        lf = target
        factors.append(lf)
        iters.append(it)
        run += 1
        if run >= 2 and dlf < nominal:
            dlf = min(nominal, 2.0 * dlf)
            level = max(0, level - 1)
            run = 0
    if not factors:  # pragma: no cover - the loop runs at least once
        factors, iters = [1.0], [0]
    kmin, stable = _stability(s, newton, H, HJ, alpha, lam, _scaled_inputs(full, 1.0))
    return StaticResult(system=s, H=H, HJ=HJ, alpha=alpha, lam=lam,
                        load_factors=np.array(factors), iterations=np.array(iters, dtype=int),
                        cuts=cuts, residual=er, constraint=ep, min_stiffness=kmin, stable=stable,
                        efforts=efforts)


def _eliminate_followers(s: System, S: np.ndarray, cs: np.ndarray) -> None:
    """The couplings' followers out of the scaled static tangent ``S`` (in place, as the time
    loop's matrix, engine.hpp): a follower's column added to its leader's and its row to the
    leader's (``n_b = ratio n_a``, in the scaled unknowns ``x = n / cs``), then the identity's."""
    for a, b, r in zip(s.cpl_lead, s.cpl_follow, s.cpl_ratio, strict=True):
        f = r * cs[a] / cs[b]
        S[:, a] += f * S[:, b]
        S[a, :] += f * S[b, :]
        S[b, :] = 0.0
        S[:, b] = 0.0
        S[b, b] = 1.0


def _mechanism_message(where: str, motion: str, extra: str = "") -> str:
    return (f"static_equilibrium: {where}: the static tangent matrix is singular - the "
            f"equilibrium is not unique or is unstable {extra}: a free motion has no stiffness "
            "(a mechanism that no spring, PD law, load or gravity holds). Free motion involves "
            f"{motion}. Add a spring or a PD law on one of these joints, fix the motion with a "
            "constraint, or load it")


def _stability(s: System, newton: _Newton, H, HJ, alpha, lam, inputs):
    """Smallest eigenvalue of the reduced (scaled) stiffness ``N^T K N`` with ``B N = 0``.

    Raises SimulationError when it vanishes (a free motion without stiffness)."""
    if s.nq == 0 or s.nq > 1500:
        return None, None
    z = np.zeros(s.nq)
    ev = evaluate(s, H, HJ, alpha, z, z, z, lam, inputs, None, full_alpha=True)
    K, _, B = newton.blocks(ev, (0.0, 0.0, 1.0))
    cs, rs = newton.cs, newton.rs
    dofs = newton.held[0]  # (driven and PID-held coordinates do not move; followers follow)
    held = held_rows(s, dofs)
    _, N = _null_space(np.vstack([rs[:, None] * B * cs, held * cs]), _RCOND)
    if N.shape[1] == 0:
        return None, None
    Kr = N.T @ (cs[:, None] * K * cs) @ N
    w, V = np.linalg.eigh(0.5 * (Kr + Kr.T))
    Ks = cs[:, None] * K * cs
    scale = max(float(np.abs(Ks).max(initial=0.0)), float(np.abs(lam).max(initial=0.0)))
    i = int(np.argmin(np.abs(w)))
    if abs(w[i]) <= 1e-10 * scale or scale == 0.0:
        raise SimulationError(_mechanism_message(
            "at the equilibrium reached (load factor 1)", _describe(N @ V[:, i] * cs, s.labels),
            "(zero stiffness along a free motion)"))
    return float(w[0]), bool(w[0] > 0)
