"""Assembly of inconsistent initial configurations (:func:`assemble`): Gauss-Newton with
minimum-norm corrections onto ``Phi = 0`` (Eq. (55)) in the unknowns of the dynamic formulation
(Sec. 3.3, Eq. (14)), then the velocities projected onto ``B v = 0``; see
:mod:`se3dyn.analysis.kinematics` for the conventions and the scaling.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from se3dyn import lie
from se3dyn._lazy import LazyModule
from se3dyn.analysis.common import (
    _as_system,
    _Blocks,
    _joint_ids,
    _joint_item,
    _OneConfiguration,
    _unknown_name,
    _zero_inputs,
)
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.projection import project_velocities
from se3dyn.engine.scaling import _RCOND, _char_length, _row_scale, _unknown_scale
from se3dyn.errors import ModelError, SimulationError
from se3dyn.model.timefunc import (
    Constant,
    Sine,
    Table,
    TimeFunction,
    as_timefunc,
)

if TYPE_CHECKING:
    from se3dyn.engine.system import System
    from se3dyn.model.specs import Model

sla = LazyModule("scipy.linalg")


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
class Assembly(_OneConfiguration):
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
        table), and ``model``: a new :class:`~se3dyn.model.specs.Model` starting in the assembled
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
    from se3dyn.engine.rank import redundant_equations

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
