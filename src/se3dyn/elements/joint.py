"""Kinematic joint or rigid constraint between two node frames through the joint frame, on a
subgroup spanned by a constant A (Eqs. (7)-(11), (54)-(59)), optionally between frames attached
to the nodes at a point (``at``).

Kernel ``se3dyn/_core/elements/joint.hpp``: six constraints ``Phi = vect((H_B X_B)^-1 H_A X_A
H_J)`` (Eq. (55)), the forces ``B^T lambda`` of the gradient at ``Phi = 0`` (Eq. (58)), the exact
linearisation of Phi (Eq. (59) at ``Phi = 0``), the geometric stiffness of the node-A force, and
for the stabilised index-2 form the velocity constraints ``B v`` with their derivative.
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie

KEY = "joint"
TRAITS = dict(conservative=True, constraint=True, objective=True)


def tables(s, lay) -> dict:
    M, m = s.M, s.m
    ja, jb = s.joint_a.astype(np.int64), s.joint_b.astype(np.int64)
    jf = M + np.arange(m, dtype=np.int64)
    c = lay.mult_groups(np.arange(m))
    fa, fb, fj = lay.frame_groups(ja), lay.frame_groups(jb), lay.frame_groups(jf)
    # per joint, in this order: ca, cb, cj, ac, bc, jc, aj and the diagonal (identity for
    # dropped, redundant, equations)
    off = lay.blocks(np.stack([c, c, c, fa, fb, fj, fa, c], axis=1),
                     np.stack([fa, fb, fj, c, c, c, fj, c], axis=1))
    lay.constraints(np.arange(m), np.stack([ja, jb, jf], axis=1))
    XA = np.ascontiguousarray(s.joint_XA, float).reshape(m, 4, 4)
    XB = np.ascontiguousarray(s.joint_XB, float).reshape(m, 4, 4)
    eye = np.eye(4)
    t = dict(fa=ja, fb=jb, fj=jf, mult=s.joint_multadr.astype(np.int64), XA=XA, XB=XB,
             PA=lie.adjoint_inv(XA) if m else np.zeros((0, 6, 6)),
             PB=lie.adjoint_inv(XB) if m else np.zeros((0, 6, 6)),
             offset=(~(np.isclose(XA, eye).all(axis=(1, 2))
                       & np.isclose(XB, eye).all(axis=(1, 2)))).astype(np.int64))
    for i, key in enumerate(("ca", "cb", "cj", "ac", "bc", "jc", "aj")):
        t["off_" + key] = np.ascontiguousarray(off[:, i], np.int64)
    return t


def index2_tables(s, lay, t: dict) -> None:
    """Blocks that only the stabilized index-2 matrix has: velocity-constraint rows."""
    for key, fr in (("xa", t["fa"]), ("xb", t["fb"]), ("xj", t["fj"])):
        t["off_" + key] = lay.blocks(lay.xi_groups(np.arange(len(fr))),
                                     lay.frame_groups(fr)).astype(np.int64)

def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def examples(rng):
    """Every joint type, with and without an attachment point, between two moving bodies."""
    import se3dyn as sd

    out = []
    for typ, kw in (("rigid", {}), ("hinge", dict(axis=_unit(rng))),
                    ("prismatic", dict(axis=_unit(rng))),
                    ("cylindrical", dict(axis=_unit(rng))), ("spherical", {}),
                    ("planar", dict(normal=_unit(rng))),
                    ("screw", dict(axis=_unit(rng), pitch=0.1))):
        for at in (None, tuple(_unit(rng))):
            mb = sd.ModelBuilder()
            mb.node("a", position=tuple(_unit(rng)), mass=1.0, inertia=(1, 1.2, 1.4))
            mb.node("b", position=tuple(_unit(rng)), mass=2.0, inertia=(1, 1.1, 1.3),
                    orientation=lie.exp_so3(_unit(rng)))
            mb.joint("j", typ, "a", "b", at=at, **kw)
            out.append(mb.build())
    return out
