"""Load at a point of a body: a force and a torque, each in the inertial or the body frame
(Sec. 10, Eqs. (66)-(67) for a force at the node).

Kernel ``se3dyn/_core/elements/load.hpp``.
"""

from __future__ import annotations

import numpy as np

KEY = "load"
TRAITS = dict(conservative=False, constraint=False, objective=False)


def tables(s, lay) -> dict:
    ld = s.inputs.load_slots  # (node, c, force slot, torque slot, force_body, torque_body)
    return dict(frame=np.array([x[0] for x in ld], np.int64),
                c=np.array([x[1] for x in ld], float).reshape(len(ld), 3),
                force=np.array([x[2] for x in ld], np.int64),
                torque=np.array([x[3] for x in ld], np.int64),
                force_body=np.array([x[4] for x in ld], np.int64),
                torque_body=np.array([x[5] for x in ld], np.int64),
                off=np.array([lay.frame_block(x[0], x[0]) for x in ld], np.int64))


def examples(rng):
    """Forces and torques in both frames, at the node and at a point of the body."""
    from se3dyn.model.builder import ModelBuilder
    from se3dyn.model.timefunc import Sine

    mb = ModelBuilder()
    mb.node("b", position=(0.2, 0.0, 0.1), mass=1.0, inertia=(1, 1.2, 1.4))
    for i, (ff, tf, at) in enumerate((("inertial", "body", None),
                                      ("body", "inertial", tuple(rng.normal(size=3))),
                                      ("inertial", "inertial", tuple(rng.normal(size=3))))):
        mb.load(f"l{i}", "b", force=Sine(tuple(rng.normal(size=3)), 0.7),
                torque=tuple(rng.normal(size=3)), at=at, force_frame=ff, torque_frame=tf)
    return [mb.build()]


def model_file(mf):
    """The ``loads:`` section of model files (:class:`se3dyn.io.modelfile.ElementSection`);
    ``mf`` is :mod:`se3dyn.io.modelfile` (its field types)."""
    F = mf.Field
    frames = mf.Str(("inertial", "body"))
    fields = (
        F("node", mf.Str(ref="node"), None, "Loaded node (a free node; required).", True),
        F("force", mf.TimeFunc(), None, "Force (3 components), in the frame `force_frame`."),
        F("torque", mf.TimeFunc(), None, "Torque (3 components), in the frame "
          "`torque_frame`."),
        F("at", mf.Vec(3), None, "Point of application of the force in the inertial frame of "
          "the initial configuration (m); it moves with the body. Absent: the node."),
        F("force_frame", frames, "inertial", "`inertial`: the force keeps its direction in "
          "space; `body`: it turns with the body (follower load)."),
        F("torque_frame", frames, "body", "Frame of the torque (`body`: the material frame of "
          "the node, as in Eq. 66)."),
    )

    def save(model) -> dict:
        out = {}
        for ld in model.loads:
            item = f"load {ld.name!r}"
            d: dict = {"node": ld.node}
            if ld.force is not None:
                d["force"] = mf.time_function_data(ld.force, item, "force")
            if ld.torque is not None:
                d["torque"] = mf.time_function_data(ld.torque, item, "torque")
            if ld.at is not None:
                d["at"] = mf.plain(ld.at)
            if ld.force_frame != "inertial":
                d["force_frame"] = ld.force_frame
            if ld.torque_frame != "body":
                d["torque_frame"] = ld.torque_frame
            out[ld.name] = d
        return out

    return mf.ElementSection(
        key="loads", kind="load", doc="External loads by name.",
        entry_doc="An entry of `loads:` (key: the load name).", fields=fields,
        add=lambda mb, name, kw: mb.load(name, kw.pop("node"), **kw), save=save)
