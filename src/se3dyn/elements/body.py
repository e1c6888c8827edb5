"""Rigid body: inertia and gravity on a node frame, centre of mass anywhere on the body.

Kernel ``se3dyn/_core/elements/body.hpp``: the constant material mass matrix about the node
``M = [[m I, -m hat(c)], [m hat(c), J_c - m hat(c)^2]]`` (Eq. (49) for ``c = 0``), the inertia
force ``M vd - ad(v)^T M v`` (Eq. (36); Eq. (51) for ``c = 0``) with its tangent damping
(Eq. (53)), gravity at the centre of mass (Eq. (66)) with its stiffness (Eq. (67)).
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie

KEY = "body"
TRAITS = dict(conservative=True, constraint=False, objective=False)


def tables(s, lay) -> dict:
    """Every node with mass or inertia is a body (``node_com``: centre of mass in the node's
    material frame)."""
    ids = [i for i in range(s.M) if s.node_mass[i] > 0 or np.any(s.node_J[i] != 0)]
    M = np.zeros((len(ids), 6, 6))
    mc = np.zeros((len(ids), 3))
    for e, i in enumerate(ids):
        m, c = s.node_mass[i], s.node_com[i]
        C = lie.hat3(c)
        M[e, :3, :3] = m * np.eye(3)
        M[e, :3, 3:] = -m * C
        M[e, 3:, :3] = m * C
        M[e, 3:, 3:] = s.node_J[i] - m * C @ C
        mc[e] = m * c
    for i in ids:
        lay.velocity_block(i, i)
    return dict(frame=np.array(ids, np.int64), M=M, mc=mc,
                m=np.array([s.node_mass[i] for i in ids], float),
                off=np.array([lay.frame_block(i, i) for i in ids], np.int64))


def examples(rng):
    """A free body with its node off the centre of mass, spinning and moving, under gravity."""
    import se3dyn as sd

    mb = sd.ModelBuilder(gravity=tuple(rng.normal(size=3)))
    J = rng.uniform(0.5, 1.0, 3)
    mb.node("b", position=tuple(rng.normal(size=3)), mass=float(rng.uniform(1, 3)),
            inertia=tuple(J), principal_axes=lie.exp_so3(rng.normal(size=3)),
            com=tuple(rng.normal(size=3)), velocity=tuple(rng.normal(size=3)),
            angular_velocity=tuple(rng.normal(size=3)),
            orientation=lie.exp_so3(rng.normal(size=3)))
    return [mb.build()]
