"""Rigid joints condensed for the time loop (:mod:`se3dyn.dynamics.condense`).

What is asserted:

* With the paper's index-3 form the condensed run is the paper's discrete motion: every node of
  the slider-crank of Sec. 11 (the auxiliary massless nodes included) and every multiplier
  (the rigid joints' reactions, recovered from the members' equations of motion) agree with
  the run that keeps the rigid joints, to the Newton tolerances.
* The reaction of a rigid joint is Newton's second law of the body it carries: on a swinging
  pendulum whose bob is a point mass joined rigidly to the rod, ``R lambda_U = m (a - g)``.
* A body built from rigidly joined massive nodes moves exactly as the same body built as one
  node with the combined centre of mass and inertia (parallel-axis rule), in both formulations.
* What is not condensed: loops of rigid joints, two fixed nodes, a member loaded in its body
  frame with another orientation than its root's; the results are then those of the model.
* Restarts of condensed runs are bit-exact; dense output of a condensed run agrees with the
  run that keeps the rigid joints.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import se3dyn as sd
from se3dyn import lie
from se3dyn.dynamics.condense import condensation
from se3dyn.engine.system import compile_model

G = 9.81


def _compare(a, b, nodes, tol_x=1e-9, tol_v=1e-7):
    for n in nodes:
        np.testing.assert_allclose(a.node_frame(n), b.node_frame(n), rtol=0, atol=tol_x)
        np.testing.assert_allclose(a.node_velocity(n), b.node_velocity(n), rtol=0, atol=tol_v)


def test_paper_slider_crank_condensed_is_the_papers_discrete_motion():
    m = sd.examples.slider_crank()
    kw = dict(rho_inf=0.9, formulation="index3")
    a = sd.simulate(m, 1.0, 1e-2, **kw)
    b = sd.simulate(m, 1.0, 1e-2, condense=False, **kw)
    assert a.stats["condensed"] == ["2", "3", "5", "6"] and b.stats["condensed"] == []
    # 4 rigid joints x 6 unknowns and 6 multipliers fewer (Sec. 11.1: 49 + 48)
    assert (a.stats["matrix_size"], b.stats["matrix_size"]) == (49, 97)
    assert a.system is b.system  # the model's own layout, compiled once
    _compare(a, b, a.system.node_names)
    for n in a.system.node_names:
        acc = np.abs(b.node_acceleration(n)).max()
        np.testing.assert_allclose(a.node_acceleration(n), b.node_acceleration(n), rtol=0,
                                   atol=1e-7 * max(acc, 1.0))
    scale = np.abs(b.lam).max()
    for j in a.system.joint_names:
        np.testing.assert_allclose(a.joint_multipliers(j), b.joint_multipliers(j), rtol=0,
                                   atol=1e-8 * scale)


@pytest.mark.parametrize("formulation", ["index3", "index2"])
def test_rigid_reaction_is_newtons_second_law_of_the_body_it_carries(formulation):
    """A rod (node r, mass and inertia at its centre) swinging about a hinge, with a bob: a
    point mass m at node p joined to the rod by a rigid joint. The joint's multipliers are
    the force and moment on p in its material frame with the sign of Eq. (36): for a ball of
    mass m and inertia j I about its centre ``lambda_U = m R^T (a - g)``, ``lambda_Omega = j
    dOmega/dt`` (Eq. (49); the gyroscopic term of a ball vanishes)."""
    m_bob, j_bob = 0.7, 2e-4
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("g", fixed=True)
    mb.node("r", position=(0.25, 0.0, 0.0), mass=0.3, inertia=(1e-4, 2e-3, 2e-3))
    mb.node("p", position=(0.5, 0.0, 0.0), mass=m_bob, inertia=(j_bob,) * 3)
    mb.joint("hinge", "hinge", "g", "r", axis=(0.0, 1.0, 0.0), at=(0.0, 0.0, 0.0))
    mb.joint("weld", "rigid", "r", "p")
    res = sd.simulate(mb.build(), 1.0, 1e-3, formulation=formulation)
    assert res.stats["condensed"] == ["weld"]
    lam = res.joint_multipliers("weld")
    R = res.node_rotation("p")
    a = res.node_acceleration("p", frame="inertial")[:, :3]
    f = np.einsum("nij,nj->ni", R, lam[:, :3])
    want = m_bob * (a - np.array([0.0, 0.0, -G]))
    assert np.abs(want).max() > 5.0  # the bob swings through
    np.testing.assert_allclose(f, want, rtol=0, atol=1e-8 * np.abs(want).max())
    dw = res.node_acceleration("p")[:, 3:]
    np.testing.assert_allclose(lam[:, 3:], j_bob * dw, rtol=0,
                               atol=1e-8 * j_bob * np.abs(dw).max())


def _three_masses(one_node: bool, omega=(0.3, 2.0, 5.0)):
    """A free body spinning without gravity: three point-like masses with their own inertia,
    either as three nodes joined by rigid joints or as one node with the combined centre of
    mass and inertia (computed here by the parallel-axis rule)."""
    pts = np.array([[0.0, 0.0, 0.0], [0.3, 0.1, 0.0], [0.1, -0.2, 0.25]])
    ms = np.array([1.0, 0.5, 2.0])
    Js = [np.diag([1e-3, 2e-3, 3e-3]), np.diag([3e-3, 2e-3, 2e-3]), np.diag([2e-3, 2e-3, 3.5e-3])]
    w = np.array(omega)
    vel = [np.array([0.1, -0.2, 0.05]) + np.cross(w, p - pts[0]) for p in pts]  # rigid motion
    mb = sd.ModelBuilder()
    if one_node:
        c = (ms[:, None] * pts).sum(axis=0) / ms.sum()
        J = sum(Ji + mi * ((p - c) @ (p - c) * np.eye(3) - np.outer(p - c, p - c))
                for Ji, mi, p in zip(Js, ms, pts, strict=True))
        mb.node("n0", position=pts[0], mass=float(ms.sum()), inertia=J, com=tuple(c),
                velocity=vel[0], angular_velocity=w)
    else:
        for i in range(3):
            mb.node(f"n{i}", position=pts[i], mass=float(ms[i]), inertia=Js[i],
                    velocity=vel[i], angular_velocity=w)
        mb.joint("w1", "rigid", "n0", "n1")
        mb.joint("w2", "rigid", "n1", "n2")
    return mb.build()


@pytest.mark.parametrize("formulation", ["index3", "index2"])
def test_rigidly_joined_nodes_move_as_one_body_with_combined_inertia(formulation):
    kw = dict(rho_inf=0.9, formulation=formulation, initial_velocities="strict")
    joined = sd.simulate(_three_masses(False), 1.0, 2e-3, **kw)
    one = sd.simulate(_three_masses(True), 1.0, 2e-3, **kw)
    assert joined.stats["condensed"] == ["w1", "w2"]
    np.testing.assert_allclose(joined.node_frame("n0"), one.node_frame("n0"), rtol=0, atol=1e-9)
    np.testing.assert_allclose(joined.node_velocity("n0"), one.node_velocity("n0"), rtol=0,
                               atol=1e-8)
    # the members are carried along: H_i = H_0 C_i with the initial C_i
    s = joined.system
    for n in ("n1", "n2"):
        i = s.node_names.index(n)
        C = lie.inverse(s.node_H0[0]) @ s.node_H0[i]
        np.testing.assert_allclose(joined.node_frame(n), joined.node_frame("n0") @ C, rtol=0,
                                   atol=1e-12)
    # the welds' reactions (n0 hangs on n1 hangs on n2, the heaviest, the root: reactions
    # found leaf first) are those of the run that keeps the rigid joints (index 3: the same
    # discrete motion)
    if formulation == "index3":
        kept = sd.simulate(_three_masses(False), 1.0, 2e-3, condense=False, **kw)
        for j in ("w1", "w2"):
            lk = kept.joint_multipliers(j)
            assert np.abs(lk).max() > 1e-2  # centripetal forces of the spinning body
            np.testing.assert_allclose(joined.joint_multipliers(j), lk, rtol=0,
                                       atol=1e-8 * np.abs(lk).max())
    # free spinning body: the kinetic energy is conserved to the scheme's accuracy
    e = joined.kinetic
    assert np.abs(e - e[0]).max() <= 1e-3 * e[0]


def test_what_is_not_condensed_keeps_its_joints():
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("g", fixed=True)
    mb.node("g2", position=(1.0, 0.0, 0.0), fixed=True)
    mb.joint("ground", "rigid", "g", "g2")  # two fixed nodes: stays (redundant, dropped)
    # a loop of rigid joints: a, b, c welded in a triangle, hinged to the ground
    mb.node("a", position=(0.0, 0.0, -0.1), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.node("b", position=(0.2, 0.0, -0.1), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.node("c", position=(0.1, 0.0, -0.3), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("h", "hinge", "g", "a", axis=(0.0, 1.0, 0.0), at=(0.0, 0.0, 0.0))
    for name, p, q in (("ab", "a", "b"), ("bc", "b", "c"), ("ca", "c", "a")):
        mb.joint(name, "rigid", p, q)
    # a member loaded in its own (turned) body frame: its group stays as it is
    mb.node("d", position=(1.0, 0.0, -0.1), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.node("e", position=(1.2, 0.0, -0.1), mass=0.5, inertia=(1e-3, 1e-3, 1e-3),
            orientation=lie.exp_so3(np.array([0.0, 0.0, 0.5])))
    mb.joint("h2", "hinge", "g2", "d", axis=(0.0, 1.0, 0.0), at=(1.0, 0.0, 0.0))
    mb.joint("de", "rigid", "d", "e")
    mb.load("push", "e", force=(0.0, 0.0, 1.0), force_frame="body")
    m = mb.build()
    assert condensation(compile_model(m)) is None
    a = sd.simulate(m, 0.2, 1e-3)
    b = sd.simulate(m, 0.2, 1e-3, condense=False)
    assert a.stats["condensed"] == []
    np.testing.assert_array_equal(a.H, b.H)
    # the same load in the inertial frame can move to the root: condensed
    mb2 = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb2.node("g2", position=(1.0, 0.0, 0.0), fixed=True)
    mb2.node("d", position=(1.0, 0.0, -0.1), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb2.node("e", position=(1.2, 0.0, -0.1), mass=0.5, inertia=(1e-3, 1e-3, 1e-3),
             orientation=lie.exp_so3(np.array([0.0, 0.0, 0.5])))
    mb2.joint("h2", "hinge", "g2", "d", axis=(0.0, 1.0, 0.0), at=(1.0, 0.0, 0.0))
    mb2.joint("de", "rigid", "d", "e")
    mb2.load("push", "e", force=sd.Sine((0.0, 0.0, 3.0), 2.0), torque=(0.0, 0.1, 0.0),
             torque_frame="inertial")
    m2 = mb2.build()
    c = sd.simulate(m2, 0.5, 1e-3, formulation="index3")
    d = sd.simulate(m2, 0.5, 1e-3, formulation="index3", condense=False)
    assert c.stats["condensed"] == ["de"]
    _compare(c, d, ("d", "e"))
    np.testing.assert_allclose(c.joint_multipliers("de"), d.joint_multipliers("de"), rtol=0,
                               atol=1e-8 * np.abs(d.lam).max())
    assert abs(c.work_loads[-1]) > 1e-3 and math.isclose(c.work_loads[-1], d.work_loads[-1],
                                                         rel_tol=1e-7)


def test_restart_of_a_condensed_run_is_bit_exact():
    m = sd.examples.slider_crank()
    full = sd.simulate(m, 0.6, 1e-2)
    half = sd.simulate(m, 0.3, 1e-2)
    rest = sd.simulate(m, 0.6, 1e-2, initial_state=half.stats["final_state"])
    assert rest.stats["condensed"] == full.stats["condensed"] != []
    n = len(half.t) - 1
    for f in ("H", "v", "vd", "lam", "alpha"):
        assert np.array_equal(getattr(rest, f), getattr(full, f)[n:]), f
    # the state handed back is the model's own (every node and joint)
    st = half.stats["final_state"]
    assert st.H.shape == (len(m.nodes), 4, 4) and st.lam.shape == (full.system.nm,)


def test_a_run_that_kept_its_rigid_joints_continues_as_it_was():
    """A state of a run with ``condense=False`` carries that run's solver memory: continued
    with the default setting, it continues that run bit for bit (nothing condensed)."""
    m = sd.examples.slider_crank()
    full = sd.simulate(m, 0.6, 1e-2, condense=False)
    half = sd.simulate(m, 0.3, 1e-2, condense=False)
    rest = sd.simulate(m, 0.6, 1e-2, initial_state=half.stats["final_state"])
    assert rest.stats["condensed"] == []
    assert np.array_equal(rest.H, full.H[len(half.t) - 1:])


def test_dense_output_of_a_condensed_run():
    m = sd.examples.slider_crank()
    kw = dict(formulation="index3", output_step=0.05)
    a = sd.simulate(m, 0.5, 1e-2, **kw)
    b = sd.simulate(m, 0.5, 1e-2, condense=False, **kw)
    np.testing.assert_array_equal(a.t, b.t)
    _compare(a, b, ("2", "4", "6", "8"))


def _every_element_on_members(rng):
    """Two bodies, each built from a massive node and rigidly joined satellite nodes (turned
    against it), with every element type attached to the satellites: a hinge with a spring,
    damper and PD law (no ``at``: the satellite's own frame), a spherical joint with ``at``, a
    point spring-damper, a bushing, loads at a point (inertial force, inertial torque) and a
    beam whose end node is the root of a third group."""
    R = lambda: lie.exp_so3(rng.normal(size=3) * 0.5)  # noqa: E731
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("g", fixed=True)
    mb.node("b1", position=(0.3, 0.0, -0.1), mass=1.0, inertia=(0.01, 0.012, 0.014),
            orientation=R())
    mb.node("s1", position=(0.0, 0.0, -0.05), orientation=R())  # massless satellite
    mb.node("t1", position=(0.5, 0.1, -0.1), mass=0.3, inertia=(0.002, 0.002, 0.003),
            orientation=R())
    mb.joint("w1", "rigid", "b1", "s1")
    mb.joint("w2", "rigid", "t1", "b1")  # a member as node A
    mb.joint("h", "hinge", "g", "s1", axis=(0.0, 1.0, 0.0), stiffness=2.0, damping=0.1,
             control=sd.PD(kp=1.0, kd=0.05, target=sd.Sine(0.2, 1.5)))
    mb.node("b2", position=(0.6, 0.2, -0.3), mass=0.8, inertia=(0.01, 0.01, 0.012),
            orientation=R())
    mb.node("s2", position=(0.55, 0.15, -0.2), mass=0.1, inertia=(1e-3, 1e-3, 1e-3),
            orientation=R())
    mb.joint("w3", "rigid", "s2", "b2")
    mb.joint("sph", "spherical", "t1", "s2", at=(0.52, 0.12, -0.15))
    mb.spring_damper("sd", "s1", "s2", stiffness=30.0, damping=0.5, length=0.5)
    mb.bushing("bu", "t1", "b2", at=(0.58, 0.18, -0.25), stiffness=5.0, damping=0.05)
    mb.load("f", "s2", force=sd.Sine((0.5, 0.0, 1.0), 2.0), torque=(0.0, 0.02, 0.0),
            at=(0.6, 0.1, -0.2), torque_frame="inertial")
    mb.node("e", position=(0.6, 0.2, -0.6), mass=0.05, inertia=(1e-4, 1e-4, 1e-4))
    mb.node("m", position=(0.65, 0.2, -0.6), mass=0.2, inertia=(1e-3, 1e-3, 1e-3),
            orientation=R())
    mb.joint("w4", "rigid", "e", "m")  # e is a beam node: the root of its group
    mb.beam("beam", "b2", "e", elements=2, EA=50.0, GA=(20.0, 20.0), GJ=0.5, EI=(0.5, 0.6),
            mass_per_length=0.2, rotary_inertia=(2e-4, 1e-4, 1e-4), damping=0.01)
    return mb.build()


@pytest.mark.parametrize("seed", [1, 2])
def test_every_element_type_on_condensed_members(seed):
    from se3dyn.elements import REGISTRY

    m = _every_element_on_members(np.random.default_rng(seed))
    kw = dict(rho_inf=0.8, formulation="index3")
    a = sd.simulate(m, 0.3, 1e-3, **kw)
    b = sd.simulate(m, 0.3, 1e-3, condense=False, **kw)
    assert a.stats["condensed"] == ["w1", "w2", "w3", "w4"]
    # every element type of the library is in the model (a new one must be added here), but
    # contacts: a model with contact pairs is not condensed (tests/test_contact.py)
    s = a.system
    assert set(REGISTRY) - {"contact"} <= {"body", "joint", "joint_force", "load",
                                           "spring_damper", "bushing", "beam"}
    assert s.model.springs and s.model.bushings and s.model.loads and s.model.beams
    moved = max(np.abs(b.node_position(n)[-1] - b.node_position(n)[0]).max()
                for n in s.node_names)
    assert moved > 1e-2
    _compare(a, b, s.node_names, tol_x=1e-8, tol_v=1e-6)
    scale = np.abs(b.lam).max()
    np.testing.assert_allclose(a.lam, b.lam, rtol=0, atol=1e-7 * scale)
    for f in ("kinetic", "potential", "spring", "work_actuators", "work_loads", "dissipation"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=1e-7,
                                   atol=1e-9 * max(1.0, np.abs(getattr(b, f)).max()))


def test_a_step_that_fails_on_the_condensed_model_is_retried_with_the_rigid_joints(monkeypatch):
    """Near a singular configuration the reduced system's Newton iterations may stall where the
    model's own converge (measured: A02 at h = 5/23872 s, t = 3.21 s, residual 2.6 tol). Such
    a run goes on with the rigid joints kept from the failing step: the rows before are the
    condensed run's, the run completes, ``stats["condensed_until"]`` says when. The failure
    is simulated here by stopping the compiled loop of the reduced system half way."""
    import importlib

    from se3dyn.engine.system import system_of

    simmod = importlib.import_module("se3dyn.dynamics.run")
    real = simmod._run_compiled

    def stop_half_way(s, integ, st, times, k0, nsteps, *args):
        if s is not cond.full:  # the reduced system
            return real(s, integ, st, times, k0, nsteps // 2, *args)
        return real(s, integ, st, times, k0, nsteps, *args)

    m = sd.examples.slider_crank()
    cond = condensation(system_of(m))
    condensed = sd.simulate(m, 1.0, 1e-2)
    kept = sd.simulate(m, 1.0, 1e-2, condense=False)
    monkeypatch.setattr(simmod, "_run_compiled", stop_half_way)
    both = sd.simulate(m, 1.0, 1e-2)
    assert both.stats["condensed_until"] == pytest.approx(0.5, abs=1e-12)
    np.testing.assert_array_equal(both.t, condensed.t)
    k = 51  # the rows up to t = 0.5 s: the condensed run's
    np.testing.assert_array_equal(both.H[:k], condensed.H[:k])
    np.testing.assert_allclose(both.lam[:k], condensed.lam[:k], rtol=0, atol=1e-12)
    # after: the model's own equations (both second-order approximations of one motion)
    assert np.abs(both.H - kept.H).max() < 1e-3 and np.isfinite(both.lam).all()
    assert both.constraint.max() <= 1e-9


def test_condensed_runs_in_threads_agree_bit_for_bit():
    """Runs of one model in two threads at once: each expands its rows and computes its rigid
    joints' reactions with its own work arrays (never the system's shared default ones), so
    both equal the sequential run, reactions and final states included."""
    import threading

    m = sd.examples.slider_crank()
    ref = sd.simulate(m, 1.0, 1e-2)
    out = [None, None]

    def run(k):
        r = sd.simulate(m, 1.0, 1e-2)
        out[k] = (r.lam.copy(), r.stats["final_state"].lam)  # reactions filled in the thread

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for lam, final in out:
        assert np.array_equal(lam, ref.lam)
        assert np.array_equal(final, ref.stats["final_state"].lam)
