"""PID control laws with an integral state, saturation and anti-windup (sd.PID, issue 30).

References are closed forms independent of se3dyn: a rotor of inertia J under
``tau = -kp e - ki z - kd e'`` (``e = theta - r``, ``z' = e``) is the linear system
``y' = A y``, ``y = (z, e, e')``, ``A = [[0, 1, 0], [0, 0, 1], [-ki/J, -kp/J, -kd/J]]``,
solved exactly by ``scipy.linalg.expm``; saturated at ``|tau| = L`` it turns at the constant
acceleration ``L / J``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.optimize as so

import se3dyn as sd
from se3dyn.errors import ModelError, Se3dynWarning
from se3dyn.io.modelfile import load_model, save_model

J, KP, KI, KD, R = 0.5, 20.0, 30.0, 4.0, 1.0
A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-KI / J, -KP / J, -KD / J]])


def _rotor(**law):
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("rotor", mass=1.0, inertia=(J, J, J))
    mb.joint("axle", "hinge", "g", "rotor", axis=(0, 0, 1),
             control=sd.PID(KP, KI, KD, target=R, **law))
    return mb.build()


def _run(model, t_end, h, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        return sd.simulate(model, t_end, h, **kw)


@pytest.mark.parametrize("formulation", ["index2", "index3"])
def test_rotor_under_pid_follows_the_third_order_closed_form_at_order_2(formulation):
    T = 2.0
    y = sla.expm(A * T) @ np.array([0.0, -R, 0.0])
    errs = []
    for h in (1e-2, 5e-3, 2.5e-3, 1.25e-3):
        res = _run(_rotor(), T, h, formulation=formulation)
        st = res.stats["final_state"]
        th, om = res.joint_coordinates("axle")[-1, 0], res.joint_velocities("axle")[-1, 0]
        # the state carries the integral and the error: (z, e) at T
        errs.append(max(abs(th - R - y[1]), abs(om - y[2]), abs(st.ctrl[0] - y[0]),
                        abs(st.ctrl[1] - (th - R))))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.9), (errs, orders)
    assert errs[-1] < 1e-6


def test_integral_action_removes_the_steady_error_of_a_constant_load():
    # a constant torque load: PD alone stops short by tau / kp, PID reaches the target
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("rotor", mass=1.0, inertia=(J, J, J))
    mb.joint("axle", "hinge", "g", "rotor", axis=(0, 0, 1), torque=-3.0,
             control=sd.PID(KP, KI, KD, target=R))
    res = _run(mb.build(), 12.0, 1e-2)
    assert abs(res.joint_coordinates("axle")[-1, 0] - R) < 1e-5
    z = res.stats["final_state"].ctrl[0]
    assert abs(-KI * z - 3.0) < 1e-4  # the integral carries the load
    # statics: the integral action's steady state holds the coordinate at the target
    st = sd.static_equilibrium(mb.build())
    np.testing.assert_allclose(st.joint_coordinates("axle"), [R], atol=1e-12)
    np.testing.assert_allclose(st.control_effort("axle"), [3.0], rtol=1e-10)


def test_saturated_start_accelerates_at_the_limit_and_the_integral_holds():
    L = 5.0
    # saturated while the unsaturated law asks for more than L (z held at 0: anti-windup)
    raw = lambda t: -KP * (L * t * t / (2 * J) - R) - KD * (L * t / J)  # noqa: E731
    ts = so.brentq(lambda t: raw(t) - L, 1e-6, 2.0)
    res = _run(_rotor(limit=L), 0.9 * ts, 1e-3)
    th = res.joint_coordinates("axle")[:, 0]
    np.testing.assert_allclose(th, L * res.t ** 2 / (2 * J), rtol=0, atol=1e-13)
    np.testing.assert_allclose(res.joint_torque("axle")[:, 0], L, rtol=1e-10)
    assert res.stats["final_state"].ctrl[0] == 0.0  # no windup
    # without anti-windup the integral would have reached int_0^t e dt (about -0.18 here)
    e = L * res.t ** 2 / (2 * J) - R
    assert abs(np.trapezoid(e, res.t)) > 0.1
    # after the switch the law is linear again: the closed form from the switch on
    T = 1.5
    y = sla.expm(A * (T - ts)) @ np.array([0.0, L * ts * ts / (2 * J) - R, L * ts / J])
    res = _run(_rotor(limit=L), T, 1e-3)
    # (the step over the switch integrates the error over all of it: O(h) once)
    assert abs(res.joint_coordinates("axle")[-1, 0] - R - y[1]) < 1e-4


def test_pid_laws_in_model_files_and_universal_joints():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("rotor", mass=1.0, inertia=(J, J, J))
    mb.joint("axle", "hinge", "g", "rotor", axis=(0, 0, 1),
             control=sd.PID(KP, KI, KD, target=sd.Ramp(1.0), limit=5.0))
    mb.node("b2", (1, 0, 0), mass=1.0, inertia=(0.5, 0.5, 0.5))
    mb.joint("u", "universal", "rotor", "b2", axes=[(1, 0, 0), (0, 1, 0)], at=(1, 0, 0),
             control=sd.PID([1, 2], [3, 4], [0.5, 0.6], target=[0.1, 0.2]))
    model = mb.build()
    text = save_model(model)
    assert "ki: [30.0]" in text and "limit: [5.0]" in text and "ki: [3.0, 4.0]" in text
    back, _ = load_model(text)
    a, b = _run(model, 0.3, 1e-2), _run(back, 0.3, 1e-2)
    for x in ("H", "v", "vd", "lam"):
        assert np.array_equal(getattr(a, x), getattr(b, x))
    assert np.array_equal(a.stats["final_state"].ctrl, b.stats["final_state"].ctrl)


def test_compiled_stepwise_and_resumed_runs_carry_the_integral_bit_for_bit():
    model = _rotor(limit=8.0)
    a = _run(model, 0.6, 1e-2)
    b = _run(model, 0.6, 1e-2, output_step=1e-2)
    assert np.array_equal(a.H, b.H) and np.array_equal(a.v, b.v)
    mid = _run(model, 0.3, 1e-2).stats["final_state"]
    c = _run(model, 0.6, 1e-2, initial_state=mid)
    assert np.array_equal(c.H[-1], a.H[-1]) and np.array_equal(c.v[-1], a.v[-1])
    assert np.array_equal(c.stats["final_state"].ctrl, a.stats["final_state"].ctrl)


@pytest.mark.parametrize("law, field", [
    (dict(kp=1.0, ki=-1.0), "ki"),
    (dict(kp=1.0, limit=0.0), "limit"),
    (dict(kp=1.0, limit=float("nan")), "limit"),
])
def test_bad_pid_laws_are_refused(law, field):
    with pytest.raises(ModelError, match=f"PID.*{field}"):
        sd.PID(**law)


def test_kinematics_says_it_leaves_the_integral_out():
    with pytest.warns(Se3dynWarning, match="integral part of the PID laws"):
        sd.kinematics(_rotor(), {"axle": lambda t: math.sin(t)}, [0.0, 0.1])


def test_armature_adds_inertia_to_the_joint_coordinate_only():
    # a rotor J with armature a under a constant torque: theta = tau t^2 / (2 (J + a)); the
    # kinetic energy counts the armature (work = 1/2 (J + a) w^2)
    a, tau = 0.3, 2.0
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("rotor", mass=1.0, inertia=(J, J, J))
    mb.joint("axle", "hinge", "g", "rotor", axis=(0, 0, 1), torque=tau, armature=a)
    res = _run(mb.build(), 1.0, 1e-2)
    np.testing.assert_allclose(res.joint_coordinates("axle")[:, 0],
                               tau * res.t ** 2 / (2 * (J + a)), rtol=0, atol=1e-12)
    w = res.joint_velocities("axle")[:, 0]
    np.testing.assert_allclose(res.kinetic, 0.5 * (J + a) * w ** 2, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(res.work_actuators, res.kinetic, rtol=1e-9, atol=1e-12)
    with pytest.raises(ModelError, match=r"joint 'b'.*armature.*abelian"):
        mb.joint("b", "spherical", "g", "rotor", armature=0.1)


# ---------------------------------------------------------------------------------------------
# sampled (digital) PID laws: zero-order hold
# ---------------------------------------------------------------------------------------------
TS = 0.02


def _sampled_rotor(limit=None):
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("rotor", mass=1.0, inertia=(J, J, J))
    mb.joint("axle", "hinge", "g", "rotor", axis=(0, 0, 1),
             control=sd.PID(KP, KI, KD, target=R, limit=limit, sample_time=TS))
    return mb.build()


def _discrete_closed_form(K, limit=math.inf):
    """The rotor under the held law, sample to sample: exact for a constant torque over each
    sample period (theta += Ts w + Ts^2 u / 2J, w += Ts u / J), the sampled law of PID's
    docstring."""
    th, om, integral = 0.0, 0.0, 0.0
    out = [th]
    for _ in range(K):
        e = th - R
        new = integral + TS * e
        u = -KP * e - KI * new - KD * om
        if abs(u) > limit:
            if -KI * TS * e * u > 0:
                new = integral
            u = max(-limit, min(limit, u))
        integral = new
        th, om = th + TS * om + TS * TS * u / (2 * J), om + TS * u / J
        out.append(th)
    return np.array(out)


@pytest.mark.parametrize("limit", [None, 3.0])
@pytest.mark.parametrize("formulation", ["index2", "index3"])
def test_sampled_pid_matches_its_discrete_time_closed_form(limit, formulation):
    ref = _discrete_closed_form(50, math.inf if limit is None else limit)
    for m in (1, 2, 5):
        res = _run(_sampled_rotor(limit), 1.0, TS / m, formulation=formulation)
        th = res.joint_coordinates("axle")[::m, 0]
        np.testing.assert_allclose(th, ref, rtol=0, atol=1e-12)
        # the torque is held between samples
        tau = res.joint_torque("axle")[:, 0]
        for k in range(3):
            np.testing.assert_allclose(tau[k * m + 1:(k + 1) * m], tau[k * m + 1], rtol=1e-12)


def test_sampled_pid_on_a_pendulum_converges_at_order_2_between_samples():
    def pend():
        mb = sd.ModelBuilder(gravity=(0, -9.81, 0))
        mb.node("g", fixed=True)
        mb.node("bar", (0.5, 0, 0), mass=2.0, inertia=(0.01, 0.1, 0.1))
        mb.joint("pin", "hinge", "g", "bar", axis=(0, 0, 1), at=(0, 0, 0),
                 control=sd.PID(30.0, 20.0, 3.0, target=0.5, limit=12.0, sample_time=TS))
        return mb.build()
    ref = _run(pend(), 1.0, TS / 64).joint_coordinates("pin")[::64, 0]
    errs = [np.abs(_run(pend(), 1.0, TS / m).joint_coordinates("pin")[::m, 0] - ref).max()
            for m in (2, 4, 8)]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.9), (errs, orders)
    res = _run(pend(), 1.0, TS / 4)
    assert res.stats["energy_balance_error"] < 1e-3 * res.stats["energy_scale"]


@pytest.mark.parametrize("kw, field", [
    (dict(step=0.003), "step"),
    (dict(step=0.01, tol=1e-6), "tol"),
    (dict(step=0.01, t_start=0.005), "t_start"),
])
def test_sampled_laws_need_steps_that_land_on_the_samples(kw, field):
    step = kw.pop("step")
    with pytest.raises(ModelError, match=f"field '{field}'.*sampled PID law"):
        sd.simulate(_sampled_rotor(), 0.1, step, **kw)


def test_sampled_law_in_a_model_file():
    text = save_model(_sampled_rotor(4.0))
    assert "sample_time: 0.02" in text
    back, _ = load_model(text)
    a, b = _run(_sampled_rotor(4.0), 0.2, 0.01), _run(back, 0.2, 0.01)
    assert np.array_equal(a.H, b.H)
    with pytest.raises(ModelError, match="sample_time"):
        sd.PID(1.0, sample_time=0.0)


def _controlled_arm():
    """Three links: a driven shoulder, a continuous PID elbow, a sampled PID wrist."""
    mb = sd.ModelBuilder(gravity=(0, -9.81, 0))
    mb.node("g", fixed=True)
    for i in range(3):
        mb.node(f"l{i}", (0.3 * i + 0.15, 0, 0), mass=1.0, inertia=(1e-3, 8e-3, 8e-3))
    mb.joint("shoulder", "hinge", "g", "l0", axis=(0, 0, 1), at=(0, 0, 0))
    mb.joint("elbow", "hinge", "l0", "l1", axis=(0, 0, 1), at=(0.3, 0, 0),
             control=sd.PID(40.0, 30.0, 2.0, target=0.4, limit=10.0), armature=0.01)
    mb.joint("wrist", "hinge", "l1", "l2", axis=(0, 0, 1), at=(0.6, 0, 0),
             control=sd.PID(20.0, 10.0, 1.0, target=-0.3, sample_time=0.004))
    mb.drive("motor", "shoulder", position=sd.Sine(0.5, 0.5))
    return mb.build()


def test_controlled_run_resumes_from_a_results_file_and_ignores_the_thread_count(tmp_path):
    from se3dyn.io.h5 import ResultsWriter, read_results

    s = sd.compile_model(_controlled_arm())
    full = _run(s, 1.0, 1e-3)
    path = tmp_path / "r.h5"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        with ResultsWriter(path, s, flush_interval=0.0) as w:
            sd.simulate(s, 0.6, 1e-3, on_rows=w.add_rows, store=False)
        w = ResultsWriter.resume(path, s)
        assert w.checkpoint.state.ctrl.size == 4
        with w:
            sd.simulate(s, 1.0, 1e-3, initial_state=w.checkpoint, on_rows=w.add_rows,
                        store=False)
    back = read_results(path)
    for f in ("H", "v", "vd", "lam", "alpha"):
        assert np.array_equal(getattr(back, f), getattr(full, f)), f
    try:
        for n in (1, 2):
            sd.set_threads(n)
            other = _run(sd.compile_model(_controlled_arm()), 1.0, 1e-3)
            for f in ("H", "v", "vd", "lam"):
                assert np.array_equal(getattr(other, f), getattr(full, f)), (n, f)
    finally:
        sd.set_threads()


def test_simulator_steps_drives_and_control_laws_as_simulate_does():
    model = _controlled_arm()
    full = _run(model, 0.5, 1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        sim = sd.Simulator(model, step=1e-3)
        sim.advance(0.2)
        mid = sim.state
        sim.advance(0.5)
        a = sim.results()
        other = sd.Simulator(model, step=1e-3)
        other.restore(mid)
        for _ in range(300):
            other.step()
        b = other.results()
    for f in ("H", "v", "vd", "lam"):
        assert np.array_equal(getattr(a, f), getattr(full, f)), f
        assert np.array_equal(getattr(b, f)[-1], getattr(full, f)[-1]), f
    assert np.array_equal(a.stats["final_state"].ctrl, full.stats["final_state"].ctrl)


def test_a_geared_motor_is_the_law_scaled_by_the_ratio_with_the_reflected_inertia():
    N, Jr, L = 5.0, 0.004, 2.0

    def rotor(**kw):
        mb = sd.ModelBuilder()
        mb.node("g", fixed=True)
        mb.node("rotor", mass=1.0, inertia=(J, J, J))
        mb.joint("axle", "hinge", "g", "rotor", axis=(0, 0, 1), **kw)
        return mb.build()

    geared = rotor(control=sd.PID(KP, KI, KD, target=R, limit=L, gear=N, rotor_inertia=Jr))
    same = rotor(control=sd.PID(N * KP, N * KI, N * KD, target=R, limit=N * L),
                 armature=N * N * Jr)
    a, b = _run(geared, 1.0, 1e-2), _run(same, 1.0, 1e-2)
    assert np.array_equal(a.H, b.H) and np.array_equal(a.v, b.v)
    assert np.abs(a.joint_torque("axle")).max() <= N * L * (1 + 1e-12)
    back, _ = load_model(save_model(geared))
    assert np.array_equal(_run(back, 1.0, 1e-2).H, a.H)
    with pytest.raises(ModelError, match="PID.*gear"):
        sd.PID(1.0, gear=0.0)


def test_a_pid_coordinate_is_not_driven_or_coupled_as_a_follower():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("a", mass=1.0, inertia=(J, J, J))
    mb.node("b", (1, 0, 0), mass=1.0, inertia=(J, J, J))
    mb.joint("ja", "hinge", "g", "a", axis=(0, 0, 1), control=sd.PID(KP, KI, KD))
    mb.joint("jb", "hinge", "g", "b", axis=(0, 0, 1), at=(1, 0, 0))
    with pytest.raises(ModelError, match=r"drive 'd'.*without a PID law"):
        mb.drive("d", "ja", velocity=1.0)
    with pytest.raises(ModelError, match=r"coupling 'c'.*without a PID law"):
        mb.coupling("c", leader="jb", follower="ja")
    mb.coupling("c", leader="ja", follower="jb")  # a PID leader drives both


def test_a_long_controlled_chain_gives_the_same_bits_on_one_and_two_threads():
    # 120 hinges (the joint-force kernel's elements in several chunks, evaluated in parts):
    # continuous and sampled PID laws (two reading sensors), a law of the user's, a drive and
    # a coupling
    def chain(n=120):
        mb = sd.ModelBuilder(gravity=(0, -9.81, 0))
        mb.node("g", fixed=True)
        prev = "g"
        for i in range(n):
            mb.node(f"b{i}", (0.1 * i + 0.05, 0, 0), mass=1.0, inertia=(1e-3, 1e-2, 1e-2))
            kw = {}
            if i % 3 == 0:
                kw["control"] = sd.PID(1.0, 0.5, 0.02, target=0.01, limit=3.0)
            elif i % 3 == 1:  # (two read sensors: the chain's end, another joint)
                sensor = {4: "marker/end/position/y", 7: "joint/j3/alpha/0"}.get(i)
                kw["control"] = sd.PID(1.0, 0.5, 0.02, target=0.0, sample_time=0.002,
                                       sensor=sensor)
            elif i == 2:
                kw["torque"] = lambda t, q, v: -2.0 * q - 0.1 * v
            mb.joint(f"j{i}", "hinge", prev, f"b{i}", axis=(0, 0, 1), at=(0.1 * i, 0, 0),
                     armature=1e-4, **kw)
            prev = f"b{i}"
        mb.marker("end", prev, offset=(0.05, 0, 0))
        mb.drive("d", "j5", velocity=0.3)
        mb.coupling("c", leader="j7", follower="j8", ratio=-0.5)
        return mb.build()

    runs = []
    try:
        for n in (1, 2, 2):
            sd.set_threads(n)
            r = _run(chain(), 0.05, 1e-3)
            runs.append((r.H, r.v, r.lam, r.stats["final_state"].ctrl))
    finally:
        sd.set_threads()
    for other in runs[1:]:
        for x, y in zip(runs[0], other, strict=True):
            assert np.array_equal(x, y)
