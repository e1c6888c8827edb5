"""Prescribed motion of joint coordinates in dynamics (ModelBuilder.drive, issue 30).

Every reference here is independent of se3dyn's dynamics: closed-form motions (a bead on a rod
turning at constant speed: r = r0 cosh(w t), torque m w^2 r0^2 sinh(2 w t); a pendulum driven
along theta(t): torque J theta'' + m g l cos theta), the energy balance, and the inverse
dynamics of ``se3dyn.kinematics`` (a different algorithm: Newton on the positions, linear
solves for velocities and accelerations, least squares for the multipliers, no time
integration). Convergence orders are measured from errors at h, h/2, h/4.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import se3dyn as sd
from _results_file import run_and_read
from se3dyn.errors import ModelError, Se3dynWarning
from se3dyn.io.modelfile import load_model, save_model
from se3dyn.results.channels import channel_unit, get_channel, list_channels

G = 9.81


def _quiet_run(model, t_end, h, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        return sd.simulate(model, t_end, h, **kw)


def _orders(errors):
    e = np.asarray(errors, dtype=float)
    return np.log2(e[:-1] / e[1:])


# ---------------------------------------------------------------------------------------------
# closed forms
# ---------------------------------------------------------------------------------------------
W_ROD, R0, M_BEAD = 2.0, 0.3, 0.7


def _bead_on_rod(drive="velocity"):
    """A rod turning about z, driven at W_ROD; a bead sliding freely along it (no gravity)."""
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    mb.node("rod", (0.5, 0, 0), mass=1.0, inertia=(1e-3, 0.1, 0.1))
    mb.node("bead", (R0, 0, 0), mass=M_BEAD, inertia=(1e-4, 1e-4, 1e-4),
            velocity=(0, W_ROD * R0, 0), angular_velocity=(0, 0, W_ROD))
    mb.joint("spin", "hinge", "ground", "rod", axis=(0, 0, 1), at=(0, 0, 0))
    mb.joint("slide", "prismatic", "rod", "bead", axis=(1, 0, 0), at=(R0, 0, 0))
    if drive == "velocity":
        mb.drive("motor", "spin", velocity=W_ROD)
    else:
        mb.drive("motor", "spin", position=sd.Ramp(W_ROD * 10.0, 0.0, 10.0))
    return mb.build()


@pytest.mark.parametrize("formulation", ["index2", "index3"])
@pytest.mark.parametrize("drive", ["velocity", "position"])
def test_bead_on_a_turning_rod_follows_cosh_and_the_drive_supplies_the_coriolis_torque(
        formulation, drive):
    T = 1.0
    r_exact = R0 * math.cosh(W_ROD * T)
    tau_exact = M_BEAD * W_ROD ** 2 * R0 ** 2 * math.sinh(2 * W_ROD * T)
    er, et = [], []
    for h in (4e-3, 2e-3, 1e-3):
        res = _quiet_run(_bead_on_rod(drive), T, h, formulation=formulation)
        # the driven angle is exact at every step
        np.testing.assert_allclose(res.joint_coordinates("spin")[:, 0], W_ROD * res.t,
                                   rtol=0, atol=1e-13)
        er.append(abs(R0 + res.joint_coordinates("slide")[-1, 0] - r_exact))
        et.append(abs(res.drive_effort("motor")[-1, 0] - tau_exact))
    assert np.all(_orders(er) > 1.8), er
    assert np.all(_orders(et) > 1.8), et
    assert et[-1] < 1e-4 * tau_exact and er[-1] < 1e-4 * r_exact


def _pendulum(**drive):
    mb = sd.ModelBuilder(gravity=(0, -G, 0))
    mb.node("ground", fixed=True)
    mb.node("bar", (0.5, 0, 0), mass=2.0, inertia=(0.01, 0.1, 0.1))
    mb.joint("pin", "hinge", "ground", "bar", axis=(0, 0, 1), at=(0, 0, 0))
    mb.drive("motor", "pin", **drive)
    return mb.build()


def test_pendulum_driven_along_a_sine_needs_inertia_times_acceleration_plus_gravity_moment():
    A, f = 0.8, 0.7
    w = 2 * math.pi * f
    J = 0.1 + 2.0 * 0.5 ** 2  # about the pin
    errs = []
    for h in (4e-3, 2e-3, 1e-3):
        res = _quiet_run(_pendulum(position=sd.Sine(A, f)), 1.0, h)
        th = A * np.sin(w * res.t)
        np.testing.assert_allclose(res.joint_coordinates("pin")[:, 0], th, rtol=0, atol=1e-13)
        vd = res.vd[:, sd.compile_model(res.system.model).drive_dof[0]]
        np.testing.assert_allclose(vd, -A * w * w * np.sin(w * res.t), rtol=0, atol=1e-13)
        tau = J * (-A * w * w * np.sin(w * res.t)) + 2.0 * G * 0.5 * np.cos(th)
        # (after the generalized-alpha start-up transient of the body's acceleration, which
        # decays like rho_inf^(t/h): at a fixed t > 0 the error is O(h^2))
        late = res.t >= 0.25
        errs.append(np.abs(res.drive_effort("motor")[late, 0] - tau[late]).max())
    assert np.all(_orders(errs) > 1.8), errs
    assert errs[-1] < 1e-5 * np.abs(tau).max()


def test_constant_speed_needs_exactly_the_gravity_moment():
    # at constant speed the centripetal force passes through the pin: tau = m g l cos(w t)
    res = _quiet_run(_pendulum(velocity=2.0), 1.0, 1e-3)
    tau = 2.0 * G * 0.5 * np.cos(2.0 * res.t)
    np.testing.assert_allclose(res.drive_effort("motor")[:, 0], tau, rtol=0, atol=1e-8)


def test_a_velocity_drive_integrates_its_position_at_order_2():
    A, f = 1.5, 0.4
    w = 2 * math.pi * f
    errs = []
    for h in (4e-3, 2e-3, 1e-3):
        res = _quiet_run(_pendulum(velocity=sd.Sine(A, f, phase=math.pi / 2)), 1.0, h)
        np.testing.assert_allclose(res.joint_velocities("pin")[:, 0],
                                   A * np.cos(w * res.t), rtol=0, atol=1e-12)
        errs.append(abs(res.joint_coordinates("pin")[-1, 0] - A / w * math.sin(w * 1.0)))
    assert np.all(_orders(errs) > 1.8), errs


def test_motion_provided_on_one_coordinate_force_on_the_other_of_the_same_joint():
    # a vertical cylindrical joint: its rotation driven, its slide free under gravity
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    mb.node("b", (0, 0, 0), mass=1.5, inertia=(0.03, 0.03, 0.05))
    mb.joint("cyl", "cylindrical", "ground", "b", axis=(0, 0, 1))
    A, f = 0.6, 1.1
    mb.drive("turn", "cyl", position={1: sd.Sine(A, f)})
    res = _quiet_run(mb.build(), 1.0, 1e-3)
    w = 2 * math.pi * f
    np.testing.assert_allclose(res.joint_coordinates("cyl")[:, 0], -G * res.t ** 2 / 2,
                               rtol=0, atol=1e-9)
    tau = 0.05 * (-A * w * w * np.sin(w * res.t))
    assert res.drive_effort("turn").shape == (len(res.t), 1)
    np.testing.assert_allclose(res.drive_effort("turn")[:, 0], tau, rtol=0,
                               atol=2e-4 * np.abs(tau).max())


# ---------------------------------------------------------------------------------------------
# against the inverse dynamics of kinematics(), and the energy balance
# ---------------------------------------------------------------------------------------------
W = 2 * math.pi


def _driven_slider_crank():
    mb = sd.ModelBuilder.from_model(sd.examples.slider_crank())
    mb.drive("motor", "1", velocity=W)
    return mb.build()


def test_crank_torque_converges_at_order_2_to_the_inverse_dynamics_of_kinematics():
    model = _driven_slider_crank()
    times = np.array([0.25, 0.5, 0.75, 1.0])
    ref = sd.kinematics(sd.examples.slider_crank(), {"1": lambda t: W * t}, times)
    tau_ref = ref.driver_effort("1")[:, 0]
    errs = []
    for h in (1e-2, 5e-3, 2.5e-3, 1.25e-3, 6.25e-4):
        res = _quiet_run(model, 1.0, h)
        rows = np.searchsorted(res.t, times - 1e-12)
        np.testing.assert_allclose(res.t[rows], times, rtol=0, atol=1e-12)
        errs.append(np.abs(res.drive_effort("motor")[rows, 0] - tau_ref).max())
    span = np.ptp(tau_ref)
    assert np.all(_orders(errs) > 1.8), errs
    assert errs[-1] < 1e-6 * span, (errs, span)
    # Richardson: the extrapolated error of the finest step is far below its own
    assert abs(errs[-1] - errs[-2] / 4) < 0.1 * errs[-1]


def test_driver_work_closes_the_energy_balance():
    model = _driven_slider_crank()
    res = _quiet_run(model, 1.0, 2e-3)
    rate = res.joint_velocities("1")[:, 0]
    p_drive = res.drive_effort("motor")[:, 0] * rate
    np.testing.assert_allclose(get_channel(res, "drive/motor/power"), p_drive, rtol=0, atol=0)
    w_drive = np.concatenate([[0.0], np.cumsum(0.5 * np.diff(res.t) * (p_drive[1:]
                                                                        + p_drive[:-1]))])
    # the model's own actuator: 0.015 N m on the crank (Sec. 11.2), dissipation in joint 8
    p_act = 0.015 * rate
    w_act = np.concatenate([[0.0], np.cumsum(0.5 * np.diff(res.t) * (p_act[1:] + p_act[:-1]))])
    E = res.total_energy
    lhs = E - E[0] + res.dissipation
    scale = np.abs(w_drive).max()
    assert scale > 0.01
    assert np.abs(lhs - (w_drive + w_act)).max() < 1e-3 * scale
    # and the run's own balance counts the drive as an actuator
    np.testing.assert_allclose(res.work_actuators, w_drive + w_act, rtol=0, atol=1e-6 * scale)
    assert res.stats["energy_balance_error"] < 1e-3 * res.stats["energy_scale"]


def test_condensed_and_full_runs_give_the_same_torque():
    model = _driven_slider_crank()
    a = _quiet_run(model, 0.5, 5e-3, formulation="index3")
    b = _quiet_run(model, 0.5, 5e-3, formulation="index3", condense=False)
    np.testing.assert_allclose(a.drive_effort("motor"), b.drive_effort("motor"), rtol=0,
                               atol=1e-8 * np.abs(b.drive_effort("motor")).max())


def test_stepwise_and_compiled_loops_give_the_same_bits():
    model = _driven_slider_crank()
    a = _quiet_run(model, 0.2, 1e-2)
    b = _quiet_run(model, 0.2, 1e-2, output_step=1e-2)
    assert not a.stats.get("adaptive") and np.array_equal(a.t, b.t)
    for x in ("H", "v", "vd", "lam", "alpha"):
        assert np.array_equal(getattr(a, x), getattr(b, x)), x


def test_adaptive_steps_follow_the_drive():
    res = _quiet_run(_pendulum(position=sd.Sine(0.8, 0.7)), 1.0, 1e-2, tol=1e-6)
    th = 0.8 * np.sin(2 * math.pi * 0.7 * res.t)
    np.testing.assert_allclose(res.joint_coordinates("pin")[:, 0], th, rtol=0, atol=1e-12)
    assert res.stats["energy_balance_error"] < 1e-3 * res.stats["energy_scale"]


# ---------------------------------------------------------------------------------------------
# initial conditions and bad input
# ---------------------------------------------------------------------------------------------
def test_a_drive_that_does_not_start_where_the_joint_is_is_refused_naming_it():
    with pytest.raises(ModelError, match=r"drive 'motor'.*position.*0\.3") as e:
        _quiet_run(_pendulum(position=sd.Sine(0.5, 1.0, offset=0.3)), 0.1, 1e-2)
    assert "initial" in str(e.value)
    # with the joint's absolute coordinate at that value the same drive runs
    mb = sd.ModelBuilder(gravity=(0, -G, 0))
    mb.node("ground", fixed=True)
    mb.node("bar", (0.5, 0, 0), mass=2.0, inertia=(0.01, 0.1, 0.1))
    mb.joint("pin", "hinge", "ground", "bar", axis=(0, 0, 1), at=(0, 0, 0), initial=0.3)
    mb.drive("motor", "pin", position=sd.Sine(0.5, 1.0, offset=0.3))
    res = _quiet_run(mb.build(), 0.1, 1e-2)
    np.testing.assert_allclose(res.joint_coordinates("pin")[:, 0],
                               0.3 + 0.5 * np.sin(2 * math.pi * res.t), atol=1e-13)


def test_initial_velocities_follow_the_drive_and_say_so():
    with pytest.warns(Warning, match=r"rates of drive 'motor'"):
        res = sd.simulate(_pendulum(velocity=2.0), 0.01, 1e-3)
    np.testing.assert_allclose(res.node_velocity("bar", frame="inertial")[0, :3], [0, 1.0, 0],
                               atol=1e-14)


def test_drives_in_conflict_are_refused():
    # two coaxial hinges between the same bodies (redundant constraints) driven at two speeds
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    mb.node("bar", (0.5, 0, 0), mass=2.0, inertia=(0.01, 0.1, 0.1))
    mb.joint("h1", "hinge", "ground", "bar", axis=(0, 0, 1), at=(0, 0, 0))
    mb.joint("h2", "hinge", "ground", "bar", axis=(0, 0, 1), at=(0, 0, 0.2))
    mb.drive("d1", "h1", velocity=1.0)
    mb.drive("d2", "h2", velocity=2.0)
    with pytest.raises(ModelError, match=r"drives 'd1', 'd2'.*velocity"):
        _quiet_run(mb.build(), 0.1, 1e-2)


def _builder():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("b", (1, 0, 0), mass=1.0, inertia=(1, 1, 1))
    mb.joint("ball", "spherical", "g", "b")
    mb.node("c", (2, 0, 0), mass=1.0, inertia=(1, 1, 1))
    mb.joint("cyl", "cylindrical", "b", "c", axis=(1, 0, 0))
    return mb


@pytest.mark.parametrize("call, field, text", [
    (dict(name="d", joint="ball", velocity=1.0), "joint", "log coordinates"),
    (dict(name="d", joint="cly", velocity=1.0), "joint", "did you mean 'cyl'"),
    (dict(name="d", joint="cyl", velocity=1.0), "velocity", "a dict"),
    (dict(name="d", joint="cyl", velocity={2: 1.0}), "velocity", "indices 0 to 1"),
    (dict(name="d", joint="cyl", position={0: 0.0}, velocity={0: 1.0}), "velocity",
     "both a position and a velocity"),
    (dict(name="d", joint="cyl", position={0: (0.0, 1.0)}), "position", "component"),
    (dict(name="d", joint="cyl"), "position", "a position or a velocity"),
    (dict(name="d", joint="cyl", velocity={0: float("nan")}), "velocity", "got nan"),
])
def test_bad_drives_are_refused_naming_the_drive_and_field(call, field, text):
    mb = _builder()
    name, joint = call.pop("name"), call.pop("joint")
    with pytest.raises(ModelError, match=f"drive '{name}'") as e:
        mb.drive(name, joint, **call)
    assert e.value.field.startswith(field) and text in str(e.value), str(e.value)


def test_a_coordinate_driven_twice_is_refused():
    mb = _builder()
    mb.drive("a", "cyl", velocity={0: 1.0})
    with pytest.raises(ModelError, match=r"drive 'b'.*drive 'a' prescribes it already"):
        mb.drive("b", "cyl", position={0: 0.0})
    with pytest.raises(ModelError, match=r"drive 'a'.*defined twice"):
        mb.drive("a", "cyl", velocity={1: 1.0})


# ---------------------------------------------------------------------------------------------
# model files, channels, results files
# ---------------------------------------------------------------------------------------------
def test_model_file_round_trip_gives_the_same_run(tmp_path):
    mb = sd.ModelBuilder.from_model(sd.examples.slider_crank())
    mb.drive("motor", "1", position=sd.Ramp(2.0, 0.0, 1.0))
    model = mb.build()
    text = save_model(model)
    assert "drives:" in text
    back, _ = load_model(text)
    a, b = _quiet_run(model, 0.1, 1e-2), _quiet_run(back, 0.1, 1e-2)
    for x in ("H", "v", "vd", "lam"):
        assert np.array_equal(getattr(a, x), getattr(b, x))
    assert np.array_equal(a.drive_effort("motor"), b.drive_effort("motor"))


def test_model_file_drive_of_several_coordinates_and_errors():
    text = ("se3dyn: 1\nnodes:\n  g: {fixed: true}\n  b: {mass: 1, inertia: [1, 1, 1]}\n"
            "joints:\n  cyl: {type: cylindrical, a: g, b: b, axis: [0, 0, 1]}\n"
            "drives:\n  d: {joint: cyl, position: {0: {ramp: {value: 0.1}}}, velocity: {1: 2}}\n")
    model, _ = load_model(text)
    (d,) = model.drives
    assert [t[1:] for t in d.targets] == [(0, "position"), (1, "velocity")]
    with pytest.raises(ModelError, match=r"line 8: drive 'd'.*'joint'.*did you mean 'cyl'"):
        load_model(text.replace("joint: cyl", "joint: cil"))


def test_drive_channels_and_units_from_memory_and_from_a_results_file(tmp_path):
    res, back = run_and_read(_driven_slider_crank(), 0.1, tmp_path / "r.h5")
    names = [c for c in list_channels(res) if c.startswith("drive/")]
    assert names == ["drive/motor/effort", "drive/motor/power"]
    assert names == [c for c in list_channels(back) if c.startswith("drive/")]
    assert channel_unit("drive/motor/effort", res) == "N m"
    assert channel_unit("drive/motor/power", res) == "W"
    for c in names:
        np.testing.assert_array_equal(get_channel(back, c), get_channel(res, c))
    with pytest.raises(KeyError, match="did you mean 'motor'"):
        res.drive_effort("mot0r")


# ---------------------------------------------------------------------------------------------
# statics and kinematics use the model's drives
# ---------------------------------------------------------------------------------------------
def test_statics_holds_driven_coordinates_and_gives_the_holding_torque():
    st = sd.static_equilibrium(_pendulum(position=sd.Ramp(0.6, 0.0, 1.0)), t=1.0, load_steps=3)
    np.testing.assert_allclose(st.joint_coordinates("pin"), [0.6], rtol=0, atol=1e-12)
    np.testing.assert_allclose(st.drive_effort("motor"), [2.0 * G * 0.5 * math.cos(0.6)],
                               rtol=1e-10)
    # a velocity drive holds its coordinate where the model starts
    st = sd.static_equilibrium(_pendulum(velocity=1.0))
    np.testing.assert_allclose(st.joint_coordinates("pin"), [0.0], atol=1e-14)
    np.testing.assert_allclose(st.drive_effort("motor"), [2.0 * G * 0.5], rtol=1e-10)


def test_kinematics_takes_the_model_drives_and_says_when_drivers_replace_them():
    mb = sd.ModelBuilder.from_model(sd.examples.slider_crank())
    mb.drive("motor", "1", position=sd.Ramp(W * 10.0, 0.0, 10.0))
    model = mb.build()
    times = [0.1, 0.3]
    a = sd.kinematics(model, None, times)
    b = sd.kinematics(sd.examples.slider_crank(), {"1": sd.Ramp(W * 10.0, 0.0, 10.0)}, times)
    np.testing.assert_allclose(a.driver_effort("motor"), b.driver_effort("1"), rtol=1e-12)
    with pytest.warns(Se3dynWarning, match=r"drives \('motor'\) are not used"):
        sd.kinematics(model, {"1": sd.Ramp(W * 10.0, 0.0, 10.0)}, times)
    with pytest.raises(ModelError, match=r"drive 'motor'.*position drives"):
        sd.kinematics(_pendulum(velocity=1.0), None, [0.0])
