"""Exact linearisation of a model in minimal coordinates: mass, damping and stiffness matrices,
inputs and outputs, modes, a python-control state space, and the Jacobian of one
generalized-alpha step.

At a configuration with multipliers ``lambda`` the engine's element kernels give the tangents
of the residual of the equations of motion (Eq. (36)) ``r(q, v, vd) + B^T lambda = f(u)``: the
mass matrix ``M = dr/dvd``, the tangent damping ``C_T = dr/dv`` (dampers, PD laws' D part and
the gyroscopic terms of Eqs. (47)-(53)) and the tangent stiffness ``K_T = dr/dn`` with
``H = H exp(n)`` (Eq. (38)): springs, PD laws' P part, the tangents of gravity and follower
loads (Eq. (67)) and the geometric stiffness of the constraint forces ``d(B^T lambda)/dq`` of
the joint kernel, the same evaluation Newton uses (:func:`se3dyn.engine.evaluate.evaluate`
with coefficients ``(1, 0, 0)``, ``(0, 1, 0)``, ``(0, 0, 1)``). With the minimal-coordinate map
``v = T z_dot``, ``vd = T z_ddot + w`` (:mod:`se3dyn.analysis.reduced`) the reduced equations
``T^T (r - f) = 0`` (the multipliers drop out) linearise to

    M_z dz_ddot + C_z dz_dot + K_z dz = B_u du,      dy = C_y [dz; dz_dot]
    M_z = T^T M T
    C_z = T^T (C_T T + M dw/dz_dot)
    K_z = T^T (K_T T + C_T d(T z_dot)/dz + M d(T z_ddot + w)/dz)
    B_u = T^T dF/du

where ``d(T^T)/dz (r - f) = -d(T^T)/dz B^T lambda = T^T d(B^T lambda)/dq T`` (from ``T^T B^T =
0``) is the joint kernel's constraint term inside ``K_T``. At an equilibrium (``z_dot = z_ddot
= 0``, ``w = 0``) only ``T^T M T``, ``T^T C_T T``, ``T^T K_T T`` remain: exact. At a state with
motion, ``dw/dz_dot`` is a central difference of the quadratic ``w`` (exact up to round-off)
and the derivatives of the velocity map along the configuration are Richardson-extrapolated
central differences of the exact Jacobian (relative error ~1e-10). With motion the coordinate
rates also differ from the velocity perturbations on non-abelian coordinates: a frame
``H exp(eta)`` moving with the material velocity ``v`` has the velocity ``v + eta_dot +
ad(v) eta``, so ``z_dot = dv_I - G z`` with ``G`` the independent rows of ``ad(v) T`` (zero on
abelian joint coordinates), and the reported matrices are those of ``z`` and its rate:
``C <- C_z + M_z G``, ``K <- K_z + C_z G``. About a relative equilibrium (a steady spin: in
material velocities the state is time-invariant) the linear model holds for all times.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from se3dyn import lie
from se3dyn._lazy import LazyModule
from se3dyn.analysis.common import _as_system, _joint_ids, _unknown_name
from se3dyn.analysis.reduced import Constraints, Partition, ReducedMap
from se3dyn.analysis.statics import StaticResult, _scaled_inputs
from se3dyn.dynamics.state import State
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.scaling import _char_length, _unknown_scale
from se3dyn.errors import ModelError

if TYPE_CHECKING:
    from se3dyn.engine.system import System
    from se3dyn.model.specs import Model

sla = LazyModule("scipy.linalg")

__all__ = ["DiscreteStep", "Linearization", "Modes", "linearize", "step_jacobian"]


@dataclass(frozen=True, eq=False)
class _Point:
    """The state linearised about (frames, coordinates, velocities, multipliers, time)."""

    H: np.ndarray
    HJ: np.ndarray
    alpha: np.ndarray
    v: np.ndarray
    vd: np.ndarray
    lam: np.ndarray
    t: float
    u: np.ndarray | None = None  # the inputs of the step that reached it (a Simulator's)


def _point(s: System, at: Any, t: float | None) -> _Point:
    z = np.zeros(s.nq)
    if at is None:  # the initial state of a run: consistent accelerations and multipliers
        from se3dyn.dynamics.integrator import GeneralizedAlpha

        at = GeneralizedAlpha().init(s, 0.0 if t is None else float(t))
    if isinstance(at, StaticResult):
        if at.system.model is not s.model:
            raise ModelError("linearize", "at", "a StaticResult of this model",
                             f"one of model {at.system.model.name!r}")
        tt = 0.0 if t is None else float(t)
        u = None
        if at.load_factor != 1.0:  # (the loads it carries: statics' scaling of the inputs)
            u = _scaled_inputs(dict(step_inputs(s, tt), kind=s.inputs.kind), at.load_factor)["u"]
        return _Point(at.H, at.HJ, at.alpha, z, z, at.lam, tt, u)
    from se3dyn.dynamics.simulator import SimulatorState

    if isinstance(at, SimulatorState):
        if at.condensed:
            raise ModelError("linearize", "at", "a SimulatorState of the model's own unknowns",
                             "the state of a run with its rigid joints condensed",
                             "use Simulator(model, step, condense=False)")
        p = _point(s, at.state, t)
        return _Point(p.H, p.HJ, p.alpha, p.v, p.vd, p.lam, p.t, np.array(at.u))
    if isinstance(at, State):
        if at.H.shape != s.node_H0.shape or at.v.shape != (s.nq,):
            raise ModelError("linearize", "at", "a State of this model",
                             f"a State of {at.H.shape[0]} nodes, {at.v.size} unknowns")
        return _Point(at.H, at.HJ, at.alpha, at.v, at.vd, at.lam, at.t if t is None else t)
    raise ModelError("linearize", "at", "None (the initial configuration at rest), a "
                     "StaticResult or a State", type(at).__name__)


def _check_model(s: System) -> None:
    bad = int(np.sum(s.dof_ki > 0))
    if bad:
        raise ModelError("linearize", "model", "a model without PID laws (their integral "
                         "states are not in the linear model yet)", f"{bad} PID law(s)",
                         "use a PD law, or linearise without the controller")


# =============================================================================================
# the result
# =============================================================================================
@dataclass(eq=False)
class Modes:
    """Modes of a linearisation (one per degree of freedom, sorted by natural frequency).

    Attributes
    ----------
    eigenvalues : ndarray (n,) complex
        One eigenvalue ``s`` of each pair (the one with ``Im s >= 0``; for a pair of real ones,
        as for an overdamped or unstable degree of freedom, the larger).
    omega : ndarray (n,)
        Natural angular frequencies (rad/s): ``|s|`` of a complex pair, ``sqrt(|s1 s2|)`` of a
        real pair (0 for a rigid-body mode).
    frequency : ndarray (n,)    ``omega / 2 pi`` (Hz)
    damping : ndarray (n,)      damping ratios ``-Re(s1 + s2) / (2 omega)``
    rigid : ndarray (n,) bool   rigid-body modes: as many as ``K_z`` has null directions (to
                                1e-9 of its largest singular value), the slowest pairs
    stable : ndarray (n,) bool  no eigenvalue of the pair with a real part above 1e-7 of the
                                largest ``|s|`` (repeated eigenvalues of a defective problem,
                                e.g. a free body's, carry errors of ``sqrt(eps)`` relative)
    shapes : ndarray (nz, n) complex   mode shapes in the minimal coordinates (the eigenvector
                                of the kept eigenvalue; a rigid mode: a null vector of K_z)
    full_shapes : ndarray (nq, n) complex   the same in all unknowns (``T shapes``)
    names : tuple of str        the minimal coordinates
    """

    eigenvalues: np.ndarray
    omega: np.ndarray
    frequency: np.ndarray
    damping: np.ndarray
    rigid: np.ndarray
    stable: np.ndarray
    shapes: np.ndarray
    full_shapes: np.ndarray
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.omega)


@dataclass(eq=False)
class Linearization:
    """The linear model of :func:`linearize` in minimal coordinates ``z`` (see the module
    docstring for the formulas and the sign conventions).

    Attributes
    ----------
    system : System
    M, C, K : ndarray (nz, nz)    mass, damping (+ gyroscopic), stiffness (+ geometric,
                                  + load tangents) of the minimal coordinates
    B : ndarray (nz, nu)          generalized forces of unit inputs
    C_y : ndarray (ny, 2 nz)      outputs from ``[dz; dz_dot]``
    T : ndarray (nq, nz)          map back to all unknowns: ``dn = T dz``, ``v = T z_dot``
    partition : Partition         the independent unknowns (by name: :attr:`names`)
    names, input_names, output_names : tuple of str
    symmetric : bool              ``K`` symmetric to 1e-9 relative (at an equilibrium of a
                                  conservative system it is)
    """

    system: System
    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    B: np.ndarray
    C_y: np.ndarray
    T: np.ndarray
    partition: Partition
    names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    _point: _Point = field(repr=False)

    def __repr__(self) -> str:
        return (f"Linearization({len(self.names)} minimal coordinates: "
                f"{', '.join(self.names[:6])}{' ...' if len(self.names) > 6 else ''}; "
                f"{len(self.input_names)} inputs, {len(self.output_names)} outputs)")

    @property
    def symmetric(self) -> bool:
        K = self.K
        return bool(np.abs(K - K.T).max(initial=0.0) <= 1e-9 * np.abs(K).max(initial=1e-300))

    @property
    def A(self) -> np.ndarray:
        """First-order system matrix (2 nz, 2 nz) of ``x = [dz; dz_dot]``:
        ``[[0, I], [-M^-1 K, -M^-1 C]]``."""
        n = len(self.M)
        Mi_K = np.linalg.solve(self.M, np.hstack([self.K, self.C]))
        return np.block([[np.zeros((n, n)), np.eye(n)], [-Mi_K]])

    @property
    def B_x(self) -> np.ndarray:
        """Input matrix (2 nz, nu) of the first-order system: ``[0; M^-1 B]``."""
        n = len(self.M)
        return np.vstack([np.zeros((n, self.B.shape[1])), np.linalg.solve(self.M, self.B)])

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(self.names) + tuple(f"d/dt {n}" for n in self.names)

    def modes(self, k: int | None = None) -> Modes:
        """The ``k`` lowest modes (all by default), from the quadratic eigenproblem
        ``(s^2 M + s C + K) x = 0`` in its first-order companion form
        ``[[0, I], [-K, -C]] y = s [[I, 0], [0, M]] y`` (dense, scipy)."""
        return _modes(self, k)

    def state_space(self):
        """The continuous linear model as a python-control ``StateSpace`` with named states
        (``z`` then ``d/dt z``), inputs and outputs (``pip install se3dyn[analysis]``)."""
        try:
            import control
        except ImportError:
            raise ModelError("state_space", "python-control", "the package 'control' "
                             "installed (pip install se3dyn[analysis])", "not installed"
                             ) from None
        D = np.zeros((self.C_y.shape[0], self.B.shape[1]))
        return control.ss(self.A, self.B_x, self.C_y, D, states=list(self.state_names),
                          inputs=list(self.input_names), outputs=list(self.output_names))

    def discrete(self, h: float, *, rho_inf: float = 0.9) -> DiscreteStep:
        """The exact Jacobian of one step of se3dyn's generalized-alpha scheme about the
        equilibrium: see :func:`se3dyn.analysis.linearize.step_jacobian`."""
        return step_jacobian(self, h, rho_inf=rho_inf)


# =============================================================================================
# the linearisation
# =============================================================================================
def linearize(model_or_system: Model | System, at: Any = None, *, inputs=(), outputs=(),
              t: float | None = None, independent=None) -> Linearization:
    """Linearise a model in minimal coordinates about an equilibrium or a state of a run.

    Parameters
    ----------
    model_or_system : Model or System
    at : StaticResult, State, SimulatorState or None
        A static equilibrium (:func:`se3dyn.static_equilibrium`), any State of a run (of
        :meth:`GeneralizedAlpha.step`), a :class:`Simulator`'s state (its inputs then those of
        the step that reached it; a simulator with ``condense=False`` if the model has rigid
        joints), or None: the initial state of a run of the model (its initial configuration
        and velocities, consistent accelerations and multipliers).
    inputs : sequence of str
        Joint names (a unit generalized force on each of the joint's coordinates, positive
        along it: an actuator's torque or force, Eq. (66)) and load names (each force and
        torque component of the load, in the load's frame).
    outputs : sequence of str
        Joint names (their coordinates), node and marker names (the position of their origin
        in the inertial frame, 3 rows ``name/x``, ``name/y``, ``name/z``); a name that is both
        a joint's and a node's is the joint.
    t : float, optional
        Time of the model's own inputs (default: the State's time, 0 for an equilibrium).
    independent : sequence of str, optional
        Joints whose coordinates must be independent (closed loops).

    Returns
    -------
    Linearization
    """
    s = _as_system(model_or_system, "linearize")
    _check_model(s)
    p = _point(s, at, t)
    con = Constraints(s, locked=s.drive_dof)
    rm = con.map_at(p.H, p.HJ, p.alpha, independent=independent)
    u = step_inputs(s, p.t) if p.u is None else dict(u=p.u)
    M, C, K = _tangents(s, con, p, u)
    T = rm.T
    Mz, Cz, Kz = T.T @ M @ T, T.T @ C @ T, T.T @ K @ T
    if np.any(p.v) or np.any(p.vd):
        dC, dK = _motion_terms(s, con, rm, p, M, C)
        Cz, Kz = Cz + dC, Kz + dK
        # from velocity perturbations to coordinate rates: dz_dot = dv_I - G dz
        G = _bracket(s, rm, p.v)
        Cz, Kz = Cz + Mz @ G, Kz + Cz @ G
    Bf, in_names = _input_matrix(s, p, u, inputs)
    Cy, out_names = _output_matrix(s, p, T, outputs)
    return Linearization(system=s, M=Mz, C=Cz, K=Kz, B=T.T @ Bf, C_y=Cy, T=T,
                         partition=rm.part, names=rm.part.names, input_names=in_names,
                         output_names=out_names, _point=p)


def _tangents(s: System, con: Constraints, p: _Point, u: dict):
    """``M``, ``C_T``, ``K_T`` (nq, nq) of all unknowns at the point (element kernels)."""
    out = []
    for coef in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)):
        ev = evaluate(s, p.H, p.HJ, p.alpha, con.zq, p.v, p.vd, p.lam, u, coef,
                      full_alpha=False)
        out.append(con.blocks.split(ev.values)[0])
    return out


def _motion_terms(s: System, con: Constraints, rm: ReducedMap, p: _Point, M, C):
    """The terms of a state with motion: ``T^T M dw/dz_dot`` and ``T^T (C_T d(T z_dot)/dz +
    M d(T z_ddot + w)/dz)`` (see the module docstring). Driven coordinates move with their
    drives' rates and accelerations (``v = T z_dot + v_p``, ``v_p`` the unknowns moving with the
    drives alone, at every configuration): a rotor driven at constant speed."""
    T, ind, dd = rm.T, rm.part.independent, s.drive_dof
    zd, zdd = p.v[ind], p.vd[ind]  # (T is the identity there, v_p and w zero)
    nz = T.shape[1]
    scale = max(float(np.abs(zd).max(initial=0.0)), 1.0)
    vp = _driven(rm, p.v[dd], s.nm)
    dw = np.zeros((s.nq, nz))
    for k in range(nz):  # w is quadratic in z_dot: the central difference is exact
        e = np.zeros(nz)
        e[k] = scale
        dw[:, k] = (con.accel_term(rm, p.H, p.HJ, p.alpha, T @ (zd + e) + vp)
                    - con.accel_term(rm, p.H, p.HJ, p.alpha, T @ (zd - e) + vp)) / (2 * scale)
    cs = _unknown_scale(s, _char_length(s))

    def along(n):  # (v, vd) at the configuration H exp(n), re-based there
        # (the matrix of an evaluation at n holds B T(n), Eq. (46): B itself is at n = 0)
        ev = evaluate(s, p.H, p.HJ, p.alpha, n, con.zq, con.zq, con.lam0, con.zin, None,
                      full_alpha=False)
        r2 = con.map_at(ev.H, ev.HJ, ev.alpha, rm.part)
        v = r2.T @ zd + _driven(r2, p.v[dd], s.nm)
        return np.concatenate([v, r2.T @ zdd + con.accel_term(r2, ev.H, ev.HJ, ev.alpha, v)
                               + _driven(r2, p.vd[dd], s.nm)])

    dV = np.zeros((2 * s.nq, nz))
    for k in range(nz):
        d = T[:, k]
        eps = 1e-3 / max(float(np.abs(d / cs).max(initial=0.0)), 1e-300)
        D1 = (along(eps * d) - along(-eps * d)) / (2 * eps)
        D2 = (along(0.5 * eps * d) - along(-0.5 * eps * d)) / eps
        dV[:, k] = (4 * D2 - D1) / 3
    nq = s.nq
    return T.T @ M @ dw, T.T @ (C @ dV[:nq] + M @ dV[nq:])


def _driven(rm: ReducedMap, x: np.ndarray, nm: int) -> np.ndarray:
    """The unknowns (nq,) moving with the driven coordinates' rates (or accelerations) ``x``
    alone, the independent ones at rest: the locked rows of ``[B; E]`` follow the ``nm``
    joint rows (:func:`se3dyn.analysis.reduced.held_rows`)."""
    out = np.zeros(rm.T.shape[0])
    if not np.any(x):
        return out
    rhs = np.zeros(rm.B.shape[0])
    rhs[nm:nm + len(x)] = x
    return rm.solve_dependent(rhs)


def _bracket(s: System, rm: ReducedMap, v: np.ndarray) -> np.ndarray:
    """``G`` (nz, nz): the independent rows of ``ad(v) T`` frame by frame. A perturbation
    ``H exp(eta)`` of a frame moving with the material velocity ``v`` has the velocity ``v +
    eta_dot + ad(v) eta`` (``Ad_{exp(-eta)} v + T(eta) eta_dot``, Eqs. (6), (27)), so the
    coordinate rates are ``eta_dot = dv - ad(v) eta``; zero on abelian joint coordinates."""
    Gf = np.zeros((s.nq, s.nq))
    for i in s.node_free:
        d = int(s.node_dofadr[i])
        Gf[d:d + 6, d:d + 6] = lie.ad6(v[d:d + 6])
    for grp in s.groups:
        for e in range(len(grp.ids)):
            if grp.k == 0 or grp.abelian[e]:
                continue
            A, dofs = grp.A[e], grp.jdof[e]
            Gf[np.ix_(dofs, dofs)] = np.linalg.pinv(A) @ lie.ad6(A @ v[dofs]) @ A
    return (Gf @ rm.T)[rm.part.independent]


def _input_matrix(s: System, p: _Point, u: dict, names) -> tuple[np.ndarray, tuple]:
    """Generalized forces (nq, nu) of unit inputs, and the input names."""
    cols, out = [], []
    loads = {ld.name: ld for ld in s.model.loads}
    for name in names:
        if name in loads:
            c, n = _load_columns(s, p, u, name)
            cols += c
            out += n
            continue
        try:
            ids = _joint_ids(s, name, "linearize", "inputs")
        except ModelError:
            valid = [n for n in s.joint_names if ":" not in n] + list(loads)
            raise ModelError("linearize", "inputs", "names of joints or loads", name,
                             _unknown_name("input", name, valid)) from None
        for j in ids:
            for c in range(int(s.joint_k[j])):
                e = np.zeros(s.nq)
                e[int(s.joint_dofadr[j]) + c] = 1.0
                cols.append(e)
                out.append(f"{s.joint_names[j]}[{c}]" if s.joint_k[j] > 1
                           else s.joint_names[j])
    B = np.array(cols).T if cols else np.zeros((s.nq, 0))
    return B, tuple(out)


def _load_columns(s: System, p: _Point, u: dict, name: str) -> tuple[list, list]:
    """The generalized force of each unit component of a load: ``-(r(u + e) - r(u))`` (the
    residual is affine in the inputs)."""
    cols, out = [], []
    z = np.zeros(s.nq)
    r0 = evaluate(s, p.H, p.HJ, p.alpha, z, p.v, p.vd, p.lam, u, None, full_alpha=False).r
    for kind, item, fld, slot, k in s.inputs.names:
        if kind != "load" or item != name:
            continue
        for c in range(k):
            u2 = u["u"].copy()
            u2[slot + c] += 1.0
            r = evaluate(s, p.H, p.HJ, p.alpha, z, p.v, p.vd, p.lam, dict(u=u2), None,
                         full_alpha=False).r
            cols.append(r0 - r)
            out.append(f"{name}/{fld}_{'xyz'[c]}")
    return cols, out


def _output_matrix(s: System, p: _Point, T: np.ndarray, names) -> tuple[np.ndarray, tuple]:
    """Rows (ny, 2 nz) of the outputs: joint coordinates, node and marker positions."""
    rows, out = [], []
    markers = {mk.name: mk for mk in s.model.markers}
    joints = set(s.joint_names) | set(s.composites)
    for name in names:
        if name in joints:
            for j in _joint_ids(s, name, "linearize", "outputs"):
                for c in range(int(s.joint_k[j])):
                    rows.append(T[int(s.joint_dofadr[j]) + c])
                    out.append(f"{s.joint_names[j]}[{c}]" if s.joint_k[j] > 1
                               else s.joint_names[j])
        elif name in s.node_names or name in markers:
            node = markers[name].node if name in markers else name
            i = s.node_names.index(node)
            X = markers[name].X if name in markers else np.eye(4)
            d = int(s.node_dofadr[i])
            Jn = np.zeros((6, T.shape[1])) if d < 0 else T[d:d + 6]
            # dx = R (n_U + n_Omega x c) with c the marker's origin on the node
            G = p.H[i, :3, :3] @ np.hstack([np.eye(3), -lie.hat3(X[:3, 3])])
            rows += list(G @ Jn)
            out += [f"{name}/{a}" for a in "xyz"]
        else:
            valid = list(s.joint_names) + list(s.node_names) + list(markers)
            raise ModelError("linearize", "outputs", "names of joints, nodes or markers",
                             name, _unknown_name("output", name, valid))
    nz = T.shape[1]
    Cy = np.hstack([np.array(rows).reshape(-1, nz), np.zeros((len(rows), nz))])
    return Cy, tuple(out)


# =============================================================================================
# modes
# =============================================================================================
def _modes(lin: Linearization, k: int | None) -> Modes:
    n = len(lin.M)
    if k is not None and not (isinstance(k, int) and 1 <= k):
        raise ModelError("modes", "k", "a positive number of modes", k)
    lam, Y = _eigen(lin.M, lin.C, lin.K, k)
    scale = max(float(np.abs(lam).max(initial=0.0)), 1e-300)
    pairs = _pairs(lam, scale)
    ev, om, zeta, shapes, st = [], [], [], [], []
    for i1, i2 in pairs:
        s1, s2 = lam[i1], lam[i2]
        w = float(np.sqrt(abs((s1 * s2).real)))
        ev.append(s1)
        om.append(w)
        zeta.append(float(-(s1 + s2).real / (2 * w)) if w > 1e-7 * scale else 0.0)
        shapes.append(Y[:n, i1])
        st.append(bool(max(s1.real, s2.real) <= 1e-7 * scale))
    om_a = np.array(om)
    # rigid-body modes: as many as the null space of K has directions, the slowest pairs (a
    # double zero eigenvalue: a Jordan block, computed as +-sqrt(eps) scale)
    _, N0 = _null(lin.K)
    rigid = np.zeros(len(om_a), bool)
    rigid[np.argsort(om_a, kind="stable")[:N0.shape[1]]] = True
    om_a[rigid] = 0.0
    order = np.lexsort((np.arange(len(om_a)), om_a))
    Sh = np.array(shapes).T.astype(complex)
    Sh[:, np.flatnonzero(rigid)] = N0
    order = order[:k] if k is not None else order
    Sh = Sh[:, order]
    Sh = Sh / np.where(np.abs(Sh).max(axis=0) > 0, _peak(Sh), 1.0)
    return Modes(eigenvalues=np.array(ev)[order], omega=om_a[order],
                 frequency=om_a[order] / (2 * np.pi), damping=np.array(zeta)[order],
                 rigid=rigid[order], stable=np.array(st)[order], shapes=Sh,
                 full_shapes=lin.T @ Sh, names=lin.names)


def _eigen(M: np.ndarray, C: np.ndarray, K: np.ndarray, k: int | None = None
           ) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues and vectors ``[x; s x]`` of ``(s^2 M + s C + K) x = 0``: the companion
    matrix ``[[0, I], [-M^-1 K, -M^-1 C]]`` scaled by ``diag(w, 1)``, ``w_i = sqrt(K_ii /
    M_ii)``, so that every block is of the size of its frequencies (a stiff structure's
    companion form spans 1e18 in magnitude unscaled, and the real parts of its eigenvalues come
    out at 1e-8 of the largest frequency instead of round-off: a slender blade's "growth"
    of 20 1/s at rest); the generalized form when M is singular."""
    n = len(M)
    I, Z = np.eye(n), np.zeros((n, n))
    dM, dK = np.abs(np.diag(M)), np.abs(np.diag(K))
    if k is not None and n >= 200 and 4 * k <= n and _conservative(M, C, K):
        return _lowest(M, K, k)
    if n == 0 or _rcond(M) < 1e-12:
        return sla.eig(np.block([[Z, I], [-K, -C]]), np.block([[I, Z], [Z, M]]))
    w = np.where((dK > 0) & (dM > 0), np.sqrt(dK / np.where(dM > 0, dM, 1.0)), 1.0)
    A = np.block([[Z, np.diag(1.0 / w)], [-np.linalg.solve(M, K) * w, -np.linalg.solve(M, C)]])
    lam, Y = sla.eig(A)
    Y[:n] *= w[:, None]
    return lam, Y


