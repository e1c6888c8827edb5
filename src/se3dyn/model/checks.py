"""Warnings about a model that is valid but probably not what was meant: an axis joint whose axis
does not pass through the attachment point the user gave (``se3dyn check``, ``se3dyn run``).
"""

from __future__ import annotations

import numpy as np

from se3dyn._lazy import LazyModule

sla = LazyModule("scipy.linalg")


#: Joint types with one axis whose line a joint between node frames places through node B.
AXIS_JOINTS = ("hinge", "prismatic", "cylindrical", "screw")


def off_axis_joints(model) -> list[str]:
    """Warnings for axis joints (hinge, prismatic, cylindrical, screw) given without ``at``
    whose node B is a body (mass or inertia) and whose node A is off the joint's axis.

    Without ``at`` a joint connects the node frames (Eq. (7), ``H_B = H_A H_J``): the axis passes
    through node B, so a body node B away from a pivot node A turns (or slides) about itself,
    held at a constant offset from A, which is rarely what was meant when A is the pivot. (The
    paper's way, a massless joint node B joined to the body by a rigid joint, and a shared
    ground node A are not warned about.) ``at`` at node B's position keeps that motion and
    silences the warning.

    Parameters
    ----------
    model : Model

    Returns
    -------
    list of str
        One line per joint: the joint, the two nodes, their distance across the axis, and the
        ``at`` to give for an axis through node A. Joints of composites (universal) are not
        checked.
    """
    nodes = {n.name: n for n in model.nodes}
    out = []
    for j in model.joints:
        nb = nodes[j.node_b]
        if (j.type not in AXIS_JOINTS or j.at is not None or j.composite is not None
                or (nb.mass <= 0 and not np.any(np.asarray(nb.inertia) != 0))):
            continue
        A = np.asarray(j.A, dtype=float).reshape(6, -1)
        u = A[3:, 0] if np.linalg.norm(A[3:, 0]) > 0 else A[:3, 0]
        u = u / np.linalg.norm(u)
        xa = np.asarray(nodes[j.node_a].position, dtype=float)
        xb = np.asarray(nodes[j.node_b].position, dtype=float)
        d = xa - xb
        across = float(np.linalg.norm(d - (d @ u) * u))
        if across > 1e-9 * max(float(np.linalg.norm(xa)), float(np.linalg.norm(xb)), 1.0):
            at = "[" + ", ".join(f"{x:.6g}" for x in xa) + "]"
            moves = "turns" if j.type in ("hinge", "screw") else "slides"
            here = "[" + ", ".join(f"{x:.6g}" for x in xb) + "]"
            out.append(f"joint {j.name!r} ({j.type}): field 'at': nothing given while its "
                       f"nodes {j.node_a!r} and {j.node_b!r} are {across:.3g} m apart across "
                       f"the axis, so the axis passes through the body node {j.node_b!r}, which "
                       f"{moves} about itself at a fixed offset from {j.node_a!r} (an axis "
                       f"through node {j.node_a!r}: at: {at}; this motion without the warning: "
                       f"at: {here})")
    return out
