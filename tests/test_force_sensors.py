"""Force sensors (issue 30, item 4): actuator efforts and spring forces of joints, and the axial
force, length and rate of point spring-dampers, as Results accessors and channels.

Every test asserts physics (static equilibrium, Newton's law with the stored accelerations, the
work of the actuators, lengths measured from positions), never numbers printed by se3dyn itself.
"""

from __future__ import annotations

import numpy as np
import pytest

import se3dyn as sd
from _results_file import run_and_read
from se3dyn import lie
from se3dyn.errors import ModelError, UnknownNameError
from se3dyn.model.specs import PD, PID
from se3dyn.results.channels import channel_unit, get_channel, list_channels

GZ = 9.81
M, L = 2.0, 0.8


def _trapezoid(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(0.5 * np.diff(t) * (p[1:] + p[:-1]))])


# -------------------------------------------------------------------------------------------------
# joint actuators and PD laws
# -------------------------------------------------------------------------------------------------
def _rod(theta: float, **joint) -> sd.Model:
    """A uniform rod of mass M and length L on a hinge at one end, at the angle theta above
    the horizontal, the hinge axis -y (a positive torque lifts it)."""
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    c = 0.5 * L * np.array([np.cos(theta), 0.0, np.sin(theta)])
    mb.node("rod", (0, 0, 0), mass=M, inertia=(1e-3, M * L**2 / 12, M * L**2 / 12),
            principal_axes=lie.exp_so3(np.array([0.0, -theta, 0.0])), com=c)
    mb.joint("hinge", "hinge", "ground", "rod", axis=(0, -1, 0), **joint)
    return mb.build()


@pytest.mark.parametrize("hold", ["pd", "actuator+pd", "spring+pd"])
def test_actuator_effort_in_a_static_hold(hold):
    # held at rest at theta: the joint must supply the gravity moment m g (L/2) cos(theta)
    theta = 0.6
    tau = M * GZ * 0.5 * L * np.cos(theta)
    kp, kd, K = 80.0, 4.0, 50.0
    kw = {"pd": dict(control=PD(kp=kp, kd=kd, target=tau / kp)),
          "actuator+pd": dict(actuator=0.3 * tau, control=PD(kp=kp, kd=kd, target=0.7 * tau / kp)),
          # the spring (reference below the rod) takes 40 %, the PD law the rest
          "spring+pd": dict(stiffness=K, reference=0.4 * tau / K, damping=1.0,
                            control=PD(kp=kp, kd=kd, target=0.6 * tau / kp))}[hold]
    r = sd.simulate(_rod(theta, **kw), t_end=0.3, step=1e-2, tol_residual=1e-13)
    assert np.abs(r.joint_coordinates("hinge")).max() <= 1e-12  # held: at rest
    act, spr, T = r.actuator_effort("hinge"), r.spring_force("hinge"), r.joint_torque("hinge")
    assert act.shape == spr.shape == (len(r), 1)
    share = {"pd": 1.0, "actuator+pd": 1.0, "spring+pd": 0.6}[hold]
    np.testing.assert_allclose(act, share * tau, rtol=1e-12)
    # the spring stretched below its reference pushes up: its force (tension positive) is -0.4 tau
    np.testing.assert_allclose(spr, -(1.0 - share) * tau, rtol=1e-12, atol=1e-12 * tau)
    # the torque sensor in the joint reads what holds the rod: actuators minus spring
    np.testing.assert_allclose(T, tau, rtol=1e-12)
    np.testing.assert_allclose(act - spr, T, rtol=0, atol=1e-12 * tau)