def _conservative(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> bool:
    """No damping or gyroscopic term, ``K`` and ``M`` symmetric (to 1e-9)."""
    def sym(X):
        return float(np.abs(X - X.T).max(initial=0.0)) <= 1e-9 * max(
            float(np.abs(X).max(initial=0.0)), 1e-300)

    return not np.any(C) and sym(K) and sym(M)


def _lowest(M: np.ndarray, K: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` slowest modes of a large conservative model by shift-invert Lanczos on
    ``K x = w^2 M x`` (ARPACK), the shift half the lowest flexible ``w^2`` of a rough LAPACK
    subset, below the spectrum: a 600-coordinate beam's 20 modes in 0.05 s (the whole
    companion spectrum 1 s), and more accurate there (eigen-residuals 1e-7 where the companion
    form's vectors of a beam with a 1e8 rad/s spread leave O(1)); as the companion form's
    eigenvalues ``+-sqrt(-w^2)`` and vectors ``[x; s x]``."""
    from scipy.sparse.linalg import eigsh

    Ks, Ms = 0.5 * (K + K.T), 0.5 * (M + M.T)
    est = sla.eigh(Ks, Ms, eigvals_only=True, subset_by_index=[0, min(12, len(K) - 1)])
    pos = est[est > 1e-8 * max(float(est[-1]), 1e-300)]
    w2, X = eigsh(Ks, k=k, M=Ms, sigma=-0.5 * (float(pos[0]) if pos.size else 1.0),
                  which="LM")
    order = np.argsort(w2)
    w2, X = w2[order], X[:, order]
    s = np.sqrt(-w2.astype(complex))
    return np.concatenate([s, -s]), np.vstack([np.hstack([X, X]), np.hstack([X * s, -X * s])])


def _rcond(M: np.ndarray) -> float:
    """LAPACK's estimate of the reciprocal condition number of ``M`` (1-norm, from its LU:
    a fraction of an SVD's cost)."""
    lu, _ = sla.lu_factor(M, check_finite=False)
    if not np.all(np.isfinite(lu)):
        return 0.0
    return float(sla.lapack.dgecon(lu, float(np.abs(M).sum(axis=0).max()), norm="1")[0])


def _peak(S: np.ndarray) -> np.ndarray:
    """The largest component (by modulus) of every column (normalisation to 1 there)."""
    return S[np.argmax(np.abs(S), axis=0), np.arange(S.shape[1])]


#: a singular value of K below this times its largest is a rigid-body direction. A null
#: direction of K comes out at round-off (1e-17 relative, also about a steady spin, where the
#: motion terms are differences); a stiff structure's softest flexible one is far above it but
#: may be small: a slender rotating blade (EA / EI = 1e6, 64 elements) keeps its first flap mode
#: at 1.2e-10 (tests/test_campbell.py)
_RIGID_SV = 1e-12


def _null(K: np.ndarray) -> tuple[int, np.ndarray]:
    _, sv, Vt = np.linalg.svd(K)
    r = int(np.sum(sv > _RIGID_SV * max(sv[0], 1e-300))) if sv.size else 0
    return r, Vt[r:].T


def _pairs(lam: np.ndarray, scale: float) -> list[tuple[int, int]]:
    """Indices of the eigenvalue pairs: complex conjugates together, real ones two by two in
    increasing order (the two roots of an overdamped, unstable or rigid degree of freedom)."""
    tol = 1e-9 * scale
    cplx = [i for i in range(len(lam)) if lam[i].imag > tol]
    used = set(cplx)
    pairs = []
    for i in cplx:
        j = min((j for j in range(len(lam)) if j not in used and lam[j].imag < -tol),
                key=lambda j: abs(lam[j] - np.conj(lam[i])))
        used.add(j)
        pairs.append((i, j))
    real = sorted((i for i in range(len(lam)) if i not in used), key=lambda i: lam[i].real)
    # pair the real roots from the outside in: an unstable dof's +-sqrt(k/m), a rigid dof's
    # double zero, an overdamped dof's two negative roots
    while len(real) >= 2:
        i, j = real.pop(), real.pop(0)
        pairs.append((i, j))
    return pairs


@dataclass(eq=False)
class DiscreteStep:
    """The Jacobian of one generalized-alpha step of size ``h`` about an equilibrium:
    ``x_{n+1} = Phi x_n + Gamma u_{n+1}`` with ``x = [dz; dz_dot; dz_ddot; a]`` (4 nz: the
    scheme's own memory, ``a`` its acceleration-like variable of Eq. (43)) and the inputs held
    at the end of the step (where the step imposes the equations of motion).

    Attributes
    ----------
    Phi : ndarray (4 nz, 4 nz); Gamma : ndarray (4 nz, nu); C_y : ndarray (ny, 4 nz)
    h : float; params : (alpha_m, alpha_f, gamma, beta) of Eq. (44)
    state_names, input_names, output_names : tuple of str
    """

    Phi: np.ndarray
    Gamma: np.ndarray
    C_y: np.ndarray
    h: float
    params: tuple
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]

    def state_space(self):
        """A discrete python-control ``StateSpace`` (``dt = h``) with named signals."""
        import control

        D = np.zeros((self.C_y.shape[0], self.Gamma.shape[1]))
        return control.ss(self.Phi, self.Gamma, self.C_y, D, self.h,
                          states=list(self.state_names), inputs=list(self.input_names),
                          outputs=list(self.output_names))


def step_jacobian(lin: Linearization, h: float, *, rho_inf: float = 0.9) -> DiscreteStep:
    """The exact Jacobian of one step of se3dyn's Lie-group generalized-alpha scheme (Eqs.
    (38)-(46); either formulation, index 3 or stabilised index 2) about an equilibrium.

    About an equilibrium the step's increments, velocities and accelerations are first order
    in the perturbation, ``H exp(n)`` composes to first order as ``z + n``, and the residual and
    the constraints linearise to ``M vd + C v + K dq + B^T dlambda = B_u u``, ``B dq = 0`` with
    the matrices of the linearisation (the constraint force's geometric stiffness inside K);
    the solution stays in the range of ``T`` (``xi = 0`` in the index-2 form). The Jacobian is
    therefore the scheme applied to ``M_z z_ddot + C_z z_dot + K_z z = B_z u``: with
    ``S = (1 - alpha_m)/(1 - alpha_f) M + gamma h C + beta h^2 K``,

        a_{n+1} = S^-1 (B u_{n+1} - M vd* - C v* - K z*)
        z* = z_n + h z_dot_n + h^2 (1/2 - beta) a_n,   v* = z_dot_n + h (1 - gamma) a_n
        vd* = (alpha_m a_n - alpha_f z_ddot_n) / (1 - alpha_f)

    and ``z_{n+1} = z* + beta h^2 a_{n+1}``, ``z_dot_{n+1} = v* + gamma h a_{n+1}``,
    ``z_ddot_{n+1} = vd* + (1 - alpha_m)/(1 - alpha_f) a_{n+1}``.

    Parameters
    ----------
    lin : Linearization        about an equilibrium (at rest, no acceleration)
    h : float                  step size
    rho_inf : float            the scheme's spectral radius at infinity (``simulate``'s)
    """
    from se3dyn.dynamics.integrator import GeneralizedAlpha

    p = lin._point
    if np.any(p.v) or np.abs(p.vd).max(initial=0.0) > 1e-9 * max(1.0, np.abs(p.v).max(
            initial=0.0)):
        raise ModelError("discrete", "at", "a linearisation about an equilibrium (no velocity "
                         "or acceleration)", "a state with motion")
    if not (isinstance(h, int | float) and 0 < h < np.inf):
        raise ModelError("discrete", "h", "a positive step size", h)
    am, af, g, b = GeneralizedAlpha(rho_inf=rho_inf).params
    n = len(lin.M)
    I, Z = np.eye(n), np.zeros((n, n))
    Pq = np.hstack([I, h * I, Z, h * h * (0.5 - b) * I])
    Pv = np.hstack([Z, I, Z, h * (1 - g) * I])
    Pd = np.hstack([Z, Z, -af / (1 - af) * I, am / (1 - af) * I])
    c = (1 - am) / (1 - af)
    S = c * lin.M + g * h * lin.C + b * h * h * lin.K
    A1 = -np.linalg.solve(S, lin.M @ Pd + lin.C @ Pv + lin.K @ Pq)
    G1 = np.linalg.solve(S, lin.B)
    Phi = np.vstack([Pq + b * h * h * A1, Pv + g * h * A1, Pd + c * A1, A1])
    Gamma = np.vstack([b * h * h * G1, g * h * G1, c * G1, G1])
    Cy = np.hstack([lin.C_y, np.zeros((lin.C_y.shape[0], 2 * n))])
    names = (tuple(lin.state_names) + tuple(f"d2/dt2 {x}" for x in lin.names)
             + tuple(f"a {x}" for x in lin.names))
    return DiscreteStep(Phi=Phi, Gamma=Gamma, C_y=Cy, h=float(h), params=(am, af, g, b),
                        state_names=names, input_names=lin.input_names,
                        output_names=lin.output_names)
