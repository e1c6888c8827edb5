"""Compliant contact between collision shapes on two nodes (issue 33): a half-space and a
sphere, or two spheres, from the pairs of :func:`se3dyn.model.contact.contact_pairs`.

Hertz's normal force with the exact-restitution dissipation of P. Carvalho and M. Martins,
"Exact restitution and generalizations for the Hunt-Crossley contact model", Mechanism and
Machine Theory 139 (2019) 277-289, ``F_n = k delta^{3/2} (1 + c(e) delta'/v_in)``, and Coulomb
friction with an elastic bristle state (no creep in stick); the states are carried by the step
(``State.ctrl`` after the PID states). Kernel ``se3dyn/_core/elements/contact.hpp`` (its
tangent by forward automatic differentiation, the SE(3) geometric stiffness included);
the laws and their parameters: docs/contact.md.
"""

from __future__ import annotations

import numpy as np

KEY = "contact"
TRAITS = dict(conservative=False, constraint=False, objective=True)


def tables(s, lay) -> dict:
    pairs = s.contacts
    nidx = {n: i for i, n in enumerate(s.node_names)}
    H0 = s.node_H0
    n = len(pairs)
    fa = np.array([nidx[p.a.node] for p in pairs], np.int64)
    fb = np.array([nidx[p.b.node] for p in pairs], np.int64)
    ca, cb, na = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    for i, p in enumerate(pairs):  # material offsets and normal: R0^T (p - x0), R0^T n
        Ra, xa = H0[fa[i], :3, :3], H0[fa[i], :3, 3]
        Rb, xb = H0[fb[i], :3, :3], H0[fb[i], :3, 3]
        ca[i], cb[i], na[i] = Ra.T @ (p.a.at - xa), Rb.T @ (p.b.at - xb), Ra.T @ p.a.normal
    col = lambda f: np.array([f(p) for p in pairs], float)  # noqa: E731
    t = dict(fa=fa, fb=fb, kind=np.array([p.a.shape == "sphere" for p in pairs], np.int64),
             ca=ca, cb=cb, na=na, ra=col(lambda p: p.a.size), rb=col(lambda p: p.b.size),
             k=col(lambda p: p.k), c=col(lambda p: p.c), mu=col(lambda p: p.mu),
             slen=col(lambda p: p.slen), tau=col(lambda p: p.tau), vmin=col(lambda p: p.vmin),
             slot=np.array(s.inputs.contact_slots, np.int64),
             ctrl0=np.array([2 * len(s.inputs.pid_slots)], np.int64))
    ga, gb = lay.frame_groups(fa), lay.frame_groups(fb)
    for key, (p, q) in (("aa", (ga, ga)), ("ab", (ga, gb)), ("ba", (gb, ga)), ("bb", (gb, gb))):
        t["off_" + key] = lay.blocks(p, q).astype(np.int64)
    lay.velocity_blocks(np.stack([fa, fa, fb, fb], axis=1), np.stack([fa, fb, fa, fb], axis=1))
    return t


def examples(rng):
    """A sphere pressed into a tilted plane on a moving body (sticking, large friction) and
    into a fixed floor, and two spheres overlapping (sliding, small friction), with spin and
    offset centres."""
    from se3dyn.model.builder import ModelBuilder
    from se3dyn.model.contact import ContactMaterial

    mb = ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("p", position=(0.0, 0.0, -0.5), mass=3.0, inertia=(1, 1.2, 1.4),
            velocity=tuple(rng.normal(size=3)), angular_velocity=tuple(rng.normal(size=3)))
    mb.node("a", position=(0.2, 0.1, 0.3), mass=1.0, inertia=(0.1, 0.12, 0.14),
            velocity=tuple(rng.normal(size=3)), angular_velocity=tuple(rng.normal(size=3)))
    mb.node("b", position=(1.3, 0.2, 0.4), mass=2.0, inertia=(0.2, 0.2, 0.3))
    stick = ContactMaterial(stiffness=50.0, restitution=0.4, friction=20.0,
                            stiction_length=10.0, stiction_damping=0.05, min_impact_speed=0.5)
    slide = ContactMaterial(stiffness=30.0, restitution=0.7, friction=0.2, stiction_length=0.01,
                            min_impact_speed=0.3)
    mb.collision("plane", "p", "plane", at=(0.1, 0.0, -0.1), normal=(0.1, 0.2, 1.0),
                 material=stick)
    mb.collision("s1", "a", "sphere", size=2.0, at=(0.25, 0.1, 0.35), material=stick,
                 exclude=("s2",))
    mb.collision("s2", "b", "sphere", size=1.2, at=(1.35, 0.15, 0.4), material=slide,
                 exclude=("plane",))
    mb.collision("s3", "a", "sphere", size=1.0, at=(0.4, 0.2, 0.3), material=slide,
                 exclude=("plane",))
    # a floor on the fixed node (the kernel's path with one moving frame)
    mb.collision("floor", "g", "plane", at=(0.0, 0.0, 0.0), material=slide,
                 exclude=("s2", "s3"))
    return [mb.build()]
