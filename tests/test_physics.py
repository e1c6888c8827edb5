"""Physics of the simulations: analytic solutions, conservation laws, invariance, convergence.

Every tolerance is derived from the known error of the method, stated next to it: the Lie-group
generalized-alpha scheme (Eqs. (38)-(44)) is second order, so global errors over a fixed horizon
are O(h^2) and halve by ~4 when h halves; with rho_inf = 1 it is the trapezoidal rule, whose
period elongation on an oscillator of frequency w is (w h)^2 / 12. A constant acceleration is
integrated exactly (Newmark formulas with consistent initial accelerations), so uniformly
accelerated joint coordinates are compared at round-off level. Constraints are enforced by Newton
to tol_constraint = 1e-11 (times the model length scale, >= 1 m).

The slider-crank runs are shared between tests (cached): h = 4e-3 and 2e-3 s over [0, 1.504] s,
8e-3 and the reference 5e-4 s over [0, 1] s.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import scipy.linalg
from scipy.special import ellipk

import se3dyn as sd
from se3dyn import lie
from se3dyn.engine.system import compile_model

G = 9.81


def _rot(axis, angle):
    """Rotation by ``angle`` about ``axis`` (independent of se3dyn.lie: scipy's expm)."""
    a = np.asarray(axis, dtype=float)
    return scipy.linalg.expm(angle * lie.hat3(a / np.linalg.norm(a)))


def _rot_batch(axis, angles):
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    K = lie.hat3(a)
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)  # Rodrigues


def _slope(h, err):
    return float(np.polyfit(np.log(h), np.log(err), 1)[0])


# ---------------------------------------------------------------------------------------------
# 1. Compound pendulum
# ---------------------------------------------------------------------------------------------
PEND_L, PEND_M, PEND_J = 0.1, 1.0, 1e-3


def _pendulum(theta0):
    """Ground - hinge (x) - massless pivot - rigid arm - bob at distance l, released from rest at
    theta0 from the downward vertical (the paper's layout of nodes 1-2-3)."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    mb.node("pivot", position=(0.0, 0.0, 0.0))
    mb.node("bob", position=(0.0, PEND_L * math.sin(theta0), -PEND_L * math.cos(theta0)),
            mass=PEND_M, inertia=(PEND_J, PEND_J, PEND_J))
    mb.joint("hinge", "hinge", "ground", "pivot", axis=(1.0, 0.0, 0.0))
    mb.joint("arm", "rigid", "pivot", "bob")
    return mb.build()


def _zero_crossings(t, y):
    i = np.flatnonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)
    # linear interpolation: O(h^3) error here since y'' = -w^2 sin(theta) = 0 at the crossing
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


@pytest.mark.parametrize("theta0_deg", [30.0, 120.0])
def test_compound_pendulum_period_is_the_elliptic_integral_period(theta0_deg):
    th0 = math.radians(theta0_deg)
    I_O = PEND_J + PEND_M * PEND_L**2
    # scipy's ellipk takes the parameter m = k^2, k = sin(theta0 / 2)
    T_exact = 4.0 * math.sqrt(I_O / (PEND_M * G * PEND_L)) * ellipk(math.sin(th0 / 2) ** 2)
    w0 = math.sqrt(PEND_M * G * PEND_L / I_O)  # small-amplitude frequency; w(theta0) <= w0
    swing = PEND_M * G * PEND_L * (1 - math.cos(th0))
    errT, errE = {}, {}
    for h in (4e-3, 2e-3):
        res = sd.simulate(_pendulum(th0), 0.8 * T_exact, h, rho_inf=1.0)
        theta = th0 + res.joint_coordinates("hinge")[:, 0]  # hinge rotates the bob about +x
        tc = _zero_crossings(res.t, theta)
        assert len(tc) == 2  # at T/4 and 3T/4
        T_num = 2.0 * (tc[1] - tc[0])
        errT[h] = abs(T_num - T_exact) / T_exact
        # trapezoidal rule (rho_inf = 1): period elongation (w h)^2 / 12 <= (w0 h)^2 / 12
        assert errT[h] <= 1.5 * (w0 * h) ** 2 / 12, (h, errT[h])
        # energy: no numerical dissipation at rho_inf = 1; bounded O((w h)^2) oscillation
        E = res.total_energy
        errE[h] = np.ptp(E) / swing
        assert errE[h] <= (w0 * h) ** 2, (h, errE[h])
        # the swing reaches -theta0 (energy conservation at the turning point)
        assert theta.min() == pytest.approx(-th0, abs=1e-3)
    # both errors are second order: halving h divides them by ~4
    assert 3.0 < errT[4e-3] / errT[2e-3] < 5.0
    assert 3.0 < errE[4e-3] / errE[2e-3] < 5.0


# ---------------------------------------------------------------------------------------------
# 2. Torque-free rigid body
# ---------------------------------------------------------------------------------------------
FREE_M, FREE_J = 2.0, np.array([1.0, 2.0, 3.0])
FREE_X0, FREE_V0, FREE_W0 = (np.array([0.1, 0.2, 0.3]), np.array([0.2, -0.1, 0.3]),
                             np.array([0.6, 1.0, -0.8]))


def _free_body(w0=FREE_W0):
    mb = sd.ModelBuilder()
    mb.node("body", position=FREE_X0, mass=FREE_M, inertia=FREE_J, velocity=FREE_V0,
            angular_velocity=w0)
    return mb.build()


def _free_body_errors(h, rho, w0=FREE_W0, t_end=2.0):
    res = sd.simulate(_free_body(w0), t_end, h, rho_inf=rho)
    R = res.node_rotation("body")
    v = res.node_velocity("body")
    L = np.einsum("nij,j,nj->ni", R, FREE_J, v[:, 3:])  # spatial angular momentum R J Omega
    p = FREE_M * np.einsum("nij,nj->ni", R, v[:, :3])  # linear momentum m R U = m xdot
    x_line = FREE_X0 + res.t[:, None] * FREE_V0
    return dict(L=np.abs(L - L[0]).max() / max(np.linalg.norm(L[0]), 1e-300),
                p=np.abs(p - p[0]).max() / np.linalg.norm(p[0]),
                K=np.ptp(res.kinetic) / res.kinetic[0],
                x=np.abs(res.node_position("body") - x_line).max() / np.linalg.norm(FREE_V0),
                wobble=np.ptp(v[:, 3:], axis=0).max())


def test_torque_free_body_conserves_momenta_and_energy_to_second_order():
    w = np.linalg.norm(FREE_W0)
    e1, e2 = _free_body_errors(0.02, 1.0), _free_body_errors(0.01, 1.0)
    # the motion is not trivial: the material angular velocity wobbles (not a principal axis)
    assert e1["wobble"] > 0.3
    for key in ("L", "p", "K", "x"):
        # global error O((w h)^2) relative to the conserved quantity (x: per unit speed, 2 s)
        assert e2[key] <= (w * 0.01) ** 2, (key, e2[key])
        assert e1[key] / e2[key] > 3.0, (key, e1[key], e2[key])


# ---------------------------------------------------------------------------------------------
# 3. Damped spring-mass on a prismatic joint
# ---------------------------------------------------------------------------------------------
SM_K, SM_C, SM_M = 40.0, 0.8, 1.0
SM_REF, SM_V0 = 0.1, 0.3  # spring reference (pre-stretch) and initial velocity


def _spring_mass():
    # gravity along -z, orthogonal to the prismatic axis x: it must not enter the motion
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("A", position=(0.0, 0.0, 0.0), fixed=True)
    mb.node("B", position=(0.0, 0.0, 0.0), mass=SM_M, inertia=(1e-2, 1e-2, 1e-2),
            velocity=(SM_V0, 0.0, 0.0))
    mb.joint("spring", "prismatic", "A", "B", axis=(1.0, 0.0, 0.0), stiffness=SM_K,
             reference=SM_REF, damping=SM_C)
    return mb.build()


def _oscillator(t, k, c, m, x0, v0, x_eq):
    """Closed form of m x'' + c x' + k (x - x_eq) = 0, underdamped."""
    w0 = math.sqrt(k / m)
    z = c / (2 * math.sqrt(k * m))
    assert z < 1
    wd = w0 * math.sqrt(1 - z * z)
    y0 = x0 - x_eq
    env = np.exp(-z * w0 * t)
    y = env * (y0 * np.cos(wd * t) + (v0 + z * w0 * y0) / wd * np.sin(wd * t))
    yd = env * (v0 * np.cos(wd * t) - (w0 * y0 + z * v0) / math.sqrt(1 - z * z) * np.sin(wd * t))
    return x_eq + y, yd


