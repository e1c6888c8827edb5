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
    from se3dyn.model.builder import ModelBuilder

    mb = ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("a", position=(0.5, 0.0, 0.0), mass=1.0, inertia=(1, 1.2, 1.4),
            velocity=tuple(rng.normal(size=3)), angular_velocity=tuple(rng.normal(size=3)))
    mb.node("b", position=(1.0, 0.3, 0.2), mass=2.0, inertia=(1, 1.1, 1.3))
    mb.spring_damper("s1", "a", "b", at_a=tuple(rng.normal(size=3)),
                     at_b=tuple(rng.normal(size=3)), stiffness=3.0, damping=0.4, length=0.7)
    mb.spring_damper("s2", "g", "a", at_b=(0.6, 0.1, 0.0), stiffness=2.0, damping=0.0)
    return [mb.build()]


def model_file(mf):
    """The ``springs:`` section of model files (:class:`se3dyn.io.modelfile.ElementSection`);
    ``mf`` is :mod:`se3dyn.io.modelfile` (its field types)."""
    F = mf.Field
    v3 = mf.Vec(3)
    fields = (
        F("a", mf.Str(ref="node"), None, "Node A (required).", True),
        F("b", mf.Str(ref="node"), None, "Node B (required).", True),
        F("at_a", v3, "position of a", "Point attached to A, in the inertial frame of the "
          "initial configuration (m)."),
        F("at_b", v3, "position of b", "Point attached to B (m)."),
        F("stiffness", mf.Num(minimum=0), None, "Stiffness (N/m) (required).", True),
        F("damping", mf.Num(minimum=0), 0, "Damping (N s/m) on the rate of the distance."),
        F("length", mf.Num(minimum=0), "initial distance", "Free length (m)."),
    )

    def save(model) -> dict:
        return {sp.name: {"a": sp.node_a, "b": sp.node_b, "at_a": mf.plain(sp.at_a),
                          "at_b": mf.plain(sp.at_b), "stiffness": float(sp.stiffness),
                          "damping": float(sp.damping), "length": float(sp.length)}
                for sp in model.springs}

    return mf.ElementSection(
        key="springs", kind="spring_damper", doc="Point-to-point spring-dampers by name.",
        entry_doc="An entry of `springs:` (key: the name). Force stiffness (L - length) + "
                  "damping dL/dt along the line of two points attached to nodes `a` and `b`.",
        fields=fields,
        add=lambda mb, name, kw: mb.spring_damper(name, kw.pop("a"), kw.pop("b"), **kw),
        save=save)
