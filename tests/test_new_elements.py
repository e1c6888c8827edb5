"""Physics of the element types added with the element library: a body whose centre of mass is
away from its node, the point spring-damper, loads at a point of a body. Every reference is a
closed-form solution or an invariance of the formulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

import se3dyn as sd
from se3dyn.analysis.statics import static_equilibrium

G = 9.81


def _top(node_at_com: bool, spin=15.0):
    """A heavy symmetric top on a spherical joint at the origin: centre of mass 0.2 m up the
    tilted axis, spinning about it."""
    m, L = 2.0, 0.2
    axis = np.array([math.sin(0.3), 0.0, math.cos(0.3)])
    com = L * axis
    J = (0.02, 0.02, 0.03)  # about the centre of mass: transverse, transverse, axial
    z = np.array([0.0, 0.0, 1.0])
    k = np.cross(z, axis)
    Rp = sd.lie.exp_so3(k / np.linalg.norm(k) * math.acos(axis @ z))  # principal axes
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    kw = dict(mass=m, inertia=J, principal_axes=Rp, angular_velocity=tuple(spin * axis))
    if node_at_com:
        mb.node("top", position=tuple(com), **kw)
        mb.joint("pivot", "spherical", "ground", "top", at=(0, 0, 0))
    else:
        mb.node("top", position=(0, 0, 0), com=tuple(com), **kw)
        mb.joint("pivot", "spherical", "ground", "top")
    return mb.build(), com


def _com_path(res, node_at_com, com0):
    x = res.node_position("top")
    if node_at_com:
        return x
    R = res.H[:, res.system.node_names.index("top"), :3, :3]
    return x + R @ com0


def test_a_body_moves_the_same_whatever_point_of_it_carries_the_node():
    """The SE(3) scheme is covariant under a change of the body's reference point: with the
    node at the centre of mass (and the joint attached at the pivot) or at the pivot (with
    com=), the index-3 solutions coincide to the Newton tolerance."""
    paths = []
    for at_com in (True, False):
        model, com0 = _top(at_com)
        res = sd.simulate(model, t_end=1.0, step=2e-3, rho_inf=0.9, formulation="index3")
        paths.append(_com_path(res, at_com, com0))
    assert np.abs(paths[0] - paths[1]).max() < 1e-8


def test_index2_solutions_do_not_depend_on_the_node_placement_either():
    """The default stabilised index-2 form: the two placements give the same motion too
    (measured to round-off for this top), and it converges at second order."""
    ends = {}
    for h in (4e-3, 2e-3, 1e-3):
        p = []
        for at_com in (True, False):
            model, com0 = _top(at_com)
            res = sd.simulate(model, t_end=0.5, step=h, rho_inf=0.9)
            p.append(_com_path(res, at_com, com0)[-1])
        assert np.linalg.norm(p[0] - p[1]) < 1e-8
        ends[h] = p[1]
    e1 = np.linalg.norm(ends[4e-3] - ends[2e-3])
    e2 = np.linalg.norm(ends[2e-3] - ends[1e-3])
    assert 3.0 < e1 / e2 < 5.0  # self-convergence order 2


def test_top_with_node_at_the_pivot_conserves_energy_and_momentum_about_the_vertical():
    drift = []
    for h in (2e-3, 1e-3):
        model, _ = _top(False, spin=30.0)
        res = sd.simulate(model, t_end=1.0, step=h, rho_inf=1.0)
        E = res.kinetic + res.potential
        assert np.abs(E - E[0]).max() < 1e-3 * abs(E[0])
        drift.append(_lz_drift(res))
    # not conserved exactly by the scheme: the drift is the O(h^2) discretisation error
    assert drift[1] < 1e-3 and 3.5 < drift[0] / drift[1] < 4.5


def _lz_drift(res) -> float:
    # angular momentum about the vertical through the pivot: R (M v)_Omega for a node at the
    # pivot (the pivot does not move, gravity and the joint exert no vertical moment)
    s = res.system
    i = s.node_names.index("top")
    d = s.node_dofadr[i]
    from se3dyn.engine.workspace import engine_of

    _, lay = engine_of(s)
    Mb = dict(lay.tables["elements"])["body"]["M"][0]
    Lz = [(res.H[k, i, :3, :3] @ (Mb @ res.v[k, d:d + 6])[3:])[2] for k in range(len(res.t))]
    return float(np.ptp(Lz) / abs(Lz[0]))


def test_free_falling_body_with_the_node_off_its_centre_of_mass_drops_it_on_the_parabola():
    """Whatever the body's tumbling, its centre of mass x + R c falls on the parabola
    x_c0 + v_c0 t + g t^2 / 2 (v_c0 = v0 + w0 x c0); the node, away from it, does not. The mass
    matrix about the node couples its translation and rotation by m hat(c) (Eq. (49)
    generalised); the error is the scheme's O(h^2)."""
    g = np.array([0.0, 0.0, -G])
    x0, c0 = np.array([0.2, -0.1, 1.0]), np.array([0.3, 0.2, -0.1])
    v0, w0 = np.array([0.5, 0.0, 2.0]), np.array([1.0, -2.0, 3.0])
    err = {}
    for h in (0.02, 0.01):
        mb = sd.ModelBuilder(gravity=tuple(g))
        mb.node("b", position=tuple(x0), com=tuple(x0 + c0), mass=2.0, inertia=(0.1, 0.2, 0.3),
                velocity=tuple(v0), angular_velocity=tuple(w0))
        res = sd.simulate(mb.build(), 1.0, h, rho_inf=0.9)
        xc = res.node_position("b") + res.node_rotation("b") @ c0
        t = res.t[:, None]
        err[h] = np.abs(xc - (x0 + c0 + (v0 + np.cross(w0, c0)) * t + g * t**2 / 2)).max()
    # |w0| h ~ 0.04 at h = 0.01: the error is about (|w0| h)^2 |c0|, far below |c0|
    assert err[0.01] < 1e-3 and 3.5 < err[0.02] / err[0.01] < 4.5, err