def _phase_error_bound(amplitude, w0, z, h):
    # trapezoidal rule: phase lag w^3 h^2 t / 12, times the decaying amplitude A e^{-z w t}:
    # max_t A w^3 h^2 t e^{-z w t} / 12 = A w^2 h^2 / (12 e z)
    return amplitude * (w0 * h) ** 2 / (12 * math.e * z)


def test_damped_spring_mass_converges_to_the_analytic_oscillator_with_order_two():
    w0 = math.sqrt(SM_K / SM_M)
    z = SM_C / (2 * math.sqrt(SM_K * SM_M))
    amp = math.hypot(SM_REF, SM_V0 / w0)
    hs = np.array([0.02, 0.01, 0.005])
    errs = []
    for h in hs:
        res = sd.simulate(_spring_mass(), 2.0, h, rho_inf=1.0)
        x = res.joint_coordinates("spring")[:, 0]
        xe, _ = _oscillator(res.t, SM_K, SM_C, SM_M, 0.0, SM_V0, SM_REF)
        errs.append(np.abs(x - xe).max())
        assert errs[-1] <= 1.5 * _phase_error_bound(amp, w0, z, h)
        # the node moves along the axis only: gravity is taken by the joint
        xB = res.node_position("B")
        np.testing.assert_allclose(xB[:, 0], x, atol=1e-14)
        assert np.abs(xB[:, 1:]).max() < 1e-14
    slope = _slope(hs, errs)
    assert 1.8 <= slope <= 2.2, slope


def test_damper_dissipates_the_energy_lost_by_the_oscillator():
    h = 0.005
    res = sd.simulate(_spring_mass(), 2.0, h, rho_inf=0.9)
    D = res.dissipation
    assert D[0] == 0.0
    assert np.all(np.diff(D) >= 0.0)  # c v^2 >= 0: a damper never returns energy
    # exact dissipation: E(0) - E(t) of the closed-form oscillator
    x, xd = _oscillator(res.t, SM_K, SM_C, SM_M, 0.0, SM_V0, SM_REF)
    E = 0.5 * SM_M * xd**2 + 0.5 * SM_K * (x - SM_REF) ** 2
    D_exact = E[0] - E
    w0 = math.sqrt(SM_K / SM_M)
    # O(h^2) global error on x, v (relative (w0 h)^2 ~ 1e-3) and on the trapezoidal quadrature
    assert np.abs(D - D_exact).max() <= (w0 * h) ** 2 * E[0]
    assert D[-1] > 0.5 * E[0]  # most of the energy is gone after 2 s (z w0 t = 0.8)


# ---------------------------------------------------------------------------------------------
# 4. Joint coordinates under constant efforts: exact relative motions
# ---------------------------------------------------------------------------------------------
JM = 2.0
JJ = np.array([[0.05, 0.01, 0.0], [0.01, 0.04, 0.005], [0.0, 0.005, 0.03]])  # not principal
JAX = np.array([1.0, 2.0, 2.0]) / 3.0  # oblique unit axis
TAU, FORCE, PITCH = 0.3, 1.5, 0.1
XA, XB = np.array([0.1, -0.2, 0.3]), np.array([0.4, 0.1, 0.2])


