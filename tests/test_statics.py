"""Static equilibrium (se3dyn.analysis.statics): analytic equilibria, moment balance, virtual
work, errors.

Newton converges to ``|r| <= 1e-10`` relative to the largest force and ``|Phi| <= 1e-10`` (scaled
by the characteristic length), so equilibrium angles, spring torques and reactions are compared
at ~1e-9 relative; the virtual-work check uses a central difference of the constrained motion
(kinematics at +-EPS) whose truncation error is O(EPS^2) relative.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

import se3dyn as sd
from se3dyn.analysis.kinematics import kinematics
from se3dyn.analysis.statics import static_equilibrium
from se3dyn.errors import ModelError, SimulationError

G = 9.81


def _pendulum(k, L=0.5, m=2.0, g=G, spring=True):
    """Ground - hinge (x) - massless pivot - rigid arm - bob, arm initially horizontal along +y;
    the torsional spring is relaxed there."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -g))
    mb.node("ground", fixed=True)
    mb.node("pivot")
    mb.node("bob", position=(0.0, L, 0.0), mass=m, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("hinge", "hinge", "ground", "pivot", axis=(1.0, 0.0, 0.0),
             stiffness=k if spring else None)
    mb.joint("arm", "rigid", "pivot", "bob")
    return mb.build()


# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("ratio", [1.0, 0.1])
def test_pendulum_with_torsional_spring_droops_to_the_analytic_angle(ratio):
    # droop phi below the horizontal: k phi = m g L cos(phi), i.e. k theta = m g L sin(theta)
    # with theta = pi/2 - phi the angle from the downward vertical
    L, m = 0.5, 2.0
    k = ratio * m * G * L
    phi = brentq(lambda p: k * p - m * G * L * math.cos(p), 0.0, math.pi / 2)
    res = static_equilibrium(_pendulum(k, L, m), load_steps=5)
    assert res.joint_coordinates("hinge")[0] == pytest.approx(-phi, rel=1e-9)
    np.testing.assert_allclose(res.load_factors, [0.2, 0.4, 0.6, 0.8, 1.0])
    assert res.cuts == 0 and res.stable
    np.testing.assert_allclose(res.node_position("bob"),
                               [0.0, L * math.cos(phi), -L * math.sin(phi)], atol=1e-10)
    # the hinge carries the weight: the multipliers are the wrench on node B (the pivot) in
    # its material frame (rotated by -phi about x): m g upwards; about the hinge axis the
    # joint passes on the spring torque k phi = m g L cos(phi) (A^T lambda + k alpha = 0)
    lam = res.joint_multipliers("hinge")
    R = res.node_rotation("pivot")
    np.testing.assert_allclose(R @ lam[:3], [0.0, 0.0, m * G], rtol=1e-9, atol=1e-9)
    assert lam[3] == pytest.approx(m * G * L * math.cos(phi), rel=1e-9)
    np.testing.assert_allclose(lam[4:], 0.0, atol=1e-9)
    if ratio == 0.1:
        assert phi > 1.4  # large rotation: 82 degrees


def test_soft_spring_needs_load_stepping_to_stay_on_the_physical_branch():
    # k = 0.02 m g L: phi = 50 cos(phi) has its first root at 88.9 degrees; other equilibria
    # exist (the line crosses the cosine again further down); load stepping from 0 follows
    # the physical branch
    L, m = 0.5, 2.0
    k = 0.02 * m * G * L
    phi = brentq(lambda p: k * p - m * G * L * math.cos(p), 0.0, math.pi / 2)
    res = static_equilibrium(_pendulum(k, L, m), load_steps=10)
    assert res.joint_coordinates("hinge")[0] == pytest.approx(-phi, rel=1e-9)
    assert res.load_factors[-1] == 1.0 and len(res.load_factors) >= 10
    assert res.stable


def test_chain_spring_torques_balance_the_moment_of_the_tip_load():
    # planar chain of 4 hinged links (hinges about z) with torsional springs under a tip force;
    # at equilibrium the spring of hinge i carries the moment of the load about that hinge
    n, l = 4, 0.25
    ks = np.array([40.0, 30.0, 20.0, 10.0])
    F = np.array([1.5, -12.0, 0.0])
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    prev = "ground"
    for i in range(n):
        mb.node(f"p{i}", position=(i * l, 0.0, 0.0))
        mb.node(f"e{i}", position=((i + 1) * l, 0.0, 0.0))
        mb.joint(f"h{i}", "hinge", prev, f"p{i}", axis=(0.0, 0.0, 1.0), stiffness=ks[i])
        mb.joint(f"l{i}", "rigid", f"p{i}", f"e{i}")
        prev = f"e{i}"
    mb.load("tip", f"e{n - 1}", force=F)
    res = static_equilibrium(mb.build(), load_steps=4)
    tip = res.node_position(f"e{n - 1}")
    turned = 0.0
    for i in range(n):
        a = res.joint_coordinates(f"h{i}")[0]
        moment = np.cross(tip - res.node_position(f"p{i}"), F)[2]
        assert ks[i] * a == pytest.approx(moment, rel=1e-9, abs=1e-9)
        turned += a
    assert abs(turned) > 0.5  # a large deflection
    # the rigid links keep their length
    for i in range(n):
        d = np.linalg.norm(res.node_position(f"e{i}") - res.node_position(f"p{i}"))
        assert d == pytest.approx(l, rel=1e-10)


def _crank_with_spring(k=0.2, tau=0.015):
    """The paper's slider-crank with a torsional spring on the crank hinge '1' and a constant
    actuator torque (gravity, Sec. 11)."""
    model = sd.examples.slider_crank()
    joints = []
    for j in model.joints:
        if j.name == "1":
            j = dataclasses.replace(j, stiffness=np.array([k]), reference=np.array([0.3]),
                                    actuator=sd.Constant(tau))
        joints.append(j)
    return dataclasses.replace(model, joints=tuple(joints))


def test_slider_crank_equilibrium_satisfies_virtual_work():
    k, tau, ref = 0.2, 0.015, 0.3
    model = _crank_with_spring(k, tau)
    res = static_equilibrium(model, load_steps=4)
    a1 = res.joint_coordinates("1")[0]
    assert abs(a1) > 0.05  # it moved
    # virtual displacement along the mechanism's single free motion, by kinematics of the
    # equilibrium configuration driven at +-EPS on the crank: d x_c / d alpha_1 of every body
    EPS = 1e-5
    eq = res.model  # starts at the equilibrium; its coordinates restart at 0
    kin = kinematics(eq, {"1": sd.Table([0.0, 1.0], [-EPS, EPS])}, [0.0, 1.0])
    work = tau - k * (a1 - ref)  # actuator and spring, per unit crank rotation
    for node in ("3", "6", "8"):
        x = kin.node_position(node)
        dx = (x[1] - x[0]) / (2 * EPS)
        work += model.node(node).mass * np.dot(model.gravity, dx)
    # each term is ~0.01-0.05 N m; central difference error O(EPS^2) ~ 1e-10
    assert abs(work) < 1e-8
    # the same in the compiled unknowns: generalized forces without multipliers have no
    # component along the free motion (null space of B)
    assert res.stable is not None
    assert res.residual < 1e-10 and res.constraint < 1e-10


def test_equilibrium_model_starts_at_rest_in_equilibrium():
    model = _crank_with_spring()
    res = static_equilibrium(model, load_steps=4)
    sim = sd.simulate(res.model, 0.05, 0.01)
    # nothing moves: the dynamic run stays in the static equilibrium
    assert np.abs(sim.node_position("6") - res.node_position("6")).max() < 1e-9
    assert np.abs(sim.joint_coordinates("1")).max() < 1e-8


# ---------------------------------------------------------------------------------------------
def test_mechanism_without_stiffness_is_reported_naming_the_free_joint():
    with pytest.raises(SimulationError, match="not unique or is unstable") as exc:
        static_equilibrium(_pendulum(0.0, g=0.0, spring=False))
    assert "joint 'hinge' alpha_0" in str(exc.value)


def test_gravity_alone_finds_the_hanging_pendulum_through_a_singular_start():
    # the horizontal start has zero stiffness along the swing (gravity moment at its maximum)
    res = static_equilibrium(_pendulum(0.0, spring=False), load_steps=2)
    assert res.joint_coordinates("hinge")[0] == pytest.approx(-math.pi / 2, abs=1e-9)
    assert res.stable


def test_torque_beyond_the_largest_spring_moment_stops_at_the_limit_load():
    # arm of radius r about z, a translational spring from the fixed point Q = (0, d) to the
    # tip; V = k (l - l0)^2 / 2 - tau theta with l^2 = r^2 + d^2 - 2 r d sin(theta) is
    # bounded in its slope: |tau| <= h_max = max |k (l - l0) r d cos(theta) / l|
    r, d, k = 0.2, 0.5, 100.0
    l0 = math.hypot(r, d)

    def h(th):
        ll = math.sqrt(r * r + d * d - 2 * r * d * math.sin(th))
        return k * (ll - l0) * r * d * math.cos(th) / ll

    opt = minimize_scalar(lambda th: -h(th), bounds=(-math.pi / 2, 0.0), method="bounded",
                          options={"xatol": 1e-12})
    hmax = -opt.fun
    tau = -1.5 * hmax  # clockwise: the spring stretches
    mb = sd.ModelBuilder()
    mb.node("O", fixed=True)
    mb.node("c")
    mb.node("tip", position=(r, 0.0, 0.0))
    mb.node("Q", position=(0.0, d, 0.0), fixed=True)
    mb.node("q1", position=(0.0, d, 0.0))
    mb.node("q2", position=(r, 0.0, 0.0))
    ax = np.array([r, -d, 0.0]) / l0
    mb.joint("crank", "hinge", "O", "c", axis=(0.0, 0.0, 1.0), torque=tau)
    mb.joint("arm", "rigid", "c", "tip")
    mb.joint("qpin", "hinge", "Q", "q1", axis=(0.0, 0.0, 1.0))
    mb.joint("spring", "prismatic", "q1", "q2", axis=ax, stiffness=k)
    mb.joint("tpin", "hinge", "q2", "tip", axis=(0.0, 0.0, 1.0))  # closes a planar loop
    model = mb.build()
    with pytest.raises(SimulationError, match="cannot proceed beyond load factor") as exc:
        static_equilibrium(model, load_steps=10, max_cuts=8)
    msg = str(exc.value)
    assert "worst: " in msg
    part = exc.value.result
    reached = part.load_factors[-1]
    # bisection resolution 0.1 / 2^8 = 4e-4; Newton also fails a little before the limit
    assert hmax / abs(tau) - 0.01 < reached <= hmax / abs(tau) + 1e-9
    # the partial result is an equilibrium at the load factor reached
    th = part.joint_coordinates("crank")[0]
    assert -reached * tau == pytest.approx(h(th), rel=1e-6)


def test_redundant_planar_loop_below_the_limit_converges_with_least_squares_multipliers():
    # the same planar loop (3 redundant constraint equations) with a torque below the limit
    r, d, k = 0.2, 0.5, 100.0
    l0 = math.hypot(r, d)
    mb = sd.ModelBuilder()
    mb.node("O", fixed=True)
    mb.node("c")
    mb.node("tip", position=(r, 0.0, 0.0))
    mb.node("Q", position=(0.0, d, 0.0), fixed=True)
    mb.node("q1", position=(0.0, d, 0.0))
    mb.node("q2", position=(r, 0.0, 0.0))
    mb.joint("crank", "hinge", "O", "c", axis=(0.0, 0.0, 1.0), torque=-1.0)
    mb.joint("arm", "rigid", "c", "tip")
    mb.joint("qpin", "hinge", "Q", "q1", axis=(0.0, 0.0, 1.0))
    mb.joint("spring", "prismatic", "q1", "q2", axis=np.array([r, -d, 0.0]) / l0,
             stiffness=k)
    mb.joint("tpin", "hinge", "q2", "tip", axis=(0.0, 0.0, 1.0))
    res = static_equilibrium(mb.build(), load_steps=2)
    th = res.joint_coordinates("crank")[0]
    ll = math.sqrt(r * r + d * d - 2 * r * d * math.sin(th))
    assert k * (ll - l0) * r * d * math.cos(th) / ll == pytest.approx(1.0, rel=1e-8)
    # the spring force equals k times the stretch, which is the distance change of the pins
    assert res.joint_coordinates("spring")[0] == pytest.approx(ll - l0, rel=1e-9)


@pytest.mark.parametrize("kw, field", [(dict(load_steps=0), "load_steps"),
                                       (dict(tol=0.0), "tol"), (dict(max_iter=1.5), "max_iter"),
                                       (dict(t=float("nan")), "t")])
def test_bad_arguments_raise_model_errors_naming_the_field(kw, field):
    with pytest.raises(ModelError, match=f"field '{field}'"):
        static_equilibrium(_pendulum(1.0), **kw)


def test_bad_model_argument_is_a_model_error():
    with pytest.raises(ModelError, match="model_or_system"):
        static_equilibrium("slider_crank")
