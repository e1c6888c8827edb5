"""JointSpace against Pinocchio (the independent reference, tests/_pinocchio_models.py): the same
serial chains built in both codes, compared at random states to 1e-10 relative (mass matrix,
rnea, nonLinearEffects, generalized gravity, aba, joint placements, LOCAL and
LOCAL_WORLD_ALIGNED Jacobians); batches give the rows of single calls; a closed loop's
joint-space dynamics against a closed form."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import se3dyn as sd
from _mechanisms import FOURBAR, delta_platform, delta_robot, parallelogram_fourbar
from _pinocchio_models import pinocchio_model, random_chain, random_states, se3dyn_model
from se3dyn.errors import ModelError

CHAINS = {
    "arm6": ("RRRRRR", False),      # a 6-axis arm: offsets, unaligned axes, rotated inertias
    "prismatic": ("PRRPR", False),  # prismatic and revolute mixed
    "floating": ("RRRR", True),     # a floating base (free flyer) carrying a chain
}
N_STATES = 20


def rel(x, ref):
    return float(np.abs(np.asarray(x) - ref).max() / max(np.abs(ref).max(), 1e-300))


@pytest.fixture(scope="module", params=sorted(CHAINS))
def pair(request):
    types, floating = CHAINS[request.param]
    chain = random_chain(types, seed=7, floating=floating)
    pm, ids = pinocchio_model(chain)
    js = sd.JointSpace(se3dyn_model(chain))
    return pm, ids, js


def test_coordinates(pair):
    pm, _, js = pair
    assert (js.nq, js.nv) == (pm.nq, pm.nv)
    assert all("joint 'j" in n or "node 'base'" in n for n in js.joint_names)


def test_dynamics_against_pinocchio(pair):
    pm, _, js = pair
    pd = pm.createData()
    Q, V, A, TAU = random_states(pm, N_STATES, seed=11)
    Mb = js.mass_matrix(Q)  # the batch
    tb = js.inverse_dynamics(Q, V, A)
    for i, (q, v, a, tau) in enumerate(zip(Q, V, A, TAU, strict=True)):
        M = pin.crba(pm, pd, q)
        M = np.triu(M) + np.triu(M, 1).T
        assert rel(Mb[i], M) <= 1e-10
        assert rel(tb[i], pin.rnea(pm, pd, q, v, a)) <= 1e-10
        assert rel(js.bias(q, v), pin.nonLinearEffects(pm, pd, q, v)) <= 1e-10
        assert rel(js.gravity(q), pin.computeGeneralizedGravity(pm, pd, q)) <= 1e-10
        assert rel(js.forward_dynamics(q, v, tau), pin.aba(pm, pd, q, v, tau)) <= 1e-10
    assert np.array_equal(Mb[3], js.mass_matrix(Q[3]))  # a batch row is the single call


def test_frames_against_pinocchio(pair):
    pm, ids, js = pair
    pd = pm.createData()
    Q = random_states(pm, N_STATES, seed=12)[0]
    for q in Q:
        pin.forwardKinematics(pm, pd, q)
        pin.computeJointJacobians(pm, pd, q)
        for i, jid in enumerate(ids):
            assert rel(js.frame_pose(q, f"L{i}"), pd.oMi[jid].homogeneous) <= 1e-10
            assert rel(js.jacobian(q, f"L{i}"),
                       pin.getJointJacobian(pm, pd, jid, pin.LOCAL)) <= 1e-10
            assert rel(js.jacobian(q, f"L{i}", frame="local_world_aligned"),
                       pin.getJointJacobian(pm, pd, jid, pin.LOCAL_WORLD_ALIGNED)) <= 1e-10


def test_bad_input():
    js = sd.JointSpace(se3dyn_model(random_chain("RR", seed=1)))
    with pytest.raises(ModelError, match="q"):
        js.mass_matrix(np.zeros(3))
    with pytest.raises(ModelError, match="frame"):
        js.jacobian(np.zeros(2), "L0", frame="world")
    with pytest.raises(KeyError, match="L1"):
        js.frame_pose(np.zeros(2), "L7")


def test_closed_loop_parallelogram():
    """A parallelogram four-bar in joint space: its one independent coordinate is the crank
    angle (the loop closed by Newton), and with the crank and rocker (centres of mass at c,
    moments J about them) and the translating coupler (mass mc) the closed forms are
    M = J1 + m1 c^2 + J3 + m3 c^2 + mc a^2, g(theta) = g (m1 c + m3 c + mc a) sin theta, the
    coupler's pose a translation by a (sin theta, 0, 1 - cos theta)."""
    a, d, c, m1, m3, mc, J1, J3 = (FOURBAR[k] for k in ("a", "d", "c", "m1", "m3", "mc", "J1",
                                                        "J3"))
    g = 9.81
    js = sd.JointSpace(parallelogram_fourbar(g))
    assert js.joint_names == ("joint 'A' alpha_0",)
    th = np.linspace(-1.2, 1.2, 7)[:, None]
    Mref = J1 + m1 * c**2 + J3 + m3 * c**2 + mc * a**2
    assert np.abs(js.mass_matrix(th)[:, 0, 0] / Mref - 1).max() <= 1e-10
    gref = g * (m1 * c + m3 * c + mc * a) * np.sin(th[:, 0])
    assert np.abs(js.gravity(th)[:, 0] - gref).max() <= 1e-10 * np.abs(gref).max()
    # a rotation about +y by theta moves the crank tip (0, 0, -a) to -a (sin theta, 0, cos theta)
    P = js.frame_pose(th, "coupler")
    assert np.abs(P[:, :3, :3] - np.eye(3)).max() <= 1e-10
    shift = -a * np.column_stack([np.sin(th[:, 0]), 0 * th[:, 0], np.cos(th[:, 0]) - 1])
    assert np.abs(P[:, :3, 3] - (np.array([d / 2, 0, -a]) + shift)).max() <= 1e-10
    # the coupler translates: with theta_dot the centripetal terms cancel in the bias (the
    # mass matrix does not depend on theta): b = g(theta)
    assert np.abs(js.bias(th, 2.0 * np.ones_like(th))[:, 0] - gref).max() <= 1e-9