@pytest.mark.parametrize("typ", ["hinge", "prismatic", "cylindrical", "screw"])
def test_constant_joint_effort_gives_uniformly_accelerated_coordinates(typ):
    kw = {"hinge": dict(axis=JAX, torque=TAU), "prismatic": dict(axis=JAX, force=FORCE),
          "cylindrical": dict(axis=JAX, actuator=(FORCE, TAU)),
          "screw": dict(axis=JAX, pitch=PITCH, torque=TAU)}[typ]
    mb = sd.ModelBuilder()  # no gravity
    mb.node("A", position=XA, fixed=True)
    mb.node("B", position=XB, mass=JM, inertia=JJ)
    mb.joint("j", typ, "A", "B", **kw)
    res = sd.simulate(mb.build(), 1.0, 0.05, rho_inf=0.9)
    t = res.t
    q = res.joint_coordinates("j")
    Ia = JAX @ JJ @ JAX  # moment of inertia about the axis
    if typ == "hinge":
        expected, angle, slide = [TAU * t**2 / (2 * Ia)], None, 0 * t
    elif typ == "prismatic":
        expected, angle, slide = [FORCE * t**2 / (2 * JM)], 0 * t, None
    elif typ == "cylindrical":
        expected = [FORCE * t**2 / (2 * JM), TAU * t**2 / (2 * Ia)]
        angle = slide = None
    else:  # screw: translation pitch * angle, kinetic energy (I + m p^2) thetadot^2 / 2
        expected, angle, slide = [TAU * t**2 / (2 * (Ia + JM * PITCH**2))], None, None
    expected = np.stack(expected, axis=1)
    assert q.shape == expected.shape
    # constant acceleration is integrated exactly by the scheme: round-off level only
    np.testing.assert_allclose(q, expected, rtol=1e-12, atol=1e-14)
    assert np.abs(q).max() > 0.3  # it really moved
    # node B: H_B = H_A H_J with H_J = H_J0 exp(A alpha): rotation exp(angle a), slide along a
    if angle is None:
        angle = q[:, -1]
    if slide is None:
        slide = PITCH * q[:, 0] if typ == "screw" else q[:, 0]
    np.testing.assert_allclose(res.node_rotation("B"), _rot_batch(JAX, angle), atol=1e-12)
    np.testing.assert_allclose(res.node_position("B"), XB + slide[:, None] * JAX, atol=1e-12)