def test_actuator_work_is_the_integral_of_effort_times_rate():
    # a double pendulum (hinge, then a prismatic joint along the arm) under time-varying
    # actuators and PD laws with moving targets, springs and dampers: the work of the actuators
    # that the run accumulates (trapezoid over the steps) is the integral of effort * rate
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("arm", (0.5, 0, 0), mass=1.0, inertia=(0.01, 0.1, 0.1))
    mb.node("slider", (1.0, 0, 0), mass=0.5, inertia=(0.01, 0.01, 0.01))
    mb.joint("shoulder", "hinge", "ground", "arm", axis=(0, 1, 0), at=(0, 0, 0),
             stiffness=3.0, damping=0.2, actuator=sd.Sine(2.0, 1.5),
             control=PD(kp=20.0, kd=1.0, target=sd.Ramp(0.5, 0.0, 1.0)))
    mb.joint("rail", "prismatic", "arm", "slider", axis=(1, 0, 0), stiffness=40.0,
             reference=0.05, damping=0.5, control=PD(kp=10.0, kd=0.3, target=sd.Sine(0.1, 3.0)))
    r = sd.simulate(mb.build(), t_end=1.0, step=2e-3)
    P = sum(np.sum(r.actuator_effort(j) * r.joint_velocities(j), axis=1)
            for j in ("shoulder", "rail"))
    W = r.work_actuators
    assert np.abs(W).max() > 0.1
    np.testing.assert_allclose(_trapezoid(r.t, P), W, rtol=0, atol=1e-12 * np.abs(W).max())
    # the springs and dampers: K (alpha - reference) + C v on these abelian joints
    for j, K, ref, C in (("shoulder", 3.0, 0.0, 0.2), ("rail", 40.0, 0.05, 0.5)):
        expected = K * (r.joint_coordinates(j) - ref) + C * r.joint_velocities(j)
        np.testing.assert_allclose(r.spring_force(j), expected, rtol=1e-13,
                                   atol=1e-13 * np.abs(expected).max())
        # and the joint's torque sensor (from the multipliers) reads actuators minus springs
        np.testing.assert_allclose(r.joint_torque(j), r.actuator_effort(j) - r.spring_force(j),
                                   rtol=0, atol=1e-9 * np.abs(r.joint_torque(j)).max())


@pytest.mark.parametrize("armature", [0.0, 0.7])
def test_spring_force_of_a_mass_on_a_prismatic_joint_is_newtons_law(armature):
    # a mass on a slanted rail with a spring and a damper, started away from its reference
    # and moving: along the rail (m + J_a) a = m g . u - F, F the spring's force (tension
    # positive), J_a the rail's armature (reflected inertia of a drive train, no weight)
    u = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)
    K, C, ref = 120.0, 1.5, 0.1
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("mass", (0.2, -0.1, 0.3), mass=M, inertia=(0.1, 0.1, 0.1), velocity=0.4 * u)
    mb.joint("rail", "prismatic", "ground", "mass", axis=u, stiffness=K, reference=ref,
             damping=C, **({"armature": armature} if armature else {}))
    r = sd.simulate(mb.build(), t_end=1.0, step=1e-3, tol_residual=1e-13)
    F = r.spring_force("rail")[:, 0]
    a = r.node_acceleration("mass", "inertial")[:, :3] @ u
    scale = K * 0.2
    np.testing.assert_allclose(F, M * (np.array([0, 0, -GZ]) @ u) - (M + armature) * a, rtol=0,
                               atol=1e-9 * scale)
    # from the positions and velocities of the mass, independently of the joint coordinates
    x = (r.node_position("mass") - r.node_position("mass")[0]) @ u
    xd = r.node_velocity("mass", "inertial")[:, :3] @ u
    np.testing.assert_allclose(F, K * (x - ref) + C * xd, rtol=0, atol=1e-12 * scale)
    assert np.ptp(F) > 0.4 * scale  # it moves
    np.testing.assert_array_equal(r.actuator_effort("rail"), 0.0)


