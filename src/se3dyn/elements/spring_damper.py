"""Spring-damper between two points attached to two nodes: force ``k (L - L0) + d dL/dt`` along
the line of the points.

Kernel ``se3dyn/_core/elements/spring_damper.hpp`` (exact linearisation in configuration and
velocity).
"""

from __future__ import annotations

import numpy as np

KEY = "spring_damper"
TRAITS = dict(conservative=True, constraint=False, objective=True)


def tables(s, lay) -> dict:
    sp = s.springs  # (node a, node b, c_a, c_b, k, d, L0)
    fa = np.array([x[0] for x in sp], np.int64)
    fb = np.array([x[1] for x in sp], np.int64)
    t = dict(fa=fa, fb=fb, ca=np.array([x[2] for x in sp], float).reshape(len(sp), 3),
             cb=np.array([x[3] for x in sp], float).reshape(len(sp), 3),
             k=np.array([x[4] for x in sp], float), d=np.array([x[5] for x in sp], float),
             L0=np.array([x[6] for x in sp], float))
    ga, gb = lay.frame_groups(fa), lay.frame_groups(fb)
    for key, (p, q) in (("aa", (ga, ga)), ("ab", (ga, gb)), ("ba", (gb, ga)), ("bb", (gb, gb))):
        t["off_" + key] = lay.blocks(p, q).astype(np.int64)
    lay.velocity_blocks(np.stack([fa, fa, fb, fb], axis=1), np.stack([fa, fb, fa, fb], axis=1))
    return t


def examples(rng):
    """Springs between two free bodies at offset points, and to the ground, with damping."""
    import se3dyn as sd

    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("a", position=(0.5, 0.0, 0.0), mass=1.0, inertia=(1, 1.2, 1.4),
            velocity=tuple(rng.normal(size=3)), angular_velocity=tuple(rng.normal(size=3)))
    mb.node("b", position=(1.0, 0.3, 0.2), mass=2.0, inertia=(1, 1.1, 1.3))
    mb.spring_damper("s1", "a", "b", at_a=tuple(rng.normal(size=3)),
                     at_b=tuple(rng.normal(size=3)), stiffness=3.0, damping=0.4, length=0.7)
    mb.spring_damper("s2", "g", "a", at_b=(0.6, 0.1, 0.0), stiffness=2.0, damping=0.0)
    return [mb.build()]