def test_linearization_about_a_moving_state_against_pinocchio_derivatives():
    """About a state with motion (the 6-axis arm started with joint rates v: the initial state
    of a run, consistent accelerations and multipliers), the linear model is the derivative of
    the inverse dynamics: K = d rnea/dq, C = d rnea/dv, M = crba (Pinocchio's
    computeRNEADerivatives at q = 0, v, a); the velocity map's derivatives along the
    configuration are differences of the exact Jacobian (1e-8)."""
    chain = random_chain("RRRRRR", seed=7)
    pm, _ = pinocchio_model(chain)
    pd = pm.createData()
    v = np.array([0.8, -1.1, 0.5, 1.3, -0.7, 0.9])
    js = sd.JointSpace(se3dyn_model(chain))
    q0 = np.zeros(6)
    vel = {f"L{i}": np.split(js.jacobian(q0, f"L{i}", "local_world_aligned") @ v, 2)
           for i in range(6)}
    model = se3dyn_model(chain, vel)
    st = sd.GeneralizedAlpha().init(sd.compile_model(model))
    lin = sd.linearize(model)
    ind = lin.partition.independent
    assert np.abs(st.v[ind] - v).max() <= 1e-12  # the joint rates given
    a = st.vd[ind]
    assert rel(a, pin.aba(pm, pd, q0, v, np.zeros(6))) <= 1e-10
    dq, dv, M = pin.computeRNEADerivatives(pm, pd, q0, v, a)
    M = np.triu(M) + np.triu(M, 1).T
    assert rel(lin.M, M) <= 1e-10
    assert rel(lin.C, dv) <= 1e-8
    assert rel(lin.K, dq) <= 1e-8


def test_non_abelian_coordinates_refused():
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("ground", fixed=True)
    mb.node("bob", position=(0, 0, -1), mass=1.0, inertia=(0.1, 0.1, 0.1))
    mb.joint("ball", "spherical", "ground", "bob", at=(0, 0, 0))
    with pytest.raises(ModelError, match="joint 'ball' \\(spherical\\)"):
        sd.JointSpace(mb.build())


def test_inverse_dynamics_with_a_coupling_is_the_free_chains_projected():
    """Virtual work: with ``q_b = r q_a + o`` the coupled chain's generalized force on q_a is
    ``tau_a + r tau_b`` of the same chain without the coupling, at the same configuration, rates
    ``(v, r v)``, accelerations ``(a, r a)`` (at nonzero rates: the velocity terms too). The
    coupled chain's b reads o = 0.3 where the free one's reads 0 (``initial``)."""
    def chain(coupled):
        mb = sd.ModelBuilder(gravity=(0, -9.81, 0))
        mb.node("g", fixed=True)
        mb.node("l1", (0.2, 0, 0), mass=1.5, inertia=(0.01, 0.02, 0.03))
        mb.node("l2", (0.6, 0.05, 0), mass=0.7, inertia=(0.004, 0.01, 0.012))
        mb.joint("a", "hinge", "g", "l1", axis=(0, 0, 1), at=(0, 0, 0))
        mb.joint("b", "hinge", "l1", "l2", axis=(0, 0.6, 0.8), at=(0.4, 0, 0),
                 initial=0.3 if coupled else None)
        if coupled:
            mb.coupling("mimic", leader="a", follower="b", ratio=-1.0, offset=0.3)
        return sd.JointSpace(mb.build())

    r, o = -1.0, 0.3
    coupled, free = chain(True), chain(False)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, v, a = rng.normal(size=3)
        tau = coupled.inverse_dynamics([q], [v], [a])
        tf = free.inverse_dynamics([q, r * q + o - 0.3], [v, r * v], [a, r * a])
        np.testing.assert_allclose(tau, [tf[0] + r * tf[1]], rtol=1e-10, atol=1e-12)


def test_delta_robot_motors_to_platform_map_and_a_passive_run_keep_the_closed_form():
    """A delta robot (three RUU legs): in joint space the motor angles are the independent
    coordinates and the platform's pose is the closed-form forward kinematics (three
    spheres) with its orientation unchanged; a 2 s passive fall keeps the loops closed (scaled
    violation <= 1e-12) and the platform on the closed form of the motors' angles."""
    model = delta_robot()
    js = sd.JointSpace(model, independent=["m0", "m1", "m2"])
    assert len(js.joint_names) == 3
    rng = np.random.default_rng(11)
    th = 0.3 + rng.uniform(-0.4, 0.4, (20, 3))
    poses = js.frame_pose(th, "platform")
    for k in range(len(th)):
        assert np.abs(poses[k, :3, 3] - delta_platform(th[k])).max() <= 1e-10
        assert np.abs(poses[k, :3, :3] - np.eye(3)).max() <= 1e-10
    res = sd.simulate(model, 2.0, 2e-3, tol_constraint=1e-13)
    assert res.stats["max_constraint"] <= 1e-12
    motors = np.column_stack([res.joint_coordinates(f"m{i}")[:, 0] for i in range(3)])
    assert np.ptp(motors) > 1.0  # (the arms swing far)
    P = res.node_position("platform")
    assert max(np.abs(P[k] - delta_platform(motors[k])).max() for k in range(len(P))) <= 1e-9