def test_constant_torque_on_an_offset_body_uses_the_parallel_axis_inertia():
    # hinge at the origin, body at distance d: I_O = J_zz + m d^2 (Huygens-Steiner)
    d, m, Jzz = 0.3, 2.0, 0.03
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    mb.node("pivot")
    mb.node("body", position=(d, 0.0, 0.0), mass=m, inertia=(0.05, 0.04, Jzz))
    mb.joint("hinge", "hinge", "ground", "pivot", axis=(0.0, 0.0, 1.0), torque=TAU)
    mb.joint("arm", "rigid", "pivot", "body")
    res = sd.simulate(mb.build(), 1.0, 0.05, rho_inf=0.9)
    a = res.joint_coordinates("hinge")[:, 0]
    np.testing.assert_allclose(a, TAU * res.t**2 / (2 * (Jzz + m * d * d)), rtol=1e-12,
                               atol=1e-14)
    circle = np.stack([d * np.cos(a), d * np.sin(a), 0 * a], axis=1)
    np.testing.assert_allclose(res.node_position("body"), circle, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# 5-10. The paper's slider-crank
# ---------------------------------------------------------------------------------------------
@functools.cache
def _crank(h: float, t_end: float):
    return sd.simulate(sd.examples.slider_crank(), t_end, h, rho_inf=0.9)


T_LONG = 1.504  # = 376 * 4e-3 = 752 * 2e-3: covers [0, 1.5] s
T_CONV = 1.0  # on the grids of 8e-3, 4e-3, 2e-3 and 5e-4


def _at(res, t):
    i = int(np.argmin(np.abs(res.t - t)))
    assert abs(res.t[i] - t) < 1e-12
    return i


@pytest.mark.slow
def test_slider_crank_energy_balance_error_is_second_order():
    dev = {}
    for h in (4e-3, 2e-3):
        res = _crank(h, T_LONG)
        keep = res.t <= 1.5 + 1e-12  # the actuator is on until 2 s: a smooth interval
        eb = res.energy_balance[keep]
        dev[h] = np.abs(eb - eb[0]).max()
        # K + V + spring - W_act + D is constant for the exact solution; the drift is the
        # O(h^2) global error (trapezoidal work quadrature included): c (w h)^2 K_max with
        # w = max |alphadot_1| (~18.5 rad/s, the fastest motion) and c = O(1); the largest
        # deviation is a transient around t = 0.73 s where the crank is fastest
        w = np.abs(res.joint_velocities("1")[keep]).max()
        assert dev[h] <= 3.0 * (w * h) ** 2 * res.kinetic[keep].max(), (h, dev[h])
    assert 3.0 < dev[4e-3] / dev[2e-3] < 5.0, dev


def _dist(a, b):
    return np.linalg.norm(a - b, axis=1)


@pytest.mark.slow
def test_slider_crank_constraints_hold_at_every_step():
    res = _crank(2e-3, T_LONG)
    # Newton enforces Eq. (40) to tol_constraint x length scale (1 m) = 1e-11
    assert res.constraint.max() < 1e-10
    x = {k: res.node_position(k) for k in "123456789"}
    R = {k: res.node_rotation(k) for k in "123456789"}
    tol = 1e-10  # metres and radians: the vectorial map vanishes to ~1e-11
    # hinge (1), spherical (4), hinge (7): coincident nodes
    for a, b in (("1", "2"), ("4", "5"), ("7", "8")):
        assert _dist(x[a], x[b]).max() < tol, (a, b)
    # rigid constraints (2), (3), (5), (6) keep the Table 2 distances
    for a, b, L in (("2", "3", 0.04), ("3", "4", 0.04), ("5", "6", 0.15), ("6", "7", 0.15)):
        assert np.abs(_dist(x[a], x[b]) - L).max() < tol, (a, b)
    for a, b in (("2", "3"), ("3", "4"), ("5", "6"), ("6", "7")):
        assert np.abs(R[a] - R[b]).max() < tol, (a, b)
    # the crank turns about the x-axis by the hinge (1) coordinate
    a1 = res.joint_coordinates("1")[:, 0]
    assert np.abs(R["2"] - _rot_batch((1, 0, 0), a1)).max() < tol
    # the slider stays on the line y = z = 0 (cylindrical (8) along x through node 9); the
    # joint coordinates are the motion of its node B = 9 relative to A = 8 (H_9 = H_8 H_J), so
    # the slider moves by minus them: H_8 = H_9 H_J^-1
    assert np.abs(x["8"][:, 1:]).max() < tol
    c8 = res.joint_coordinates("8")
    assert np.abs(x["8"][:, 0] - (0.2 - c8[:, 0])).max() < tol
    assert np.abs(R["8"] - _rot_batch((1, 0, 0), -c8[:, 1])).max() < tol
    assert np.ptp(c8[:, 0]) > 0.05  # the slider really slides
    # hinge (7): the rod turns relative to the slider about its axis (0, 0.2, -0.1)/sqrt(0.05)
    a7 = res.joint_coordinates("7")[:, 0]
    axis7 = np.array([0.0, 0.2, -0.1]) / math.sqrt(0.05)
    rel = np.einsum("nji,njk->nik", R["7"], R["8"])
    assert np.abs(rel - _rot_batch(axis7, a7)).max() < tol
    # and the motion is genuinely three-dimensional
    assert np.ptp(x["6"], axis=0).min() > 0.01


@pytest.mark.slow
def test_slider_crank_converges_with_order_two():
    # node 6 at t = 1 s for h = 8e-3, 4e-3, 2e-3 against a reference computed with h = 5e-4;
    # the reference's own error is (5e-4 / h)^2 <= 1/16 of the others, which biases the fitted
    # slope by < 0.05
    hs = [8e-3, 4e-3, 2e-3]
    ref = _crank(5e-4, T_CONV)
    x_ref = ref.node_position("6")[_at(ref, T_CONV)]
    errs = []
    for h in hs:
        res = _crank(h, T_CONV if h > 5e-3 else T_LONG)
        errs.append(np.linalg.norm(res.node_position("6")[_at(res, T_CONV)] - x_ref))
    slope = _slope(hs, errs)
    assert 1.7 <= slope <= 2.3, (slope, errs)


def moved_slider_crank(Q, d, frames: bool) -> sd.Model:
    """``examples.slider_crank`` under the superposed rigid motion x -> Q x + d.

    ``frames=False``: node frames start at the identity (the paper's choice), inertia tensors are
    rotated (Q J Q^T, full tensors). ``frames=True``: node frames start at Q with the Table 3
    principal values about principal axes Q. Joint axes and gravity are rotated in both.
    """
    Q = np.asarray(Q, dtype=float)
    d = np.asarray(d, dtype=float)
    mb = sd.ModelBuilder(gravity=Q @ np.array([0.0, 0.0, -9.81]), name="moved")

    def node(name, pos, mass=0.0, J=None, fixed=False):
        kw = {"orientation": Q} if frames else {}
        if J is not None:
            kw.update(dict(inertia=J, principal_axes=Q) if frames
                      else dict(inertia=Q @ np.diag(J) @ Q.T))
        mb.node(name, position=Q @ np.asarray(pos) + d, mass=mass, fixed=fixed, **kw)

    node("1", (0.0, 0.1, 0.12), fixed=True)
    node("2", (0.0, 0.1, 0.12))
    node("3", (0.0, 0.1, 0.16), mass=0.12, J=(1e-4, 1e-4, 1e-5))
    node("4", (0.0, 0.1, 0.2))
    node("5", (0.0, 0.1, 0.2))
    node("6", (0.1, 0.05, 0.1), mass=0.5, J=(4e-3, 4e-4, 4e-3))
    node("7", (0.2, 0.0, 0.0))
    node("8", (0.2, 0.0, 0.0), mass=2.0, J=(1e-4, 1e-4, 1e-4))
    node("9", (0.2, 0.0, 0.0), fixed=True)
    s = math.sqrt(0.05)
    mb.joint("1", "hinge", "1", "2", axis=Q @ np.array([1.0, 0.0, 0.0]),
             torque=sd.Step(0.015, 0.0, 2.0))
    mb.joint("2", "rigid", "2", "3")
    mb.joint("3", "rigid", "3", "4")
    mb.joint("4", "spherical", "4", "5", axes=Q.T)  # rows: the rotated axes Q e_i
    mb.joint("5", "rigid", "5", "6")
    mb.joint("6", "rigid", "6", "7")
    mb.joint("7", "hinge", "7", "8", axis=Q @ np.array([0.0, 0.2 / s, -0.1 / s]))
    mb.joint("8", "cylindrical", "8", "9", axis=Q @ np.array([1.0, 0.0, 0.0]),
             damping=(1.0, 0.0))
    return mb.build()


@pytest.mark.parametrize("frames", [False, True], ids=["identity_frames", "rotated_frames"])
def test_slider_crank_is_invariant_under_a_superposed_rigid_motion(frames):
    Q = _rot((0.3, -1.0, 0.5), 2.0)
    d = np.array([1.5, -0.7, 2.0])
    h, T = 1e-2, 1.0
    ref = _crank(h, T)
    mov = sd.simulate(moved_slider_crank(Q, d, frames), T, h, rho_inf=0.9)
    # x' = Q x + d for every node; R' = Q R Q^T (identity initial frames) or Q R (frames at Q);
    # relative coordinates identical. Differences come from round-off and Newton tolerances
    # (1e-10 relative per step) accumulated over 100 steps: 1e-9 is ample
    for k in "123456789":
        np.testing.assert_allclose(mov.node_position(k), ref.node_position(k) @ Q.T + d,
                                   atol=1e-9, err_msg=f"node {k}")
        Rm, Rr = mov.node_rotation(k), ref.node_rotation(k)
        expected = Q @ Rr if frames else Q @ Rr @ Q.T
        np.testing.assert_allclose(Rm, expected, atol=1e-9, err_msg=f"node {k}")
    for j in "1478":
        np.testing.assert_allclose(mov.joint_coordinates(j), ref.joint_coordinates(j),
                                   atol=1e-9, err_msg=f"joint {j}")
    # energies are invariant too (gravity rotated with the mechanism)
    np.testing.assert_allclose(mov.kinetic, ref.kinetic, atol=1e-10)
    np.testing.assert_allclose(mov.potential - mov.potential[0],
                               ref.potential - ref.potential[0], atol=1e-10)


def test_moved_slider_crank_with_identity_motion_is_the_example():
    m0 = sd.examples.slider_crank()
    m1 = moved_slider_crank(np.eye(3), np.zeros(3), frames=False)
    s0, s1 = compile_model(m0), compile_model(m1)
    np.testing.assert_array_equal(s0.node_H0, s1.node_H0)
    np.testing.assert_array_equal(s0.node_J, s1.node_J)
    assert [j.type for j in m0.joints] == [j.type for j in m1.joints]
    for j0, j1 in zip(m0.joints, m1.joints, strict=True):
        np.testing.assert_allclose(j0.A, j1.A, atol=1e-15)


def test_slider_crank_sizes_are_those_of_the_paper():
    s = compile_model(sd.examples.slider_crank())
    # Sec. 11.1: 9 nodes, 2 clamped -> 42 nodal unknowns + 7 relative coordinates
    assert (s.nq, s.nm, s.N) == (49, 48, 97)


@pytest.mark.slow
def test_crank_node_velocity_is_along_material_y_only():
    # Fig. 4: node 3 sits 0.04 m above the hinge axis x on the crank; in its material frame its
    # velocity is Omega x r = (alphadot, 0, 0) x (0, 0, 0.04) = (0, -0.04 alphadot, 0)
    res = _crank(4e-3, T_LONG)
    v = res.node_velocity("3", frame="material")
    ad = res.joint_velocities("1")[:, 0]
    assert np.abs(v[:, [0, 2]]).max() < 1e-10
    np.testing.assert_allclose(v[:, 1], -0.04 * ad, atol=1e-10)
    np.testing.assert_allclose(v[:, 3], ad, atol=1e-10)
    assert np.abs(v[:, 4:]).max() < 1e-10
    vi = res.node_velocity("3", frame="inertial")
    # the crank turns about the inertial x-axis: xdot has y and z components, no x component
    # (the paper's Fig. 4b text says "x and y"; for this mechanism it is y and z)
    assert np.abs(vi[:, 0]).max() < 1e-10
    assert np.abs(vi[:, 1]).max() > 1e-2 and np.abs(vi[:, 2]).max() > 1e-2
    np.testing.assert_allclose(np.linalg.norm(vi[:, :3], axis=1), 0.04 * np.abs(ad), atol=1e-10)


@pytest.mark.slow
def test_hinge_coordinate_passes_two_pi_without_wrapping():
    # Fig. 3b: the relative coordinate of hinge (1) exceeds 2 pi (Eq. (60) sums increments)
    res = _crank(4e-3, T_LONG)
    a = res.joint_coordinates("1")[:, 0]
    ad = res.joint_velocities("1")[:, 0]
    assert a.max() > 2 * math.pi
    # continuous: each step moves it by ~h alphadot, never by a multiple of 2 pi
    assert np.abs(np.diff(a)).max() < 1.5 * 4e-3 * np.abs(ad).max()
    # and it is the actual rotation of the crank, beyond 2 pi
    np.testing.assert_allclose(res.node_rotation("2"), _rot_batch((1, 0, 0), a), atol=1e-10)


@pytest.mark.slow
def test_slider_damper_dissipates_energy_monotonically():
    res = _crank(4e-3, T_LONG)
    D = res.dissipation
    assert np.all(np.diff(D) >= 0.0)
    assert D[-1] > 0.0
    # D = int c v^2 dt with c = 1 N s/m on the slider translation (trapezoidal, O(h^2))
    v = res.joint_velocities("8")[:, 0]
    D_ref = np.concatenate([[0.0], np.cumsum(0.5 * np.diff(res.t) * (v[1:] ** 2 + v[:-1] ** 2))])
    np.testing.assert_allclose(D, D_ref, rtol=1e-9, atol=1e-15)


def test_newton_converges_for_steps_from_1e_1_to_1e_6():
    model = sd.examples.slider_crank()
    for h in (1e-1, 1e-2, 1e-4, 1e-6):
        res = sd.simulate(model, 4 * h, h, rho_inf=0.9)
        assert len(res.t) == 5
        # the scaled iteration matrix has O(1) entries for any h: few iterations per step
        assert res.iterations[1:].max() <= 8, (h, res.iterations)
        assert res.constraint.max() < 1e-10


# ---------------------------------------------------------------------------------------------
# 10. Numerical damping does not spoil momentum conservation
# ---------------------------------------------------------------------------------------------
def test_free_body_momentum_with_numerical_damping():
    # rho_inf < 1 damps only high frequencies; a free rigid body has none: its momenta are
    # conserved to the same O(h^2) as with rho_inf = 1
    w = np.linalg.norm(FREE_W0)
    e1, e2 = _free_body_errors(0.02, 0.9), _free_body_errors(0.01, 0.9)
    for key in ("L", "p", "K"):
        assert e2[key] <= (w * 0.01) ** 2, (key, e2[key])
        assert e1[key] / e2[key] > 3.0, (key, e1[key], e2[key])
    # without rotation the uniform translation is reproduced exactly: momentum to round-off
    e0 = _free_body_errors(0.02, 0.9, w0=np.zeros(3))
    assert e0["p"] < 1e-14 and e0["x"] < 1e-14


# ---------------------------------------------------------------------------------------------
# 11. Universal joint
# ---------------------------------------------------------------------------------------------
def test_universal_joint_keeps_the_cross_axes_perpendicular():
    a1, a2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("ground", fixed=True)
    mb.node("yoke")
    mb.node("body", position=(0.15, 0.1, -0.4), mass=1.0, inertia=(0.01, 0.02, 0.03))
    mb.joint("u", "universal", "ground", "yoke", axes=[a1, a2])
    mb.joint("arm", "rigid", "yoke", "body")
    h = 5e-3
    res = sd.simulate(mb.build(), 1.0, h, rho_inf=1.0)
    q = res.joint_coordinates("u")
    assert q.shape == (len(res.t), 2)
    assert np.ptp(q, axis=0).min() > 0.3  # both hinges of the cross move (spatial pendulum)
    R = res.node_rotation("body")
    # axis 1 is fixed in the ground, axis 2 is carried by the body: they stay at 90 degrees
    cosang = np.einsum("i,nij,j->n", a1, R, a2)
    assert np.abs(cosang).max() < 1e-12
    # R_body = exp(q1 a1) exp(q2 a2): first hinge on the ground side, second on the body side
    expected = _rot_batch(a1, q[:, 0]) @ _rot_batch(a2, q[:, 1])
    np.testing.assert_allclose(R, expected, atol=1e-12)
    # the pivot does not move and energy is conserved to O((w h)^2) (w ~ sqrt(g / l) ~ 5 /s)
    assert np.abs(res.node_position("yoke")).max() < 1e-12
    E = res.total_energy
    assert np.ptp(E) <= (5.0 * h) ** 2 * abs(res.potential[0] - res.potential.min())


# ---------------------------------------------------------------------------------------------
# 12. PD control
# ---------------------------------------------------------------------------------------------
def test_pd_controlled_hinge_follows_the_closed_form_second_order_response():
    I_ax, kp, kd, target = 0.05, 2.0, 0.1, 0.7
    w0 = math.sqrt(kp / I_ax)
    z = kd / (2 * math.sqrt(kp * I_ax))
    errs = {}
    for h in (0.01, 0.005):
        mb = sd.ModelBuilder()  # no gravity
        mb.node("ground", fixed=True)
        mb.node("rotor", mass=1.0, inertia=(0.02, 0.03, I_ax))
        mb.joint("servo", "hinge", "ground", "rotor", axis=(0.0, 0.0, 1.0),
                 control=sd.PD(kp, kd, target))
        res = sd.simulate(mb.build(), 3.0, h, rho_inf=1.0)
        a = res.joint_coordinates("servo")[:, 0]
        # I a'' + kd a' + kp (a - target) = 0, a(0) = 0, a'(0) = 0
        ae, _ = _oscillator(res.t, kp, kd, I_ax, 0.0, 0.0, target)
        errs[h] = np.abs(a - ae).max()
        assert errs[h] <= 1.5 * _phase_error_bound(target, w0, z, h)
    assert 3.0 < errs[0.01] / errs[0.005] < 5.0
    assert abs(a[-1] - target) < 0.1 * target  # settles towards the target (e^{-z w0 t})


# ---------------------------------------------------------------------------------------------
# 13. External loads
# ---------------------------------------------------------------------------------------------
def test_constant_inertial_force_accelerates_the_center_uniformly_while_spinning():
    m, F = 2.0, np.array([0.5, -1.0, 2.0])
    x0, v0, w0 = np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.0, 0.0]), np.array([0.5, 1.0, -2.0])
    err = {}
    for h in (0.02, 0.01):
        mb = sd.ModelBuilder()
        mb.node("body", position=x0, mass=m, inertia=(0.1, 0.2, 0.3), velocity=v0,
                angular_velocity=w0)
        mb.load("thrust", "body", force=F)  # inertial frame: independent of the rotation
        res = sd.simulate(mb.build(), 1.0, h, rho_inf=0.9)
        x = res.node_position("body")
        t = res.t[:, None]
        x_exact = x0 + v0 * t + F * t**2 / (2 * m)
        err[h] = np.abs(x - x_exact).max()
        # the body turns by ~2 rad: a force fixed in the body would miss the parabola by O(1);
        # the scheme's O(h^2) coupling error is ~ (|w| h)^2 relative to the displacement
        disp = np.linalg.norm(x_exact[-1] - x0)
        assert err[h] <= (np.linalg.norm(w0) * h) ** 2 * disp, (h, err[h])
        # work of the load = gain of kinetic energy
        np.testing.assert_allclose(res.kinetic - res.kinetic[0], res.work_loads,
                                   atol=10 * (np.linalg.norm(w0) * h) ** 2 * res.work_loads[-1])
    assert err[0.02] / err[0.01] > 3.0


