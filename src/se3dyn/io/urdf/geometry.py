"""Poses of URDF: roll-pitch-yaw angles, joint motions, inertia in other frames.

URDF's ``rpy`` are fixed-axis angles: ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (the ROS
specification of ``<origin>``). Poses are 4 x 4 homogeneous matrices ``T_A_B`` (frame B in
frame A), as :mod:`se3dyn.lie` writes them.
"""

from __future__ import annotations

import numpy as np

from se3dyn.lie import exp_so3


def frame(R: np.ndarray, p) -> np.ndarray:
    """The pose (4, 4) with rotation R (3, 3) and origin p (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def rpy_matrix(rpy) -> np.ndarray:
    """``Rz(y) Ry(p) Rx(r)`` (3, 3) of URDF's ``rpy = (r, p, y)`` (rad)."""
    r, p, y = (float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def pose_of(value, item: str, fld: str, fail) -> np.ndarray:
    """A pose from a 4 x 4 matrix or a 6-vector ``(x, y, z, roll, pitch, yaw)`` (URDF's
    convention); ``fail(expected, got)`` raises."""
    expected = "a pose: a 4x4 matrix or (x, y, z, roll, pitch, yaw)"
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        fail(expected, value)
    if not np.all(np.isfinite(a)):
        fail(expected, value)
    if a.shape == (6,):
        return frame(rpy_matrix(a[3:]), a[:3])
    if a.shape == (4, 4):
        R = a[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0 or \
                np.any(a[3] != (0, 0, 0, 1)):
            fail(expected + " (rotation orthonormal, det +1; last row 0 0 0 1)", value)
        return a.copy()
    fail(expected, value)


def motion(jtype: str, axis: np.ndarray, q, plane: np.ndarray | None = None) -> np.ndarray:
    """The joint's motion ``M(q)`` (4, 4) in its joint frame: the child frame is
    ``T_parent_joint M(q)``. ``q``: a number (revolute, continuous, prismatic), a pose
    (floating) or ``(u, v, theta)`` on the in-plane axes ``plane`` (2, 3) (planar)."""
    if jtype in ("revolute", "continuous"):
        return frame(exp_so3(axis * float(q)), np.zeros(3))
    if jtype == "prismatic":
        return frame(np.eye(3), axis * float(q))
    if jtype == "floating":
        return q
    if jtype == "planar":
        return frame(exp_so3(axis * q[2]), q[0] * plane[0] + q[1] * plane[1])
    return np.eye(4)


def plane_axes(axis: np.ndarray) -> np.ndarray:
    """Two in-plane unit axes (2, 3) of a planar joint with normal ``axis`` (its joint frame):
    the joint frame's x (or y, when x is along the normal) made normal to it, and
    ``axis x e1``."""
    e = np.eye(3)[0] if abs(axis[0]) < 0.9 else np.eye(3)[1]
    e1 = e - (e @ axis) * axis
    e1 /= np.linalg.norm(e1)
    return np.array([e1, np.cross(axis, e1)])


def world_inertia(T_world_link: np.ndarray, T_link_com: np.ndarray, J: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass (3,) and inertia tensor about it (3, 3), both in the world frame, of a
    tensor ``J`` given in the ``<inertial>`` frame ``T_link_com``: ``R J R^T`` with
    ``R = R_world_link R_link_com`` (the rotated inertial frame of URDF)."""
    T = T_world_link @ T_link_com
    R = T[:3, :3]
    Jw = R @ J @ R.T
    return T[:3, 3].copy(), 0.5 * (Jw + Jw.T)
