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
    slots = {"tau": {}, "ref": {}, "rate": {}, "pid": {}}
    for slot, _k, kind, j in s.inputs.joint_slots:
        slots[kind][j] = slot
    first_pid, count = {}, 0  # joint -> its first PID coordinate among all (input order)
    for j in sorted(slots["pid"], key=slots["pid"].get):
        first_pid[j] = count
        count += int(s.joint_k[j])
    m, M = s.m, s.M
    jk = np.asarray(s.joint_k, np.int64)
    withk = np.flatnonzero(jk > 0)
    # every joint unknown: its joint and its index
    jd_joint = np.repeat(withk, jk[withk])
    jd_dof = np.repeat(np.asarray(s.joint_dofadr, np.int64)[withk], jk[withk]) + (
        np.arange(len(jd_joint)) - np.repeat(np.cumsum(jk[withk]) - jk[withk], jk[withk]))
    K, D = np.asarray(s.dof_stiffness)[jd_dof], np.asarray(s.dof_damping)[jd_dof]
    Ja = np.asarray(s.dof_armature)[jd_dof]
    used = np.zeros(m, bool)
    used[jd_joint[(K != 0) | (D != 0) | (Ja != 0)]] = True
    law_off = {s.joint_names.index(name): off for name, _, _, off in law_table(s)[0]}
    used[np.array(list(law_off), np.int64)] = True
    used[np.array(list(slots["tau"]) + list(slots["ref"]), np.int64)] = True
    used &= jk > 0
    ids = np.flatnonzero(used)
    n = len(ids)
    sel = used[jd_joint]  # the unknowns of the joints in ids, in order
    e_of = np.cumsum(used) - 1
    row, col = e_of[jd_joint[sel]], (np.arange(len(jd_joint)) - np.repeat(
        np.cumsum(jk[withk]) - jk[withk], jk[withk]))[sel]

    def pad(name):
        out = np.zeros((n, 6))
        out[row, col] = np.asarray(getattr(s, name), float)[jd_dof[sel]]
        return out

    A = np.ascontiguousarray(lay.frame_A[M + ids])
    Apinv = np.zeros((n, 6, 6))
    for k in sorted(set(jk[ids].tolist())):  # (np.unique would import numpy.ma: 20 ms)
        e = np.flatnonzero(jk[ids] == k)
        Apinv[e, :k, :] = np.linalg.pinv(A[e][:, :, :k])
    stiff = np.zeros(m, bool)
    stiff[jd_joint[K != 0]] = True
    nonab = ((~np.asarray(s.joint_abelian, bool)[ids]) & stiff[ids]).astype(np.int64)
    lay.velocity_blocks(M + ids, M + ids)
    lay.log_needed(M + ids[nonab > 0])
    fg = lay.frame_groups(M + ids)
    return dict(frame=(M + ids).astype(np.int64), K=pad("dof_stiffness"),
                ref=pad("dof_reference"), C=pad("dof_damping"), kp=pad("dof_kp"),
                kd=pad("dof_kd"), ki=pad("dof_ki"), lim=pad("dof_limit"),
                Ja=pad("dof_armature"), ts=pad("dof_ts"),
                lidx=np.array([law_off.get(j, -1) for j in ids.tolist()], np.int64),
                zslot=np.array([slots["pid"].get(j, -1) for j in ids.tolist()], np.int64),
                zidx=np.array([first_pid.get(j, -1) for j in ids.tolist()], np.int64),
                tau=np.array([slots["tau"].get(j, -1) for j in ids.tolist()], np.int64),
                pref=np.array([slots["ref"].get(j, -1) for j in ids.tolist()], np.int64),
                prate=np.array([slots["rate"].get(j, -1) for j in ids.tolist()], np.int64),
                nonab=nonab, Apinv=Apinv, A=A, off=lay.blocks(fg, fg).astype(np.int64),
                **_sensors(s, row, col, jd_dof[sel], n))