def test_constant_material_torque_about_a_principal_axis_spins_up_linearly():
    J3, Mz = 0.3, 0.6
    mb = sd.ModelBuilder()
    mb.node("body", position=(1.0, 2.0, 3.0), mass=2.0, inertia=(0.1, 0.2, J3))
    mb.load("motor", "body", torque=(0.0, 0.0, Mz))
    res = sd.simulate(mb.build(), 1.0, 0.05, rho_inf=0.9)
    w = res.node_velocity("body", frame="material")[:, 3:]
    # Euler's equations with Omega = (0, 0, w3): w3 = M t / J3, exact for constant acceleration
    np.testing.assert_allclose(w[:, 2], Mz * res.t / J3, rtol=1e-12, atol=1e-14)
    assert np.abs(w[:, :2]).max() < 1e-14
    np.testing.assert_allclose(res.node_rotation("body"),
                               _rot_batch((0, 0, 1), Mz * res.t**2 / (2 * J3)), atol=1e-12)
    np.testing.assert_allclose(res.node_position("body"), np.tile([1.0, 2.0, 3.0], (len(res.t),
                                                                                     1)),
                               atol=1e-14)


# ---------------------------------------------------------------------------------------------
# 14. Failures
# ---------------------------------------------------------------------------------------------
def _kicked_pendulum(kick):
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    mb.node("pivot")
    mb.node("bob", position=(0.2, 0.0, 0.0), mass=1.0, inertia=(0.01, 0.01, 0.01))
    mb.joint("ball", "spherical", "ground", "pivot", stiffness=1e3)
    mb.joint("arm", "rigid", "pivot", "bob")
    mb.load("kick", "bob", torque=kick)
    return mb.build()