def test_inertia_violating_the_triangle_inequality_is_refused():
    mb = sd.ModelBuilder()
    with pytest.raises(sd.ModelError, match="triangle inequality"):
        mb.node("b", mass=1.0, inertia=(1.0, 1.0, 3.0))


def test_spring_mass_oscillates_at_the_natural_frequency_with_second_order_error():
    k, m, L0, a = 40.0, 2.0, 0.5, 0.3
    w = math.sqrt(k / m)
    errs = []
    for h in (2e-3, 1e-3):
        mb = sd.ModelBuilder()
        mb.node("g", fixed=True)
        mb.node("m", position=(L0 + a, 0, 0), mass=m, inertia=(1e-2, 1e-2, 1e-2))
        mb.spring_damper("s", "g", "m", stiffness=k, length=L0)
        res = sd.simulate(mb.build(), t_end=2.0, step=h, rho_inf=1.0)
        x = res.node_position("m")[:, 0]
        errs.append(np.abs(x - (L0 + a * np.cos(w * res.t))).max())
        E = res.kinetic + res.spring
        assert np.abs(E - 0.5 * k * a * a).max() < 1e-9
    assert 3.5 < errs[0] / errs[1] < 4.5


def test_spring_damper_decays_like_the_damped_oscillator():
    k, m, c, L0, a = 40.0, 2.0, 1.2, 0.5, 0.3
    w0 = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    wd = w0 * math.sqrt(1 - zeta ** 2)
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    # points off the nodes: the line of action is still along x
    mb.node("m", position=(L0 + a + 0.1, 0, 0), mass=m, inertia=(1e-2, 1e-2, 1e-2))
    mb.spring_damper("s", "g", "m", at_a=(-0.05, 0, 0), at_b=(L0 + a - 0.05, 0, 0),
                     stiffness=k, damping=c, length=L0)
    mb.joint("slide", "prismatic", "g", "m", axis=(1, 0, 0))
    res = sd.simulate(mb.build(), t_end=2.0, step=5e-4, rho_inf=0.9)
    t = res.t
    x = res.node_position("m")[:, 0] - 0.1
    xa = L0 + a * np.exp(-zeta * w0 * t) * (np.cos(wd * t) + zeta * w0 / wd * np.sin(wd * t))
    assert np.abs(x - xa).max() < 1e-5
    # dissipated work = energy lost (the work is accumulated by the trapezoidal rule: O(h^2))
    E = res.kinetic + res.spring
    assert abs(E[0] - E[-1] - res.dissipation[-1]) < 1e-5 * E[0]


