"""Force elements on the relative coordinates of a joint (Secs. 8-10): springs (Eq. (62)),
dampers (Eq. (64)), actuators (Eq. (66)) and PD control laws.

Kernel ``se3dyn/_core/elements/joint_force.hpp``; on non-abelian joints springs act on the log
coordinates ``A^+ log(H_J0^-1 H_J)``.
"""

from __future__ import annotations

import numpy as np

KEY = "joint_force"
TRAITS = dict(conservative=False, constraint=False, objective=True)


def tables(s, lay) -> dict:
    slots = {"tau": {}, "ref": {}, "rate": {}}
    for slot, _k, kind, j in s.inputs.joint_slots:
        slots[kind][j] = slot
    ids = []
    for j in range(s.m):
        k = int(s.joint_k[j])
        if not k:
            continue
        d = s.joint_dofadr[j] + np.arange(k)
        if (np.any(s.dof_stiffness[d] != 0) or np.any(s.dof_damping[d] != 0)
                or j in slots["tau"] or j in slots["ref"]):
            ids.append(j)
    n = len(ids)
    M = s.M

    def pad(name):
        arr = getattr(s, name)
        return np.array([np.pad(arr[s.joint_dofadr[j] + np.arange(s.joint_k[j])],
                                (0, 6 - s.joint_k[j])) for j in ids], float).reshape(n, 6)

    A = np.zeros((n, 6, 6))
    Apinv = np.zeros((n, 6, 6))
    nonab = np.zeros(n, np.int64)
    for e, j in enumerate(ids):
        k = int(s.joint_k[j])
        A[e] = lay.frame_A[M + j]
        Apinv[e, :k, :] = np.linalg.pinv(A[e][:, :k])
        d = s.joint_dofadr[j] + np.arange(k)
        nonab[e] = int((not s.joint_abelian[j]) and np.any(s.dof_stiffness[d] != 0))
        lay.velocity_block(M + j, M + j)
        if nonab[e]:
            lay.log_needed(M + j)
    return dict(frame=np.array([M + j for j in ids], np.int64), K=pad("dof_stiffness"),
                ref=pad("dof_reference"), C=pad("dof_damping"), kp=pad("dof_kp"),
                kd=pad("dof_kd"),
                tau=np.array([slots["tau"].get(j, -1) for j in ids], np.int64),
                pref=np.array([slots["ref"].get(j, -1) for j in ids], np.int64),
                prate=np.array([slots["rate"].get(j, -1) for j in ids], np.int64),
                nonab=nonab, Apinv=Apinv, A=A,
                off=np.array([lay.frame_block(M + j, M + j) for j in ids], np.int64))


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def examples(rng):
    """Spring, damper, actuator and PD law on abelian joints (hinge, cylindrical)."""
    import se3dyn as sd

    out = []
    for typ in ("hinge", "cylindrical"):
        mb = sd.ModelBuilder()
        mb.node("g", fixed=True)
        mb.node("b", position=(0.3, 0.1, 0.0), mass=1.5, inertia=(1, 1.2, 1.4))
        k = 1 if typ == "hinge" else 2
        mb.joint("j", typ, "g", "b", axis=_unit(rng),
                 stiffness=tuple(rng.uniform(1, 3, k)), reference=tuple(rng.normal(size=k)),
                 damping=tuple(rng.uniform(0.1, 1, k)),
                 actuator=sd.Sine(tuple(rng.normal(size=k)), 1.3),
                 control=sd.PD(kp=tuple(rng.uniform(1, 2, k)), kd=tuple(rng.uniform(0, 1, k)),
                               target=sd.Ramp(tuple(rng.normal(size=k)), 0.1, 2.0)))
        out.append(mb.build())
    return out
