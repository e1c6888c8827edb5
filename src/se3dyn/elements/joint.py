"""Kinematic joint or rigid constraint between two node frames through the joint frame, on a
subgroup spanned by a constant A (Eqs. (7)-(11), (54)-(59)), optionally between frames attached
to the nodes at a point (``at``).

Kernel ``se3dyn/_core/elements/joint.hpp``: six constraints ``Phi = vect((H_B X_B)^-1 H_A X_A
H_J)`` (Eq. (55)), the forces ``B^T lambda`` of the gradient at ``Phi = 0`` (Eq. (58)), the exact
linearisation of Phi (Eq. (59) at ``Phi = 0``), the geometric stiffness of the node-A force, and
for the stabilised index-2 form the velocity constraints ``B v`` with their derivative.
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie

KEY = "joint"
TRAITS = dict(conservative=True, constraint=True, objective=True)


def tables(s, lay) -> dict:
    M, m = s.M, s.m
    ja, jb = s.joint_a.astype(np.int64), s.joint_b.astype(np.int64)
    jf = M + np.arange(m, dtype=np.int64)
    c = lay.mult_groups(np.arange(m))
    fa, fb, fj = lay.frame_groups(ja), lay.frame_groups(jb), lay.frame_groups(jf)
    # per joint, in this order: ca, cb, cj, ac, bc, jc, aj and the diagonal (identity for
    # dropped, redundant, equations)
    off = lay.blocks(np.stack([c, c, c, fa, fb, fj, fa, c], axis=1),
                     np.stack([fa, fb, fj, c, c, c, fj, c], axis=1))
    lay.constraints(np.arange(m), np.stack([ja, jb, jf], axis=1))
    XA = np.ascontiguousarray(s.joint_XA, float).reshape(m, 4, 4)
    XB = np.ascontiguousarray(s.joint_XB, float).reshape(m, 4, 4)
    eye = np.eye(4)
    t = dict(fa=ja, fb=jb, fj=jf, mult=s.joint_multadr.astype(np.int64), XA=XA, XB=XB,
             PA=lie.adjoint_inv(XA) if m else np.zeros((0, 6, 6)),
             PB=lie.adjoint_inv(XB) if m else np.zeros((0, 6, 6)),
             offset=(~(np.isclose(XA, eye).all(axis=(1, 2))
                       & np.isclose(XB, eye).all(axis=(1, 2)))).astype(np.int64))
    for i, key in enumerate(("ca", "cb", "cj", "ac", "bc", "jc", "aj")):
        t["off_" + key] = np.ascontiguousarray(off[:, i], np.int64)
    return t


def index2_tables(s, lay, t: dict) -> None:
    """Blocks that only the stabilized index-2 matrix has: velocity-constraint rows."""
    for key, fr in (("xa", t["fa"]), ("xb", t["fb"]), ("xj", t["fj"])):
        t["off_" + key] = lay.blocks(lay.xi_groups(np.arange(len(fr))),
                                     lay.frame_groups(fr)).astype(np.int64)

def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def examples(rng):
    """Every joint type, with and without an attachment point, between two moving bodies."""
    from se3dyn.model.builder import ModelBuilder

    out = []
    for typ, kw in (("rigid", {}), ("hinge", dict(axis=_unit(rng))),
                    ("prismatic", dict(axis=_unit(rng))),
                    ("cylindrical", dict(axis=_unit(rng))), ("spherical", {}),
                    ("planar", dict(normal=_unit(rng))),
                    ("screw", dict(axis=_unit(rng), pitch=0.1))):
        for at in (None, tuple(_unit(rng))):
            mb = ModelBuilder()
            mb.node("a", position=tuple(_unit(rng)), mass=1.0, inertia=(1, 1.2, 1.4))
            mb.node("b", position=tuple(_unit(rng)), mass=2.0, inertia=(1, 1.1, 1.3),
                    orientation=lie.exp_so3(_unit(rng)))
            mb.joint("j", typ, "a", "b", at=at, **kw)
            out.append(mb.build())
    return out


# ---------------------------------------------------------------------------------------------
# model file: the `joints:` section (with its `control:` mapping), see se3dyn.io.modelfile
def model_file(mf):
    """The ``joints:`` section of model files (:class:`se3dyn.io.modelfile.ElementSection`).

    ``mf`` is :mod:`se3dyn.io.modelfile` (its field types), passed by it: the element library
    never imports the YAML layer.
    """
    from se3dyn.model.joint_types import JOINT_SYNONYMS, JOINT_TYPES

    keys = tuple(sorted([*JOINT_TYPES, "universal"])) + tuple(JOINT_SYNONYMS)
    v3 = mf.Vec(3)
    kvec = mf.OneOf((mf.Num(), mf.Vec(None, 1, 6)))
    kvec_nn = mf.OneOf((mf.Num(minimum=0), mf.Vec(None, 1, 6)))
    act_doc = ("Actuator force/torque tau(t) on the relative coordinates (Eq. 66), k components "
               "(a number applies to all). `actuator`, `torque` and `force` are aliases; give "
               "at most one.")
    F = mf.Field
    fields = (
        F("type", mf.Str(keys), None, "Joint type, see [joint types](#joint-types) (the "
          "names of other tools are accepted too: " + ", ".join(
              f"{k} = {v}" for k, v in JOINT_SYNONYMS.items()) + ").", True),
        F("a", mf.Str(ref="node"), None, "Node A (H_B = H_A H_J, Eq. 7).", True),
        F("b", mf.Str(ref="node"), None, "Node B.", True),
        F("axis", v3, None, "Unit axis in the inertial frame of the initial configuration "
          "(hinge, prismatic, cylindrical, screw)."),
        F("axes", mf.Mat(2, 3, 3), None, "Spherical: 3 orthonormal rotation axes (identity "
          "by default); planar: 2 in-plane axes; universal: the 2 hinge axes."),
        F("normal", v3, None, "Planar joint: plane normal."),
        F("pitch", mf.Num(), None, "Screw joint: translation per radian (m/rad)."),
        F("A", mf.Mat(6, 6, None, flat=True), None, "General joint: 6 x k subalgebra basis, "
          "columns (e_U, e_Omega)."),
        F("stiffness", kvec_nn, 0, "Spring K on the relative coordinates (Eq. 62)."),
        F("reference", kvec, 0, "Spring reference alpha0 (absolute when `initial` is given)."),
        F("initial", kvec, None, "Abelian joints: the values of the relative coordinates in "
          "the initial configuration (e.g. a hinge that starts at an absolute angle): "
          "coordinates, `reference` and PD targets are then absolute; absent: they count from "
          "the initial configuration."),
        F("damping", kvec_nn, 0, "Damper C on the relative velocities (Eq. 64)."),
        F("armature", kvec_nn, 0, "Abelian joints: inertia on the relative coordinates (the "
          "reflected rotor inertia N^2 J_rotor of a geared motor; kg m^2 or kg)."),
        F("actuator", mf.TimeFunc(), None, act_doc),
        F("torque", mf.TimeFunc(), None, "Alias of `actuator`."),
        F("force", mf.TimeFunc(), None, "Alias of `actuator`."),
        F("control", mf.Section("control"), None, "PD or PID control law (abelian joints "
          "only)."),
        F("at", v3, None, "Attachment point in the inertial frame of the initial "
          "configuration (m): the joint connects frames fixed to `a` and `b` at this point "
          "(inertial orientation at t0), H_B X_B = H_A X_A H_J with X = H0^-1 H(I, at), "
          "instead of the node frames, so a body needs one node whatever its joints; "
          "absent: between the node frames (Eq. 7)."),
    )
    control = (
        F("kp", kvec_nn, None, "Proportional gain(s) (required).", True),
        F("ki", kvec_nn, 0, "Integral gain(s) (1/s): a PID law when given, tau = -kp e - ki "
          "int e dt - kd e_dot, the integral a state of the run (trapezoidal rule in the "
          "step's Newton iterations)."),
        F("kd", kvec_nn, 0, "Derivative gain(s)."),
        F("limit", mf.OneOf((mf.Num(exclusive_minimum=0), mf.Vec(None, 1, 6))), None,
          "Largest magnitude of the law's force/torque (a PID law; anti-windup: the integral "
          "holds while saturated). Absent: no saturation."),
        F("gear", mf.Num(), 1, "A PID law driving a motor behind a gear of this ratio: the "
          "law's output and limit are the motor's torque, the joint gets gear times it."),
        F("rotor_inertia", mf.Num(minimum=0), 0, "The motor's rotor inertia (a PID law): the "
          "joint carries gear^2 times it."),
        F("sample_time", mf.Num(exclusive_minimum=0), None, "A sampled PID law: evaluated "
          "at the times k sample_time only and held between them (zero-order hold), the "
          "integral summed; the step must divide it. Absent: the continuous law."),
        F("sensor", mf.StrList(), None, "A sampled PID law reading a sensor instead of the "
          "joint's coordinates (one channel name per coordinate): marker/<m>/position/x|y|z, "
          "marker/<a>/distance/<b> or joint/<j>/alpha/<i>; e = sensor - target."),
        F("target", mf.TimeFunc(), 0, "Target relative coordinates alpha_ref(t)."),
        F("target_rate", mf.TimeFunc(), "d target/dt", "Target rates (the derivative of "
          "`target` when absent)."),
    )

    def add(mb, name, kw):
        from se3dyn.model.specs import PD, PID

        if "control" in kw:
            law = dict(kw["control"].values)
            pid = any(f in law for f in ("ki", "limit", "sample_time", "gear",
                                         "rotor_inertia", "sensor"))
            kw["control"] = PID(**law) if pid else PD(**law)
        mb.joint(name, kw.pop("type"), kw.pop("a"), kw.pop("b"), **kw)

    return mf.ElementSection(
        key="joints", kind="joint", doc="Kinematic joints by name, in order.",
        entry_doc="An entry of `joints:` (key: the joint name). A kinematic joint H_B = H_A H_J "
                  "between nodes `a` and `b` (or between frames attached to them at the point "
                  "`at`), with its force elements. Vector force elements have "
                  "k components (k = number of relative coordinates of the type); a number "
                  "applies to all of them.",
        fields=fields, add=add, save=lambda model: _save(mf, model),
        subsections=(("control", "The `control:` mapping of a joint: tau = -kp (alpha - "
                                 "target(t)) - kd (alpha_dot - target_rate(t)).", control),))


def _act_key(type_: str) -> str:
    return {"hinge": "torque", "spherical": "torque", "universal": "torque",
            "prismatic": "force"}.get(type_, "actuator")


def _joint_out(mf, j) -> dict:
    item = f"joint {j.name!r}"
    py, tf_out = mf.plain, mf.time_function_data
    d = {"type": j.type, "a": j.node_a, "b": j.node_b}
    if j.at is not None:
        d["at"] = py(j.at)
    for key, val in j.params.items():
        if val is not None:
            d[key] = py(val) if key != "pitch" else float(val)
    for key, arr in (("stiffness", j.stiffness), ("reference", j.reference),
                     ("damping", j.damping)):
        if np.any(arr != 0):
            d[key] = py(arr)
    if j.initial is not None:
        d["initial"] = py(j.initial)
    if j.armature is not None:
        d["armature"] = py(j.armature)
    if j.actuator is not None:
        k = _act_key(j.type)
        d[k] = tf_out(j.actuator, item, k)
    if getattr(j, "law", None) is not None:
        from se3dyn.errors import ModelError

        raise ModelError(item, _act_key(j.type), "a built-in time function to write a model "
                         "file", "a law f(t, q, v) in Python", "a Python function cannot be "
                         "saved; keep such a model in Python")
    if j.control is not None:
        c = j.control
        d["control"] = {"kp": py(c.kp), "kd": py(c.kd),
                        "target": tf_out(c.target, item, "control.target")}
        d["control"].update(_pid_out(c, item))
        if c.target_rate is not None:
            d["control"]["target_rate"] = tf_out(c.target_rate, item, "control.target_rate")
    return d


def _universal_out(mf, name: str, parts: tuple[str, ...], model) -> dict:
    from se3dyn.model.timefunc import Component

    item = f"joint {name!r}"
    py, tf_out = mf.plain, mf.time_function_data
    j1, j2 = (model.joint(p) for p in parts)
    d = {"type": "universal", "a": j1.node_a, "b": j2.node_b}
    if j1.at is not None:
        d["at"] = py(j1.at)
    d["axes"] = [py(j1.params["axis"]), py(j2.params["axis"])]
    for key in ("stiffness", "reference", "damping"):
        a1, a2 = getattr(j1, key), getattr(j2, key)
        if a1[0] != 0 or a2[0] != 0:
            d[key] = [float(a1[0]), float(a2[0])]
    if j1.initial is not None:
        d["initial"] = [float(j1.initial[0]), float(j2.initial[0])]
    if j1.armature is not None:
        d["armature"] = [float(j1.armature[0]), float(j2.armature[0])]

    def source(f, fld):
        # the k-vector function a universal joint's per-hinge component was cut from
        src = f.base if isinstance(f, Component) else None
        if src is None:
            tf_out(f, item, fld)  # raises for callables
        return tf_out(src, item, fld)

    if j1.actuator is not None:
        d["torque"] = source(j1.actuator, "torque")
    if j1.control is not None:
        c1, c2 = j1.control, j2.control
        d["control"] = {"kp": [float(c1.kp[0]), float(c2.kp[0])],
                        "kd": [float(c1.kd[0]), float(c2.kd[0])],
                        "target": source(c1.target, "control.target")}
        if hasattr(c1, "ki"):
            from se3dyn.model.specs import PID

            d["control"].update(_pid_out(PID(np.r_[c1.kp, c2.kp], np.r_[c1.ki, c2.ki],
                                             np.r_[c1.kd, c2.kd], 0.0, None,
                                             np.r_[c1.limit, c2.limit], c1.sample_time,
                                             c1.gear, c1.rotor_inertia,
                                             None if c1.sensor is None
                                             else [*c1.sensor, *c2.sensor]), item))
        if c1.target_rate is not None:
            d["control"]["target_rate"] = source(c1.target_rate, "control.target_rate")
    return d


def _pid_out(c, item: str) -> dict:
    """The PID fields of a normalised control law (none for a PD law)."""
    if not hasattr(c, "ki"):
        return {}
    out = {"ki": [float(x) for x in c.ki]}
    if c.sample_time is not None:
        out["sample_time"] = float(c.sample_time)
    if c.sensor is not None:
        out["sensor"] = list(c.sensor)
    if c.gear != 1.0:
        out["gear"] = float(c.gear)
    if c.rotor_inertia:
        out["rotor_inertia"] = float(c.rotor_inertia)
    lim = np.asarray(c.limit, dtype=float)
    if np.all(np.isfinite(lim)):
        out["limit"] = [float(x) for x in lim]
    elif np.any(np.isfinite(lim)):
        from se3dyn.errors import ModelError

        raise ModelError(item, "control.limit", "limits on all coordinates or none, to write a "
                         "model file", lim)
    return out


def _save(mf, model) -> dict:
    """name -> entry of the ``joints:`` section (a universal joint once, by its name)."""
    joints: dict = {}
    for j in model.joints:
        if j.composite is not None:
            if j.composite not in joints:
                joints[j.composite] = _universal_out(mf, j.composite,
                                                     model.composites[j.composite], model)
        else:
            joints[j.name] = _joint_out(mf, j)
    return joints
