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


def mass_matrices(s, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The constant material mass matrices about the nodes ``ids`` (n,) (module docstring),
    ``(M (n, 6, 6), m c (n, 3), m (n,))``; zero for a node without mass."""
    n = len(ids)
    m, c = np.asarray(s.node_mass, float)[ids], np.asarray(s.node_com, float)[ids]
    C = lie.hat3(c).reshape(n, 3, 3)
    M = np.zeros((n, 6, 6))
    M[:, :3, :3] = m[:, None, None] * np.eye(3)
    M[:, :3, 3:] = -m[:, None, None] * C
    M[:, 3:, :3] = m[:, None, None] * C
    M[:, 3:, 3:] = np.asarray(s.node_J)[ids] - (m[:, None, None] * C) @ C
    return M, (m[:, None] * c).reshape(n, 3), m.astype(float)


def tables(s, lay) -> dict:
    """Every node with mass or inertia is a body (``node_com``: centre of mass in the node's
    material frame)."""
    ids = np.flatnonzero((np.asarray(s.node_mass) > 0)
                         | np.any(np.asarray(s.node_J).reshape(s.M, 9) != 0, axis=1))
    M, mc, m = mass_matrices(s, ids)
    lay.velocity_blocks(ids, ids)
    fg = lay.frame_groups(ids)
    return dict(frame=ids.astype(np.int64), M=M, mc=mc, m=m,
                off=lay.blocks(fg, fg).astype(np.int64))


def examples(rng):
    """A free body with its node off the centre of mass, spinning and moving, under gravity."""
    from se3dyn.model.builder import ModelBuilder

    mb = ModelBuilder(gravity=tuple(rng.normal(size=3)))
    J = rng.uniform(0.5, 1.0, 3)
    mb.node("b", position=tuple(rng.normal(size=3)), mass=float(rng.uniform(1, 3)),
            inertia=tuple(J), principal_axes=lie.exp_so3(rng.normal(size=3)),
            com=tuple(rng.normal(size=3)), velocity=tuple(rng.normal(size=3)),
            angular_velocity=tuple(rng.normal(size=3)),
            orientation=lie.exp_so3(rng.normal(size=3)))
    return [mb.build()]
