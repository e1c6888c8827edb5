"""The loads, actuators and control targets of a step: every time function of the model sampled
at one time (:func:`step_inputs`) or at many (:func:`input_table`, the compiled loop's table),
with an error naming the item and field when a user's function fails or returns a bad value.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.errors import SimulationError

if TYPE_CHECKING:
    from se3dyn.engine.system import System
    from se3dyn.model.specs import Model

sla = LazyModule("scipy.linalg")
sp = LazyModule("scipy.sparse")
spla = LazyModule("scipy.sparse.linalg")


#: numbers of a contact pair in State.ctrl (elements/contact.hpp): its state, bristle (3), slip
#: velocity (3), penetration, its rate, the impact speed; then its outputs, the normal force,
#: the force on shape b (3), the contact point (3) and the normal (3), inertial frame
CONTACT_STATE = 19


class _Inputs:
    """Slots of the time-dependent inputs ``u`` (nu,) handed to the element kernels.

    ``u[0:3]`` is gravity; then per load its force (3) and torque (3) components, per actuated
    joint its k actuator values, per controlled joint its k PD targets and k target rates, per
    driven coordinate its prescribed position (position drivers), rate and acceleration.
    ``kind`` (nu,) tells each slot's kind (0 gravity, 1 load, 2 actuator, 3 PD target, 4 PD
    target rate, 5 driven position, 6 driven rate, 7 driven acceleration, 8 PID state, 9 time,
    10 contact state), for load stepping in statics. ``names`` lists, per input a user may set
    (:class:`se3dyn.dynamics.simulator.Simulator`), ``(kind, item, field, slot, k)``: kind
    ``"gravity"``, ``"load"`` or ``"joint"``, the item's name, the field (``"force"``,
    ``"torque"``, ``"actuator"``, ``"target"``, ``"target_rate"``; None for gravity).
    """

    def __init__(self, d: dict, model: Model):
        nidx = {n: i for i, n in enumerate(d["node_names"])}
        # (slot, k, time function, item, what, the derivative that is the input: 0 the value,
        # 1 the rate, 2 the second derivative)
        self.sources = []
        self.names = [("gravity", None, None, 0, 3)]
        kind = [0, 0, 0]
        self.load_slots = []
        for ld in model.loads:
            fs = ts = -1
            if ld.force is not None:
                fs = len(kind)
                self.sources.append((fs, 3, ld.force, f"load '{ld.name}'", "force", 0))
                self.names.append(("load", ld.name, "force", fs, 3))
                kind += [1] * 3
            if ld.torque is not None:
                ts = len(kind)
                self.sources.append((ts, 3, ld.torque, f"load '{ld.name}'", "torque", 0))
                self.names.append(("load", ld.name, "torque", ts, 3))
                kind += [1] * 3
            i = nidx[ld.node]
            R0, x0 = d["node_H0"][i, :3, :3], d["node_H0"][i, :3, 3]
            c = np.zeros(3) if ld.at is None else R0.T @ (ld.at - x0)
            self.load_slots.append((i, c, fs, ts, int(ld.force_frame == "body"),
                                    int(ld.torque_frame == "body")))
        self.joint_slots = []  # (slot, k, kind, joint index)
        #: per PID-controlled coordinate, in order: the first of its 3 state slots (z_n, e_n,
        #: h/2; joint_force.hpp), which the time loop fills (zero in the tables)
        self.pid_slots: list[int] = []
        #: and its target's input slot and its unknown
        self.pid_ref: list[tuple[int, int]] = []
        for j, js in enumerate(model.joints):
            k = js.k
            if js.actuator is not None:
                item = f"joint '{js.name}' actuator"
                self.joint_slots.append((len(kind), k, "tau", j))
                self.names.append(("joint", js.name, "actuator", len(kind), k))
                self.sources.append((len(kind), k, js.actuator, item, "value", 0))
                kind += [2] * k
            if js.control is not None:
                item = f"joint '{js.name}' control target"
                tgt, rt = js.control.target, js.control.target_rate
                self.joint_slots.append((len(kind), k, "ref", j))
                self.names.append(("joint", js.name, "target", len(kind), k))
                self.sources.append((len(kind), k, tgt, item, "target", 0))
                kind += [3] * k
                self.joint_slots.append((len(kind), k, "rate", j))
                self.names.append(("joint", js.name, "target_rate", len(kind), k))
                if rt is None:
                    self.sources.append((len(kind), k, tgt, item, "target rate", 1))
                else:
                    self.sources.append((len(kind), k, rt, item, "target_rate", 0))
                kind += [4] * k
                if hasattr(js.control, "ki"):  # a PID law: its states, written by the loop
                    ref = self.joint_slots[-2][0]
                    self.joint_slots.append((len(kind), k, "pid", j))
                    self.pid_slots += [len(kind) + 3 * c for c in range(k)]
                    self.pid_ref += [(ref + c, int(d["joint_dofadr"][j]) + c) for c in range(k)]
                    kind += [8] * (3 * k)
        # per driven coordinate (System.drive_dof): the slots of its position (-1 for a
        # velocity driver), rate and acceleration, kinds 5, 6, 7
        self.drive_slots = []
        for dr in model.drives:
            for (_, i, what), f in zip(dr.targets, dr.functions, strict=True):
                item = f"drive '{dr.name}' coordinate {i}"
                order = 0 if what == "position" else -1  # derivative of f that is the position
                slots = [-1]
                if order == 0:
                    self.sources.append((len(kind), 1, f, item, "position", 0))
                    slots[0] = len(kind)
                    kind.append(5)
                for o, what_o, kd in ((order + 1, "velocity", 6), (order + 2, "acceleration", 7)):
                    self.sources.append((len(kind), 1, f, item, what_o, o))
                    slots.append(len(kind))
                    kind.append(kd)
                self.drive_slots.append(tuple(slots))
        # the time itself, for the user's laws f(t, q, v) (engine.hpp, Engine::law_t), kind 9
        self.time_slot = -1
        if any(getattr(js, "law", None) is not None for js in model.joints):
            self.time_slot = len(kind)
            self.sources.append((len(kind), 1, _Time(), "the model", "time", 0))
            kind.append(9)
        #: per contact pair (System.contacts): the first of its state slots (19 numbers and h/2,
        #: elements/contact.hpp), which the time loop fills (zero in the tables), kind 10
        self.contact_slots: list[int] = []
        for _ in d.get("contacts", ()):
            self.contact_slots.append(len(kind))
            kind += [10] * (CONTACT_STATE + 1)
        #: the states a step carries (State.ctrl): 2 per PID-controlled coordinate, then
        #: CONTACT_STATE per contact
        self.contact_ctrl = 2 * len(self.pid_slots)  # (where the contacts' states begin)
        self.nctrl = self.contact_ctrl + CONTACT_STATE * len(self.contact_slots)
        self.kind = np.array(kind, np.int64)
        self.nu = len(kind)
        self.gravity = np.asarray(model.gravity, float)


class _Time:
    """The time function ``t`` (the input slot of the time: the user's laws read it)."""

    def __call__(self, t):
        return float(t)

    def rate(self, t):
        return 1.0

    def accel(self, t):
        return 0.0

    def sample(self, times):
        return np.array(times, dtype=float)


#: the function of a time function that gives its value, rate or second derivative
_DERIV = (lambda tf: tf, lambda tf: tf.rate, lambda tf: tf.accel)


def _sample(f, t: float, shape: tuple[int, ...], item: str, what: str) -> np.ndarray:
    """Evaluate a time function, checking shape and finiteness, naming the item on failure."""
    try:
        val = np.asarray(f(t), dtype=float)
        val = np.broadcast_to(val, shape)
    except Exception as exc:  # user callables may raise anything
        raise SimulationError(f"t={t:.9g}: {item}: {what} could not be evaluated to "
                              f"{shape[0]} component(s): {type(exc).__name__}: {exc}") from None
    if not np.all(np.isfinite(val)):
        raise SimulationError(f"t={t:.9g}: {item}: {what} returned a non-finite value {val}")
    return val


def step_inputs(s: System, t: float) -> dict:
    """Time-dependent inputs at time t.

    Returns
    -------
    dict
        ``u`` (nu,): gravity, load forces and torques, actuator values, PD targets and target
        rates in the slots of :class:`se3dyn.engine.inputs._Inputs` (what the element kernels read).

    Raises
    ------
    SimulationError
        When a time function fails, changes size or returns a non-finite value (naming it).
    """
    ins = s.inputs
    u = np.zeros(ins.nu)
    u[:3] = ins.gravity
    for slot, k, tf, item, what, order in ins.sources:
        u[slot:slot + k] = _sample(_DERIV[order](tf), t, (k,), item, what)
    return dict(u=u)


def input_table(s: System, times: np.ndarray) -> tuple[np.ndarray, int]:
    """The inputs ``u`` of :func:`step_inputs` at many times, (nt, nu), one vectorised
    evaluation per time function (:meth:`se3dyn.model.timefunc.TimeFunction.sample`); where that is
    not possible, time by time. Returns the table and the number of leading rows filled: less
    than nt when a time function fails at ``times[n_ok]`` (the step to that time then
    reports the error, naming the function)."""
    ins = s.inputs
    nt = len(times)
    U = np.zeros((nt, ins.nu))
    U[:, :3] = ins.gravity
    slow = []
    for src in ins.sources:
        slot, k, tf, _item, _what, order = src
        fn = getattr(tf, ("sample", "sample_rate", "sample_accel")[order], None)
        try:
            val = np.asarray(fn(times), dtype=float).reshape(nt, -1)
            val = np.broadcast_to(val, (nt, k))
            ok = bool(np.all(np.isfinite(val)))
        except Exception:  # user code: anything; the per-time path names the failure
            ok = False
        if ok:
            U[:, slot:slot + k] = val
        else:
            slow.append(src)
    if not slow:
        return U, nt
    for row, t in enumerate(times):
        try:
            for slot, k, tf, item, what, order in slow:
                U[row, slot:slot + k] = _sample(_DERIV[order](tf), t, (k,), item, what)
        except SimulationError:
            return U, row
    return U, nt