def test_newton_failure_names_time_and_step_and_keeps_the_results():
    # a torque of 1e6 N m switched on at t = 0.05 s turns the bob by ~1e4 rad in one step:
    # no Newton iteration can converge
    model = _kicked_pendulum(sd.Step((1e6, 1e6 / 3, 1e6 / 2), start=0.05))
    h, t_end = 0.01, 0.2
    with pytest.raises(sd.NewtonError) as info:
        sd.simulate(model, t_end, h)
    err = info.value
    assert isinstance(err, sd.SimulationError)
    assert err.t == pytest.approx(0.05) and err.h == pytest.approx(h)
    msg = str(err)
    assert "t=0.05" in msg and "h=0.01" in msg
    res = err.result
    assert res is not None and len(res.t) > 1 and res.t[-1] < t_end
    assert res.t[-1] == pytest.approx(err.t - err.h)
    # before the kick nothing moves (no gravity, no velocity): the stored states are the rest
    assert np.abs(res.joint_coordinates("ball")).max() < 1e-14
    assert np.all(np.isfinite(res.H))


def _nan_torque_model():
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    mb.node("rotor", position=(0.2, 0.0, 0.0), mass=1.0, inertia=(0.01, 0.01, 0.01))
    mb.joint("motor", "hinge", "ground", "rotor", axis=(0.0, 0.0, 1.0),
             torque=lambda t: 0.015 if t <= 0.05 else float("nan"))
    return mb.build()