def _sensors(s, row: np.ndarray, col: np.ndarray, dofs: np.ndarray, n: int) -> dict:
    """The sensors of sampled PID laws (System.sensor_*) by element and coordinate: kind
    ``skind`` (n, 6), markers' node frames ``snode`` (n, 6, 2), their points ``spoint``
    (n, 6, 2, 3), the axis or the joint unknown ``sidx`` (n, 6)."""
    at = {int(d): i for i, d in enumerate(np.asarray(s.sensor_dof).tolist())}
    skind, sidx = np.zeros((n, 6), np.int64), np.zeros((n, 6), np.int64)
    snode, spoint = np.zeros((n, 6, 2), np.int64), np.zeros((n, 6, 2, 3))
    for r, c, d in zip(row.tolist(), col.tolist(), dofs.tolist(), strict=True):
        i = at.get(int(d))
        if i is None:
            continue
        skind[r, c], sidx[r, c] = s.sensor_kind[i], s.sensor_index[i]
        snode[r, c], spoint[r, c] = s.sensor_node[i], s.sensor_point[i]
    return dict(skind=skind, sidx=sidx, snode=snode, spoint=spoint)

def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _orthonormal_axes(rng):
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q.T


def examples(rng):
    """Spring, damper, actuator and PD law on abelian joints (hinge, cylindrical), PID laws
    (unsaturated, saturated) on a cylindrical joint; spring,
    damper and actuator on non-abelian ones (spherical, planar; they take no PD law), whose
    spring (Eq. (62) on the log coordinates) acts through T_A(alpha)^-T: anisotropic stiffness
    and a nonzero reference, so that the derivative of T_A^-T at fixed force is exercised (an
    isotropic spring without reference cannot tell it from K alpha: T(theta)^T theta = theta)."""
    from se3dyn.model.builder import ModelBuilder
    from se3dyn.model.specs import PD, PID
    from se3dyn.model.timefunc import Ramp, Sine

    out = []
    for typ in ("hinge", "cylindrical"):
        mb = ModelBuilder()
        mb.node("g", fixed=True)
        mb.node("b", position=(0.3, 0.1, 0.0), mass=1.5, inertia=(1, 1.2, 1.4))
        k = 1 if typ == "hinge" else 2
        mb.joint("j", typ, "g", "b", axis=_unit(rng),
                 stiffness=tuple(rng.uniform(1, 3, k)), reference=tuple(rng.normal(size=k)),
                 damping=tuple(rng.uniform(0.1, 1, k)),
                 actuator=Sine(tuple(rng.normal(size=k)), 1.3),
                 control=PD(kp=tuple(rng.uniform(1, 2, k)), kd=tuple(rng.uniform(0, 1, k)),
                               target=Ramp(tuple(rng.normal(size=k)), 0.1, 2.0)))
        out.append(mb.build())
    for limit in (1e3, 0.05):  # PID laws, unsaturated and saturated (the contract tests fill
        mb = ModelBuilder()   # the laws' state slots: z_n, e_n, h/2)
        mb.node("g", fixed=True)
        mb.node("b", position=(0.3, 0.1, 0.0), mass=1.5, inertia=(1, 1.2, 1.4))
        mb.joint("j", "cylindrical", "g", "b", axis=_unit(rng), damping=(0.3, 0.2),
                 armature=tuple(rng.uniform(0.1, 0.5, 2)),
                 control=PID(kp=tuple(rng.uniform(1, 2, 2)), ki=tuple(rng.uniform(1, 3, 2)),
                             kd=tuple(rng.uniform(0, 1, 2)),
                             target=Ramp(tuple(rng.normal(size=2)), 0.1, 2.0), limit=limit))
        out.append(mb.build())
    for typ in ("spherical", "planar"):
        mb = ModelBuilder()
        mb.node("g", fixed=True)
        mb.node("b", position=(0.3, 0.1, 0.0), mass=1.5, inertia=(1, 1.2, 1.4))
        kw = dict(axes=_orthonormal_axes(rng)) if typ == "spherical" else dict(normal=_unit(rng))
        mb.joint("j", typ, "g", "b", stiffness=tuple(rng.uniform(1, 3, 3)),
                 reference=tuple(rng.normal(size=3)), damping=tuple(rng.uniform(0.1, 1, 3)),
                 actuator=Sine(tuple(rng.normal(size=3)), 1.3), **kw)
        out.append(mb.build())
    return out


def law_table(s) -> tuple[list, int]:
    """Per law ``(joint name, unknowns (k,), Law, offset)`` in the engine's buffer (k + 2 k^2
    values each: the force, d/dq, d/dv) and the buffer's size."""
    out, off = [], 0
    for j, js in enumerate(s.model.joints):
        if getattr(js, "law", None) is None:
            continue
        k = int(s.joint_k[j])
        out.append((js.name, int(s.joint_dofadr[j]) + np.arange(k), js.law, off))
        off += k + 2 * k * k
    return out, off
