"""Assembly and kinematic analysis with inverse dynamics (se3dyn.kinematics).

Tolerances:

* Finite differences use the step H = 1e-4 s. Their truncation error is estimated from the
  differences themselves: a central difference with step h has the error ``c h^2 + O(h^4)``, so
  ``|FD(2h) - FD(h)| = 3 c h^2`` and the error of FD(h) is ``|FD(2h) - FD(h)| / 3``; the
  computed velocities and accelerations must agree with FD(h) within twice that (plus a round-off
  floor), and with the Richardson extrapolation ``(4 FD(h) - FD(2h)) / 3`` (truncation O(h^4),
  ~1e-16 relative) within the round-off floor alone: positions converge to ~1e-15 relative, so
  the differences carry ~1e-11 relative noise in the velocities and ~1e-9 in the accelerations
  (floors 1e-10 and 1e-8 of the velocity and acceleration scales).
* Positions are converged to a scaled constraint residual of 1e-12; the Richardson-extrapolated
  quadratic velocity term is accurate to ~1e-12 relative.
* Inverse dynamics is exact for exact accelerations: the driven pendulum torque is compared at
  1e-9 relative.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

import se3dyn as sd
from se3dyn import lie
from se3dyn.analysis.assemble import AssemblyError, assemble
from se3dyn.analysis.kinematics import kinematics, time_derivatives
from se3dyn.engine.rank import constraint_jacobian
from se3dyn.engine.system import compile_model
from se3dyn.errors import ModelError

G = 9.81
W = 2 * math.pi  # crank speed, rad/s
H = 1e-4
T_SAMPLES = np.array([0.07, 0.23, 0.41, 0.58, 0.76, 0.93])


def _grid(tc, h=H):
    return np.concatenate([[0.0], np.sort((tc[:, None] + h * np.arange(-2, 3)).ravel())])


@functools.cache
def _crank_run():
    """The paper's slider-crank with the crank (hinge '1') turning at constant speed W, sampled
    at t - 2H ... t + 2H around T_SAMPLES."""
    times = _grid(T_SAMPLES)
    return kinematics(sd.examples.slider_crank(), {"1": lambda t: W * t}, times), times


def _fd_check(x, xdot, times, floor):
    """Central differences at the sample times vs the computed derivative.

    FD(h) must agree within twice its truncation estimate |FD(2h) - FD(h)| / 3 (plus ``floor``),
    and the Richardson extrapolation (4 FD(h) - FD(2h)) / 3, whose truncation is O(h^4)
    (~1e-16 relative here), within the round-off ``floor`` alone.
    """
    i = np.arange(1, len(times), 5) + 2  # centre of each 5-point group
    fd1 = (x[i + 1] - x[i - 1]) / (2 * H)
    fd2 = (x[i + 2] - x[i - 2]) / (4 * H)
    trunc = np.abs(fd2 - fd1) / 3
    err = np.abs(fd1 - xdot[i])
    assert np.all(err <= 2 * trunc + floor), (err.max(), trunc.max())
    err_r = np.abs((4 * fd1 - fd2) / 3 - xdot[i])
    assert np.all(err_r <= floor), (err_r.max(), floor)
    return err.max(), trunc.max()


def test_slider_crank_velocities_and_accelerations_are_the_derivatives_of_the_motion():
    res, times = _crank_run()
    assert np.all(res.iterations[1:] <= 6)
    for node in ("3", "6", "8"):
        x = res.node_position(node)
        v = res.node_velocity(node, frame="inertial")
        vm = res.node_velocity(node)
        a = res.node_acceleration(node)
        vs = np.abs(vm).max()
        _fd_check(x, v[:, :3], times, 1e-10 * vs)
        # rotations: log(R(t-h)^T R(t+h)) / 2h = Omega(t) + O(h^2) (material frame)
        R = res.node_rotation(node)
        i = np.arange(1, len(times), 5) + 2
        fd1, fd2 = (lie.log_so3(np.einsum("nji,njk->nik", R[i - s], R[i + s])) / (2 * s * H)
                    for s in (1, 2))
        err = np.abs(fd1 - vm[i, 3:])
        assert np.all(err <= 2 * np.abs(fd2 - fd1) / 3 + 1e-10 * vs)
        assert np.all(np.abs((4 * fd1 - fd2) / 3 - vm[i, 3:]) <= 1e-10 * vs)
        # accelerations: derivative of the material velocities
        _fd_check(vm, a, times, 1e-8 * W * vs)
    # joint coordinates of the cylindrical joint: alpha, alpha_dot, alpha_ddot
    q = res.joint_coordinates("8")
    qd = res.joint_velocities("8")
    qdd = res.joint_accelerations("8")
    _fd_check(q, qd, times, 1e-10 * np.abs(qd).max())
    _fd_check(qd, qdd, times, 1e-8 * np.abs(qdd).max())
    # the crank turns uniformly about a fixed axis: constant material velocity
    assert np.abs(res.node_acceleration("3")).max() < 1e-8
    np.testing.assert_allclose(res.joint_velocities("1")[:, 0], W, rtol=1e-12)
    np.testing.assert_allclose(res.joint_coordinates("1")[:, 0], W * times, rtol=1e-12,
                               atol=1e-14)


def test_slider_crank_driving_torque_power_equals_the_rate_of_energy():
    # inverse-dynamics energy balance: P_driver + P_model actuator (0.015 N m, Sec. 11.2) -
    # damper dissipation (1 N s/m on joint 8) = d(K + V)/dt
    res, times = _crank_run()
    E = res.total_energy
    P = (res.driver_power + 0.015 * res.joint_velocities("1")[:, 0]
         - 1.0 * res.joint_velocities("8")[:, 0] ** 2)
    err, trunc = _fd_check(E, P, times, 1e-8 * np.abs(P).max())
    assert np.abs(res.driver_effort("1")).max() > 0.05  # a real torque is needed
    assert err < 1e-4 * np.abs(P).max()


def test_constraints_hold_along_the_driven_motion():
    res, _ = _crank_run()
    x = {k: res.node_position(k) for k in "12345678"}
    for a, b in (("1", "2"), ("4", "5"), ("7", "8")):
        assert np.abs(x[a] - x[b]).max() < 1e-12
    for a, b, L in (("2", "3", 0.04), ("3", "4", 0.04), ("5", "6", 0.15), ("6", "7", 0.15)):
        np.testing.assert_allclose(np.linalg.norm(x[a] - x[b], axis=1), L, rtol=1e-12)
    # the slider stays on its axis: y = z = 0
    assert np.abs(x["8"][:, 1:]).max() < 1e-12


def test_driven_pendulum_torque_is_inertia_times_acceleration_plus_gravity_moment():
    L, m, J = 0.4, 1.5, 2e-3
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("ground", fixed=True)
    mb.node("pivot")
    mb.node("bob", position=(0.0, 0.0, -L), mass=m, inertia=(J, J, J))
    mb.joint("hinge", "hinge", "ground", "pivot", axis=(1.0, 0.0, 0.0))
    mb.joint("arm", "rigid", "pivot", "bob")
    drive = sd.Sine(amplitude=0.8, frequency=0.7, offset=0.3)
    t = np.linspace(0.0, 1.5, 16)
    res = kinematics(mb.build(), {"hinge": drive}, t)
    th, thd, thdd = (np.array([time_derivatives(drive, ti)[i][0] for ti in t])
                     for i in range(3))
    np.testing.assert_allclose(res.joint_coordinates("hinge")[:, 0], th, rtol=1e-12)
    np.testing.assert_allclose(res.joint_velocities("hinge")[:, 0], thd, rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_allclose(res.joint_accelerations("hinge")[:, 0], thdd, rtol=1e-9,
                               atol=1e-9)
    tau = (J + m * L * L) * thdd + m * G * L * np.sin(th)
    np.testing.assert_allclose(res.driver_effort("hinge")[:, 0], tau, rtol=1e-9, atol=1e-9)
    # the hinge reaction (wrench on the pivot, material frame) is the force accelerating the
    # bob against gravity: m (x_ddot - g)
    xdd = L * (thdd[:, None] * np.stack([0 * th, np.cos(th), np.sin(th)], axis=1)
               + thd[:, None] ** 2 * np.stack([0 * th, -np.sin(th), np.cos(th)], axis=1))
    Rp = res.node_rotation("pivot")
    lam = res.joint_multipliers("hinge")
    F = np.einsum("nij,nj->ni", Rp, lam[:, :3])
    np.testing.assert_allclose(F, m * (xdd - np.array([0.0, 0.0, -G])), rtol=1e-9, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# a planar four-bar (4 parallel hinges: 3 redundant constraint equations)
# ---------------------------------------------------------------------------------------------
FB = dict(a=0.1, b=0.3, c=0.25, d=0.35)  # crank, coupler, rocker, ground (Grashof crank-rocker)


def _fourbar_points(theta):
    a, b, c, d = FB["a"], FB["b"], FB["c"], FB["d"]
    A = np.zeros(3)
    D = np.array([d, 0.0, 0.0])
    B = np.array([a * math.cos(theta), a * math.sin(theta), 0.0])
    e = D - B
    L = np.linalg.norm(e)
    x = (b * b - c * c + L * L) / (2 * L)
    y = math.sqrt(b * b - x * x)
    u = e / L
    C = B + x * u + y * np.array([-u[1], u[0], 0.0])
    return A, B, C, D


def _fourbar(theta0=math.pi / 2, mass=True):
    A, B, C, D = _fourbar_points(theta0)
    mb = sd.ModelBuilder(gravity=(0.0, -G, 0.0))
    z = (0.0, 0.0, 1.0)

    def body(name, P, Q, m):
        kw = dict(mass=m, inertia=(1e-4, m * np.sum((Q - P) ** 2) / 12 + 1e-4,  # a bar
                                     m * np.sum((Q - P) ** 2) / 12 + 2e-4)) \
            if mass else {}
        mb.node(name, position=(P + Q) / 2, **kw)

    mb.node("A", position=A, fixed=True)
    mb.node("D", position=D, fixed=True)
    for n, P in (("a0", A), ("a1", B), ("b0", B), ("b1", C), ("c0", C), ("c1", D)):
        mb.node(n, position=P)
    body("crank", A, B, 0.2)
    body("coupler", B, C, 0.6)
    body("rocker", C, D, 0.5)
    mb.joint("hA", "hinge", "A", "a0", axis=z)
    mb.joint("crank0", "rigid", "a0", "crank")
    mb.joint("crank1", "rigid", "crank", "a1")
    mb.joint("hB", "hinge", "a1", "b0", axis=z)
    mb.joint("coupler0", "rigid", "b0", "coupler")
    mb.joint("coupler1", "rigid", "coupler", "b1")
    mb.joint("hC", "hinge", "b1", "c0", axis=z)
    mb.joint("rocker0", "rigid", "c0", "rocker")
    mb.joint("rocker1", "rigid", "rocker", "c1")
    mb.joint("hD", "hinge", "c1", "D", axis=z)
    return mb.build()


def test_four_bar_kinematics_with_redundant_constraints_balances_energy():
    times = _grid(np.array([0.2, 0.6]))
    res = kinematics(_fourbar(), {"hA": lambda t: W * t}, times)
    for i in range(len(times)):
        A, B, C, D = _fourbar_points(math.pi / 2 + W * times[i])
        np.testing.assert_allclose(res.node_position("b1")[i], C, atol=1e-12)
    _fd_check(res.total_energy, res.driver_power, times, 1e-8 * np.abs(res.driver_power).max())


# ---------------------------------------------------------------------------------------------
# assembly
# ---------------------------------------------------------------------------------------------
def test_perturbed_slider_crank_is_assembled_with_a_small_reported_move():
    model = sd.examples.slider_crank()
    d6 = np.array([2e-3, -1e-3, 1e-3])
    a = assemble(model, positions={"6": model.node("6").position + d6,
                                   "8": model.node("8").position + [5e-3, 0.0, 0.0]})
    assert a.violation_before > 1e-3
    assert a.violation < 1e-12
    assert a.iterations <= 6
    # the geometry of Table 2 holds again: coincident joint nodes, rigid link lengths
    x = {k: a.node_position(k) for k in "123456789"}
    for p, q in (("1", "2"), ("4", "5"), ("7", "8")):
        assert np.linalg.norm(x[p] - x[q]) < 1e-12
    assert np.abs(x["8"][1:]).max() < 1e-12  # on the axis of the cylindrical joint
    for p, q, L in (("2", "3", 0.04), ("3", "4", 0.04), ("5", "6", 0.15), ("6", "7", 0.15)):
        assert np.linalg.norm(x[p] - x[q]) == pytest.approx(L, rel=1e-12)
    # small move: of the order of the perturbation, and reported
    assert 0 < a.translation.max() < 2 * 5e-3
    assert a.translation[list(model.node_names).index("6")] < 2 * np.linalg.norm(d6)
    text = str(a)
    assert "largest node moves" in text and "'8'" in text and "'6'" in text


def test_assembly_keeps_an_imposed_crank_angle_and_yields_a_simulable_model():
    model = sd.examples.slider_crank()
    th = 0.7
    a = assemble(model, coordinates={"1": th}, keep=["1"])
    assert a.violation < 1e-12
    assert a.joint_coordinates("1")[0] == th  # exactly: kept
    assert a.joint_change("1")[0] == 0.0
    # the crank pin (node 4) is 0.08 above the hinge, rotated by th about x
    np.testing.assert_allclose(a.node_position("4"),
                               [0.0, 0.1 - 0.08 * math.sin(th), 0.12 + 0.08 * math.cos(th)],
                               atol=1e-12)
    assert abs(a.joint_change("8")[0]) > 0.01  # the slider had to move
    # the new model starts there and runs
    s = compile_model(a.model)
    np.testing.assert_allclose(s.node_H0, a.H, atol=1e-14)
    res = sd.simulate(a.model, 0.02, 0.01)
    assert res.constraint.max() < 1e-10
    np.testing.assert_allclose(res.node_position("4")[0], a.node_position("4"), atol=1e-14)


def test_assembled_velocities_satisfy_the_velocity_constraints_in_kinetic_energy_norm():
    # hanging pendulum whose bob is given a velocity with a radial component
    L, m, J = 0.5, 2.0, 1e-2
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("ground", fixed=True)
    mb.node("pivot")
    mb.node("bob", position=(0.0, 0.0, -L), mass=m, inertia=(J, J, J),
            velocity=(0.0, 1.0, 0.5))
    mb.joint("hinge", "hinge", "ground", "pivot", axis=(1.0, 0.0, 0.0))
    mb.joint("arm", "rigid", "pivot", "bob")
    a = assemble(mb.build())
    # min m (w L - 1)^2 + J w^2 over the hinge rate w
    w = m * L / (m * L * L + J)
    assert a.joint_velocities("hinge")[0] == pytest.approx(w, rel=1e-12)
    np.testing.assert_allclose(a.node_velocity("bob", frame="inertial"),
                               [0.0, w * L, 0.0, w, 0.0, 0.0], atol=1e-12)
    assert a.velocity_change[2, 0] == pytest.approx(math.hypot(1 - w * L, 0.5), rel=1e-12)
    # the velocities are kept by the integrator's own consistency step
    B = constraint_jacobian(compile_model(a.model))
    assert np.abs(B @ a.v).max() < 1e-14
    res = sd.simulate(a.model, 0.01, 0.01)
    assert res.joint_velocities("hinge")[0, 0] == pytest.approx(w, rel=1e-12)


def test_assembly_of_a_perturbed_four_bar_with_redundant_constraints():
    model = _fourbar()
    a = assemble(model, positions={"b1": model.node("b1").position + [3e-3, -2e-3, 0.0],
                                   "coupler": model.node("coupler").position + [0, 1e-3, 0]},
                 coordinates={"hA": 0.05}, keep=["hA"])
    assert a.violation < 1e-12
    A, B, C, D = _fourbar_points(math.pi / 2 + 0.05)
    np.testing.assert_allclose(a.node_position("b1"), C, atol=1e-12)
    np.testing.assert_allclose(a.node_position("a1"), B, atol=1e-12)


def test_a_loop_that_cannot_close_raises_naming_the_joint():
    # the rocker of a Grashof crank-rocker cannot reach 150 degrees from its initial angle
    model = _fourbar()
    with pytest.raises(AssemblyError, match="cannot be satisfied") as exc:
        assemble(model, coordinates={"hD": 2.6}, keep=["hD", "hA"])
    assert exc.value.joint in ("hA", "hB", "hC", "hD") or exc.value.joint.startswith(
        ("crank", "coupler", "rocker"))
    assert f"worst: joint {exc.value.joint!r}" in str(exc.value)


# ---------------------------------------------------------------------------------------------
# bad inputs
# ---------------------------------------------------------------------------------------------
def test_bad_drivers_raise_model_errors_naming_item_and_field():
    model = sd.examples.slider_crank()
    t = [0.0, 0.1]
    with pytest.raises(ModelError, match=r"driver 'crank': field 'joint'.*valid: '1'"):
        kinematics(model, {"crank": 1.0}, t)
    with pytest.raises(ModelError, match=r"joint '4' \(spherical\): field 'drivers'.*abelian"):
        kinematics(model, {"4": [0.0, 0.0, 0.0]}, t)
    with pytest.raises(ModelError, match=r"joint '8' \(cylindrical\): field 'drivers'.*2 comp"):
        kinematics(model, {"8": [0.0, 0.0, 0.0]}, t)
    with pytest.raises(ModelError, match=r"joint '2' \(rigid\): field 'drivers'"):
        kinematics(model, {"2": 0.0}, t)
    with pytest.raises(ModelError, match=r"field 'times'"):
        kinematics(model, {"1": 0.0}, [0.1, 0.0])
    with pytest.raises(ModelError, match=r"field 'drivers'"):
        kinematics(model, {}, t)


def test_bad_keep_and_coordinates_raise_model_errors_naming_item_and_field():
    model = sd.examples.slider_crank()
    with pytest.raises(ModelError, match=r"joint 'l': field 'keep'.*unknown joint"):
        assemble(model, keep=["l"])
    with pytest.raises(ModelError, match=r"joint '2' \(rigid\): field 'keep'"):
        assemble(model, keep=["2"])
    with pytest.raises(ModelError, match=r"field 'keep'"):
        assemble(model, keep="1")
    with pytest.raises(ModelError, match=r"joint '8' \(cylindrical\): field 'coordinates'"):
        assemble(model, coordinates={"8": [1.0, 2.0, 3.0]})
    with pytest.raises(ModelError, match=r"node 'x': field 'positions'"):
        assemble(model, positions={"x": [0.0, 0.0, 0.0]})


def test_remaining_mobility_is_reported_naming_the_free_joint():
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("ground", fixed=True)
    mb.node("p1")
    mb.node("b1", position=(0.0, 0.3, 0.0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.node("p2", position=(0.0, 0.3, 0.0))
    mb.node("b2", position=(0.0, 0.6, 0.0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("h1", "hinge", "ground", "p1", axis=(1.0, 0.0, 0.0))
    mb.joint("arm1", "rigid", "p1", "b1")
    mb.joint("h2", "hinge", "b1", "p2", axis=(1.0, 0.0, 0.0))
    mb.joint("arm2", "rigid", "p2", "b2")
    with pytest.raises(ModelError, match=r"1 remaining degree.*joint 'h2' alpha_0"):
        kinematics(mb.build(), {"h1": lambda t: t}, [0.0, 0.1])


def test_conflicting_driver_is_reported():
    # the slider position is fixed by the crank angle: driving both over-determines the motion
    with pytest.raises(ModelError, match=r"field 'drivers'.*redundant or conflicting driver"):
        kinematics(sd.examples.slider_crank(), {"1": 0.0, "8": [0.0, 0.0]}, [0.0])