def test_non_finite_time_function_stops_with_time_and_results():
    with pytest.raises(sd.SimulationError) as info:
        sd.simulate(_nan_torque_model(), 0.2, 0.01)
    assert "t=0.06" in str(info.value)
    res = info.value.result
    assert len(res.t) > 1 and res.t[-1] == pytest.approx(0.05)
    # the converged part is the uniformly accelerated rotor: alpha = tau t^2 / (2 J)
    np.testing.assert_allclose(res.joint_coordinates("motor")[:, 0], 0.015 * res.t**2 / 0.02,
                               rtol=1e-12)


def test_non_finite_time_function_error_names_the_step():
    with pytest.raises(sd.SimulationError) as info:
        sd.simulate(_nan_torque_model(), 0.2, 0.01)
    assert "0.01" in str(info.value)


def test_non_finite_time_function_error_names_the_joint():
    with pytest.raises(sd.SimulationError) as info:
        sd.simulate(_nan_torque_model(), 0.2, 0.01)
    assert "'motor'" in str(info.value)


# ---------------------------------------------------------------------------------------------
# Springs on non-abelian joints (log coordinates)
# ---------------------------------------------------------------------------------------------
def test_isotropic_spherical_spring_is_a_harmonic_oscillator():
    # isotropic inertia J and stiffness K, rotation vector theta = log(R): for an initial spin
    # w0 about u the motion stays about u with theta = (w0 / W) sin(W t), W = sqrt(K / J)
    # (V = K |theta|^2 / 2 and T(theta u) u = u, so the torque is -K theta u)
    J, K = 0.02, 0.5
    u = np.array([1.0, -2.0, 2.0]) / 3.0
    w0 = 3.0
    W = math.sqrt(K / J)
    assert w0 / W < math.pi  # log coordinates stay below pi
    err = {}
    for h in (0.01, 0.005):
        mb = sd.ModelBuilder()
        mb.node("ground", fixed=True)
        mb.node("ball", mass=1.0, inertia=(J, J, J), angular_velocity=w0 * u)
        mb.joint("socket", "spherical", "ground", "ball", stiffness=K)
        res = sd.simulate(mb.build(), 1.0, h, rho_inf=1.0)
        th = res.joint_coordinates("socket")
        th_exact = (w0 / W) * np.sin(W * res.t)[:, None] * u
        err[h] = np.abs(th - th_exact).max()
        # trapezoidal phase error: amplitude (w0/W) x W^3 h^2 t / 12 at t = 1 s
        assert err[h] <= 1.5 * (w0 / W) * W**3 * h**2 * 1.0 / 12, (h, err[h])
        np.testing.assert_allclose(res.node_rotation("ball"), _rot_batch(u, th @ u),
                                   atol=1e-12)
    assert 3.0 < err[0.01] / err[0.005] < 5.0


@pytest.mark.parametrize("typ", ["spherical", "planar"])
def test_anisotropic_spring_on_a_non_abelian_joint_conserves_energy(typ):
    # a spring on the log coordinates alpha of a non-abelian joint, V = (alpha - alpha0)^T K
    # (alpha - alpha0) / 2, exerts T_A(alpha)^-T K (alpha - alpha0), the gradient of V along the
    # joint's motion: undamped (rho_inf = 1), kinetic + spring energy is conserved up to the
    # scheme's O(h^2) error. (The isotropic spring above cannot tell K alpha from it:
    # T(theta)^T theta = theta; with a reference and unequal stiffnesses it can, by O(1).)
    drift = {}
    for h in (0.01, 0.005):
        mb = sd.ModelBuilder()
        mb.node("ground", fixed=True)
        kw = dict(normal=(0.0, 0.0, 1.0)) if typ == "planar" else {}
        w0 = (0.0, 0.0, 2.0) if typ == "planar" else (1.0, -2.0, 1.5)
        v0 = (0.3, -0.2, 0.0) if typ == "planar" else None
        mb.node("b", mass=1.0, inertia=(0.02, 0.03, 0.04), velocity=v0, angular_velocity=w0)
        mb.joint("j", typ, "ground", "b", stiffness=(0.5, 1.0, 1.5), reference=(0.4, -0.3, 0.2),
                 **kw)
        res = sd.simulate(mb.build(), 2.0, h, rho_inf=1.0)
        assert np.abs(res.joint_coordinates("j")).max() > 0.5  # large rotations and slides
        E = res.kinetic + res.spring
        drift[h] = np.ptp(E) / E[0]
    assert drift[0.005] < 1e-4 and 3.5 < drift[0.01] / drift[0.005] < 4.5, drift


# ---------------------------------------------------------------------------------------------
# A chain with a moving hinge against the Lagrange equations in minimal coordinates
# ---------------------------------------------------------------------------------------------
DP = dict(m1=1.0, m2=0.7, l1=0.4, l2=0.3, J1=0.01, J2=0.005, beta=0.8, w1=2.0, w2=-3.0)


def _double_pendulum():
    """Planar double pendulum in the x-y plane, gravity along -y: ground - hinge (z) - pivot -
    rigid - body 1 at distance l1; body 1 - hinge (z) - pivot 2 - rigid - body 2 at distance l2,
    bent by beta, with consistent initial velocities of the two bodies."""
    p = DP
    mb = sd.ModelBuilder(gravity=(0.0, -G, 0.0))
    mb.node("ground", fixed=True)
    mb.node("p1")
    mb.node("b1", position=(p["l1"], 0.0, 0.0), mass=p["m1"], inertia=(p["J1"],) * 3,
            velocity=(0.0, p["w1"] * p["l1"], 0.0), angular_velocity=(0.0, 0.0, p["w1"]))
    mb.node("p2", position=(p["l1"], 0.0, 0.0))
    x2 = np.array([p["l1"] + p["l2"] * math.cos(p["beta"]), p["l2"] * math.sin(p["beta"]), 0.0])
    v2 = (np.cross([0, 0, p["w1"]], x2) + np.cross([0, 0, p["w2"]], x2 - [p["l1"], 0, 0]))
    mb.node("b2", position=x2, mass=p["m2"], inertia=(p["J2"],) * 3, velocity=v2,
            angular_velocity=(0.0, 0.0, p["w1"] + p["w2"]))
    mb.joint("h1", "hinge", "ground", "p1", axis=(0.0, 0.0, 1.0))
    mb.joint("r1", "rigid", "p1", "b1")
    mb.joint("h2", "hinge", "b1", "p2", axis=(0.0, 0.0, 1.0))
    mb.joint("r2", "rigid", "p2", "b2")
    return mb.build()