def test_hanging_spring_stretches_by_mg_over_k():
    k, m, L0 = 100.0, 3.0, 0.4
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("g", position=(0, 0, 1.0), fixed=True)
    mb.node("m", position=(0, 0, 0.5), mass=m, inertia=(1e-2, 1e-2, 1e-2))
    mb.spring_damper("s", "g", "m", stiffness=k, length=L0)
    mb.joint("guide", "prismatic", "g", "m", axis=(0, 0, 1))
    res = static_equilibrium(mb.build())
    z = res.node_position("m")[2]
    assert abs((1.0 - z) - (L0 + m * G / k)) < 1e-10


@pytest.mark.parametrize("frame", ["body", "inertial"])
def test_force_at_a_point_balances_a_torsional_spring(frame):
    """A bar on a hinge about z with a torsional spring K, a force F along y at the point
    p = (L, 0, 0) of the bar. Follower force (body frame): K theta = L F. Inertial force: the
    arm turns, K theta = L F cos(theta)."""
    K, L, F = 2.0, 0.5, 3.0
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("bar", position=(0, 0, 0), mass=1.0, inertia=(0.1, 0.1, 0.1))
    mb.joint("h", "hinge", "g", "bar", axis=(0, 0, 1), stiffness=K)
    mb.load("F", "bar", force=(0, F, 0), at=(L, 0, 0), force_frame=frame)
    res = static_equilibrium(mb.build(), load_steps=4)
    th = res.joint_coordinates("h")[0]
    ref = L * F / K if frame == "body" else brentq(lambda t: K * t - L * F * math.cos(t), 0, 2)
    assert abs(th - ref) < 1e-9


def test_inertial_torque_on_a_turning_body_keeps_its_direction():
    """A torque about the inertial z axis on a body turning about z on a hinge: the angle grows
    as T t^2 / (2 J) whatever the body's orientation."""
    J, T = 0.3, 0.6
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("b", mass=1.0, inertia=(J, J, J))
    mb.joint("h", "hinge", "g", "b", axis=(0, 0, 1))
    mb.load("T", "b", torque=(0, 0, T), torque_frame="inertial")
    res = sd.simulate(mb.build(), t_end=2.0, step=1e-2, rho_inf=0.9)
    th = res.joint_coordinates("h")[:, 0]
    assert np.abs(th - T * res.t ** 2 / (2 * J)).max() < 1e-9


def test_pd_law_tracks_a_moving_target_using_its_rate():
    """A hinge with inertia J under tau = -kp (theta - A sin wt) - kd (theta' - A w cos wt),
    starting at rest: the tracking error e obeys J e'' + kd e' + kp e = J A w^2 sin wt with
    e(0) = 0, e'(0) = -A w, solved independently here (scipy, tight tolerances)."""
    from scipy.integrate import solve_ivp

    J, kp, kd, A, f = 0.5, 40.0, 3.0, 0.4, 1.5
    w = 2 * math.pi * f
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("b", mass=1.0, inertia=(J, J, J))
    mb.joint("h", "hinge", "g", "b", axis=(0, 0, 1),
             control=sd.PD(kp=kp, kd=kd, target=sd.Sine(A, f)))
    res = sd.simulate(mb.build(), t_end=2.0, step=1e-3, rho_inf=0.9)
    def rhs(t, y):
        return [y[1], (J * A * w * w * math.sin(w * t) - kd * y[1] - kp * y[0]) / J]

    sol = solve_ivp(rhs, (0.0, 2.0), [0.0, -A * w], t_eval=res.t, rtol=1e-11, atol=1e-13)
    theta_ref = sol.y[0] + A * np.sin(w * res.t)
    assert np.abs(res.joint_coordinates("h")[:, 0] - theta_ref).max() < 2e-5


def test_newton_converges_while_a_damped_body_comes_to_rest():
    """Forces vanish with the motion: the relative residual then meets the round-off of the
    forces computed from positions (K times the round-off of the frames); Newton stops at the
    round-off of the positions instead of failing (it failed at t = 50 s before)."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("m", mass=2.0, inertia=(1e-2, 2e-2, 3e-2), velocity=(0.3, 0.1, 0.0),
            angular_velocity=(0.5, 0.2, 0.1))
    mb.bushing("b", "g", "m", stiffness=40.0, damping=4.0)
    res = sd.simulate(mb.build(), t_end=60.0, step=1e-2, rho_inf=0.9)
    assert not res.stats["failed"]
    # every mode decays at least as exp(-c t / (2 m)) = exp(-60): at rest, at its node
    assert np.abs(res.v[-1]).max() < 1e-20
    assert np.abs(res.node_position("m")[-1]).max() < 1e-20
