"""Assembly of initial configurations and kinematic analysis with inverse dynamics.

Both work directly on the unknowns of the dynamic formulation (Sec. 3.3, Eq. (14)): the
increments ``n`` of the free nodes (6 each) and of the joint relative coordinates (k each), with
the configuration updated on the group, ``H <- H exp(n)`` (Eq. (38)), and the frames re-based after
every correction so that the tangent operator is ``T(0) = I`` (Eqs. (25)-(27)). The constraints
are the vectorial map of Eq. (55), ``Phi_I = vect(H_B^-1 H_A H_J)`` (``vect((H_B X_B)^-1 H_A X_A
H_J)`` for joints with attachment offsets), and the constraint Jacobian
``B`` is its exact linearisation (Eq. (58) when ``Phi = 0``), obtained from
:func:`se3dyn.system.matrix_values` with coefficients ``(0, 0, 0)``.

* :func:`assemble` projects an inconsistent initial configuration onto ``Phi = 0`` by Gauss-Newton
  with minimum-norm corrections, then the velocities onto the velocity constraints ``B v = 0``.
* :func:`kinematics` prescribes the relative coordinates of abelian joints as functions of time
  (driving constraints ``alpha_D - f(t) = 0``, with alpha of Eq. (60)) on a mechanism left with
  no mobility, and solves positions, velocities, accelerations and, by inverse dynamics
  (Eq. (36)), the multipliers: joint reactions and driver efforts.

Scaling. Rank decisions and minimum-norm corrections use dimensionless unknowns and rows:
translations (node components ``U``, joint coordinates along translations, constraint rows 0-2)
are divided by the characteristic length ``L`` of the model (largest distance of a node from the
centroid of all nodes), rotations are left in radians.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from se3dyn import lie
from se3dyn._lazy import LazyModule
from se3dyn.errors import ModelError, SimulationError, close_matches
from se3dyn.model import Model
from se3dyn.results import node_accelerations, node_dofs
from se3dyn.system import LinearSolver, System, compile_model, evaluate, matrix_values, step_inputs
from se3dyn.timefunc import (
    Callable,
    Component,
    Constant,
    Ramp,
    Sine,
    Step,
    Table,
    TimeFunction,
    as_timefunc,
)

sla = LazyModule("scipy.linalg")

__all__ = ["Assembly", "AssemblyError", "KinematicsResult", "assemble", "kinematics",
           "time_derivatives"]

_RCOND = 1e-10  # relative singular-value cut-off of the scaled Jacobians (rank decisions)


# =============================================================================================
# shared helpers (also used by se3dyn.statics)
# =============================================================================================
def _as_system(obj: Any, where: str) -> System:
    """A compiled System from a Model or a System (ModelError naming ``where`` otherwise)."""
    if isinstance(obj, System):
        return obj
    if isinstance(obj, Model):
        return compile_model(obj)
    raise ModelError(where, "model_or_system", "an se3dyn Model or a compiled System",
                     type(obj).__name__)


def _unknown_name(kind: str, name: Any, valid: list[str]) -> str:
    close = close_matches(str(name), valid, n=1)
    hint = f"did you mean '{close[0]}'? " if close else ""
    shown = ", ".join(repr(v) for v in valid[:20]) + (" ..." if len(valid) > 20 else "")
    return f"unknown {kind} {name!r}; {hint}valid: {shown}"


def _joint_ids(s: System, name: Any, item_kind: str, fld: str) -> list[int]:
    """Indices of the joint called ``name`` (the parts of a composite joint, e.g. universal)."""
    names = list(s.joint_names)
    comp = s.composites
    if isinstance(name, str) and name in comp:
        return [names.index(n) for n in comp[name]]
    if isinstance(name, str) and name in names:
        return [names.index(name)]
    valid = [n for n in names if ":" not in n] + list(comp)
    raise ModelError(f"{item_kind} {name!r}", fld, "the name of a joint of the model", name,
                     _unknown_name("joint", name, valid))


def _joint_item(s: System, name: str) -> str:
    ids = _joint_ids(s, name, "joint", "name")
    typ = "universal" if name in s.composites else s.joint_type[ids[0]]
    return f"joint {name!r} ({typ})"


def _char_length(s: System, H: np.ndarray | None = None) -> float:
    """Characteristic length L: largest distance of a node from the centroid (1 if all coincide)."""
    x = (s.node_H0 if H is None else H)[:, :3, 3]
    if len(x) == 0:
        return 1.0
    L = float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1)))
    return L if L > 0 else 1.0


def _unknown_scale(s: System, L: float) -> np.ndarray:
    """(nq,) scale of each unknown: L for translations, 1 for rotations (and screw motions)."""
    cs = np.ones(s.nq)
    for i in s.node_free:
        d = s.node_dofadr[i]
        cs[d:d + 3] = L
    for g in s.groups:
        if not g.k:
            continue
        trans = np.linalg.norm(g.A[:, 3:, :], axis=1) == 0  # (nj, k): no rotation part
        cs[g.jdof[trans]] = L
    return cs


def _row_scale(s: System, L: float) -> np.ndarray:
    """(nm,) scale of the constraint rows: 1/L for the position rows 0-2 of Eq. (56)."""
    rs = np.ones(s.nm)
    for j in range(s.m):
        a = s.joint_multadr[j]
        rs[a:a + 3] = 1.0 / L
    return rs


def _zero_inputs(s: System) -> dict:
    """Inputs of :func:`evaluate` with no load at all, not even gravity (assembly)."""
    return dict(u=np.zeros(s.inputs.nu))


class _Blocks:
    """Dense blocks of the matrix of :func:`matrix_values`: ``[[K, Phi_q^T], [B, 0]]``."""

    def __init__(self, s: System):
        self.s = s
        self.solver = LinearSolver(s, dense_max=2000)

    def __call__(self, ev, coef=(0.0, 0.0, 0.0)):
        s = self.s
        A = self.solver.matrix(matrix_values(s, ev, coef))
        nq = s.nq
        if not isinstance(A, np.ndarray):
            A = A.tocsr()
            return (A[:nq, :nq].toarray(), A[:nq, nq:].toarray(), A[nq:, :nq].toarray())
        return A[:nq, :nq], A[:nq, nq:], A[nq:, :nq]


def _describe(vec: np.ndarray, labels: tuple[str, ...] | list[str], limit: int = 6) -> str:
    """The labels of the dominant components of a (null) vector, joint coordinates first."""
    a = np.abs(vec)
    if a.size == 0 or a.max() == 0:
        return "(none)"
    big = np.flatnonzero(a >= 0.2 * a.max())
    big = sorted(big, key=lambda i: (not labels[i].startswith("joint"), -a[i]))
    out = [f"{labels[i]} ({vec[i] / vec[big[0]]:+.2g})" for i in big[:limit]]
    more = len(big) - limit
    return ", ".join(out) + (f" and {more} more" if more > 0 else "")


def _svd(A: np.ndarray, full: bool = False):
    """SVD by LAPACK gesvd (gesdd is 40x slower on these small matrices with a threaded BLAS on
    a busy machine: measured 47 ms vs 1.2 ms for 55 x 49)."""
    return sla.svd(A, full_matrices=full, check_finite=False, lapack_driver="gesvd")


def _null_space(Jsc: np.ndarray, rcond: float = _RCOND) -> tuple[int, np.ndarray]:
    """Rank and an orthonormal basis (ncols, nnull) of the null space of a scaled matrix."""
    n = Jsc.shape[1]
    if Jsc.shape[0] == 0 or n == 0:
        return 0, np.eye(n)
    _, sv, Vt = _svd(Jsc, full=True)
    r = int(np.sum(sv > rcond * sv[0])) if sv.size and sv[0] > 0 else 0
    return r, Vt[r:].T


# ---------------------------------------------------------------------------------------------
class _Accessors:
    """Accessors by node and joint name on arrays with a leading axis (one row per configuration).

    Subclasses provide ``system`` and the arrays ``_H`` (n, M, 4, 4), ``_alpha``, ``_v``, ``_vd``
    (n, nq), ``_lam`` (n, nm) and ``_squeeze`` (drop the leading axis for single configurations).
    """

    system: System
    _squeeze: bool = False

    def _out(self, a: np.ndarray) -> np.ndarray:
        return a[0] if self._squeeze else a

    def _node(self, name: str) -> int:
        names = list(self.system.node_names)
        if name in names:
            return names.index(name)
        raise KeyError(_unknown_name("node", name, names))

    def _jids(self, name: str) -> list[int]:
        try:
            return _joint_ids(self.system, name, "joint", "name")
        except ModelError as exc:
            raise KeyError(str(exc)) from None

    def node_position(self, name: str) -> np.ndarray:
        """Position of a node in the inertial frame, shape (n, 3) ((3,) for one configuration)."""
        return self._out(self._H[:, self._node(name), :3, 3].copy())

    def node_rotation(self, name: str) -> np.ndarray:
        """Rotation of a node (material axes in the inertial frame), shape (n, 3, 3) / (3, 3)."""
        return self._out(self._H[:, self._node(name), :3, :3].copy())

    def node_frame(self, name: str) -> np.ndarray:
        """Homogeneous frame of a node, shape (n, 4, 4) / (4, 4)."""
        return self._out(self._H[:, self._node(name)].copy())

    def _node_dof(self, name: str, arr: np.ndarray, frame: str) -> np.ndarray:
        return self._out(node_dofs(self.system, self._H, arr, self._node(name), frame))

    def _joint_cols(self, name: str, arr: np.ndarray) -> np.ndarray:
        s = self.system
        cols = [arr[:, s.joint_dofadr[j]:s.joint_dofadr[j] + s.joint_k[j]]
                for j in self._jids(name) if s.joint_k[j]]
        return self._out(np.concatenate(cols, axis=1) if cols else np.zeros((len(arr), 0)))

    def joint_coordinates(self, name: str) -> np.ndarray:
        """Relative coordinates alpha of a joint (Eq. (60)), measured from the model's initial
        configuration, shape (n, k) / (k,); the parts side by side for a composite joint."""
        return self._joint_cols(name, self._alpha)

    def joint_multipliers(self, name: str) -> np.ndarray:
        """Multipliers of a joint: the reaction wrench (force, moment) on node B in its material
        frame (in its attachment frame ``H_B X_B`` for a joint with ``at``) with the sign of
        Eq. (36), shape (n, 6) / (6,) (6 per part for a composite)."""
        s = self.system
        lam = self._lam
        return self._out(np.concatenate([lam[:, s.joint_multadr[j]:s.joint_multadr[j] + 6]
                                         for j in self._jids(name)], axis=1))


def _shift_tf(tf: TimeFunction | None, off: np.ndarray, item: str, fld: str):
    """``tf(t) - off`` as a TimeFunction (same kind when possible)."""
    if tf is None or not np.any(off):
        return tf
    k = off.size
    scalar = k == 1
    o = float(off[0]) if scalar else off
    if isinstance(tf, Constant):
        return Constant(np.asarray(tf.value) - o if not scalar else tf.value - o)
    if isinstance(tf, Sine):
        return dataclasses.replace(tf, offset=np.asarray(tf.offset) - o if not scalar
                                   else tf.offset - o)
    if isinstance(tf, Table):
        return Table(tf.times, tf.values - o)
    base = tf
    return as_timefunc(lambda t: np.asarray(base(t), dtype=float) - o, item, fld, k)


def _model_at(s: System, H: np.ndarray, alpha: np.ndarray, v: np.ndarray) -> Model:
    """A new Model whose initial configuration is (H, v), with the same physics.

    Nodes get the positions and orientations of H, inertia tensors and joint axes rotated with
    their node (so material inertias and the bases A in the material frame of node B are
    unchanged), inertial velocities ``(R v_U, R v_Omega)``. Joints with absolute coordinates
    (``initial``) get the coordinates reached as their new ``initial``; the others restart at 0:
    spring references and PD targets are shifted by the coordinates alpha reached (exact for
    abelian joints, Eq. (60); for non-abelian joints with springs the shift is exact only to
    first order).

    A joint with an attachment point gets the point where the attachment frame of node B,
    ``H_B X_B``, is in H: its orientation there is ``Q_B = R_B R_B0^T``, so with the new
    ``X_B' = H_B^-1 H(I, at')`` we have ``H_B X_B = H_B X_B' H(Q_B, 0)`` and the joint basis
    rotated by ``Q_B`` (like the axes of joints between node frames) describes the same
    constraint; ``X_A' = H_A^-1 H(I, at')`` then follows from ``H_B X_B = H_A X_A H_J``.

    Points given in the inertial frame of the initial configuration follow their nodes: centres
    of mass, points of application of loads, the points of spring-dampers (same free length).
    Bushings get
    the frame attached to node a in H as their point and orientation and the relative motion
    reached as their initial deformation: same attached frames, same loading.
    """
    model = s.model
    nodes = []
    Q = {}
    Rn = {}
    for i, n in enumerate(model.nodes):
        R = H[i, :3, :3]
        # orthonormalise exactly (the product of many exponentials drifts at round-off level)
        U, _, Vt = np.linalg.svd(R)
        R = U @ Vt
        Rn[n.name] = R
        Qi = R @ n.orientation.T  # rotation from the old to the new initial frame
        Q[n.name] = Qi
        vel = np.zeros(6)
        if not s.node_fixed[i]:
            d = s.node_dofadr[i]
            vel = np.concatenate([R @ v[d:d + 3], R @ v[d + 3:d + 6]])
        J = Qi @ n.inertia @ Qi.T
        com = None if n.com is None else R @ s.node_com[i] + H[i, :3, 3]
        nodes.append(dataclasses.replace(n, position=H[i, :3, 3].copy(), orientation=R,
                                         inertia=0.5 * (J + J.T), velocity=vel, com=com))
    joints = []
    for jj, j in enumerate(model.joints):
        Qb = Q[j.node_b]
        A = np.concatenate([Qb @ j.A[:3], Qb @ j.A[3:]], axis=0)
        params = dict(j.params)
        for key in ("axis", "normal"):
            if params.get(key) is not None:
                params[key] = Qb @ np.asarray(params[key], dtype=float)
        if params.get("axes") is not None:
            params["axes"] = np.asarray(params["axes"], dtype=float) @ Qb.T
        if params.get("A") is not None:
            params["A"] = A.copy()
        upd = dict(A=A, params=params)
        if j.at is not None:
            ib = s.joint_b[jj]
            upd["at"] = H[ib, :3, 3] + Rn[j.node_b] @ s.joint_XB[jj, :3, 3]
        if j.k and j.initial is not None:  # absolute coordinates: the new start's values
            d = s.joint_dofadr[jj]
            upd["initial"] = alpha[d:d + j.k].copy()
        elif j.k:
            d = s.joint_dofadr[jj]
            a = alpha[d:d + j.k]
            item = f"joint {j.name!r} ({j.type})"
            upd["reference"] = j.reference - a
            if j.control is not None:
                upd["control"] = dataclasses.replace(
                    j.control, target=_shift_tf(j.control.target, a, item, "control.target"))
        joints.append(dataclasses.replace(j, **upd))
    Hr = lie.make_frame(np.array([n.orientation for n in nodes]).reshape(len(nodes), 3, 3),
                        np.array([n.position for n in nodes]).reshape(len(nodes), 3))
    nidx = {n.name: i for i, n in enumerate(model.nodes)}
    loads = []
    for ld in model.loads:  # points of application where they are in H
        at = ld.at
        if at is not None:
            i = nidx[ld.node]
            at = Hr[i, :3, :3] @ (s.node_H0[i, :3, :3].T @ (at - s.node_H0[i, :3, 3])) \
                + Hr[i, :3, 3]
        loads.append(dataclasses.replace(ld, at=at))
    springs = tuple(dataclasses.replace(sp, at_a=Hr[a, :3, :3] @ ca + Hr[a, :3, 3],
                                        at_b=Hr[b, :3, :3] @ cb + Hr[b, :3, 3])
                    for sp, (a, b, ca, cb, *_) in zip(model.springs, s.springs, strict=True))
    bushings = []
    if model.bushings:
        from se3dyn.elements import bushing

        fa, fb, Xa, Xb = bushing.frames(s)
        for e, bu in enumerate(model.bushings):
            Ha, Hb = Hr[fa[e]] @ Xa[e], Hr[fb[e]] @ Xb[e]
            bushings.append(dataclasses.replace(
                bu, at=Ha[:3, 3].copy(), orientation=Ha[:3, :3].copy(),
                deformation=lie.log_se3(lie.inverse(Ha) @ Hb)))
    return dataclasses.replace(model, nodes=tuple(nodes), joints=tuple(joints),
                               loads=tuple(loads), springs=springs, bushings=tuple(bushings))


# =============================================================================================
# assembly
# =============================================================================================
class AssemblyError(SimulationError):
    """The constraints cannot be satisfied (e.g. a link too short to close a loop).

    Attributes
    ----------
    joint : str
        Name of the joint with the largest remaining violation.
    violations : dict
        Joint name -> remaining scaled violation (translation rows divided by L).
    """

    def __init__(self, message: str, joint: str, violations: dict):
        super().__init__(message)
        self.joint = joint
        self.violations = violations


@dataclass(eq=False)
class Assembly(_Accessors):
    """Outcome of :func:`assemble`: a consistent configuration and what it took to get there.

    Attributes
    ----------
    system : System
        The compiled input model.
    H : ndarray (M, 4, 4)
        Assembled node frames.
    HJ : ndarray (m, 4, 4)
        Assembled joint transformations.
    alpha : ndarray (nq,)
        Joint relative coordinates (from the model's initial configuration; 0 on node unknowns).
    v : ndarray (nq,)
        Consistent velocities (material frame, Eq. (4)).
    translation, rotation : ndarray (M,)
        How far every node moved from the starting configuration: distance (length units) and
        rotation angle ``|log(R_0^T R)|`` (rad).
    velocity_change : ndarray (M, 2)
        Change of the inertial linear and angular velocity of every node with mass (norms;
        0 for massless nodes, whose velocities are solved for).
    coordinate_change : ndarray (nq,)
        Change of the joint coordinates during the assembly (0 on node unknowns).
    iterations : int
        Gauss-Newton iterations.
    violation_before, violation : float
        Largest scaled constraint violation before and after (``|Phi|``, translation rows
        divided by L).
    model : Model
        A new model whose initial configuration is the assembled one (see :func:`assemble`).
    speeds_kept : bool
        Whether the given (nonzero) velocities and angular velocities were kept (see
        :func:`project_velocities`).
    """

    system: System
    H: np.ndarray
    HJ: np.ndarray
    alpha: np.ndarray
    v: np.ndarray
    translation: np.ndarray
    rotation: np.ndarray
    velocity_change: np.ndarray
    coordinate_change: np.ndarray
    iterations: int
    violation_before: float
    violation: float
    model: Model = field(repr=False)
    speeds_kept: bool = True
    _squeeze: bool = field(default=True, repr=False)

    @property
    def _H(self):
        return self.H[None]

    @property
    def _alpha(self):
        return self.alpha[None]

    @property
    def _v(self):
        return self.v[None]

    @property
    def _lam(self):  # pragma: no cover - no multipliers in an assembly
        return np.zeros((1, self.system.nm))

    def joint_multipliers(self, name):  # noqa: D102 - not available
        raise AttributeError("an assembly has no multipliers")

    def node_velocity(self, name: str, frame: str = "material") -> np.ndarray:
        """Consistent velocity ``(U, Omega)`` of a node, shape (6,) (see Eq. (4))."""
        return self._node_dof(name, self._v, frame)

    def joint_velocities(self, name: str) -> np.ndarray:
        """Relative velocities of a joint (Eq. (61)), shape (k,)."""
        return self._joint_cols(name, self._v)

    def joint_change(self, name: str) -> np.ndarray:
        """Change of the relative coordinates of a joint during the assembly, shape (k,)."""
        return self._joint_cols(name, self.coordinate_change[None])

    def __str__(self) -> str:
        s = self.system
        lines = [f"assembly of {s.model.name!r}: {self.iterations} iterations, constraint "
                 f"violation {self.violation_before:.3e} -> {self.violation:.3e}"]
        order = np.argsort(-(self.translation + _char_length(s, self.H) * self.rotation))
        rows = [i for i in order[:10] if self.translation[i] > 0 or self.rotation[i] > 0]
        lines.append("largest node moves:" if rows else "no node moved")
        if rows:
            lines.append(f"  {'node':<16}{'translation':>14}{'rotation [deg]':>16}"
                         f"{'|dv|':>12}{'|dw|':>12}")
        for i in rows:
            lines.append(f"  {s.node_names[i]!r:<16}{self.translation[i]:>14.4e}"
                         f"{math.degrees(self.rotation[i]):>16.4e}"
                         f"{self.velocity_change[i, 0]:>12.3e}{self.velocity_change[i, 1]:>12.3e}")
        vel = s.node_v0[s.node_free]
        scale = max(float(np.abs(vel).max(initial=0.0)), float(np.abs(self.v).max(initial=0.0)),
                    1e-300)
        vrows = [i for i in range(s.M) if self.velocity_change[i].max() > 1e-9 * scale]
        lines.append(("initial velocities changed to satisfy the joints ("
                      + ("the nonzero given ones kept" if self.speeds_kept else
                         "the given ones conflict with the joints: closest consistent ones")
                      + "):") if vrows else "no initial velocity changed")
        if vrows:
            lines.append(f"  {'node':<16}{'|dv| [m/s]':>12}{'|dw| [rad/s]':>14}  velocity, "
                         "angular velocity used (inertial)")
        for i in vrows[:10]:
            d = s.node_dofadr[i]
            R = self.H[i, :3, :3]
            u, w = R @ self.v[d:d + 3], R @ self.v[d + 3:d + 6]
            lines.append(f"  {s.node_names[i]!r:<16}{self.velocity_change[i, 0]:>12.3e}"
                         f"{self.velocity_change[i, 1]:>14.3e}  "
                         f"({', '.join(f'{x:.4g}' for x in u)}), "
                         f"({', '.join(f'{x:.4g}' for x in w)})")
        if len(vrows) > 10:
            lines.append(f"  ... and {len(vrows) - 10} more")
        jrows = []
        for j in range(s.m):
            k = s.joint_k[j]
            if not k:
                continue
            d = s.joint_dofadr[j]
            ch = self.coordinate_change[d:d + k]
            jrows.append((float(np.abs(ch).max()), j, ch, self.v[d:d + k]))
        jrows.sort(key=lambda r: -r[0])
        jrows = [r for r in jrows[:10] if r[0] > 0]
        lines.append("largest joint coordinate changes:" if jrows else
                     "no joint coordinate changed")
        if jrows:
            lines.append(f"  {'joint':<16}change / velocity (per coordinate)")
        for _, j, ch, vj in jrows:
            fmt = " ".join(f"{c:+.4e}" for c in ch)
            fv = " ".join(f"{c:+.3e}" for c in vj)
            lines.append(f"  {s.joint_names[j]!r:<16}{fmt}  /  {fv}")
        return "\n".join(lines)


def _start_config(s: System, coordinates, positions, orientations):
    """Starting frames: the model's, with imposed joint coordinates and node guesses."""
    H = s.node_H0.copy()
    HJ = s.joint_H0.copy()
    alpha = s.alpha0.copy()
    for fld, mapping, shape in (("positions", positions, (3,)),
                                ("orientations", orientations, (3, 3))):
        if mapping is None:
            continue
        if not isinstance(mapping, Mapping):
            raise ModelError("assemble", fld, "a mapping node name -> value", mapping)
        for name, val in mapping.items():
            if name not in s.node_names:
                raise ModelError(f"node {name!r}", fld, "the name of a node of the model", name,
                                 _unknown_name("node", name, list(s.node_names)))
            try:
                a = np.asarray(val, dtype=float)
            except (TypeError, ValueError):
                a = None
            if a is None or a.shape != shape or not np.all(np.isfinite(a)):
                raise ModelError(f"node {name!r}", fld, f"finite values of shape {shape}", val)
            i = s.node_names.index(name)
            if fld == "positions":
                H[i, :3, 3] = a
            else:
                if np.abs(a.T @ a - np.eye(3)).max() > 1e-9 or np.linalg.det(a) < 0:
                    raise ModelError(f"node {name!r}", fld, "a rotation matrix", a)
                H[i, :3, :3] = a
    if coordinates is not None:
        if not isinstance(coordinates, Mapping):
            raise ModelError("assemble", "coordinates", "a mapping joint name -> coordinates",
                             coordinates)
        for name, val in coordinates.items():
            ids = _joint_ids(s, name, "joint", "coordinates")
            k = int(sum(s.joint_k[j] for j in ids))
            item = _joint_item(s, name)
            try:
                a = np.broadcast_to(np.asarray(val, dtype=float), (k,)).copy()
            except (TypeError, ValueError):
                raise ModelError(item, "coordinates", f"{k} number(s)", val) from None
            if k == 0 or not np.all(np.isfinite(a)):
                raise ModelError(item, "coordinates", f"{k} finite number(s) (a joint with "
                                 "relative coordinates)", val)
            off = 0
            for j in ids:
                kj = int(s.joint_k[j])
                aj = a[off:off + kj]
                off += kj
                g, row = _group_of(s, j)
                d = s.joint_dofadr[j]  # (coordinates absolute when the joint has initial)
                HJ[j] = s.joint_H0[j] @ lie.exp_se3(g.A[row] @ (aj - s.alpha0[d:d + kj]))
                alpha[d:d + kj] = aj
    return H, HJ, alpha


def _group_of(s: System, j: int):
    for g in s.groups:
        hit = np.flatnonzero(g.ids == j)
        if hit.size:
            return g, int(hit[0])
    raise AssertionError(j)  # pragma: no cover


def _keep_columns(s: System, keep) -> np.ndarray:
    if isinstance(keep, str) or not hasattr(keep, "__iter__"):
        raise ModelError("assemble", "keep", "a list of joint names", keep)
    held = np.zeros(s.nq, dtype=bool)
    for name in keep:
        ids = _joint_ids(s, name, "joint", "keep")
        if not any(s.joint_k[j] for j in ids):
            raise ModelError(_joint_item(s, name), "keep", "a joint with relative coordinates",
                             name, "a rigid joint has none to keep")
        for j in ids:
            held[s.joint_dofadr[j]:s.joint_dofadr[j] + s.joint_k[j]] = True
    return held


def _violations(s: System, phi_s: np.ndarray) -> dict:
    out = {}
    for j in range(s.m):
        a = s.joint_multadr[j]
        out[s.joint_names[j]] = float(np.abs(phi_s[a:a + 6]).max())
    return out


def assemble(model_or_system: Model | System, *, keep=(), coordinates: Mapping | None = None,
             positions: Mapping | None = None, orientations: Mapping | None = None,
             tol: float = 1e-12, max_iter: int = 50) -> Assembly:
    """Assemble a consistent initial configuration: positions on ``Phi = 0``, velocities on
    ``B v = 0``.

    The starting configuration is the model's (node frames ``H_0``, joint transformations
    ``H_J0``), with optional imposed joint coordinates (``H_J = H_J0 exp(A alpha)``, Eq. (9)) and
    guessed node positions/orientations. Any of these may violate the constraints of Eq. (55).

    Positions: Gauss-Newton on the group. At the current frames, the correction ``dn`` (nq,) is
    the minimum-norm solution of ``B dn = -Phi`` (B: exact linearisation of Eq. (55), i.e.
    Eq. (58) at ``Phi = 0``), in the scaled norm (translations divided by the characteristic
    length L), with the columns of the joint coordinates named in ``keep`` removed so that they do
    not move; then ``H <- H exp(dn)`` (Eq. (38)) and the joint coordinates ``alpha += dn``
    (Eq. (60)). Redundant constraints are handled by the least-squares solution (SVD, relative
    cut-off 1e-10). Converges quadratically for a consistent problem.

    Velocities: :func:`project_velocities` at the assembled configuration: the nonzero given
    velocities and angular velocities of the nodes with mass are kept, the rest completed
    closest to the given ones in the kinetic-energy norm (Eq. (47)) such that ``B v = 0``; when
    the given ones conflict with the joints, the closest consistent velocities
    (``speeds_kept`` False). ``print`` lists every node whose velocity changed.

    Parameters
    ----------
    model_or_system : Model or System
    keep : iterable of str
        Joints whose relative coordinates must not change (e.g. the crank angle of a
        mechanism placed by ``coordinates``).
    coordinates : mapping joint name -> array (k,), optional
        Relative coordinates to impose before assembling (measured from the model's initial
        configuration, as everywhere in se3dyn).
    positions : mapping node name -> array (3,), optional
        Guessed node positions.
    orientations : mapping node name -> array (3, 3), optional
        Guessed node rotations.
    tol : float
        Tolerance on the largest scaled constraint violation (translation rows divided by L).
    max_iter : int
        Maximum Gauss-Newton iterations.

    Returns
    -------
    Assembly
        Frames, coordinates, velocities, the moves of every node and joint (``print`` it for a
        table), and ``model``: a new :class:`~se3dyn.model.Model` starting in the assembled
        configuration with the consistent velocities (joint coordinates restart at 0; spring
        references and PD targets are shifted accordingly).

    Raises
    ------
    ModelError
        Unknown or unsuitable names in ``keep``/``coordinates``/``positions``/``orientations``.
    AssemblyError
        The constraints cannot be satisfied (the violation stalls, e.g. a loop that cannot
        close); names the joint with the largest remaining violation.
    """
    s = _as_system(model_or_system, "assemble")
    if not (isinstance(tol, int | float) and 0 < tol < 1):
        raise ModelError("assemble", "tol", "a positive tolerance below 1", tol)
    if not (isinstance(max_iter, int) and max_iter >= 1):
        raise ModelError("assemble", "max_iter", "a positive integer", max_iter)
    held = _keep_columns(s, keep)
    H, HJ, alpha = _start_config(s, coordinates, positions, orientations)
    H_start, alpha_start = H.copy(), alpha.copy()
    L = _char_length(s, H)
    cs = _unknown_scale(s, L)
    rs = _row_scale(s, L)
    free = ~held
    blocks = _Blocks(s)
    inputs = _zero_inputs(s)
    zq = np.zeros(s.nq)
    lam0 = np.zeros(s.nm)
    history: list[float] = []
    it = 0
    while True:
        ev = evaluate(s, H, HJ, alpha, zq, zq, zq, lam0, inputs, None, full_alpha=True)
        H, HJ, alpha = ev.H, ev.HJ, ev.alpha
        phi_s = rs * ev.phi
        err = float(np.abs(phi_s).max(initial=0.0))
        if not np.isfinite(err):
            raise SimulationError("assemble: the configuration became non-finite")
        history.append(err)
        if err <= tol:
            break
        stalled = (it >= 6 and history[-1] > 0.5 * history[-4])
        if it >= max_iter or stalled:
            viol = _violations(s, phi_s)
            worst = max(viol, key=viol.get)
            bad = sorted((k for k, x in viol.items() if x > max(tol, 1e-3 * viol[worst])),
                         key=lambda k: -viol[k])
            a = s.joint_multadr[s.joint_names.index(worst)]
            comp = int(np.argmax(np.abs(phi_s[a:a + 6])))
            raise AssemblyError(
                f"assemble: the constraints cannot be satisfied: after {it} iterations the "
                f"largest violation stays at {err:.3e} (scaled: translations / L = {L:.3g}); "
                f"worst: joint {worst!r} ({s.labels[s.nq + a + comp].split(' ', 2)[-1]}); "
                f"violated joints: " + ", ".join(f"{k!r} ({viol[k]:.2e})" for k in bad[:8])
                + ". The geometry cannot close (a link too short or too long, or imposed "
                "coordinates out of reach); check the joint and node positions"
                + (" or release some joints from 'keep'" if held.any() else ""),
                worst, viol)
        _, _, B = blocks(ev)
        Bs = (rs[:, None] * B)[:, free] * cs[free]
        y = sla.lstsq(Bs, -phi_s, cond=_RCOND, lapack_driver="gelsd")[0]
        dn = np.zeros(s.nq)
        dn[free] = cs[free] * y
        ev = evaluate(s, H, HJ, alpha, dn, zq, zq, lam0, inputs, None, full_alpha=True)
        H, HJ, alpha = ev.H, ev.HJ, ev.alpha
        it += 1
    alpha[held] = alpha_start[held]  # exactly (they received no correction)
    # ----- velocities
    Wm, _, B = blocks(ev, (1.0, 0.0, 0.0))
    from se3dyn.analysis import redundant_equations

    v0 = np.zeros(s.nq)
    for i in s.node_free:
        d = s.node_dofadr[i]
        R = H[i, :3, :3]
        vin = s.model.nodes[i].velocity
        v0[d:d + 3], v0[d + 3:d + 6] = R.T @ vin[:3], R.T @ vin[3:]
    v, kept = project_velocities(s, Wm, B, v0, L=L, dropped=redundant_equations(s, H, HJ))
    # ----- report
    dx = np.linalg.norm(H[:, :3, 3] - H_start[:, :3, 3], axis=1)
    rel = np.einsum("nji,njk->nik", H_start[:, :3, :3], H[:, :3, :3])
    rot = np.linalg.norm(lie.log_so3(rel), axis=1) if s.M else np.zeros(0)
    dv = np.zeros((s.M, 2))
    for i in s.node_free:
        if s.node_mass[i] <= 0:
            continue  # massless: velocities solved for, none given to compare with
        d = s.node_dofadr[i]
        R = H[i, :3, :3]
        v_in = s.model.nodes[i].velocity
        dv[i, 0] = np.linalg.norm(R @ v[d:d + 3] - v_in[:3])
        dv[i, 1] = np.linalg.norm(R @ v[d + 3:d + 6] - v_in[3:])
    change = np.where(s.dof_is_joint, alpha - alpha_start, 0.0)
    model = _model_at(s, H, alpha, v)
    return Assembly(system=s, H=H, HJ=HJ, alpha=alpha, v=v, translation=dx, rotation=rot,
                    velocity_change=dv, coordinate_change=change, iterations=it,
                    violation_before=history[0], violation=history[-1], model=model,
                    speeds_kept=kept)


def _held_rows(s: System, v0: np.ndarray) -> np.ndarray:
    """Rows ``E`` (h, nq) selecting the given parts of ``v0``: per free node with mass, the three
    components of its linear velocity and of its angular velocity where that part is nonzero
    (a zero part counts as not given)."""
    cols = []
    for i in s.node_free:
        if s.node_mass[i] <= 0 and not np.any(s.node_J[i]):
            continue
        d = s.node_dofadr[i]
        for a in (d, d + 3):
            if np.any(v0[a:a + 3] != 0):
                cols += [a, a + 1, a + 2]
    E = np.zeros((len(cols), s.nq))
    E[np.arange(len(cols)), cols] = 1.0
    return E


def project_velocities(s: System, Wm, B, v0: np.ndarray, *, L: float | None = None,
                       dropped=()) -> tuple[np.ndarray, bool]:
    """Initial velocities satisfying the velocity constraints ``B v = 0``, keeping the given
    speeds.

    ``v = v0 + dv`` with ``dv`` the smallest change in the kinetic-energy norm ``dv^T M dv``
    (Eq. (47)) such that ``B v = 0`` (the time derivative of Eq. (55), B of Eq. (58)) and that
    every node with mass keeps the parts of its velocity that were given: its linear velocity
    if nonzero, its angular velocity if nonzero (a zero part counts as not given). A crank
    given only ``angular_velocity: [0, 0, w]`` keeps ``w`` and gets the linear velocity its
    hinge implies; the other links follow. Consistent velocities are kept exactly. When the
    given parts conflict with the joints (a velocity the joints do not allow, or two links
    given speeds the mechanism cannot have together), they are released and the closest
    consistent velocities in the kinetic-energy norm are taken (``kept`` False).
    Unknowns without mass (massless nodes, joint coordinates) are solved for, minimum norm
    where the joints leave them free (translations scaled by ``L``). Redundant equations
    (``dropped``) are left out: they hold whenever the others do.

    Solved as one sparse saddle-point system first (:func:`_project_sparse`, milliseconds),
    and by rank-revealing dense factorisations (:func:`_project_dense`, up to 3000 unknowns)
    when that does not satisfy the constraints (conflicting given parts, dependent rows):
    the A02 N-four-bar (1099 unknowns) starts in 0.03 s instead of the 5 s of the dense
    solution alone.

    Parameters
    ----------
    s : System
    Wm : ndarray or sparse, shape (nq, nq)
        Mass matrix (material frame, Eq. (47)).
    B : ndarray or sparse, shape (nm, nq)
        Velocity constraint gradient.
    v0 : ndarray, shape (nq,)
        Given velocities (material frame, Eq. (4)); joint coordinates' entries are ignored.
    L : float, optional
        Characteristic length (default ``s.length_scale``).
    dropped : sequence of int
        Redundant constraint equations (indices into the nm rows).

    Returns
    -------
    v : ndarray, shape (nq,)
    kept : bool
        Whether the given parts were kept.

    Raises
    ------
    SimulationError
        The velocity constraints have no solution (a non-finite matrix).
    """
    import scipy.sparse as sp

    nq, nm = s.nq, s.nm
    L = float(s.length_scale if L is None else L)
    v0 = np.asarray(v0, dtype=float).copy()
    v0[s.dof_is_joint] = 0.0
    E = _held_rows(s, v0)
    if nm == 0:
        return v0, True
    rows = np.setdiff1d(np.arange(nm), np.asarray(dropped, dtype=np.int64))
    Bs = _row_scale(s, L)[rows, None] * (B[rows].toarray() if sp.issparse(B) else B[rows])
    if not np.all(np.isfinite(Bs)):
        raise SimulationError("initial velocities: the velocity constraints are not finite")
    # first the whole problem as one sparse solve (milliseconds); the rank-revealing dense
    # solution below when it fails (dependent rows the regularisation does not settle)
    v = _project_sparse(s, Wm, Bs, v0, E)
    if v is not None:
        return v, True
    if nq > 3000:
        v = _project_sparse(s, Wm, Bs, v0, E[:0])
        if v is None:
            raise SimulationError("initial velocities: the velocity constraints of the joints "
                                  "have no solution (check 'se3dyn check' for singular "
                                  "configurations)")
        return v, False
    return _project_dense(s, Wm.toarray() if sp.issparse(Wm) else np.asarray(Wm), Bs, v0, E, L)


def _project_dense(s: System, Wd: np.ndarray, Bs: np.ndarray, v0: np.ndarray, E: np.ndarray,
                   L: float) -> tuple[np.ndarray, bool]:
    """The problem of :func:`project_velocities` by rank-revealing dense factorisations (SVD of
    the massless columns, least squares on the body velocities in ``M^-1/2`` coordinates), with
    the held parts ``E`` first and without them when they conflict with the joints."""
    import scipy.sparse as sp

    nq = s.nq
    cs = _unknown_scale(s, L)
    # body directions (M^-1/2 of each node's mass block) and massless ones (scaled by cs)
    bi, bj, bv, ui, uj, uv = [], [], [], [], [], []
    nodal = np.zeros(nq, dtype=bool)
    for i in s.node_free:
        idx = s.node_dofadr[i] + np.arange(6)
        nodal[idx] = True
        w, Q = np.linalg.eigh(Wd[np.ix_(idx, idx)])
        pos = w > 1e-12 * max(float(w.max()), 0.0) if w.max() > 0 else np.zeros(6, bool)
        for k in range(6):
            if pos[k]:
                bi += list(idx)
                bj += [len(bj) // 6] * 6
                bv += list(Q[:, k] / np.sqrt(w[k]))
            else:
                ui += list(idx)
                uj += [len(uj) // 6] * 6
                uv += list(Q[:, k] * cs[idx])
    kb, ku0 = len(bj) // 6, len(uj) // 6
    rest = np.flatnonzero(~nodal)
    Tb = sp.csc_matrix((bv, (bi, bj)), shape=(nq, kb))
    Tu = sp.hstack([sp.csc_matrix((uv, (ui, uj)), shape=(nq, ku0)),
                    sp.csc_matrix((cs[rest], (rest, np.arange(len(rest)))),
                                  shape=(nq, len(rest)))]).tocsc()
    Pb = np.asarray((Tb.T @ Bs.T).T)
    Pu = np.asarray((Tu.T @ Bs.T).T)
    r0 = Bs @ v0
    if Pu.shape[1]:
        U, sv, _ = _svd(Pu)
        r = int(np.sum(sv > _RCOND * sv[0])) if sv.size and sv[0] > 0 else 0
        Ur = U[:, :r]
    else:
        Ur = np.zeros((Bs.shape[0], 0))
    C = Pb - Ur @ (Ur.T @ Pb)  # the conditions on the body velocities alone
    c = -(r0 - Ur @ (Ur.T @ r0))
    EB = np.asarray((Tb.T @ E.T).T) if len(E) else np.zeros((0, kb))
    for kept in (True, False):
        A = np.vstack([C, EB]) if kept else C
        rhs = np.concatenate([c, np.zeros(len(EB))]) if kept else c
        z = sla.lstsq(A, rhs, cond=_RCOND, lapack_driver="gelsd")[0] if A.size else np.zeros(kb)
        vb = v0 + Tb @ z
        y = (sla.lstsq(Pu, -(Bs @ vb), cond=_RCOND, lapack_driver="gelsd")[0] if Pu.size
             else np.zeros(0))
        v = vb + Tu @ y
        if not kept or (_solves(Bs, v, np.zeros(Bs.shape[0])) and _solves(E, v, E @ v0)):
            break
    return v, kept


def _solves(A, x: np.ndarray, b: np.ndarray, rtol: float = 1e-9) -> bool:
    """Whether ``A x = b`` holds row by row to ``rtol`` of the row's terms ``|A| |x| + |b|``
    (plus round-off of the largest term: ``1e-3 rtol max|A| max|x|``)."""
    x = np.asarray(x)
    if not np.all(np.isfinite(x)):
        return False
    if A.shape[0] == 0:
        return True
    aA = abs(A)
    floor = 1e-3 * rtol * (float(aA.max()) * float(np.abs(x).max(initial=0.0))
                           + float(np.abs(b).max(initial=0.0)))
    return bool(np.all(np.abs(A @ x - b) <= rtol * (aA @ np.abs(x) + np.abs(b)) + floor))


def _project_sparse(s: System, Wm, Bs: np.ndarray, v0: np.ndarray, E: np.ndarray
                    ) -> np.ndarray | None:
    """The problem of :func:`project_velocities` as one sparse saddle point system
    ``[[W, G^T], [G, -d I]]`` with ``G = [B; E]`` (W: M plus 1e-12 of its largest entry on the
    diagonal, so massless unknowns take the smallest change; ``d`` a relative 1e-13 that makes
    dependent rows of G, e.g. a held part that a joint already fixes, harmless), by SuperLU.
    Returns the velocities when they satisfy ``G v = g`` row by row, else None."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    nq = s.nq
    Wm = sp.csc_matrix(Wm)
    wmax = max(float(np.abs(Wm.diagonal()).max(initial=0.0)), 1e-300)
    W = (Wm + 1e-12 * wmax * sp.identity(nq)).tocsc()
    G = sp.vstack([sp.csr_matrix(Bs), sp.csr_matrix(E)]).tocsr()
    g = np.concatenate([np.zeros(Bs.shape[0]), E @ v0])
    d = 1e-13 * max(float(abs(G).max()) if G.nnz else 0.0, 1e-300) ** 2 / wmax
    K = sp.bmat([[W, G.T], [G, -d * sp.identity(G.shape[0])]], format="csc")
    try:
        sol = spla.splu(K).solve(np.concatenate([W @ v0, g]))
    except RuntimeError:  # exactly singular
        return None
    v = np.asarray(sol[:nq])
    return v if _solves(G, v, g) else None


# =============================================================================================
# time functions: first and second derivatives
# =============================================================================================
def time_derivatives(f: TimeFunction, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Value, first and second time derivative of a time function at t.

    Exact for :class:`Constant`, :class:`Step` (away from the jump), :class:`Ramp` and
    :class:`Table` (piecewise linear: second derivative 0 away from the kinks) and :class:`Sine`.
    For a :class:`Callable` ``fn`` the derivatives are fourth-order central differences of ``fn``
    with steps ``h1 = 1e-3 max(1, |t|)`` for the rate (truncation ``h1^4 |f^(5)| / 30``,
    round-off ``~ 1.5 u |f| / h1``: ~1e-13 relative for functions varying on a time scale of 1)
    and ``h2 = 2e-3 max(1, |t|)`` for the second derivative (truncation ``h2^4 |f^(6)| / 90``,
    round-off ``~ 5 u |f| / h2^2``, ~1e-10 relative). Other TimeFunction subclasses: their
    ``rate`` and the same fourth-order difference of ``rate`` for the second derivative.

    Returns
    -------
    (value, rate, acceleration) : ndarrays, shape of ``f(t)`` (at least 1-D)
    """
    val = np.atleast_1d(np.asarray(f(t), dtype=float))
    if isinstance(f, Constant | Step | Ramp | Table):
        return val, np.atleast_1d(np.asarray(f.rate(t), dtype=float)), np.zeros_like(val)
    if isinstance(f, Sine):
        w = 2 * math.pi * f.frequency
        amp = np.asarray(f.amplitude, dtype=float)
        rate = np.atleast_1d(amp * w * math.cos(w * t + f.phase))
        acc = np.atleast_1d(-amp * w * w * math.sin(w * t + f.phase))
        return val, rate * np.ones_like(val), acc * np.ones_like(val)
    if isinstance(f, Component):
        _, r, a = time_derivatives(f.base, t)
        i = f.index if r.size > 1 else 0
        return val, r[i:i + 1], a[i:i + 1]
    scale = max(1.0, abs(t))
    if isinstance(f, Callable):
        fn = f.fn
        h1 = 1e-3 * scale
        p = [np.asarray(fn(t + c * h1), dtype=float) for c in (-2, -1, 1, 2)]
        rate = (p[0] - 8 * p[1] + 8 * p[2] - p[3]) / (12 * h1)
        h2 = 2e-3 * scale
        q = [np.asarray(fn(t + c * h2), dtype=float) for c in (-2, -1, 0, 1, 2)]
        acc = (-q[0] + 16 * q[1] - 30 * q[2] + 16 * q[3] - q[4]) / (12 * h2 * h2)
        return val, np.atleast_1d(rate) * np.ones_like(val), np.atleast_1d(acc) * \
            np.ones_like(val)
    h1 = 1e-3 * scale
    rate = np.atleast_1d(np.asarray(f.rate(t), dtype=float))
    p = [np.asarray(f.rate(t + c * h1), dtype=float) for c in (-2, -1, 1, 2)]
    acc = (p[0] - 8 * p[1] + 8 * p[2] - p[3]) / (12 * h1)
    return val, rate * np.ones_like(val), np.atleast_1d(acc) * np.ones_like(val)


# =============================================================================================
# kinematic analysis and inverse dynamics
# =============================================================================================
@dataclass(eq=False)
class KinematicsResult(_Accessors):
    """Outcome of :func:`kinematics` (one row per time).

    Attributes
    ----------
    system : System
    t : ndarray (n,)
    H : ndarray (n, M, 4, 4)       node frames
    HJ : ndarray (n, m, 4, 4)      joint transformations
    alpha : ndarray (n, nq)        joint coordinates (Eq. (60)), 0 on node unknowns
    v, vd : ndarray (n, nq)        velocities and accelerations (material frame, Eq. (4))
    lam : ndarray (n, nm)          joint multipliers from inverse dynamics (reaction wrenches)
    efforts : dict                 driver name -> ndarray (n, k): the force/torque an actuator in
                                   that joint must exert (actuator sign of Eq. (66): power
                                   ``effort . alpha_dot``)
    kinetic, potential, spring : ndarray (n,)   energies (Eq. (47), gravity, elastic: Eq. (62)
                                   and the elastic elements, e.g. spring-dampers, bushings)
    iterations : ndarray (n,) int  Newton iterations for the positions
    """

    system: System
    t: np.ndarray
    H: np.ndarray
    HJ: np.ndarray
    alpha: np.ndarray
    v: np.ndarray
    vd: np.ndarray
    lam: np.ndarray
    efforts: dict
    kinetic: np.ndarray
    potential: np.ndarray
    spring: np.ndarray
    iterations: np.ndarray

    @property
    def _H(self):
        return self.H

    @property
    def _alpha(self):
        return self.alpha

    @property
    def _lam(self):
        return self.lam

    def node_velocity(self, name: str, frame: str = "material") -> np.ndarray:
        """Velocity ``(U, Omega)`` of a node, shape (n, 6); ``frame="inertial"`` gives
        ``(R v_U, R v_Omega)`` (the time derivative of the position, the spatial angular
        velocity)."""
        return self._node_dof(name, self.v, frame)

    def node_acceleration(self, name: str, frame: str = "material") -> np.ndarray:
        """Acceleration of a node, shape (n, 6): material ``(dU/dt, dOmega/dt)``, or
        ``frame="inertial"`` the acceleration of its origin and its angular acceleration in the
        inertial frame (:func:`se3dyn.results.node_accelerations`)."""
        return self._out(node_accelerations(self.system, self._H, self.v, self.vd,
                                            self._node(name), frame))

    def joint_velocities(self, name: str) -> np.ndarray:
        """Relative velocities of a joint (Eq. (61)), shape (n, k)."""
        return self._joint_cols(name, self.v)

    def joint_accelerations(self, name: str) -> np.ndarray:
        """Relative accelerations of a joint, shape (n, k)."""
        return self._joint_cols(name, self.vd)

    def driver_effort(self, name: str) -> np.ndarray:
        """Force/torque of a driver, shape (n, k)."""
        if name not in self.efforts:
            raise KeyError(_unknown_name("driver", name, list(self.efforts)))
        return self.efforts[name]

    @property
    def driver_power(self) -> np.ndarray:
        """Total power of the drivers ``sum effort . alpha_dot``, shape (n,)."""
        p = np.zeros(len(self.t))
        for name, e in self.efforts.items():
            p += np.sum(e * self.joint_velocities(name), axis=1)
        return p

    @property
    def total_energy(self) -> np.ndarray:
        """Kinetic + gravity potential + spring energy, shape (n,)."""
        return self.kinetic + self.potential + self.spring

    def __len__(self) -> int:
        return len(self.t)


def _drivers(s: System, drivers) -> list[tuple[str, np.ndarray, list[TimeFunction]]]:
    """Validate drivers: [(name, dof indices (k,), [TimeFunction per joint part])]."""
    if not isinstance(drivers, Mapping) or not drivers:
        raise ModelError("kinematics", "drivers", "a non-empty mapping joint name -> time "
                         "function of its relative coordinate(s)", drivers)
    out = []
    used = np.zeros(s.nq, dtype=bool)
    for name, spec in drivers.items():
        ids = _joint_ids(s, name, "driver", "joint")
        item = _joint_item(s, name)
        k = int(sum(s.joint_k[j] for j in ids))
        if k == 0:
            raise ModelError(item, "drivers", "a joint with relative coordinates to drive", name,
                             "a rigid joint has none")
        for j in ids:
            if not s.joint_abelian[j]:
                raise ModelError(item, "drivers", "an abelian joint (hinge, prismatic, "
                                 "cylindrical, screw, universal) whose relative coordinates "
                                 "exist (Eq. (60))", s.joint_type[j],
                                 "the coordinates of a non-abelian joint (spherical, planar) "
                                 "are not additive; drive its motion by other joints")
        tf = as_timefunc(spec, item, "drivers", k)
        dofs = np.concatenate([s.joint_dofadr[j] + np.arange(s.joint_k[j]) for j in ids])
        if used[dofs].any():
            raise ModelError(item, "drivers", "each joint driven once", name)
        used[dofs] = True
        out.append((name, dofs, tf))
    return out


def _driver_values(drv, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    vals, rates, accs = [], [], []
    for name, dofs, tf in drv:
        k = len(dofs)
        try:
            f, r, a = time_derivatives(tf, t)
            f, r, a = (np.broadcast_to(x, (k,)) for x in (f, r, a))
        except Exception as exc:  # user callables may raise anything
            raise SimulationError(f"t={t:.9g}: driver {name!r} could not be evaluated to {k} "
                                  f"component(s): {type(exc).__name__}: {exc}") from None
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(r)) and np.all(np.isfinite(a))):
            raise SimulationError(f"t={t:.9g}: driver {name!r} returned a non-finite value")
        vals.append(f)
        rates.append(r)
        accs.append(a)
    return np.concatenate(vals), np.concatenate(rates), np.concatenate(accs)


def _check_rows(s: System, n: int) -> None:
    """Refuse, before anything is computed, more output times than a run may store
    (``simulate.MAX_STEPS``) or rows that would not fit in the available memory."""
    from se3dyn.simulate import MAX_STEPS, _available_memory

    if n > MAX_STEPS:
        raise ModelError("kinematics", "times", f"at most {MAX_STEPS:.0e} output times",
                         f"{n} times")
    per_row = 8 * (16 * (s.M + s.m) + 5 * s.nq + s.nm + 5)  # (H, HJ, alpha, v, vd, lam, ...)
    avail = _available_memory()
    if avail is not None and n * per_row > avail:
        raise ModelError("kinematics", "times", "results that fit in memory",
                         f"{n} times of {per_row} bytes = {n * per_row / 2**30:.1f} GiB",
                         f"{avail / 2**30:.1f} GiB available; ask for fewer output times")


def kinematics(model_or_system: Model | System, drivers: Mapping, times, *, tol: float = 1e-12,
               max_iter: int = 30) -> KinematicsResult:
    """Kinematic analysis of a driven mechanism and inverse dynamics.

    The relative coordinates of the driven (abelian) joints are prescribed,
    ``alpha_D(t) = f(t)`` (alpha of Eq. (60), measured from the model's initial configuration,
    or absolute for joints given ``initial`` values).
    With the joint constraints ``Phi = 0`` (Eq. (55)) they must leave no mobility: the Jacobian
    ``J = [B; D]`` (B: Eq. (58); D: selection of the driven coordinates) must have rank nq,
    redundant joint constraints being allowed. At every time:

    * positions: Newton on ``[Phi; alpha_D - f(t)] = 0`` from the previous solution advanced by
      ``exp(dt v + dt^2/2 vd)``, least-squares corrections ``J dn = -residual`` (SVD), to a
      scaled residual below ``tol``;
    * velocities: ``J v = [0; f'(t)]`` (``Phi_t = 0``: the joint constraints are scleronomic);
    * accelerations: ``J vd = [-(dB/dt) v; f''(t)]``. The quadratic velocity term
      ``c = (dB/dt) v = d/de [B(H exp(e v)) v]`` at ``e = 0`` (exactly, since ``T(e v) v = v``,
      Eq. (23)) is a Richardson-extrapolated central difference of the exact Jacobian:
      ``D(e) = (g(e) - g(-e)) / 2e``, ``c = (4 D(e/2) - D(e)) / 3``, truncation ``O(e^4)``, with
      ``e`` such that the scaled increment ``e |v|`` is 1e-3: relative error ~1e-12 truncation,
      ~1e-13 round-off;
    * inverse dynamics: with these accelerations the equations of motion (Eq. (36)) give
      ``Phi_q^T lambda + D^T mu = -(M vd - v^T M v + g_int - g_ext)`` (model actuators, PD laws,
      springs, dampers, loads and gravity included), solved by least squares (minimum norm in
      the scaled sense when constraints are redundant). The driver efforts are ``-mu`` (the
      actuator force of Eq. (66) that produces the motion), the joint reactions ``lambda``.

    Parameters
    ----------
    model_or_system : Model or System
    drivers : mapping joint name -> number, array (k,), TimeFunction or callable of t
        Prescribed relative coordinates of abelian joints (hinge, prismatic, cylindrical, screw,
        universal). Derivatives: see :func:`time_derivatives`.
    times : array_like (n,)
        Increasing output times.
    tol : float
        Newton tolerance on the scaled residual (translations / L, radians).
    max_iter : int
        Maximum Newton iterations per time.

    Returns
    -------
    KinematicsResult

    Raises
    ------
    ModelError
        Bad drivers (unknown joint, rigid or non-abelian joint, wrong number of components, a
        driver the constraints already fix) or a remaining mobility (naming the free unknowns).
    SimulationError
        Newton failure or a singular configuration (the mechanism loses its determinacy, e.g. a
        dead point), with the time and the worst item.
    """
    s = _as_system(model_or_system, "kinematics")
    drv = _drivers(s, drivers)
    try:
        tt = np.asarray(times, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ModelError("kinematics", "times", "increasing finite times", times) from None
    if tt.size == 0 or not np.all(np.isfinite(tt)) or np.any(np.diff(tt) <= 0):
        raise ModelError("kinematics", "times", "a non-empty list of increasing finite times",
                         times)
    _check_rows(s, tt.size)
    if not (isinstance(tol, int | float) and 0 < tol < 1):
        raise ModelError("kinematics", "tol", "a positive tolerance below 1", tol)
    if not (isinstance(max_iter, int) and max_iter >= 1):
        raise ModelError("kinematics", "max_iter", "a positive integer", max_iter)
    nq, nm = s.nq, s.nm
    ddofs = np.concatenate([d for _, d, _ in drv])
    nd = len(ddofs)
    D = np.zeros((nd, nq))
    D[np.arange(nd), ddofs] = 1.0
    L = _char_length(s)
    cs = _unknown_scale(s, L)
    rs = np.concatenate([_row_scale(s, L), 1.0 / cs[ddofs]])
    blocks = _Blocks(s)
    zq = np.zeros(nq)
    lam0 = np.zeros(nm)
    zin = _zero_inputs(s)
    labels = list(s.labels)

    def jac(ev):
        _, PT, B = blocks(ev)
        return np.vstack([B, D]), PT

    # ----- structure at the initial configuration: mobility and redundant drivers
    H, HJ, alpha = s.node_H0.copy(), s.joint_H0.copy(), s.alpha0.copy()
    ev = evaluate(s, H, HJ, alpha, zq, zq, zq, lam0, zin, None, full_alpha=True)
    J, _ = jac(ev)
    Js = rs[:, None] * J * cs
    r, N = _null_space(Js)
    if r < nq:
        raise ModelError("kinematics", "drivers", "drivers that leave no mobility (remaining "
                         "degrees of freedom 0)", f"{nq - r} remaining degree(s) of freedom",
                         "free motion involves " + _describe(N[:, 0] * cs, labels)
                         + "; drive one of these joints or fix the motion")
    rB = _null_space(Js[:nm])[0]
    if rB + nd > r:
        for name, dofs, _ in drv:
            keep_rows = np.ones(nm + nd, dtype=bool)
            keep_rows[nm + np.flatnonzero(np.isin(ddofs, dofs))] = False
            if _null_space(Js[keep_rows])[0] == r:
                raise ModelError(_joint_item(s, name), "drivers", "a driver on a coordinate the "
                                 "constraints leave free", name, "the joint constraints "
                                 "already determine this coordinate from the other drivers "
                                 "(redundant or conflicting driver)")

    n_t = tt.size
    out_H = np.zeros((n_t, s.M, 4, 4))
    out_HJ = np.zeros((n_t, s.m, 4, 4))
    out_a = np.zeros((n_t, nq))
    out_v = np.zeros((n_t, nq))
    out_vd = np.zeros((n_t, nq))
    out_lam = np.zeros((n_t, nm))
    out_mu = np.zeros((n_t, nd))
    energy = np.zeros((n_t, 3))
    iters = np.zeros(n_t, dtype=int)
    v = np.zeros(nq)
    vd = np.zeros(nq)
    for i, t in enumerate(tt):
        f, fr, fa = _driver_values(drv, float(t))
        # ----- positions: Newton from the predicted configuration
        pred = zq if i == 0 else (t - tt[i - 1]) * v + 0.5 * (t - tt[i - 1]) ** 2 * vd
        ev = evaluate(s, H, HJ, alpha, pred, zq, zq, lam0, zin, None, full_alpha=True)
        it = 0
        while True:
            H, HJ, alpha = ev.H, ev.HJ, ev.alpha
            res = np.concatenate([ev.phi, alpha[ddofs] - f]) * rs
            err = float(np.abs(res).max(initial=0.0))
            if not np.isfinite(err):
                raise SimulationError(f"kinematics: t={t:.9g}: the configuration became "
                                      "non-finite")
            if err <= tol:
                break
            if it >= max_iter:
                w = int(np.argmax(np.abs(res)))
                where = labels[nq + w] if w < nm else f"driver on {labels[ddofs[w - nm]]}"
                raise SimulationError(
                    f"kinematics: Newton failed at t={t:.9g} after {it} iterations: scaled "
                    f"residual {err:.3e} (tol {tol:.1e}); worst: {where}. The prescribed "
                    "motion may be out of reach of the mechanism, or the time step too large "
                    "for the predictor")
            J, _ = jac(ev)
            Js = rs[:, None] * J * cs
            y = sla.lstsq(Js, -res, cond=_RCOND, lapack_driver="gelsd")[0]
            ev = evaluate(s, H, HJ, alpha, cs * y, zq, zq, lam0, zin, None, full_alpha=True)
            it += 1
        iters[i] = it
        # ----- velocities
        J, PT = jac(ev)
        Js = rs[:, None] * J * cs
        U, sv, Vt = _svd(Js)
        rank = int(np.sum(sv > _RCOND * sv[0])) if sv.size and sv[0] > 0 else 0
        if rank < nq:
            Nv = _svd(Js, full=True)[2][rank:].T
            raise SimulationError(
                f"kinematics: singular configuration at t={t:.9g}: the drivers no longer "
                f"determine the motion (rank {rank} < {nq}; a dead point or a change of "
                "branch); free motion involves " + _describe(Nv[:, 0] * cs, labels))
        Ur, Vr, sr = U[:, :rank], Vt[:rank].T, sv[:rank]

        def solve(rhs, Ur=Ur, Vr=Vr, sr=sr):
            return cs * (Vr @ ((Ur.T @ (rs * rhs)) / sr))

        v = solve(np.concatenate([np.zeros(nm), fr]))
        # ----- accelerations: quadratic velocity term by Richardson extrapolation
        vs = np.abs(v / cs).max(initial=0.0)
        c = np.zeros(nm)
        if vs > 0:
            eps = 1e-3 / vs

            def g(e, v=v, H=H, HJ=HJ, alpha=alpha):
                evp = evaluate(s, H, HJ, alpha, e * v, zq, zq, lam0, zin, None, full_alpha=False)
                return blocks(evp)[2] @ v

            D1 = (g(eps) - g(-eps)) / (2 * eps)
            D2 = (g(eps / 2) - g(-eps / 2)) / eps
            c = (4 * D2 - D1) / 3
        vd = solve(np.concatenate([-c, fa]))
        # ----- inverse dynamics (Eq. (36)): Phi_q^T lam + D^T mu = -r0
        inputs = step_inputs(s, float(t))
        evd = evaluate(s, H, HJ, alpha, zq, v, vd, lam0, inputs, None, full_alpha=True)
        # rows (equations) times cs and columns (multipliers) times rs: moment units
        G = cs[:, None] * np.hstack([PT, D.T]) * rs
        sol = rs * sla.lstsq(G, -cs * evd.r, cond=_RCOND, lapack_driver="gelsd")[0]
        out_H[i], out_HJ[i], out_a[i] = H, HJ, alpha
        out_v[i], out_vd[i] = v, vd
        out_lam[i] = sol[:nm]
        out_mu[i] = sol[nm:]
        # kinetic (Eq. (47)), gravity potential, elastic energy of every element (joint
        # springs Eq. (62), spring-dampers, bushings), by the element kernels
        energy[i] = evd.energy[:3]
    efforts = {}
    off = 0
    for name, dofs, _ in drv:
        efforts[name] = -out_mu[:, off:off + len(dofs)]
        off += len(dofs)
    return KinematicsResult(system=s, t=tt, H=out_H, HJ=out_HJ, alpha=out_a, v=out_v,
                            vd=out_vd, lam=out_lam, efforts=efforts, kinetic=energy[:, 0],
                            potential=energy[:, 1], spring=energy[:, 2], iterations=iters)