def _double_pendulum_rhs(t, y):
    """Lagrange equations in the absolute angles (phi1, phi2) of the two links."""
    p = DP
    p1, p2, d1, d2 = y
    D = p2 - p1
    c = p["m2"] * p["l1"] * p["l2"]
    M = np.array([[(p["m1"] + p["m2"]) * p["l1"] ** 2 + p["J1"], c * math.cos(D)],
                  [c * math.cos(D), p["m2"] * p["l2"] ** 2 + p["J2"]]])
    q = np.array([-c * math.sin(D) * d2**2, c * math.sin(D) * d1**2])
    # V = (m1 + m2) g l1 sin(phi1) + m2 g l2 sin(phi2)
    grav = np.array([(p["m1"] + p["m2"]) * G * p["l1"] * math.cos(p1),
                     p["m2"] * G * p["l2"] * math.cos(p2)])
    acc = np.linalg.solve(M, -q - grav)
    return [d1, d2, acc[0], acc[1]]


def _joint_dof(res, name):
    s = res.system
    return s.joint_dofadr[list(s.joint_names).index(name)]


def test_double_pendulum_matches_the_lagrange_equations_in_minimal_coordinates():
    from scipy.integrate import solve_ivp

    beta = DP["beta"]
    err = {}
    for h in (0.01, 0.005):
        res = sd.simulate(_double_pendulum(), 1.0, h, rho_inf=0.9)
        a1 = res.joint_coordinates("h1")[:, 0]
        a2 = res.joint_coordinates("h2")[:, 0]
        w1, w2 = res.joint_velocities("h1")[0, 0], res.joint_velocities("h2")[0, 0]
        y0 = [0.0, beta, w1, w1 + w2]  # phi1 = alpha1, phi2 = alpha1 + alpha2 + beta
        sol = solve_ivp(_double_pendulum_rhs, (0.0, 1.0), y0, method="DOP853", rtol=1e-12,
                        atol=1e-12, dense_output=True)
        Y = sol.sol(res.t)
        err[h] = max(np.abs(a1 - Y[0]).max(), np.abs(a1 + a2 + beta - Y[1]).max())
        # initial accelerations are consistent (Sec. 5.2): the joint accelerations at t = 0 are
        # those of the Lagrange equations at the same state (no time-integration error yet)
        acc = _double_pendulum_rhs(0.0, y0)
        vd0 = res.vd[0]
        np.testing.assert_allclose([vd0[_joint_dof(res, "h1")], vd0[_joint_dof(res, "h2")]],
                                   [acc[2], acc[3] - acc[2]], rtol=1e-9)
    # global error O(h^2): ~ (w h)^2 with w ~ 20 rad/s the fastest relative rate here
    assert err[0.005] <= (20 * 0.005) ** 2 * 0.1
    assert 3.0 < err[0.01] / err[0.005] < 5.0, err


def test_consistent_initial_body_velocities_are_kept():
    l, v = 0.5, 1.0
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    mb.node("pivot")
    mb.node("bob", position=(0.0, 0.0, -l), mass=1.0, inertia=(1e-3, 1e-3, 1e-3),
            velocity=(0.0, v, 0.0), angular_velocity=(v / l, 0.0, 0.0))  # consistent
    mb.joint("hinge", "hinge", "ground", "pivot", axis=(1.0, 0.0, 0.0))
    mb.joint("arm", "rigid", "pivot", "bob")
    res = sd.simulate(mb.build(), 1e-3, 1e-3)
    assert res.joint_velocities("hinge")[0, 0] == pytest.approx(v / l, rel=1e-12)
    np.testing.assert_allclose(res.node_velocity("bob", frame="inertial")[0],
                               [0.0, v, 0.0, v / l, 0.0, 0.0], atol=1e-12)


def test_joint_multipliers_are_the_support_wrench_on_node_b():
    # a cantilever at rest: ground - weld - massless node at the origin - beam - body at
    # (L, 0, 0). Statics: the weight pulls the root with (0, 0, -m g) applied at (L, 0, 0), i.e.
    # a moment (L, 0, 0) x (0, 0, -m g) = (0, m g L, 0); the weld's wrench on its node B (the
    # root) balances it: lambda = (0, 0, m g, 0, -m g L, 0), material (= inertial) frame
    m, L = 2.0, 0.5
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("ground", fixed=True)
    mb.node("root")
    mb.node("tip", position=(L, 0.0, 0.0), mass=m, inertia=(0.1, 0.1, 0.1))
    mb.joint("weld", "rigid", "ground", "root")
    mb.joint("beam", "rigid", "root", "tip")
    res = sd.simulate(mb.build(), 0.05, 0.01)
    np.testing.assert_allclose(res.joint_multipliers("weld"),
                               np.tile([0, 0, m * G, 0, -m * G * L, 0], (len(res.t), 1)),
                               atol=1e-10)
    # the beam joint acts at the tip itself: pure force, no moment
    np.testing.assert_allclose(res.joint_multipliers("beam"),
                               np.tile([0, 0, m * G, 0, 0, 0], (len(res.t), 1)), atol=1e-10)
    assert np.abs(res.node_position("tip") - [L, 0.0, 0.0]).max() < 1e-12


def test_spherical_joint_coordinates_are_the_relative_rotation_vector():
    # for a non-abelian joint the coordinates are log(H_J0^-1 H_J) in the basis A: with
    # coinciding, initially aligned nodes 4 and 5 (Table 2) that is log_so3(R_4^T R_5)
    res = _crank(1e-2, 1.0)
    rel = np.einsum("nji,njk->nik", res.node_rotation("4"), res.node_rotation("5"))
    np.testing.assert_allclose(res.joint_coordinates("4"), sd.lie.log_so3(rel), rtol=0,
                               atol=1e-10)
    assert np.abs(res.joint_coordinates("4")).max() > 1.0  # a large relative rotation
