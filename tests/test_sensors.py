"""Markers and kinematic sensors (issue 30, item 4): frames fixed on nodes, their position,
velocity and acceleration, an accelerometer and a gyroscope, as Results accessors and channels.

Every test asserts physics (closed forms, free fall, rest, finite differences in time), never
numbers printed by se3dyn itself.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

import se3dyn as sd
from _results_file import run_and_read
from se3dyn.errors import ModelError
from se3dyn.io.modelfile import ModelFileError, loads_model, save_model
from se3dyn.lie import exp_so3, log_so3
from se3dyn.results.channels import channel_unit, get_channel, list_channels

G = np.array([0.0, 0.0, -9.81])
EPS = np.finfo(float).eps


def _rot(axis, angle) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    return exp_so3(angle * a / np.linalg.norm(a))


Q = _rot((1, -2, 0.5), 0.9)  # a marker orientation, neither the node's nor the identity


def _free_body(markers=True) -> sd.Model:
    """A free body (centre of mass away from its node) spinning about an axis off its
    principal axes, under gravity only."""
    mb = sd.ModelBuilder(gravity=G)
    mb.node("body", (0.2, -0.1, 1.0), orientation=_rot((0, 1, 1), 0.4), mass=2.0,
            inertia=(0.1, 0.2, 0.25), principal_axes=_rot((1, 0, 0), 0.3),
            com=(0.3, 0.1, 0.9), velocity=(0.5, 0.0, 2.0), angular_velocity=(1.0, 2.0, 3.0))
    if markers:
        mb.marker("com", "body", at=(0.3, 0.1, 0.9), orientation=Q)
        mb.marker("tip", "body", offset=(0.2, 0.05, -0.1), orientation=Q)
    return mb.build()


def _top(markers=True, rho=0.9) -> sd.Model:
    """A heavy top on a spherical joint (general 3D motion with constraint forces)."""
    mb = sd.ModelBuilder(gravity=G)
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("top", (0, 0, 0), mass=1.0, inertia=(0.02, 0.02, 0.005), com=(0.05, 0.0, 0.3),
            principal_axes=_rot((0, 1, 0), 0.16), angular_velocity=(0.5, 0.2, 40.0))
    mb.joint("pivot", "spherical", "ground", "top")
    if markers:
        mb.marker("imu", "top", at=(0.1, -0.05, 0.35), orientation=Q)
        mb.marker("base", "ground", orientation=Q)
    return mb.build()


# -------------------------------------------------------------------------------------------------
# the accelerometer: zero in free fall, -g at rest
# -------------------------------------------------------------------------------------------------
def test_accelerometer_reads_zero_in_free_fall():
    # at the centre of mass of a free body under gravity only, whatever the spin: the specific
    # force is zero (the equations solved to round-off with a tight Newton tolerance)
    r = sd.simulate(_free_body(), t_end=0.5, step=1e-3, tol_residual=1e-13)
    acc = r.accelerometer("com")
    assert acc.shape == (len(r), 3)
    assert np.abs(acc).max() <= 100 * EPS * np.linalg.norm(G)
    # away from the centre of mass it reads only the tangential and centripetal terms,
    # R_m^T (dw/dt x d + w x (w x d)), d from the centre of mass to the marker
    w = r.node_velocity("body", "inertial")[:, 3:]
    dw = r.node_acceleration("body", "inertial")[:, 3:]
    d = r.marker_position("tip") - r.marker_position("com")
    expected = np.cross(dw, d) + np.cross(w, np.cross(w, d))
    tip = r.accelerometer("tip")
    assert np.abs(tip).max() > 0.1
    np.testing.assert_allclose(np.einsum("nij,nj->ni", r.marker_rotation("tip"), tip), expected,
                               rtol=0, atol=100 * EPS * np.linalg.norm(G))


def test_accelerometer_reads_minus_g_at_rest():
    mb = sd.ModelBuilder(gravity=G)
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("block", (1, 0, 0), mass=1.0, inertia=(1, 1, 1))
    mb.joint("weld", "rigid", "ground", "block")
    mb.node("bob", (0, 0, -1), mass=1.0, inertia=(1e-2, 1e-2, 1e-2))
    # a pendulum held at its equilibrium by a stiff spring-damper: at rest
    mb.joint("hinge", "hinge", "ground", "bob", axis=(0, 1, 0), at=(0, 0, 0),
             stiffness=1e4, damping=10.0)
    mb.marker("on_ground", "ground", orientation=Q)
    mb.marker("on_block", "block", offset=(0.1, 0.2, 0.3), orientation=Q)
    mb.marker("on_bob", "bob", at=(0.0, 0.1, -1.1), orientation=Q)
    mb.marker("upright", "bob")
    r = sd.simulate(mb.build(), t_end=0.2, step=1e-2, tol_residual=1e-13)
    expected = -Q.T @ G  # -g in the marker's axes
    for name in ("on_ground", "on_block", "on_bob"):
        acc = r.accelerometer(name)
        np.testing.assert_allclose(acc, np.broadcast_to(expected, acc.shape), rtol=0,
                                   atol=1e-12 * 9.81, err_msg=name)
        assert np.abs(r.gyroscope(name)).max() <= 1e-12
    # the sign convention: +9.81 along the upward axis of an upright accelerometer
    np.testing.assert_allclose(r.accelerometer("upright")[-1], [0, 0, 9.81], atol=1e-11)


# -------------------------------------------------------------------------------------------------
# closed form: constant spin about a fixed hinge
# -------------------------------------------------------------------------------------------------
def test_marker_on_a_body_spinning_about_a_fixed_hinge():
    a = np.array([1.0, 2.0, 2.0]) / 3.0  # hinge axis (unit)
    p0 = np.array([0.3, -0.2, 0.5])  # a point of the axis, the body's node
    w = 7.0
    mb = sd.ModelBuilder(gravity=9.81 * a)  # gravity along the axis: no torque about it
    mb.node("ground", p0, fixed=True)
    mb.node("rotor", p0, mass=3.0, inertia=(0.1, 0.2, 0.3), principal_axes=_rot((1, 1, 0), 0.5),
            angular_velocity=w * a)
    mb.joint("axle", "hinge", "ground", "rotor", axis=a)
    x = np.array([0.8, 0.4, -0.3])  # the marker's point at t = 0
    mb.marker("m", "rotor", at=x, orientation=Q)
    r = sd.simulate(mb.build(), t_end=1.0, step=1e-2, tol_residual=1e-13)
    R = exp_so3(np.outer(r.t * w, a))  # (n, 3, 3) rotation about the axis
    rel = np.einsum("nij,j->ni", R, x - p0)
    tol = 1e-11
    np.testing.assert_allclose(r.marker_position("m"), p0 + rel, rtol=0, atol=tol)
    np.testing.assert_allclose(r.marker_rotation("m"), R @ Q, rtol=0, atol=tol)
    vel = r.marker_velocity("m", frame="inertial")
    np.testing.assert_allclose(vel[:, :3], np.cross(w * a, rel), rtol=0, atol=tol * w)
    np.testing.assert_allclose(vel[:, 3:], np.broadcast_to(w * a, (len(r), 3)), atol=tol * w)
    acc = r.marker_acceleration("m", frame="inertial")
    r_perp = rel - np.outer(rel @ a, a)
    np.testing.assert_allclose(acc[:, :3], -w**2 * r_perp, rtol=0, atol=tol * w**2)
    np.testing.assert_allclose(acc[:, 3:], 0.0, atol=tol * w**2)
    # material components: the same vectors in the marker's axes R Q
    Rm = R @ Q
    mat = r.marker_velocity("m")
    np.testing.assert_allclose(mat[:, :3], np.einsum("nji,nj->ni", Rm, vel[:, :3]), atol=tol)
    np.testing.assert_allclose(mat[:, 3:], np.broadcast_to(Q.T @ (w * a), (len(r), 3)),
                               atol=tol * w)
    # the accelerometer: R_m^T (a - g)
    np.testing.assert_allclose(r.accelerometer("m"),
                               np.einsum("nji,nj->ni", Rm, -w**2 * r_perp - 9.81 * a),
                               atol=tol * w**2)


def test_gyroscope_of_a_rotated_marker():
    # R_m^T R_node Omega_node (Omega_node material): the inertial angular velocity in the
    # marker's axes
    r = sd.simulate(_free_body(), t_end=0.2, step=1e-2)
    om = r.node_velocity("body")[:, 3:]
    Rn = r.node_rotation("body")
    Rm = r.marker_rotation("tip")
    expected = np.einsum("nji,njk,nk->ni", Rm, Rn, om)
    np.testing.assert_allclose(r.gyroscope("tip"), expected, rtol=0, atol=1e-13)
    np.testing.assert_allclose(r.gyroscope("tip"), om @ (Rn[0].T @ Rm[0]), rtol=0, atol=1e-13)


# -------------------------------------------------------------------------------------------------
# finite differences in time on a general 3D motion
# -------------------------------------------------------------------------------------------------
def _fd_errors(h: float) -> dict[str, float]:
    """Largest differences between the marker accessors and central differences of the marker
    positions and rotations of a heavy top (rho_inf = 1: the stored accelerations are then
    second-order consistent with the positions, no O(h) lag of the alpha method)."""
    r = sd.simulate(_top(), t_end=0.2, step=h, rho_inf=1.0, tol_residual=1e-13)
    p, R = r.marker_position("imu"), r.marker_rotation("imu")
    vi = r.marker_velocity("imu", "inertial")
    vm = r.marker_velocity("imu", "material")
    ai = r.marker_acceleration("imu", "inertial")
    am = r.marker_acceleration("imu", "material")
    c = slice(1, -1)
    dp = (p[2:] - p[:-2]) / (2 * h)
    ddp = (p[2:] - 2 * p[1:-1] + p[:-2]) / h**2
    w_in = log_so3(R[2:] @ np.swapaxes(R[:-2], 1, 2)) / (2 * h)
    w_mat = log_so3(np.swapaxes(R[:-2], 1, 2) @ R[2:]) / (2 * h)
    Rt = np.swapaxes(R[c], 1, 2)
    return {
        "velocity/inertial/U": np.abs(vi[c, :3] - dp).max(),
        "velocity/inertial/Omega": np.abs(vi[c, 3:] - w_in).max(),
        "velocity/material/U": np.abs(vm[c, :3] - np.einsum("nij,nj->ni", Rt, dp)).max(),
        "velocity/material/Omega": np.abs(vm[c, 3:] - w_mat).max(),
        "acceleration/inertial/U": np.abs(ai[c, :3] - ddp).max(),
        "acceleration/inertial/Omega":
            np.abs(ai[c, 3:] - (vi[2:, 3:] - vi[:-2, 3:]) / (2 * h)).max(),
        "acceleration/material": np.abs(am[c] - (vm[2:] - vm[:-2]) / (2 * h)).max(),
        "accelerometer": np.abs(r.accelerometer("imu")[c]
                                - np.einsum("nij,nj->ni", Rt, ddp - G)).max(),
        "gyroscope": np.abs(r.gyroscope("imu")[c] - w_mat).max(),
        # scales for the tolerance: the fastest rate of the motion and its largest acceleration
        "_rate": np.abs(vi[:, 3:]).max(), "_acc": np.abs(ai[:, :3]).max(),
    }


def test_marker_kinematics_against_finite_differences():
    # central differences are second-order: their error is about (h w)^2 / 6 times the
    # quantity differentiated (w the fastest rate, ~40 rad/s here); halving the step divides
    # it by ~4, which shows that the accessors are the exact derivatives of the motion
    h = 2e-4
    e1, e2 = _fd_errors(h), _fd_errors(h / 2)
    w = e1["_rate"]
    scale = {"velocity": e1["_acc"] / w, "acceleration": e1["_acc"], "accelerometer":
             e1["_acc"], "gyroscope": w}
    for key in e1:
        if key.startswith("_"):
            continue
        s = scale[key.split("/")[0]]
        if "Omega" in key or key == "acceleration/material":
            s = max(s, w * w)
        tol = (h * w) ** 2 * s
        assert e1[key] <= tol, (key, e1[key], tol)
        assert e2[key] <= e1[key] / 3.0, (key, e1[key], e2[key])


# -------------------------------------------------------------------------------------------------
# markers are outputs: no number of a run changes
# -------------------------------------------------------------------------------------------------
def _digest(r) -> str:
    h = hashlib.sha256()
    for a in (r.H, r.v, r.lam):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("make", [_top, _free_body])
def test_markers_change_no_number_of_a_run(make):
    a = sd.simulate(make(markers=False), t_end=0.1, step=1e-2)
    b = sd.simulate(make(markers=True), t_end=0.1, step=1e-2)
    assert _digest(a) == _digest(b)
    sa, sb = sd.compile_model(make(markers=False)), sd.compile_model(make(markers=True))
    assert (sa.nq, sa.nm, sa.node_names, sa.joint_names) == (sb.nq, sb.nm, sb.node_names,
                                                             sb.joint_names)


# -------------------------------------------------------------------------------------------------
# model files and results files
# -------------------------------------------------------------------------------------------------
def test_markers_round_trip_through_a_model_file():
    m = _top()
    text = save_model(m)
    assert "markers:" in text
    back, _ = loads_model(text)
    assert [mk.name for mk in back.markers] == ["imu", "base"]
    for x, y in zip(m.markers, back.markers, strict=True):
        assert (x.node, x.name) == (y.node, y.name)
        np.testing.assert_array_equal(x.X, y.X)
    assert save_model(back) == text


def _run_and_read(model, t_end: float, path):
    """A run at h = 1e-2 streamed into a results file: (results in memory, read back)."""
    return run_and_read(model, t_end, path)


def test_marker_channels_equal_in_memory_and_from_a_results_file(tmp_path):
    model = _top()
    res, back = _run_and_read(model, 0.1, tmp_path / "res.h5")
    names = [c for c in list_channels(res) if c.startswith("marker/")]
    assert names == [c for c in list_channels(back) if c.startswith("marker/")]
    assert len(names) == 2 * (3 + 9 + 24 + 6) + 2  # + distance and its rate for the pair
    for c in names:
        np.testing.assert_array_equal(get_channel(res, c), get_channel(back, c), err_msg=c)
    np.testing.assert_array_equal(res.marker_frame("imu"), back.marker_frame("imu"))
    np.testing.assert_array_equal(get_channel(back, "marker/base/accelerometer/z"),
                                  np.full(len(back), (-Q.T @ G)[2]))


def test_marker_channel_units_and_names():
    assert channel_unit("marker/imu/position/x") == "m"
    assert channel_unit("marker/imu/velocity/inertial/x") == "m/s"
    assert channel_unit("marker/imu/velocity/material/wz") == "rad/s"
    assert channel_unit("marker/imu/acceleration/inertial/y") == "m/s^2"
    assert channel_unit("marker/imu/acceleration/material/wx") == "rad/s^2"
    assert channel_unit("marker/imu/accelerometer/z") == "m/s^2"
    assert channel_unit("marker/imu/gyroscope/x") == "rad/s"
    r = sd.simulate(_top(), t_end=0.02, step=1e-2)
    with pytest.raises(KeyError, match="no marker 'imv'"):
        get_channel(r, "marker/imv/position/x")
    with pytest.raises(KeyError, match="unknown channel"):
        get_channel(r, "marker/imu/accelerometer/wx")


# -------------------------------------------------------------------------------------------------
# errors name the marker and the field
# -------------------------------------------------------------------------------------------------
def _builder() -> sd.ModelBuilder:
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    mb.node("body", (1, 0, 0), mass=1.0, inertia=(1, 1, 1))
    return mb


@pytest.mark.parametrize("kwargs, field, text", [
    ({"node": "bdy"}, "node", "valid: 'ground', 'body'"),
    ({"node": "body", "at": (0, np.nan, 0)}, "at", "finite"),
    ({"node": "body", "offset": (0, 1)}, "offset", "3 numbers"),
    ({"node": "body", "at": (0, 0, 0), "offset": (0, 0, 0)}, "offset", "not both"),
    ({"node": "body", "orientation": np.diag([1.0, 1.0, -1.0])}, "orientation", "rotation"),
    ({"node": "body", "orientation": np.full((3, 3), np.inf)}, "orientation", "rotation"),
])
def test_marker_errors_name_the_marker_and_the_field(kwargs, field, text):
    mb = _builder()
    node = kwargs.pop("node")
    with pytest.raises(ModelError, match=text) as e:
        mb.marker("imu", node, **kwargs)
    assert e.value.item == "marker 'imu'" and e.value.field == field
    assert str(e.value).startswith("marker 'imu': field '" + field + "'")


def test_duplicate_marker_and_unknown_marker_names():
    mb = _builder()
    mb.marker("imu", "body")
    with pytest.raises(ModelError, match="marker 'imu': field 'name'.*defined twice"):
        mb.marker("imu", "ground")
    r = sd.simulate(mb.build(), t_end=0.01, step=1e-2)
    with pytest.raises(KeyError, match=r"unknown marker 'imx'.*did you mean 'imu'.*valid: imu"):
        r.accelerometer("imx")
    with pytest.raises(ModelError, match="'material' or 'inertial'"):
        r.marker_velocity("imu", frame="body")


def test_marker_errors_in_a_model_file_name_the_line():
    text = save_model(_top())
    bad = text.replace("    node: top\n", "    node: tpo\n")
    assert bad != text
    with pytest.raises(ModelFileError) as e:
        loads_model(bad)
    assert e.value.item == "marker 'imu'" and e.value.field == "node"
    assert e.value.line == bad.splitlines().index("    node: tpo") + 1
    assert "valid:" in str(e.value)


def test_markers_of_a_moved_node_save_their_offset():
    # a model whose node frames changed after the markers were added (what assemble returns):
    # the file keeps each marker where it sits on its body (its X), not its old point
    import dataclasses

    m = _top()
    top = m.node("top")
    R = _rot((1, 0, 0), 0.2)
    moved = dataclasses.replace(top, position=np.array([0.0, 0.0, 0.01]), orientation=R)
    m2 = dataclasses.replace(m, nodes=(m.nodes[0], moved))
    back, _ = loads_model(save_model(m2))
    for x, y in zip(m2.markers, back.markers, strict=True):
        np.testing.assert_allclose(y.X, x.X, rtol=0, atol=1e-15)


# -------------------------------------------------------------------------------------------------
# distance between two markers
# -------------------------------------------------------------------------------------------------
def test_marker_distance_on_a_spinning_body_and_to_the_ground():
    a = np.array([1.0, 2.0, 2.0]) / 3.0
    p0 = np.array([0.3, -0.2, 0.5])
    w = 7.0
    mb = sd.ModelBuilder(gravity=9.81 * a)
    mb.node("ground", p0, fixed=True)
    mb.node("rotor", p0, mass=3.0, inertia=(0.1, 0.2, 0.3), principal_axes=_rot((1, 1, 0), 0.5),
            angular_velocity=w * a)
    mb.joint("axle", "hinge", "ground", "rotor", axis=a)
    x, y = np.array([0.8, 0.4, -0.3]), np.array([-0.2, 0.5, 0.9])
    q = np.array([1.5, -1.0, 0.2])  # a marker on the ground
    mb.marker("m1", "rotor", at=x)
    mb.marker("m2", "rotor", at=y, orientation=Q)
    mb.marker("g", "ground", at=q)
    h = 1e-3
    r = sd.simulate(mb.build(), t_end=0.5, step=h, tol_residual=1e-13)
    # two points of one rigid body keep their distance, its rate is zero
    d12 = r.marker_distance("m1", "m2")
    assert d12.shape == (len(r),)
    np.testing.assert_allclose(d12, np.linalg.norm(y - x), rtol=0, atol=1e3 * EPS)
    np.testing.assert_array_equal(d12, r.marker_distance("m2", "m1"))
    assert np.abs(r.marker_distance_rate("m1", "m2")).max() <= 1e3 * EPS * w
    # a point of the rotor and a point of the ground: closed form p(t) = p0 + R(t) (x - p0)
    R = exp_so3(np.outer(r.t * w, a))
    rel = np.einsum("nij,j->ni", R, x - p0)
    d = p0 + rel - q
    dist = np.linalg.norm(d, axis=1)
    rate = np.einsum("ni,ni->n", d, np.cross(w * a, rel)) / dist
    assert np.ptp(dist) > 0.1 and np.abs(rate).max() > 1.0
    np.testing.assert_allclose(r.marker_distance("g", "m1"), dist, rtol=0, atol=1e-11)
    np.testing.assert_allclose(r.marker_distance_rate("g", "m1"), rate, rtol=0, atol=1e-10 * w)
    np.testing.assert_allclose(r.marker_distance_rate("m1", "g"), rate, rtol=0, atol=1e-10 * w)
    # and the rate is the time derivative of the distance (central differences, O(h^2))
    D = r.marker_distance("g", "m1")
    fd = (D[2:] - D[:-2]) / (2 * h)
    assert np.abs(fd - r.marker_distance_rate("g", "m1")[1:-1]).max() <= (h * w) ** 2 * w


def test_marker_pair_channels_and_units():
    r = sd.simulate(_top(), t_end=0.05, step=1e-2)
    names = list_channels(r)
    assert "marker/imu/distance/base" in names and "marker/imu/distance_rate/base" in names
    assert "marker/base/distance/imu" not in names  # listed once per pair
    np.testing.assert_array_equal(get_channel(r, "marker/base/distance/imu"),
                                  r.marker_distance("imu", "base"))
    np.testing.assert_array_equal(get_channel(r, "marker/imu/distance_rate/base"),
                                  r.marker_distance_rate("imu", "base"))
    assert channel_unit("marker/imu/distance/base") == "m"
    assert channel_unit("marker/imu/distance_rate/base") == "m/s"
    with pytest.raises(KeyError, match="no marker 'bsae'"):
        get_channel(r, "marker/imu/distance/bsae")


# -------------------------------------------------------------------------------------------------
# joint reaction and joint torque from the multipliers
# -------------------------------------------------------------------------------------------------
M_BOB, L_ROD, GZ = 2.0, 0.8, 9.81


def _hanging_pendulum(at: bool) -> sd.Model:
    """A point mass m on a massless rod of length L, hanging at rest below a hinge."""
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0.1, 0.2, 1.0), fixed=True)
    mb.node("bob", (0.1, 0.2, 1.0 - L_ROD), orientation=_rot((1, 2, 3), 0.7), mass=M_BOB,
            inertia=(1e-4, 1e-4, 1e-4))
    if at:  # the hinge at the pivot, attached to the bob
        mb.joint("hinge", "hinge", "ground", "bob", axis=(0, 1, 0), at=(0.1, 0.2, 1.0))
    else:  # the hinge's frame at the bob's node (a joint without ``at``)
        mb.joint("hinge", "hinge", "ground", "bob", axis=(0, 1, 0))
    return mb.build()


@pytest.mark.parametrize("at", [True, False])
def test_reaction_of_a_hanging_pendulum(at):
    r = sd.simulate(_hanging_pendulum(at), t_end=0.2, step=1e-2, tol_residual=1e-13)
    w = r.joint_reaction("hinge", frame="inertial")
    assert w.shape == (len(r), 6)
    # the joint holds the bob up: m g upward on the body B; no moment about the hinge point
    # (or about the bob itself, where the joint sits without ``at``)
    expected = np.array([0.0, 0.0, M_BOB * GZ, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(w, np.broadcast_to(expected, w.shape), rtol=0, atol=1e-10)
    # joint axes: with ``at`` those of the inertial frame at t0 carried by the bob (at rest:
    # the inertial ones); without, the bob's own axes
    Rb = r.node_rotation("bob")[0]
    wj = r.joint_reaction("hinge")
    exp_j = expected if at else np.concatenate([Rb.T @ expected[:3], Rb.T @ expected[3:]])
    np.testing.assert_allclose(wj, np.broadcast_to(exp_j, wj.shape), rtol=0, atol=1e-10)
    np.testing.assert_array_equal(wj, r.joint_multipliers("hinge"))
    np.testing.assert_allclose(r.joint_torque("hinge"), 0.0, atol=1e-10)


@pytest.mark.parametrize("hold", ["actuator", "spring", "pd"])
def test_joint_torque_sensor_in_a_static_hold(hold):
    # a uniform rod of mass m and length L on a hinge at one end, held horizontal by a torque
    # about the axis -y; its centre of mass also sits c off the rod's line along the axis, so
    # that gravity has a moment perpendicular to the axis too (taken by the bearing)
    from se3dyn.model.specs import PD

    m, L, c = M_BOB, L_ROD, 0.1
    tau = m * GZ * L / 2
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("rod", (0, 0, 0), mass=m, inertia=(1e-3, m * L**2 / 12, m * L**2 / 12),
            com=(L / 2, -c, 0))
    kw = {"actuator": dict(actuator=tau),
          "spring": dict(stiffness=50.0, reference=tau / 50.0, damping=1.0),
          "pd": dict(control=PD(kp=80.0, kd=4.0, target=tau / 80.0))}[hold]
    mb.joint("hinge", "hinge", "ground", "rod", axis=(0, -1, 0), **kw)
    r = sd.simulate(mb.build(), t_end=0.3, step=1e-2, tol_residual=1e-13)
    assert np.abs(r.joint_coordinates("hinge")).max() <= 1e-12  # held: at rest
    # what a torque sensor in the joint reads: the torque that holds the rod, m g L / 2
    T = r.joint_torque("hinge")
    assert T.shape == (len(r), 1)
    np.testing.assert_allclose(T, tau, rtol=1e-12)
    # the load cell: force m g up; moments about the hinge (inertial axes) balance gravity's
    # (L/2, -c, 0) x (0, 0, -m g) = (c m g, m g L/2, 0)
    w = r.joint_reaction("hinge", frame="inertial")
    np.testing.assert_allclose(w, np.broadcast_to([0, 0, m * GZ, -c * m * GZ, -tau, 0], w.shape),
                               rtol=0, atol=1e-10)
    # its constraint part: zero moment about the axis, the perpendicular moment unchanged
    wc = r.joint_reaction("hinge", frame="inertial", part="constraint")
    np.testing.assert_allclose(wc, np.broadcast_to([0, 0, m * GZ, -c * m * GZ, 0, 0], w.shape),
                               rtol=0, atol=1e-10)


def _conical(theta=0.5, at=True) -> tuple[sd.Model, float]:
    """A conical pendulum: a point mass (isotropic inertia) on a massless rod of length L from a
    spherical joint, in steady rotation at the rate Omega^2 = g / (L cos theta)."""
    Om = np.sqrt(GZ / (L_ROD * np.cos(theta)))
    r0 = L_ROD * np.array([np.sin(theta), 0.0, -np.cos(theta)])
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("bob", r0, mass=M_BOB, inertia=(1e-3, 1e-3, 1e-3),
            velocity=np.cross([0, 0, Om], r0), angular_velocity=(0, 0, Om))
    mb.joint("pivot", "spherical", "ground", "bob", at=(0, 0, 0))
    mb.marker("bob", "bob")
    mb.marker("pivot", "ground")
    return mb.build(), Om


def test_reaction_of_a_conical_pendulum():
    theta = 0.5
    model, Om = _conical(theta)
    r = sd.simulate(model, t_end=1.0, step=1e-3, tol_residual=1e-13)
    # closed form: the bob turns about z at the rate Omega; the rod pulls it with
    # F = m (a - g), a = -Omega^2 r_perp the centripetal acceleration
    ang = Om * r.t
    r_perp = L_ROD * np.sin(theta) * np.stack([np.cos(ang), np.sin(ang), 0 * ang], axis=1)
    F = M_BOB * (-Om**2 * r_perp - np.array([0, 0, -GZ]))
    w = r.joint_reaction("pivot", frame="inertial")
    scale = M_BOB * GZ
    tol = 30 * (1e-3 * Om) ** 2 * scale  # the alpha method's O(h^2) error on the motion
    np.testing.assert_allclose(w[:, :3], F, rtol=0, atol=tol)
    np.testing.assert_allclose(np.linalg.norm(w[:, :3], axis=1), scale / np.cos(theta), rtol=1e-4)
    # the force is along the rod (tension), no moment about the pivot (a spherical joint)
    rod = r.marker_position("bob") / L_ROD
    np.testing.assert_allclose(np.cross(rod, w[:, :3]), 0.0, atol=tol)
    np.testing.assert_allclose(w[:, 3:], 0.0, atol=1e-9 * scale)
    # Newton's law for the bob with the stored accelerations, to round-off
    acc = r.node_acceleration("bob", "inertial")[:, :3]
    np.testing.assert_allclose(w[:, :3], M_BOB * (acc - [0, 0, -GZ]), rtol=0, atol=1e-9 * scale)
    # its torque along the three rotation coordinates: nothing drives them
    np.testing.assert_allclose(r.joint_torque("pivot"), 0.0, atol=1e-9 * scale)
    # distance to the pivot: the rod's length
    np.testing.assert_allclose(r.marker_distance("pivot", "bob"), L_ROD, rtol=1e-9)


def test_joint_sensor_channels_equal_in_memory_and_from_a_results_file(tmp_path):
    model, _ = _conical()
    res, back = _run_and_read(model, 0.05, tmp_path / "res.h5")
    names = [c for c in list_channels(res)
             if "/reaction/" in c or "/torque/" in c or "/distance" in c]
    assert names == [c for c in list_channels(back)
                     if "/reaction/" in c or "/torque/" in c or "/distance" in c]
    assert len(names) == 12 + 3 + 2
    for c in names:
        np.testing.assert_array_equal(get_channel(res, c), get_channel(back, c), err_msg=c)
    for frame in ("joint", "inertial"):
        np.testing.assert_array_equal(res.joint_reaction("pivot", frame),
                                      back.joint_reaction("pivot", frame))
    np.testing.assert_array_equal(res.joint_torque("pivot"), back.joint_torque("pivot"))
    assert channel_unit("joint/pivot/reaction/inertial/fz") == "N"
    assert channel_unit("joint/pivot/reaction/joint/mx") == "N m"
    assert channel_unit("joint/pivot/torque/0", res) == "N m"
    assert channel_unit("joint/pivot/torque/0") == "N m | N"


def test_joint_torque_units_and_composites():
    # a prismatic joint's sensor is a force (N); a universal joint gives both hinges' torques
    mb = sd.ModelBuilder(gravity=(0, 0, -GZ))
    mb.node("ground", (0, 0, 0), fixed=True)
    mb.node("slider", (0, 0, 0), mass=M_BOB, inertia=(1, 1, 1))
    mb.joint("rail", "prismatic", "ground", "slider", axis=(0, 0, 1), actuator=M_BOB * GZ)
    mb.node("arm", (0, 0, -L_ROD), mass=M_BOB, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("u", "universal", "slider", "arm", axes=((1, 0, 0), (0, 1, 0)), at=(0, 0, 0),
             actuator=(0.0, 0.0))
    r = sd.simulate(mb.build(), t_end=0.05, step=1e-2, tol_residual=1e-13)
    assert channel_unit("joint/rail/torque/0", r) == "N"
    assert channel_unit("joint/u/torque/1", r) == "N m"
    assert r.joint_torque("u").shape == (len(r), 2)
    # the actuator pushes the slider (and the arm hanging below it, 2 m in all) up with m g:
    # both fall with g/2, and the rail's sensor reads what the actuator applies, m g
    np.testing.assert_allclose(r.joint_torque("rail"), M_BOB * GZ, rtol=1e-12)
    # the arm hangs from the cross: the universal joint pulls it up with m (g + a), a = -g/2
    w = r.joint_reaction("u", frame="inertial")
    np.testing.assert_allclose(w, np.broadcast_to([0, 0, M_BOB * GZ / 2, 0, 0, 0], w.shape),
                               rtol=0, atol=1e-10)
    with pytest.raises(ModelError, match="'joint' or 'inertial'"):
        r.joint_reaction("u", frame="body")
