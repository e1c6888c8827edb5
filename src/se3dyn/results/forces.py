"""Force sensors of a run (issue 30, item 4): the generalized forces of the joints' force
elements split into the actuator part and the spring-damper part, and the axial force, length
and rate of the point spring-dampers.

**Joint force elements, through the compiled kernels.** The joint coordinates' rows of the
equations of motion (Eq. (36)) are ``A^T lambda + g_j = 0`` with the force elements' residual

    g_j = K (alpha - alpha_ref) + C v - tau(t) - PD,   PD = -kp (alpha - target(t))
                                                             - kd (v - target_rate(t))

(springs Eq. (62), dampers Eq. (64), actuators Eq. (66) (time functions or the user's laws
``f(t, q, v)``), PD and PID laws; a joint's armature adds the inertia ``J_a dv/dt``; on
non-abelian joints the spring acts on the log coordinates, ``T_A(alpha)^-T K (alpha -
alpha_ref)``, see ``se3dyn/_core/elements/joint_force.hpp``).
Rather than writing these formulas a second time, each part is the residual that the same
kernels give for a copy of the model holding that part only (:func:`part_model`), at the
stored rows with zero multipliers (:func:`se3dyn.engine.system.residual_rows`): the joint rows
then hold ``g_j`` of that part alone, exactly as the run evaluated it (time functions at the
rows' times, the log coordinates and ``T_A`` of non-abelian joints included). The armature
(inertia, not a force) is in neither part.

A PID law's integral ``z`` is a state of the step (``State.ctrl``), not stored in the rows, so
the kernel cannot evaluate the law again at a stored row; the effort of a PID-controlled joint
is taken from its equation of motion instead (:func:`pid_joints`; the results' accessor):
``A^T lambda + spring + J_a dv/dt``, exact to the Newton tolerance of the step.

**Point spring-dampers, in numpy.** Their kernel returns the two nodes' wrenches, not the scalar
force of the line between the points, so :func:`point_spring` computes ``L``, ``dL/dt`` and
``N = k (L - L0) + d dL/dt`` from the stored frames and velocities with the kernel's formulas
(``se3dyn/_core/elements/spring_damper.hpp``); tests/test_force_sensors.py checks them against
Newton's law on a mass hanging from the spring and against lengths measured from the node
positions.
"""

from __future__ import annotations

import weakref
from dataclasses import replace

import numpy as np

__all__ = ["PARTS", "part_model", "has_part", "pid_joints", "joint_force_rows",
           "point_spring"]

#: The parts of a joint's force elements: ``"actuator"`` (time-function actuator and PD law)
#: and ``"spring"`` (spring and damper).
PARTS = ("actuator", "spring")

# per compiled System: the compiled model of each part (a System compares by identity)
_PART_SYSTEMS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def has_part(joint, part: str) -> bool:
    """Whether a :class:`~se3dyn.model.specs.JointSpec` has force elements of ``part``."""
    if part == "actuator":  # (control: a PD or a PID law; law: the user's f(t, q, v))
        return (joint.actuator is not None or joint.control is not None
                or getattr(joint, "law", None) is not None)
    return bool(np.any(np.asarray(joint.stiffness) != 0) or np.any(np.asarray(joint.damping)
                                                                     != 0))


def pid_joints(model) -> list[int]:
    """Indices of the joints under a PID law (:class:`~se3dyn.model.specs.PID`)."""
    return [j for j, js in enumerate(model.joints) if hasattr(js.control, "ki")]


def part_model(model, part: str):
    """A copy of ``model`` whose joints keep only the force elements of ``part`` (the others
    zero or absent, and no armature), without the elements that never act on joint
    coordinates (loads, point spring-dampers, bushings, beams) nor drives and couplings: the
    same nodes, joints and numbering of the unknowns, so its residual's joint rows are ``g_j``
    of that part alone."""
    if part not in PARTS:
        raise ValueError(f"part: expected one of {PARTS}, got {part!r}")
    joints = []
    for j in model.joints:
        if part == "actuator":
            z = np.zeros(j.k)
            joints.append(replace(j, stiffness=z, reference=z.copy(), damping=z.copy(),
                                  armature=None))
        else:
            joints.append(replace(j, actuator=None, control=None, armature=None, law=None))
    return replace(model, joints=tuple(joints), loads=(), springs=(), bushings=(), beams=(),
                   drives=(), couplings=())


def _part_system(s, part: str):
    from se3dyn.engine.system import compile_model

    parts = _PART_SYSTEMS.setdefault(s, {})
    if part not in parts:
        ps = compile_model(part_model(s.model, part))
        # the numbering must be the model's own (it is: same nodes and joints)
        if ps.nq != s.nq or not np.array_equal(ps.joint_dofadr, s.joint_dofadr):
            raise RuntimeError("se3dyn internal error: the force part's system is numbered "
                               "differently")  # pragma: no cover
        parts[part] = ps
    return parts[part]


def joint_force_rows(s, part: str, t: np.ndarray, H: np.ndarray, alpha: np.ndarray,
                     v: np.ndarray, vd: np.ndarray) -> np.ndarray:
    """The residual ``g_j`` of the joints' force elements of ``part`` (module docstring) at
    stored rows, shape (n, nq) (zero on node unknowns): times (n,), node frames (n, M, 4, 4),
    coordinates, velocities and accelerations (n, nq) of the compiled System ``s``."""
    from se3dyn.engine.system import joint_frames, residual_rows

    n = len(t)
    if not any(has_part(j, part) for j in s.model.joints):
        return np.zeros((n, s.nq))
    ps = _part_system(s, part)
    H = np.asarray(H, dtype=float)
    return residual_rows(ps, np.asarray(t, dtype=float), H, joint_frames(ps, H), alpha, v, vd,
                         np.zeros((n, ps.nm)))


def point_spring(Ha: np.ndarray, wa: np.ndarray, ca: np.ndarray, Hb: np.ndarray,
                 wb: np.ndarray, cb: np.ndarray, k: float, d: float, L0: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Length, its rate and the axial force (tension positive) of a point spring-damper.

    The points ``p = x + R c`` are attached to two node frames ``H`` (n, 4, 4) at the material
    offsets ``c`` (3,); they move with ``dp/dt = R (U + Omega x c)`` from the material twists
    ``w = (U, Omega)`` (n, 6) of the nodes (Eq. (4)). ``L = |p_b - p_a|``, ``dL/dt = e .
    (dp_b/dt - dp_a/dt)`` with ``e = (p_b - p_a) / L`` (zero where the points coincide, as the
    kernel takes it), ``N = k (L - L0) + d dL/dt``; the spring pulls b towards a with ``N e``.

    Returns
    -------
    L, Ldot, N : ndarray (n,)
    """
    def point(H, w, c):
        R = H[:, :3, :3]
        return (np.einsum("nij,j->ni", R, c) + H[:, :3, 3],
                np.einsum("nij,nj->ni", R, w[:, :3] + np.cross(w[:, 3:], c)))

    pa, va = point(np.asarray(Ha, float), np.asarray(wa, float), np.asarray(ca, float))
    pb, vb = point(np.asarray(Hb, float), np.asarray(wb, float), np.asarray(cb, float))
    dvec = pb - pa
    L = np.linalg.norm(dvec, axis=1)
    e = np.divide(dvec, L[:, None], out=np.zeros_like(dvec), where=L[:, None] > 0)
    Ldot = np.einsum("ni,ni->n", e, vb - va)
    return L, Ldot, k * (L - L0) + d * Ldot
