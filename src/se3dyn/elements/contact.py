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
        at_a = p.a.at - 0.5 * p.a.length * p.a.normal  # (a capsule: its segment's first end)
        ca[i], cb[i], na[i] = Ra.T @ (at_a - xa), Rb.T @ (p.b.at - xb), Ra.T @ p.a.normal
    col = lambda f: np.array([f(p) for p in pairs], float)  # noqa: E731
    kind = {"plane": 0, "sphere": 1, "capsule": 2}
    t = dict(fa=fa, fb=fb, kind=np.array([kind[p.a.shape] for p in pairs], np.int64),
             ca=ca, cb=cb, na=na, la=col(lambda p: p.a.length), ra=col(lambda p: p.a.size),
             rb=col(lambda p: p.b.size),
             k=col(lambda p: p.k), c=col(lambda p: p.c), mu=col(lambda p: p.mu),
             slen=col(lambda p: p.slen), tau=col(lambda p: p.tau), vmin=col(lambda p: p.vmin),
             slot=np.array(s.inputs.contact_slots, np.int64),
             ctrl0=np.array([s.inputs.contact_ctrl], np.int64))
    ga, gb = lay.frame_groups(fa), lay.frame_groups(fb)
    for key, (p, q) in (("aa", (ga, ga)), ("ab", (ga, gb)), ("ba", (gb, ga)), ("bb", (gb, gb))):
        t["off_" + key] = lay.blocks(p, q).astype(np.int64)
    lay.velocity_blocks(np.stack([fa, fa, fb, fb], axis=1), np.stack([fa, fb, fa, fb], axis=1))
    return t


def examples(rng):
    """A sphere pressed into a tilted plane on a moving body (sticking, large friction) and
    into a fixed floor, two spheres overlapping (sliding, small friction), with spin and
    offset centres, and a capsule touching three spheres (one at its segment's end)."""
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
    # a capsule touching s1 and s3 along its segment and s2 at its end (clamped)
    mb.node("c", position=(0.3, 1.2, 0.4), mass=1.5, inertia=(0.1, 0.3, 0.3),
            velocity=tuple(rng.normal(size=3)), angular_velocity=tuple(rng.normal(size=3)))
    mb.collision("cap", "c", "capsule", size=0.5, length=2.0, axis=(1.0, 0.1, 0.0),
                 at=(0.35, 1.2, 0.4), material=slide, exclude=("plane", "floor"))
    return [mb.build()]


def model_file(mf):
    """The ``collisions:`` section of model files (:class:`se3dyn.io.modelfile.ElementSection`);
    ``mf`` is :mod:`se3dyn.io.modelfile` (its field types)."""
    from se3dyn.model.contact import SHAPES, ContactMaterial

    F = mf.Field
    v3 = mf.Vec(3)
    fields = (
        F("node", mf.Str(ref="node"), None, "The node the shape moves with (required).", True),
        F("shape", mf.Str(choices=SHAPES), None, "`sphere`, `plane` (the half-space below "
          "it) or `capsule` (required).", True),
        F("size", mf.Num(exclusive_minimum=0), None, "Radius of a sphere or a capsule (m)."),
        F("at", v3, "position of node", "Centre of a sphere or a capsule, a point of a plane "
          "(inertial frame, initial configuration)."),
        F("normal", v3, [0, 0, 1], "Outward normal of a plane (inertial frame, initial "
          "configuration)."),
        F("length", mf.Num(exclusive_minimum=0), None, "Length of a capsule's segment (m)."),
        F("axis", v3, [0, 0, 1], "Direction of a capsule's segment (inertial frame, initial "
          "configuration)."),
        F("material", mf.Section("contact_material"), "ContactMaterial()", "The contact law "
          "of the shape (docs/contact.md)."),
        F("exclude", mf.StrList(), [], "Shapes or nodes this shape never touches."),
    )
    material = (
        F("stiffness", mf.Num(exclusive_minimum=0), None, "Hertz constant k of k delta^3/2 "
          "(N/m^1.5)."),
        F("young", mf.Num(exclusive_minimum=0), 1e9, "Young's modulus (Pa), when no "
          "`stiffness`."),
        F("poisson", mf.Num(minimum=0), 0.3, "Poisson's ratio."),
        F("restitution", mf.Num(minimum=0), 0.5, "Coefficient of restitution in [0.01, 1] "
          "(exact for any stiffness and impact speed)."),
        F("friction", mf.Num(minimum=0), 0.5, "Coulomb coefficient."),
        F("stiction_length", mf.Num(exclusive_minimum=0), 1e-5, "Elastic slip of the "
          "bristle at the onset of sliding (m)."),
        F("stiction_damping", mf.Num(minimum=0), "2 sqrt(stiction_length / (friction g0))",
          "Damping time of the bristle (s)."),
        F("min_impact_speed", mf.Num(exclusive_minimum=0), 1e-3, "Floor of the impact "
          "speed of the damping law (m/s)."),
    )

    def add(mb, name, kw):
        if "material" in kw:
            kw["material"] = dict(kw["material"].values)
        mb.collision(name, kw.pop("node"), kw.pop("shape"), **kw)

    def save(model) -> dict:
        out = {}
        ref = ContactMaterial()
        for c in model.collisions:
            e = {"node": c.node, "shape": c.shape}
            if c.shape != "plane":
                e["size"] = float(c.size)
            e["at"] = mf.plain(c.at)
            if c.shape == "plane":
                e["normal"] = mf.plain(c.normal)
            if c.shape == "capsule":
                e["length"], e["axis"] = float(c.length), mf.plain(c.normal)
            mat = {k: v for k, v in c.material.as_dict().items()
                   if v is not None and v != getattr(ref, k)}
            if c.material.stiffness is not None:
                mat.pop("young", None)
            if mat:
                e["material"] = mat
            if c.exclude:
                e["exclude"] = list(c.exclude)
            out[c.name] = e
        return out

    return mf.ElementSection(
        key="collisions", kind="collision", doc="Collision shapes on nodes, by name "
        "(compliant contact, docs/contact.md): every sphere touches every plane and sphere "
        "of another node unless excluded.",
        entry_doc="An entry of `collisions:` (key: the shape name).", fields=fields, add=add,
        save=save, subsections=(("contact_material", "The `material:` mapping of a shape "
                                 "(se3dyn.ContactMaterial).", material),))
