"""The link tree of a URDF: checked (every joint names known links, one root, each link the
child of one joint, no cycle), ordered from the root, and its poses and velocities at a
configuration (forward kinematics in the world frame)."""

from __future__ import annotations

from collections import deque

import numpy as np

from se3dyn.errors import close_matches
from se3dyn.io.urdf.geometry import motion, plane_axes
from se3dyn.io.urdf.parse import Joint, Robot, UrdfError


def tree_order(robot: Robot) -> tuple[str, list[Joint]]:
    """The root link and the joints in breadth-first order from it (parents first)."""
    f = robot.file
    child_of: dict[str, Joint] = {}
    children: dict[str, list[Joint]] = {n: [] for n in robot.links}
    for j in robot.joints.values():
        for fld, end in (("<parent> link", j.parent), ("<child> link", j.child)):
            if end not in robot.links:
                close = close_matches(end, list(robot.links), n=1)
                raise UrdfError(f"{f}: joint {j.name!r}", fld, "the name of a link of the file",
                                end, f"did you mean {close[0]!r}?" if close else "no such link")
        if j.parent == j.child:
            raise UrdfError(f"{f}: joint {j.name!r}", "<child> link", "a link other than the "
                            "parent", j.child)
        if j.child in child_of:
            raise UrdfError(f"{f}: joint {j.name!r}", "<child> link", "a link that no other "
                            "joint has as its child (a URDF is a tree; declare a loop closure "
                            "as a <loop_joint> or <se3dyn:loop>, docs/urdf.md)", j.child,
                            f"joint {child_of[j.child].name!r} has it as its child already")
        child_of[j.child] = j
        children[j.parent].append(j)
    if not robot.links:
        raise UrdfError(f, "<link>", "at least one link", 0)
    roots = [n for n in robot.links if n not in child_of]
    if len(roots) > 1:
        raise UrdfError(f, "<link>", "one root link (every other link the child of a joint)",
                        roots[:6], "join them by joints, or load them as separate models")
    order, seen = [], set(roots)
    todo = deque(roots)
    while todo:
        for j in children[todo.popleft()]:
            order.append(j)
            seen.add(j.child)
            todo.append(j.child)
    if len(seen) < len(robot.links):
        cyc = next(j for j in robot.joints.values() if j.child not in seen)
        raise UrdfError(f"{f}: joint {cyc.name!r}", "<child> link", "a tree of links (no "
                        "cycle: the root link reaches every link)", cyc.child,
                        "the joints form a cycle; declare a loop closure as a <loop_joint> "
                        "or <se3dyn:loop> instead")
    return roots[0], order


def poses(order: list[Joint], root: str, T_root: np.ndarray, q: dict) -> dict[str, np.ndarray]:
    """World poses (4, 4) of every link at the joint values ``q`` (name -> value)."""
    Tw = {root: T_root}
    for j in order:
        plane = plane_axes(j.axis) if j.type == "planar" else None
        Tw[j.child] = Tw[j.parent] @ j.T @ motion(j.type, j.axis, q.get(j.name, 0.0), plane)
    return Tw


def twists(order: list[Joint], root: str, Tw: dict, v: dict, v_root: np.ndarray
           ) -> dict[str, np.ndarray]:
    """World velocities ``(velocity of the link origin, angular velocity)`` (6,) of every link
    at the joint rates ``v`` (name -> value; a floating joint's is the child's own (6,))."""
    out = {root: np.asarray(v_root, dtype=float)}
    for j in order:
        vp = out[j.parent]
        dp = Tw[j.child][:3, 3] - Tw[j.parent][:3, 3]
        lin, ang = vp[:3] + np.cross(vp[3:], dp), vp[3:].copy()
        R = (Tw[j.parent] @ j.T)[:3, :3]
        a = R @ j.axis
        rate = v.get(j.name, 0.0)
        if j.type in ("revolute", "continuous"):
            ang = ang + a * rate
        elif j.type == "prismatic":
            lin = lin + a * rate
        elif j.type == "planar":
            e = plane_axes(j.axis)
            lin = lin + R @ (rate[0] * e[0] + rate[1] * e[1])
            ang = ang + a * rate[2]
        elif j.type == "floating":
            lin, ang = np.asarray(rate[:3], float), np.asarray(rate[3:], float)
        out[j.child] = np.concatenate([lin, ang])
    return out
