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
    import se3dyn as sd

    mb = sd.ModelBuilder()
    mb.node("b", position=(0.2, 0.0, 0.1), mass=1.0, inertia=(1, 1.2, 1.4))
    for i, (ff, tf, at) in enumerate((("inertial", "body", None),
                                      ("body", "inertial", tuple(rng.normal(size=3))),
                                      ("inertial", "inertial", tuple(rng.normal(size=3))))):
        mb.load(f"l{i}", "b", force=sd.Sine(tuple(rng.normal(size=3)), 0.7),
                torque=tuple(rng.normal(size=3)), at=at, force_frame=ff, torque_frame=tf)
    return [mb.build()]
