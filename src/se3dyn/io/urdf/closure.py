"""Closing the loops of a URDF's initial configuration: the joint values not given in ``q0``
found so that every loop closure's two frames meet (Gauss-Newton with the least change, on
the revolute, continuous and prismatic joints between the root and the loops' links)."""

from __future__ import annotations

import numpy as np

from se3dyn.io.urdf.tree import poses
from se3dyn.lie import log_so3

ONE_DOF = ("revolute", "continuous", "prismatic")


def loop_residual(lp, Tw: dict) -> np.ndarray:
    """The gap of one loop closure (6,): the two frames' origins apart (m), then their axes
    apart (rad; a fixed closure: the relative rotation, a spherical one: nothing)."""
    F1, F2 = Tw[lp.link1] @ lp.T1, Tw[lp.link2] @ lp.T2
    turn = np.zeros(3)
    if lp.type in ONE_DOF:
        turn = np.cross(F1[:3, :3] @ lp.axis, F2[:3, :3] @ lp.axis)
    elif lp.type == "fixed":
        turn = log_so3(F1[:3, :3].T @ F2[:3, :3])
    return np.concatenate([F1[:3, 3] - F2[:3, 3], turn])


def close_loops(order: list, root: str, T_root: np.ndarray, q: dict, loops: list, held: set,
                follow: dict, tol: float = 1e-14, max_iter: int = 40) -> list[str]:
    """Move the free joint values of ``q`` (in place) until every loop closes; returns the
    joints moved (empty when the loops were closed already or could not be closed: the
    importer then refuses them with the gap)."""
    free = _free_joints(order, loops, held | set(follow))
    if not loops or not free:
        return []

    def residual(x):
        qq = dict(q)
        qq.update(zip(free, x, strict=True))
        for f, (lead, r, o) in follow.items():
            qq[f] = r * qq[lead] + o
        Tw = poses(order, root, T_root, qq)
        return np.concatenate([loop_residual(lp, Tw) for lp in loops])

    x = np.array([q[n] for n in free], dtype=float)
    r = residual(x)
    if np.abs(r).max() <= tol:
        return []
    for _ in range(max_iter):
        J = np.column_stack([(residual(x + e) - residual(x - e)) / 2e-7
                             for e in 1e-7 * np.eye(len(x))])
        x = x - np.linalg.lstsq(J, r, rcond=1e-10)[0]
        r = residual(x)
        if np.abs(r).max() <= tol:
            moved = [n for n, v in zip(free, x, strict=True) if v != q[n]]
            q.update(zip(free, x.tolist(), strict=True))
            for f, (lead, rr, o) in follow.items():
                q[f] = rr * q[lead] + o
            return moved
    return []


def _free_joints(order: list, loops: list, held: set) -> list[str]:
    """The 1-dof joints on the paths from the root to the loops' links, not held."""
    parent = {j.child: j for j in order}
    out = []
    for link in {lk for lp in loops for lk in (lp.link1, lp.link2)}:
        while link in parent:
            j = parent[link]
            if j.type in ONE_DOF and j.name not in held and j.name not in out:
                out.append(j.name)
            link = j.parent
    return sorted(out, key=[j.name for j in order].index)