def test_spring_force_on_a_spherical_joint_acts_on_the_log_coordinates():
    # a non-abelian joint: the spring's generalized force is T(alpha)^-T K (alpha - reference)
    # + C v (Eq. (62) on the log coordinates of the rotation); computed here with se3dyn.lie's
    # tangent of SO(3), and equal to actuator minus torque sensor (from the multipliers)
    K = np.array([2.0, 3.0, 5.0])
    ref = np.array([0.3, -0.2, 0.4])
    Cd = np.array([0.1, 0.2, 0.3])
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("top", (0, 0, 0), mass=1.0, inertia=(0.02, 0.03, 0.01), com=(0.05, 0.0, 0.3),
            angular_velocity=(0.5, 1.0, 4.0))
    mb.joint("pivot", "spherical", "ground", "top", stiffness=K, reference=ref, damping=Cd,
             actuator=sd.Sine((0.1, 0.2, 0.0), 2.0))
    r = sd.simulate(mb.build(), t_end=0.5, step=1e-3, tol_residual=1e-13)
    al, v = r.joint_coordinates("pivot"), r.joint_velocities("pivot")
    T = np.array([lie.tangent_so3(a) for a in al])
    expected = np.linalg.solve(np.transpose(T, (0, 2, 1)), (K * (al - ref))[..., None])[..., 0]
    expected += Cd * v
    F = r.spring_force("pivot")
    assert np.abs(al).max() > 0.5  # far from the linear range
    np.testing.assert_allclose(F, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    act = r.actuator_effort("pivot")
    np.testing.assert_allclose(act, np.sin(4 * np.pi * r.t)[:, None] * [0.1, 0.2, 0.0],
                               rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(r.joint_torque("pivot"), act - F, rtol=0,
                               atol=1e-9 * np.abs(F).max())


@pytest.mark.parametrize("gear, rotor", [(1.0, 0.0), (3.0, 0.004)])
def test_pid_effort_is_the_law_with_its_integral_state(gear, rotor):
    # a rod on a hinge under gravity, with armature and a spring, lifted to a ramped target by
    # a PID law (behind a gear: the joint gets gear times the motor's torque, and the rotor's
    # inertia reflected, gear^2 J_rotor): the integral state is not in the rows, so the effort
    # comes from the joint's equation of motion; it must be the law itself, gear (-kp e - ki z
    # - kd (v - rate)), with z = int e dt by the trapezoidal rule over the stored steps (every
    # step is stored), and its power must integrate to the run's actuator work
    kp, ki, kd = 60.0 / gear, 40.0 / gear, 5.0 / gear
    Ja = 0.05 + gear**2 * rotor
    law = PID(kp=kp, ki=ki, kd=kd, target=sd.Ramp(0.5, 0.0, 0.5),
              **({"gear": gear, "rotor_inertia": rotor} if rotor else {}))
    r = sd.simulate(_rod(0.0, armature=0.05, stiffness=2.0, control=law), t_end=2.0, step=1e-3,
                    tol_residual=1e-12)
    act = r.actuator_effort("hinge")[:, 0]
    al, v = r.joint_coordinates("hinge")[:, 0], r.joint_velocities("hinge")[:, 0]
    e = al - 0.5 * np.clip(r.t / 0.5, 0.0, 1.0)
    rate = np.where(r.t < 0.5, 1.0, 0.0)  # (the ramp's rate; at t = 0.5 s its left value)
    tau = gear * (-kp * e - ki * _trapezoid(r.t, e) - kd * (v - rate))
    np.testing.assert_allclose(act, tau, rtol=0, atol=1e-9 * np.abs(act).max())
    assert abs(e[-1]) < 0.05 and abs(gear * ki * _trapezoid(r.t, e)[-1]) > 1.0  # it integrates
    W = r.work_actuators
    np.testing.assert_allclose(_trapezoid(r.t, act * v), W, rtol=0, atol=1e-9 * np.abs(W).max())
    # at the end, nearly at rest: it holds the gravity moment and the spring
    assert act[-1] == pytest.approx(M * GZ * 0.5 * L * np.cos(al[-1]) + 2.0 * al[-1], rel=1e-2)
    d = r.system.joint_dofadr[r.system.joint_names.index("hinge")]
    np.testing.assert_allclose(r.joint_torque("hinge")[:, 0],
                               act - r.spring_force("hinge")[:, 0] - Ja * r.vd[:, d], rtol=0,
                               atol=1e-12 * np.abs(act).max())


def test_sampled_pid_effort_is_held_between_samples():
    # a digital PID (sample time 10 steps): the effort is constant over each sample period and
    # changes at the samples k T (a row at k T holds the new output); the run's actuator work
    # is the held effort times the trapezoid of the rate, step by step
    T, h = 0.01, 1e-3
    r = sd.simulate(_rod(0.0, control=PID(kp=60.0, ki=40.0, kd=5.0, target=0.3, sample_time=T)),
                    t_end=0.2, step=h)
    act = r.actuator_effort("hinge")[:, 0]
    period = np.floor(r.t / T + 1e-9).astype(int)
    for p in range(int(period.max())):
        held = act[period == p]
        assert len(held) == 10 and np.all(held == held[0]), p
    assert np.all(np.diff(act)[np.diff(period) > 0] != 0)  # a new output at every sample
    v = r.joint_velocities("hinge")[:, 0]
    W = np.concatenate([[0.0], np.cumsum(0.5 * np.diff(r.t) * act[:-1] * (v[1:] + v[:-1]))])
    np.testing.assert_allclose(W, r.work_actuators, rtol=0,
                               atol=1e-12 * np.abs(r.work_actuators).max())


def test_effort_of_a_law_of_the_users_is_the_law_at_the_stored_rows():
    # an actuator law f(t, q, v) (a Python callable, called by the engine): the effort at every
    # stored row is the law evaluated there, and the torque sensor reads it minus the spring
    r = sd.simulate(_rod(0.0, stiffness=2.0,
                         actuator=lambda t, q, v: -20.0 * (q - 0.3 * t) - 2.0 * v + 5.0),
                    t_end=0.5, step=1e-2, tol_residual=1e-13)
    q, v = r.joint_coordinates("hinge"), r.joint_velocities("hinge")
    act = r.actuator_effort("hinge")
    np.testing.assert_allclose(act, -20.0 * (q - 0.3 * r.t[:, None]) - 2.0 * v + 5.0,
                               rtol=1e-14, atol=1e-13)
    np.testing.assert_allclose(r.joint_torque("hinge"), act - 2.0 * q, rtol=0,
                               atol=1e-9 * np.abs(act).max())
    assert "joint/hinge/actuator/0" in list_channels(r)


# -------------------------------------------------------------------------------------------------
# point spring-dampers
# -------------------------------------------------------------------------------------------------
def _hanging_spring(damping: float = 0.8) -> sd.Model:
    """A body hanging from the ground by a spring-damper attached off its centre of mass,
    swinging in 3D."""
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("bob", (0.2, 0.1, -1.0), mass=M, inertia=(0.02, 0.03, 0.04),
            velocity=(0.0, 0.8, 0.3), angular_velocity=(0.5, -0.3, 1.0))
    mb.spring_damper("cord", "ground", "bob", at_a=(0.0, 0.0, 0.1), at_b=(0.25, 0.1, -0.9),
                     stiffness=150.0, damping=damping, length=0.8)
    mb.marker("top", "ground", at=(0.0, 0.0, 0.1))
    mb.marker("hook", "bob", at=(0.25, 0.1, -0.9))
    return mb.build()


def test_point_spring_force_is_newtons_law_and_its_length_the_points_distance():
    r = sd.simulate(_hanging_spring(), t_end=1.0, step=1e-3, tol_residual=1e-13)
    N = r.spring_damper_force("cord")
    Lm = r.spring_damper_length("cord")
    assert N.shape == Lm.shape == r.spring_damper_rate("cord").shape == (len(r),)
    # the length between the attachment points, measured with markers on them
    d = r.marker_position("hook") - r.marker_position("top")
    np.testing.assert_allclose(Lm, np.linalg.norm(d, axis=1), rtol=1e-14)
    e = d / np.linalg.norm(d, axis=1)[:, None]
    # its rate from the markers' velocities and, at order 2, from the lengths in time
    Ld = np.einsum("ni,ni->n", e, r.marker_velocity("hook", "inertial")[:, :3])
    np.testing.assert_allclose(r.spring_damper_rate("cord"), Ld, rtol=0, atol=1e-12)
    fd = (Lm[2:] - Lm[:-2]) / (r.t[2:] - r.t[:-2])
    np.testing.assert_allclose(r.spring_damper_rate("cord")[1:-1], fd, rtol=0,
                               atol=1e-2 * np.abs(fd).max())
    np.testing.assert_allclose(N, 150.0 * (Lm - 0.8) + 0.8 * Ld, rtol=1e-13)
    # Newton's law for the bob (its node at the centre of mass): m a = m g - N e
    acc = r.node_acceleration("bob", "inertial")[:, :3]
    np.testing.assert_allclose(N, np.einsum("ni,ni->n", e, M * (np.array([0, 0, -GZ]) - acc)),
                               rtol=0, atol=1e-9 * np.abs(N).max())
    assert N.min() > 0 and np.ptp(N) > 1.0  # a cord in tension, swinging


def test_force_sensor_channels_equal_in_memory_and_from_a_results_file(tmp_path):
    mb = sd.ModelBuilder.from_model(_hanging_spring())
    mb.node("arm", (0.0, 0.5, 0.0), mass=1.0, inertia=(0.01, 0.01, 0.01))
    mb.joint("hinge", "hinge", "ground", "arm", axis=(1, 0, 0), at=(0, 0, 0), stiffness=2.0,
             actuator=sd.Sine(0.5, 2.0))
    mb.node("cart", (0.0, 0.5, -0.5), mass=1.0, inertia=(0.01, 0.01, 0.01))
    mb.joint("rail", "prismatic", "arm", "cart", axis=(0, 0, 1),
             control=PD(kp=50.0, kd=2.0, target=0.1))
    mb.node("tip", (0.0, 0.5, -0.8), mass=0.5, inertia=(0.01, 0.01, 0.01))
    mb.joint("plain", "hinge", "cart", "tip", axis=(1, 0, 0), at=(0.0, 0.5, -0.5))
    model = mb.build()
    res, back = run_and_read(model, 0.1, tmp_path / "res.h5")
    want = ["joint/hinge/actuator/0", "joint/hinge/spring/0", "joint/rail/actuator/0",
            "spring/cord/force", "spring/cord/length", "spring/cord/rate"]
    pick = lambda names: [c for c in names  # noqa: E731
                          if c.startswith("spring/") or "/actuator/" in c or "/spring/" in c]
    assert sorted(pick(list_channels(res))) == sorted(want)  # only where they exist
    assert pick(list_channels(back)) == pick(list_channels(res))
    for c in want:
        np.testing.assert_array_equal(get_channel(res, c), get_channel(back, c), err_msg=c)
    np.testing.assert_allclose(get_channel(res, "joint/hinge/actuator/0"),
                               0.5 * np.sin(4 * np.pi * res.t), rtol=1e-14, atol=1e-15)
    np.testing.assert_array_equal(res.spring_force("rail"), back.spring_force("rail"))
    assert channel_unit("joint/hinge/actuator/0", res) == "N m"
    assert channel_unit("joint/rail/actuator/0", res) == "N"
    assert channel_unit("joint/rail/spring/0") == "N m | N"
    assert [channel_unit(f"spring/cord/{q}") for q in ("force", "length", "rate")] == \
        ["N", "m", "m/s"]
    with pytest.raises(KeyError, match="has no actuator"):
        get_channel(res, "joint/plain/actuator/0")
    with pytest.raises(KeyError, match="no spring-damper 'cable'"):
        get_channel(back, "spring/cable/force")


def test_force_sensor_errors_and_composites():
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("arm", (0, 0, -L), mass=M, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("u", "universal", "ground", "arm", axes=((1, 0, 0), (0, 1, 0)), at=(0, 0, 0),
             actuator=(0.5, -0.25), stiffness=(1.0, 2.0))
    r = sd.simulate(mb.build(), t_end=0.05, step=1e-2)
    # a universal joint: both hinges' values side by side, as its coordinates
    np.testing.assert_array_equal(r.actuator_effort("u"), np.broadcast_to([0.5, -0.25],
                                                                          (len(r), 2)))
    np.testing.assert_allclose(r.spring_force("u"), [1.0, 2.0] * r.joint_coordinates("u"),
                               rtol=1e-14, atol=1e-300)
    assert "joint/u/actuator/1" in list_channels(r) and "joint/u/spring/1" in list_channels(r)
    with pytest.raises(UnknownNameError, match="unknown joint 'v'"):
        r.actuator_effort("v")
    with pytest.raises(UnknownNameError, match="model has no spring-dampers"):
        r.spring_damper_force("cord")
    # results without their model (a layout only) cannot tell the parts apart
    import dataclasses

    bare = dataclasses.replace(r, system=type("Layout", (), dict(
        node_names=r.system.node_names, joint_names=r.system.joint_names,
        composites=r.system.composites, joint_k=r.system.joint_k,
        joint_dofadr=r.system.joint_dofadr))())
    with pytest.raises(ModelError, match="with their model"):
        bare.spring_force("u")


def test_force_sensors_of_a_condensed_run_are_those_of_the_full_model():
    # a rod built of two nodes joined rigidly (condensed for the time loop): the sensors read
    # the full model's joints, and the torque sensor is still actuator minus spring
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("a", (0.2, 0, 0), mass=1.0, inertia=(0.01, 0.02, 0.02))
    mb.node("b", (0.6, 0, 0), mass=0.5, inertia=(0.01, 0.01, 0.01))
    mb.joint("weld", "rigid", "a", "b")
    mb.joint("hinge", "hinge", "ground", "a", axis=(0, 1, 0), at=(0, 0, 0), stiffness=4.0,
             damping=0.3, control=PD(kp=30.0, kd=2.0, target=sd.Sine(0.4, 1.0)))
    r = sd.simulate(mb.build(), t_end=0.5, step=1e-2, condense=True, tol_residual=1e-13)
    assert r.stats.get("condensed_until") is None or r.stats["condensed_until"] > 0.5
    al, v = r.joint_coordinates("hinge"), r.joint_velocities("hinge")
    target = 0.4 * np.sin(2 * np.pi * r.t)[:, None]
    rate = 0.4 * 2 * np.pi * np.cos(2 * np.pi * r.t)[:, None]
    np.testing.assert_allclose(r.actuator_effort("hinge"),
                               -30.0 * (al - target) - 2.0 * (v - rate), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(r.spring_force("hinge"), 4.0 * al + 0.3 * v, rtol=1e-12,
                               atol=1e-14)
    np.testing.assert_allclose(r.joint_torque("hinge"),
                               r.actuator_effort("hinge") - r.spring_force("hinge"), rtol=0,
                               atol=1e-9 * np.abs(r.joint_torque("hinge")).max())
    assert r.actuator_effort("weld").shape == (len(r), 0)
