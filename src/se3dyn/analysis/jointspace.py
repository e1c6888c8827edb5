"""Joint-space view of a model: mass matrix, bias forces, inverse and forward dynamics, frame
poses and Jacobians in the independent coordinates (:mod:`se3dyn.analysis.reduced`).

Everything is computed by the engine from the SE(3) model: at a configuration the element kernels
give the mass matrix ``M`` of all unknowns (material velocities of the nodes, joint rates; Eqs.
(47)-(53)), the residual ``r(q, v, vd)`` of the equations of motion (Eq. (36), with gravity,
springs, dampers, PD laws, actuators and loads of the model) and the constraint Jacobian ``B``
(Eq. (58)). With ``v = T z_dot`` and ``vd = T z_ddot + w`` (the minimal-coordinate map),

    M_z = T^T M T,      tau = T^T r(q, T z_dot, T z_ddot + w)

(the multipliers drop out: ``T^T B^T = 0``). The sign convention is Pinocchio's:
``M_z z_ddot + b(q, z_dot) = tau`` with ``b = T^T r(q, T z_dot, w)``, ``tau`` the generalized
forces applied on the independent coordinates (for a joint coordinate: the actuator torque or
force along it, as ``ModelBuilder.joint(..., torque=)``).

On trees whose forces are inertia, gravity and the joints' armatures, springs and dampers, the
same quantities come from a compiled path (recursive Newton-Euler, composite-rigid-body
algorithm: :mod:`se3dyn.analysis._jointtree`, ``se3dyn/_core/joint_tree.hpp``);
:attr:`JointSpace.compiled` and :attr:`JointSpace.fallback_reason` say which path a model takes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from se3dyn import lie
from se3dyn._core import _engine
from se3dyn.analysis._jointtree import fallback_reason, tree_tables
from se3dyn.analysis.common import _as_system, _unknown_name
from se3dyn.analysis.reduced import Constraints, partition, reduced_map
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.scaling import _char_length, _row_scale, _unknown_scale
from se3dyn.errors import ModelError, SimulationError

if TYPE_CHECKING:
    from se3dyn.engine.system import System
    from se3dyn.model.specs import Model

__all__ = ["JointSpace"]

_NONE = np.zeros(0)  # (a velocity or acceleration of zero for the compiled path)
_FRAMES = ("local", "local_world_aligned")


def quat_to_rot(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) ``(x, y, z, w)`` (Pinocchio's
    order); normalised first."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


class JointSpace:
    """Joint-space dynamics of a model, in its independent coordinates.

    Coordinates: on a tree, the joint coordinates (Eq. (60): as the results report them,
    absolute for joints given ``initial``) and, for every free node that no joint carries (a
    floating root), its pose as 7 numbers ``(x, y, z, qx, qy, qz, qw)`` (position, unit
    quaternion: Pinocchio's free-flyer convention) with 6 velocities, its material velocity
    ``(U, Omega)`` (Eq. (4), Pinocchio's LOCAL). On closed loops, the independent joint
    coordinates of the coordinate partitioning (:attr:`joint_names`); the dependent ones are
    solved by Newton on the closure constraints from the tree's positions.

    Parameters
    ----------
    model_or_system : Model or System
    t : float
        Time at which the model's own time-dependent inputs (gravity, actuator signals, loads,
        PD targets) are taken.
    independent : sequence of str, optional
        Joints whose coordinates must be independent (closed loops).
    compiled : bool
        False: the general path even on trees (the reference of the compiled one).

    Attributes
    ----------
    system : System
    joint_names : tuple of str (nv,)
        Names of the velocity coordinates (``joint 'name'`` labels of the unknowns).
    nq, nv : int
        Sizes of a configuration ``q`` and of a velocity ``v`` (``nq = nv + 1`` per root).
    compiled : bool
        Whether :meth:`inverse_dynamics`, :meth:`bias`, :meth:`gravity`, :meth:`mass_matrix`
        and :meth:`forward_dynamics` take the compiled path (C++ recursive Newton-Euler and
        composite-rigid-body algorithm, batches looped in C++): trees of abelian joints and
        floating roots whose forces are inertia, gravity and the joints' armatures, springs
        and dampers. The others (closed loops, couplings, drives, loads, PD/PID laws,
        actuators, spring-dampers, beams, bushings, contacts) take the general path, as do
        :meth:`jacobian` and :meth:`frame_pose`; both paths agree to rounding.
    fallback_reason : str
        Why the general path is taken ('' when ``compiled``).
    """

    def __init__(self, model_or_system: Model | System, *, t: float = 0.0,
                 independent=None, compiled: bool = True):
        s = _as_system(model_or_system, "JointSpace")
        self.system = s
        self._con = Constraints(s)
        B0 = self._con.jacobian(s.node_H0, s.joint_H0, s.alpha0)
        self.partition = partition(s, B0, independent, self._con.first)
        self.joint_names = self.partition.names
        self._layout()
        self._plan = _tree_plan(s, self._roots)
        self._inputs = step_inputs(s, float(t))
        self._rs = _row_scale(s, _char_length(s))
        self.fallback_reason = fallback_reason(self) if compiled else "compiled=False"
        self.compiled = not self.fallback_reason
        self._fast = (_engine.JointTree(tree_tables(self, self._inputs["u"][:3]))
                      if self.compiled else None)

    def _fast_tau(self, q, v, a):
        """``M a + b`` by the compiled path, or None (not a tree, or input the general path
        must judge)."""
        try:
            q = np.ascontiguousarray(q, dtype=float)
            v = _NONE if v is None else np.ascontiguousarray(v, dtype=float)
            a = _NONE if a is None else np.ascontiguousarray(a, dtype=float)
        except (TypeError, ValueError):
            return None
        shape = q.shape[:-1] + (self.nv,)
        if (q.ndim not in (1, 2) or q.shape[-1] != self.nq or (v.size and v.shape != shape)
                or (a.size and a.shape != shape)):
            return None
        out = np.empty(shape)
        return out if self._fast.rnea(q, v, a, out) else None

    def _fast_mass(self, q):
        """The mass matrix by the compiled path, or None (as :meth:`_fast_tau`)."""
        try:
            q = np.ascontiguousarray(q, dtype=float)
        except (TypeError, ValueError):
            return None
        if q.ndim not in (1, 2) or q.shape[-1] != self.nq:
            return None
        out = np.empty(q.shape[:-1] + (self.nv, self.nv))
        return out if self._fast.crba(q, out) else None

    # ------------------------------------------------------------------ set-up
    def _layout(self) -> None:
        """Roots (free nodes with all 6 unknowns independent) and the q layout."""
        s, ind = self.system, self.partition.independent
        ind_set = set(int(i) for i in ind)
        self._roots = []
        for i in s.node_free:
            d = int(s.node_dofadr[i])
            mine = [d + c in ind_set for c in range(6)]
            if all(mine):
                self._roots.append(int(i))
            elif any(mine):
                raise ModelError("JointSpace", "model", "independent unknowns that are whole "
                                 "nodes or joint coordinates",
                                 f"a part of node {s.node_names[i]!r}'s 6 unknowns",
                                 "a free body partly held by its joints: model it with a "
                                 "joint of the remaining freedom")
        jointdofs = [i for i in ind if s.dof_is_joint[i]]
        jid = np.zeros(s.nq, np.int64)
        for j in range(s.m):
            jid[s.joint_dofadr[j]:s.joint_dofadr[j] + s.joint_k[j]] = j
        for i in jointdofs:
            if not s.joint_abelian[jid[i]]:
                j = int(jid[i])
                raise ModelError(f"joint {s.joint_names[j]!r} ({s.joint_type[j]})", "type",
                                 "abelian joints for JointSpace coordinates (hinge, "
                                 "prismatic, cylindrical, screw, universal)",
                                 s.joint_type[j], "its coordinates are not coordinates of "
                                 "a configuration; linearize handles it")
        self._jointdofs = np.array(jointdofs, np.int64)
        self._rootdofs = [int(s.node_dofadr[i]) for i in self._roots]
        # positions in q and in v of every independent unknown (roots take 7 in q)
        qpos, pos = [], 0
        for i in ind:
            qpos.append(pos)
            pos += 1
            if any(i == d + 5 for d in self._rootdofs):
                pos += 1
        self._qpos = np.array(qpos, np.int64)
        self.nq = pos
        self.nv = len(ind)

    # ------------------------------------------------------------------ configurations
    def _batch(self, x, n: int, what: str) -> tuple[np.ndarray, bool]:
        a = np.asarray(x, dtype=float)
        one = a.ndim == 1
        a = np.atleast_2d(a)
        if a.ndim != 2 or a.shape[1] != n or not np.all(np.isfinite(a)):
            raise ModelError("JointSpace", what, f"finite arrays of shape ({n},) or (N, {n})",
                             f"shape {np.shape(x)}" + ("" if np.all(np.isfinite(a))
                                                      else " with non-finite values"))
        return a, one

    def _frames(self, q: np.ndarray):
        """Node frames (N, M, 4, 4), joint frames (N, m, 4, 4), coordinates (N, nq) of rows of
        independent coordinates (N, self.nq): the tree by composition, loops by Newton."""
        s = self.system
        N = len(q)
        alpha = self._alpha(q, np.tile(s.alpha0, (N, 1)))
        H, HJ = self._tree(q, alpha, np.tile(s.joint_H0, (N, 1, 1, 1)))
        if self._plan.closures:
            for r in range(N):
                H[r], HJ[r], alpha[r] = self._continue(q[r])
        return H, HJ, alpha

    def _alpha(self, q: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """Coordinates (N, nq): the independent joint coordinates from q, the others kept."""
        for d in self._jointdofs:
            alpha[:, d] = q[:, self._qpos[np.searchsorted(self.partition.independent, d)]]
        s = self.system
        for a, b, r, o in zip(s.cpl_lead, s.cpl_follow, s.cpl_ratio, s.cpl_offset,
                              strict=True):  # couplings, in order (a follower may lead)
            alpha[:, b] = r * alpha[:, a] + o
        return alpha

    def _tree(self, q: np.ndarray, alpha: np.ndarray, HJ: np.ndarray):
        """Node and joint frames by composition along the tree (Eq. (7)) from the roots' poses
        in q, the abelian joints' frames from their coordinates (the others' kept in HJ)."""
        s = self.system
        N = len(q)
        HJ = HJ.copy()
        for g in s.groups:
            ids, jd = g.ids[g.abelian], g.jdof[g.abelian]
            if g.k and len(ids):
                da = alpha[:, jd] - s.alpha0[jd]  # (N, nj, k)
                HJ[:, ids] = s.joint_H0[ids] @ lie.exp_se3(np.einsum("jck,njk->njc",
                                                                      g.A[g.abelian], da))
        H = np.tile(s.node_H0, (N, 1, 1, 1))
        for i, d in zip(self._roots, self._rootdofs, strict=True):
            p = self._qpos[np.searchsorted(self.partition.independent, d)]
            H[:, i, :3, 3] = q[:, p:p + 3]
            H[:, i, :3, :3] = quat_to_rot(q[:, p + 3:p + 7])
        for j, forward, a, b, XA, XBi in self._plan.order:
            if forward:  # H_B = H_A X_A H_J X_B^-1
                H[:, b] = H[:, a] @ XA @ HJ[:, j] @ XBi
            else:  # H_A = H_B X_B H_J^-1 X_A^-1 (XA, XBi hold X_B, X_A^-1 here)
                H[:, a] = H[:, b] @ XA @ lie.inverse(HJ[:, j]) @ XBi
        return H, HJ

    def _continue(self, qr: np.ndarray):
        """One configuration with closed loops: from the model's configuration to ``qr`` in
        steps of at most 0.2 (rad, or the model's length) of the independent coordinates, the
        loops closed by Newton at each, so that the solution stays on the model's branch."""
        s = self.system
        q0 = self.neutral()
        scale = np.ones(self.nq)
        scale[self._qpos] = _unknown_scale(s, _char_length(s))[self.partition.independent]
        steps = max(1, int(np.ceil(np.abs((qr - q0) / scale).max(initial=0.0) / 0.2)))
        alpha, HJ = s.alpha0[None].copy(), s.joint_H0[None].copy()
        for k in range(1, steps + 1):
            qk = (q0 + (k / steps) * (qr - q0))[None]
            alpha = self._alpha(qk, alpha)
            H, HJ = self._tree(qk, alpha, HJ)
            H0, HJ0, a0 = self._close(H[0], HJ[0], alpha[0])
            H, HJ, alpha = H0[None], HJ0[None], a0[None]
        return H[0], HJ[0], alpha[0]

    def _close(self, H, HJ, alpha, tol: float = 1e-13, max_iter: int = 30):
        """Newton on the closure constraints, the independent unknowns held."""
        s, con = self.system, self._con
        z = con.zq
        n = np.zeros(s.nq)
        for _ in range(max_iter):
            ev = evaluate(s, H, HJ, alpha, n, z, z, con.lam0, con.zin, (0.0, 0.0, 0.0),
                          full_alpha=True)
            H, HJ, alpha = ev.H, ev.HJ, ev.alpha
            if float(np.abs(self._rs * ev.phi).max(initial=0.0)) <= tol:
                return H, HJ, alpha
            rm = reduced_map(s, con.rows(con.blocks.split(ev.values)[2]), self.partition,
                             con.cs)
            n = -rm.solve_dependent(con.residual(ev))
        raise SimulationError("JointSpace: the closed loops do not close at these "
                              "independent coordinates (Newton did not converge; the "
                              "configuration may be out of reach)")

    # ------------------------------------------------------------------ one configuration
    def _mass_and_map(self, H, HJ, alpha):
        """Mass matrix of all unknowns (nq, nq) and the reduced map at a configuration."""
        s, con = self.system, self._con
        z = con.zq
        ev = evaluate(s, H, HJ, alpha, z, z, z, con.lam0, con.zin, (1.0, 0.0, 0.0),
                      full_alpha=False)
        M, _, B = con.blocks.split(ev.values)
        return M, reduced_map(s, con.rows(B), self.partition, con.cs)

    def _tau(self, H, HJ, alpha, zd, zdd, inputs) -> tuple[np.ndarray, np.ndarray]:
        """``(tau, M_z)``: generalized forces on the independent coordinates and the mass
        matrix, at one configuration."""
        s, con = self.system, self._con
        M, rm = self._mass_and_map(H, HJ, alpha)
        T = rm.T
        v = T @ zd
        ev = evaluate(s, H, HJ, alpha, con.zq, v, con.zq, con.lam0, inputs, None,
                      full_alpha=False, accel=True)
        # (the extra rows of couplings and held coordinates are linear: no right-hand side)
        w = (rm.solve_dependent(np.concatenate([ev.arhs, np.zeros(len(con.E))]))
             if np.any(v) else 0.0)
        return T.T @ (ev.r + M @ (T @ zdd + w)), T.T @ M @ T

    def _rows(self, q, v=None, a=None, inputs=None):
        """Per configuration ``(tau, M_z)`` for rows of q, v, a; and whether q was one row."""
        qb, one = self._batch(q, self.nq, "q")
        N = len(qb)
        vb = np.zeros((N, self.nv)) if v is None else self._batch(v, self.nv, "v")[0]
        ab = np.zeros((N, self.nv)) if a is None else self._batch(a, self.nv, "a")[0]
        if len(vb) != N or len(ab) != N:
            raise ModelError("JointSpace", "v", f"as many rows as q ({N})", len(vb))
        H, HJ, alpha = self._frames(qb)
        out = [self._tau(H[r], HJ[r], alpha[r], vb[r], ab[r], inputs or self._inputs)
               for r in range(N)]
        return out, one

    # ------------------------------------------------------------------ public
    def mass_matrix(self, q) -> np.ndarray:
        """Mass matrix ``T^T M T`` of the independent coordinates, (nv, nv) or (N, nv, nv)."""
        if self._fast is not None and (out := self._fast_mass(q)) is not None:
            return out
        qb, one = self._batch(q, self.nq, "q")
        H, HJ, alpha = self._frames(qb)
        out = []
        for r in range(len(qb)):
            M, rm = self._mass_and_map(H[r], HJ[r], alpha[r])
            out.append(rm.T.T @ M @ rm.T)
        return out[0] if one else np.array(out)

    def inverse_dynamics(self, q, v, a) -> np.ndarray:
        """Generalized forces ``tau = M(q) a + b(q, v)`` (Pinocchio's rnea), (nv,) or (N, nv).

        Includes the model's own forces (gravity, springs, dampers, PD laws, actuator signals
        and loads at the time ``t`` of the JointSpace): ``tau`` is what must be applied in
        addition."""
        if self._fast is not None and (tau := self._fast_tau(q, v, a)) is not None:
            return tau
        out, one = self._rows(q, v, a)
        tau = np.array([o[0] for o in out])
        return tau[0] if one else tau

    def bias(self, q, v) -> np.ndarray:
        """``b(q, v)``: Coriolis, centrifugal and gyroscopic forces, gravity and the model's
        other state forces (Pinocchio's nonLinearEffects), (nv,) or (N, nv)."""
        return self.inverse_dynamics(q, v, None)

    def gravity(self, q) -> np.ndarray:
        """``b(q, 0)``: gravity and the other forces at rest (springs, PD laws, loads),
        Pinocchio's computeGeneralizedGravity for a model with gravity only, (nv,) or (N, nv)."""
        return self.inverse_dynamics(q, None, None)

    def forward_dynamics(self, q, v, tau) -> np.ndarray:
        """Accelerations ``a = M^-1 (tau - b(q, v))`` (Pinocchio's aba), (nv,) or (N, nv)."""
        tb, one_t = self._batch(tau, self.nv, "tau")
        if self._fast is not None:
            b, M = self._fast_tau(q, v, None), self._fast_mass(q)
            if b is not None and M is not None and np.shape(b) == np.shape(tau):
                return np.linalg.solve(M, (tb - np.atleast_2d(b))[..., None])[..., 0].reshape(
                    b.shape)
        out, one = self._rows(q, v, None)
        a = np.array([np.linalg.solve(M, t - b) for (b, M), t in zip(out, tb, strict=True)])
        return a[0] if one else a

    def _frame(self, name: str) -> tuple[int, np.ndarray]:
        s = self.system
        if name in s.node_names:
            return s.node_names.index(name), np.eye(4)
        for mk in s.model.markers:
            if mk.name == name:
                return s.node_names.index(mk.node), np.asarray(mk.X, float)
        valid = list(s.node_names) + [mk.name for mk in s.model.markers]
        raise KeyError(_unknown_name("frame (node or marker)", name, valid))

    def frame_pose(self, q, name: str) -> np.ndarray:
        """Pose of a node or marker frame in the inertial frame, (4, 4) or (N, 4, 4)."""
        i, X = self._frame(name)
        qb, one = self._batch(q, self.nq, "q")
        Hm = self._frames(qb)[0][:, i] @ X
        return Hm[0] if one else Hm

    def jacobian(self, q, name: str, frame: str = "local") -> np.ndarray:
        """Jacobian of a node or marker frame, (6, nv) or (N, 6, nv): its velocity ``(linear,
        angular)`` from the coordinate velocities.

        ``frame="local"``: the velocity in the frame itself (material: ``(R^T x_dot, omega
        in the frame)``, Eq. (4); Pinocchio's LOCAL). ``frame="local_world_aligned"``: the
        velocity of the frame's origin and the angular velocity in the inertial axes
        (Pinocchio's LOCAL_WORLD_ALIGNED)."""
        if frame not in _FRAMES:
            raise ModelError("JointSpace.jacobian", "frame", " or ".join(map(repr, _FRAMES)),
                             frame)
        s = self.system
        i, X = self._frame(name)
        qb, one = self._batch(q, self.nq, "q")
        H, HJ, alpha = self._frames(qb)
        out = np.zeros((len(qb), 6, self.nv))
        d = int(s.node_dofadr[i])
        for r in range(len(qb)):
            if d >= 0:
                T = self._mass_and_map(H[r], HJ[r], alpha[r])[1].T
                out[r] = lie.adjoint_inv(X) @ T[d:d + 6]
        if frame == "local_world_aligned":
            R = (H[:, i] @ X)[:, :3, :3]
            out[:, :3] = R @ out[:, :3]
            out[:, 3:] = R @ out[:, 3:]
        return out[0] if one else out

    def neutral(self) -> np.ndarray:
        """The configuration of the model as built, (nq,) (roots at their initial poses)."""
        s = self.system
        q = np.zeros(self.nq)
        for k, i in enumerate(self.partition.independent):
            q[self._qpos[k]] = s.alpha0[i]
        for i, d in zip(self._roots, self._rootdofs, strict=True):
            p = self._qpos[np.searchsorted(self.partition.independent, d)]
            q[p:p + 3] = s.node_H0[i, :3, 3]
            q[p + 3:p + 7] = _rot_to_quat(s.node_H0[i, :3, :3])
        return q


def _rot_to_quat(R: np.ndarray) -> np.ndarray:
    """A unit quaternion ``(x, y, z, w)`` of a rotation matrix (3, 3)."""
    w = 0.5 * np.sqrt(max(0.0, 1.0 + np.trace(R)))
    if w > 0.1:
        return np.array([(R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                         (R[1, 0] - R[0, 1]) / (4 * w), w])
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    x = np.zeros(4)
    x[i] = 0.5 * np.sqrt(max(0.0, 1.0 + R[i, i] - R[j, j] - R[k, k]))
    x[j] = (R[j, i] + R[i, j]) / (4 * x[i])
    x[k] = (R[k, i] + R[i, k]) / (4 * x[i])
    x[3] = (R[k, j] - R[j, k]) / (4 * x[i])
    return x


class _Plan:
    """The order in which joints place their nodes, and the joints left closing loops."""

    def __init__(self, order: list, closures: list):
        self.order = order
        self.closures = closures


def _tree_plan(s: System, roots: list[int]) -> _Plan:
    """Joints in an order where each places an unplaced node from a placed one (fixed nodes and
    roots placed first), ``(joint, forward, a, b, X, Y)`` with the constant factors of the
    composition (``X_A, X_B^-1`` forward, ``X_B, X_A^-1`` backward); the others close
    loops."""
    placed = set(int(i) for i in np.flatnonzero(s.node_fixed)) | set(roots)
    left = list(range(s.m))
    order: list[tuple[int, bool]] = []
    progress = True
    while progress:
        progress = False
        for j in list(left):
            a, b = int(s.joint_a[j]), int(s.joint_b[j])
            XA, XB = s.joint_XA[j], s.joint_XB[j]
            if a in placed and b not in placed:
                order.append((j, True, a, b, XA, lie.inverse(XB)))
                placed.add(b)
            elif b in placed and a not in placed:
                order.append((j, False, a, b, XB, lie.inverse(XA)))
                placed.add(a)
            else:
                continue
            left.remove(j)
            progress = True
    return _Plan(order, left)
