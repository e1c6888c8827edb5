"""Physics of the bushing element (6 x 6 stiffness and damping on ``d = log(H_a'^-1 H_b')``).

Every reference is a closed-form solution, an exact equivalence or a conservation law: natural
frequencies sqrt(k/m) and sqrt(k_rot/J) of a body on a bushing, second-order energy drift of a
large-rotation free vibration, the damped oscillator, the point spring-damper in the 1D axial
case, static deflections F/k and T/k_rot. The tangent blocks, the objectivity and the energy
gradient are checked by the contract test (tests/test_elements.py) on the examples of
:mod:`se3dyn.elements.bushing`.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.analysis.statics import static_equilibrium
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.linsolve import LinearSolver
from se3dyn.engine.system import compile_model

M, J = 2.0, np.array([0.10, 0.15, 0.20])
KD = np.array([200.0, 300.0, 400.0, 5.0, 6.0, 7.0])  # kx, ky, kz (N/m), krx, kry, krz (N m/rad)


def _body_on_bushing(stiffness=KD, damping=0.0, *, velocity=None, angular_velocity=None,
                     node_orientation=None, at=None, gravity=(0.0, 0.0, 0.0), **bushing):
    """A rigid body (node at its centre of mass) on a bushing to the ground, principal axes of
    inertia along the inertial axes."""
    mb = sd.ModelBuilder(gravity=gravity)
    mb.node("g", position=(0.0, 0.0, 0.0), fixed=True)
    mb.node("b", position=(0.3, -0.2, 0.5), mass=M, inertia=tuple(J),
            orientation=node_orientation, velocity=velocity, angular_velocity=angular_velocity)
    mb.bushing("bush", "g", "b", at=at, stiffness=stiffness, damping=damping, **bushing)
    return mb


def _matrix(s, coef):
    z = np.zeros(s.nq)
    ev = evaluate(s, s.node_H0, s.joint_H0, z, z, z, z, np.zeros(s.nm), step_inputs(s, 0.0),
                  coef)
    return np.asarray(LinearSolver(s, dense_max=10 ** 9).matrix(ev.values))


def test_small_motion_natural_frequencies_are_sqrt_k_over_m_and_sqrt_krot_over_j():
    """Linearised about the rest state (tangent stiffness K_T and mass M of the engine), the six
    eigenfrequencies are sqrt(k_i/m) (translations) and sqrt(k_rot,i/J_i) (rotations), also
    for a node turned away from the bushing axes."""
    R0 = sd.lie.exp_so3(np.array([0.4, -0.7, 1.1]))
    s = compile_model(_body_on_bushing(node_orientation=R0).build())
    K = _matrix(s, (0.0, 0.0, 1.0))
    Mm = _matrix(s, (1.0, 0.0, 0.0))
    w = np.sort(np.sqrt(np.linalg.eigvals(np.linalg.solve(Mm, K)).real))
    ref = np.sort(np.sqrt(np.concatenate([KD[:3] / M, KD[3:] / J])))
    np.testing.assert_allclose(w, ref, rtol=1e-12)


def test_tangent_is_exact_at_large_relative_rotations():
    """The contract test samples relative rotations below 1 rad (the Taylor-series branch of the
    coefficient functions); here the closed-form branch: configuration and velocity columns of
    the iteration matrix against central differences of the residual, rotations of 1-2.5 rad."""
    from se3dyn.elements import bushing

    s = compile_model(bushing.examples(np.random.default_rng(0))[0])
    rng = np.random.default_rng(1)
    Hn = s.node_H0 @ sd.lie.exp_se3(rng.normal(size=(s.M, 6)))
    fa, fb, Xa, Xb = bushing.frames(s)
    G = np.linalg.inv(Hn[fa] @ Xa) @ (Hn[fb] @ Xb)  # relative motion of the attached frames
    ang = np.linalg.norm(sd.lie.log_so3(G[:, :3, :3]), axis=1)
    assert np.all((1.0 < ang) & (ang < 2.5)), ang
    st = dict(alpha=np.zeros(s.nq), n=0.1 * rng.normal(size=s.nq), v=rng.normal(size=s.nq),
              vd=rng.normal(size=s.nq))
    inputs = step_inputs(s, 0.0)

    def ev(coef=None, **kw):
        x = dict(st, **kw)
        return evaluate(s, Hn, s.joint_H0, x["alpha"], x["n"], x["v"], x["vd"], np.zeros(s.nm),
                        inputs, coef)

    for coef, name in (((0.0, 0.0, 1.0), "n"), ((0.0, 1.0, 0.0), "v")):
        A = np.asarray(LinearSolver(s, dense_max=10 ** 9).matrix(ev(coef).values))
        eps = 1e-6
        fd = np.array([(ev(**{name: st[name] + eps * e}).r - ev(**{name: st[name] - eps * e}).r)
                       / (2 * eps) for e in np.eye(s.nq)]).T
        assert np.abs(A - fd).max() < 2e-7 * np.abs(fd).max(), name


def _angle_z(res):
    R = res.H[:, res.system.node_names.index("b"), :3, :3]
    return np.arctan2(R[:, 1, 0], R[:, 0, 0])


@pytest.mark.parametrize("mode", ["translation y", "rotation z"])
def test_free_vibration_follows_the_harmonic_solution_with_second_order_error(mode):
    """A small initial velocity along y (or about z): y = v0/w sin(w t) with w = sqrt(ky/m)
    (theta = w0/w sin(w t) with w = sqrt(krz/Jz)); the error of the integrator is O(h^2)."""
    errs = []
    for h in (2e-3, 1e-3):
        if mode == "translation y":
            w, v0 = math.sqrt(KD[1] / M), 1e-3
            res = sd.simulate(_body_on_bushing(velocity=(0, v0, 0)).build(), t_end=1.5,
                              step=h, rho_inf=1.0)
            q = res.node_position("b")[:, 1] + 0.2
        else:
            w, v0 = math.sqrt(KD[5] / J[2]), 1e-3
            res = sd.simulate(_body_on_bushing(angular_velocity=(0, 0, v0)).build(), t_end=1.5,
                              step=h, rho_inf=1.0)
            q = _angle_z(res)
        exact = v0 / w * np.sin(w * res.t)
        errs.append(np.abs(q - exact).max() / (v0 / w))
    assert errs[1] < 2e-3
    assert 3.5 < errs[0] / errs[1] < 4.5


def _relative_angle(res):
    R = res.H[:, res.system.node_names.index("b"), :3, :3]
    return np.linalg.norm(sd.lie.log_so3(R), axis=1)


def test_large_rotation_free_vibration_conserves_energy_to_second_order():
    """Undamped, full symmetric positive-definite K, bushing point away from the centre of mass,
    relative rotations above 1 rad: with rho_inf = 1 the total energy (kinetic + elastic
    d^T K d / 2) is constant up to the O(h^2) error of the scheme."""
    rng = np.random.default_rng(3)
    B = rng.normal(size=(6, 6))
    K = B @ B.T / 6 + np.diag([100.0, 100.0, 100.0, 2.0, 2.0, 2.0])
    drift = []
    for h in (2e-3, 1e-3):
        model = _body_on_bushing(K, at=(0.35, -0.1, 0.45), velocity=(0.2, -0.1, 0.3),
                                 angular_velocity=(3.0, -2.0, 4.0)).build()
        res = sd.simulate(model, t_end=2.0, step=h, rho_inf=1.0)
        ang = _relative_angle(res)
        assert 1.0 < ang.max() < 2.5  # large rotations, on the principal branch of log
        E = res.kinetic + res.spring
        assert res.spring.max() > 0.3 * E[0]  # the bushing stores a good part of it
        drift.append(np.abs(E - E[0]).max() / E[0])
    assert drift[1] < 1e-5
    assert 3.5 < drift[0] / drift[1] < 4.5


def test_damped_translational_mode_decays_like_the_damped_oscillator():
    """x'' + (c/m) x' + (k/m) x = 0 from x = 0, x' = v0: x = v0/wd exp(-zeta w0 t) sin(wd t);
    the dissipated work equals the energy lost."""
    c = 3.0
    k = KD[0]
    w0 = math.sqrt(k / M)
    zeta = c / (2 * math.sqrt(k * M))
    wd = w0 * math.sqrt(1 - zeta ** 2)
    v0 = 0.05
    D = np.diag([c, 0.7, 0.7, 0.01, 0.01, 0.01])
    res = sd.simulate(_body_on_bushing(damping=D, velocity=(v0, 0, 0)).build(), t_end=2.0,
                      step=5e-4, rho_inf=0.9)
    x = res.node_position("b")[:, 0] - 0.3
    xa = v0 / wd * np.exp(-zeta * w0 * res.t) * np.sin(wd * res.t)
    assert np.abs(x - xa).max() < 2e-5 * v0 / wd
    E = res.kinetic + res.spring
    assert E[-1] < 0.25 * E[0]
    assert abs(E[0] - E[-1] - res.dissipation[-1]) < 1e-5 * E[0]  # trapezoidal rule, O(h^2)


def test_bushing_is_the_point_spring_damper_in_the_1d_axial_case():
    """K = diag(k, 0, ...), D = diag(c, 0, ...) along the line of a spring-damper (stiffness k,
    damping c, free length the initial distance): the two give the same motion, energies and
    dissipation, to round-off."""
    k, c = 50.0, 0.8
    out = []
    for kind in ("spring", "bushing"):
        mb = sd.ModelBuilder()
        mb.node("g", fixed=True)
        mb.node("m", position=(1.0, 0.0, 0.0), mass=1.5, inertia=(0.1, 0.1, 0.1),
                velocity=(0.7, 0.0, 0.0))
        if kind == "spring":
            mb.spring_damper("s", "g", "m", stiffness=k, damping=c)
        else:
            mb.bushing("s", "g", "m", stiffness=(k, 0, 0, 0, 0, 0), damping=(c, 0, 0, 0, 0, 0))
        out.append(sd.simulate(mb.build(), t_end=1.0, step=1e-3, rho_inf=0.8))
    a, b = out
    np.testing.assert_allclose(b.node_position("m"), a.node_position("m"), rtol=0, atol=1e-12)
    for what in ("spring", "dissipation", "kinetic"):
        np.testing.assert_allclose(getattr(b, what), getattr(a, what), rtol=0, atol=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_static_deflection_under_a_force_along_an_axis_is_f_over_k(axis):
    """A force F along an axis of the (diagonal) K at the bushing point: pure translation
    d = (x, 0) with K x parallel to x, so T(d)^-T K d = (K x, 0) and x = F/k exactly (no
    small-motion approximation)."""
    F = np.zeros(3)
    F[axis] = [30.0, -45.0, 80.0][axis]
    mb = _body_on_bushing()
    mb.load("F", "b", force=tuple(F))
    res = static_equilibrium(mb.build())
    x = res.node_position("b") - np.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(x, F / KD[:3], rtol=0, atol=1e-12)


def test_static_deflection_off_the_axes_couples_translation_and_rotation_as_the_log():
    """A force F off the axes: the log of SE(3) couples a finite translation u with rotation,
    d_U = T_SO(3)(d_Omega)^-T u: at first order d_U = u + u x theta / 2, so the energy
    u^T K u / 2 gives the moment (u x K u) / 2 and the body turns by
    theta = K_rot^-1 (u x K u) / 2 = O(|F|^2), while u = K^-1 F: both hold up to relative
    errors O(|F|^2) (the next terms are odd in F for u, even for theta), which shrink by 4 when
    the force is halved."""
    F = np.array([30.0, -45.0, 80.0])
    err_u, err_th = [], []
    for scale in (1e-2, 5e-3):
        mb = _body_on_bushing()
        mb.load("F", "b", force=tuple(scale * F))
        res = static_equilibrium(mb.build())
        x = res.node_position("b") - np.array([0.3, -0.2, 0.5])
        u = scale * F / KD[:3]
        th = sd.lie.log_so3(res.H[res.system.node_names.index("b"), :3, :3])
        th_ref = 0.5 * np.cross(u, KD[:3] * u) / KD[3:]
        err_u.append(np.abs(x - u).max() / np.abs(u).max())
        err_th.append(np.abs(th - th_ref).max() / np.abs(th_ref).max())
    assert err_u[0] < 1e-4 and err_th[0] < 1e-3
    assert 3.5 < err_u[0] / err_u[1] < 4.5
    assert 3.5 < err_th[0] / err_th[1] < 4.5


def test_static_rotation_under_a_torque_is_t_over_krot_even_when_large():
    """A torque T about z: d = (0, theta e_z), T(d)^-T K d = krz theta e_z, theta = T/krz
    exactly, here 1.2 rad."""
    T = 1.2 * KD[5]
    mb = _body_on_bushing()
    mb.load("T", "b", torque=(0.0, 0.0, T), torque_frame="inertial")
    res = static_equilibrium(mb.build(), load_steps=3)
    R = res.H[res.system.node_names.index("b"), :3, :3]
    np.testing.assert_allclose(sd.lie.log_so3(R), [0.0, 0.0, T / KD[5]], rtol=0, atol=1e-11)
    np.testing.assert_allclose(res.node_position("b"), [0.3, -0.2, 0.5], rtol=0, atol=1e-12)


def test_hanging_body_sags_by_mg_over_kz():
    g = 9.81
    res = static_equilibrium(_body_on_bushing(gravity=(0, 0, -g)).build())
    assert abs(res.node_position("b")[2] - (0.5 - M * g / KD[2])) < 1e-12


# ---------------------------------------------------------------------------------------------
# bad input: se3dyn errors naming the bushing, the field, what was expected and what came
@pytest.mark.parametrize("kw, field, expected", [
    (dict(stiffness=(1.0, 2.0, 3.0)), "stiffness", "6 non-negative diagonal values"),
    (dict(stiffness=np.ones((6, 5))), "stiffness", "shape (6, 5)"),
    (dict(stiffness="stiff"), "stiffness", "symmetric positive"),
    (dict(stiffness=(1, 1, 1, 1, 1, -1)), "stiffness", "non-negative diagonal values"),
    (dict(stiffness=np.triu(np.ones((6, 6)))), "stiffness", "a symmetric 6 x 6 matrix"),
    (dict(stiffness=np.ones((6, 6)) - 2 * np.eye(6)), "stiffness", "positive semi-definite"),
    (dict(stiffness=1.0, damping=(1, 2, 3, 4, 5, math.nan)), "damping", "finite values"),
    (dict(stiffness=1.0, damping=-1.0), "damping", "non-negative"),
    (dict(stiffness=1.0, at=(0, 1)), "at", "3 numbers"),
])
def test_bad_bushing_input_is_a_model_error_naming_field_and_expectation(kw, field, expected):
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("b", mass=1.0, inertia=(1, 1, 1))
    with pytest.raises(sd.ModelError) as ei:
        mb.bushing("bu", "g", "b", **kw)
    e = ei.value
    assert e.item == "bushing 'bu'" and e.field == field
    assert expected in str(e)


def test_bad_bushing_nodes_are_model_errors():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("g2", fixed=True)
    mb.node("b", mass=1.0, inertia=(1, 1, 1))
    with pytest.raises(sd.ModelError, match="did you mean 'b'"):
        mb.bushing("x", "g", "bb", stiffness=1.0)
    with pytest.raises(sd.ModelError, match="a node other than node_a"):
        mb.bushing("x", "b", "b", stiffness=1.0)
    with pytest.raises(sd.ModelError, match="at least one free node"):
        mb.bushing("x", "g", "g2", stiffness=1.0)
    mb.bushing("x", "g", "b", stiffness=1.0)
    with pytest.raises(sd.ModelError, match="defined twice"):
        mb.bushing("x", "g", "b", stiffness=1.0)


MOUNT = """\
se3dyn: 1
name: mount
nodes:
  ground: {fixed: true}
  engine: {position: [0, 0, 0.3], mass: 120, inertia: [4, 5, 6]}
bushings:
  left: {a: ground, b: engine, at: [0.3, 0.2, 0], stiffness: [2e5, 2e5, 3e5, 1e3, 1e3, 1e3],
         damping: 200}
  right:
    a: ground
    b: engine
    stiffness: [[2e5, 0, 0, 0, 1e3, 0], [0, 2e5, 0, 0, 0, 0], [0, 0, 3e5, 0, 0, 0],
                [0, 0, 0, 1e3, 0, 0], [1e3, 0, 0, 0, 1e3, 0], [0, 0, 0, 0, 0, 1e3]]
"""


def test_model_file_bushings_give_the_builder_model_and_are_counted_by_check(tmp_path, capsys):
    from se3dyn.cli.commands import main
    from se3dyn.io.modelfile import loads_model, save_model

    model, _ = loads_model(MOUNT)
    left, right = model.bushings
    np.testing.assert_array_equal(left.at, [0.3, 0.2, 0.0])
    np.testing.assert_array_equal(right.at, [0.0, 0.0, 0.3])  # default: the position of b
    np.testing.assert_array_equal(left.stiffness, np.diag([2e5, 2e5, 3e5, 1e3, 1e3, 1e3]))
    np.testing.assert_array_equal(left.damping, 200 * np.eye(6))
    assert right.stiffness[4, 0] == right.stiffness[0, 4] == 1e3
    np.testing.assert_array_equal(right.damping, np.zeros((6, 6)))
    again, _ = loads_model(save_model(model))
    for a, b in zip(model.bushings, again.bushings, strict=True):
        for f in ("at", "stiffness", "damping"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    p = tmp_path / "mount.yaml"
    p.write_text(MOUNT)
    assert main(["check", str(p)]) == 0
    assert "force elements: 2 bushings" in capsys.readouterr().out


def test_bushing_axes_turn_k_as_the_adjoint_of_the_rotation():
    """Bushing axes R (``orientation``) with a diagonal K are the same element as the bushing
    on the inertial axes with K' = diag(R, R) K diag(R, R)^T: d' = Ad(H(R, 0)^-1) d, so the
    energies and dissipation functions agree; the motions coincide to round-off."""
    R = sd.lie.exp_so3(np.array([0.3, -0.5, 0.8]))
    B = np.zeros((6, 6))
    B[:3, :3] = B[3:, 3:] = R
    D = np.array([3.0, 2.0, 1.0, 0.05, 0.04, 0.03])
    runs = []
    for kw in (dict(stiffness=KD, damping=D, orientation=R),
               dict(stiffness=B @ np.diag(KD) @ B.T, damping=B @ np.diag(D) @ B.T)):
        mb = _body_on_bushing(velocity=(0.3, -0.2, 0.4), angular_velocity=(1.0, 2.0, -1.5),
                              **dict(kw, at=(0.2, 0.1, 0.4)))
        runs.append(sd.simulate(mb.build(), t_end=1.0, step=2e-3, rho_inf=0.9))
    a, b = runs
    assert np.abs(a.H - b.H).max() < 1e-11
    np.testing.assert_allclose(a.spring, b.spring, rtol=0, atol=1e-11 * a.spring.max())


def test_preloaded_bushing_relaxes_to_zero_deformation():
    """A bushing starting deformed by d0 (``deformation``; turned axes, full K, damping) and
    nothing else: its equilibrium is d = 0, H_b' = H_a', i.e. H_b = P exp(-d0) P^-1 H_b0 with
    P = H(orientation, at): there the generalised forces and the energy vanish (to round-off),
    and the damped motion from the preloaded state goes there, dissipating d0^T K d0 / 2."""
    rng = np.random.default_rng(11)
    Bm = rng.normal(size=(6, 6))
    K = Bm @ Bm.T + np.diag([40.0, 40.0, 40.0, 1.0, 1.0, 1.0])
    R = sd.lie.exp_so3(np.array([-0.4, 0.2, 0.9]))
    at = np.array([0.5, 0.0, 0.2])
    d0 = np.array([0.05, -0.1, 0.08, 0.6, -0.3, 0.9])
    model = _body_on_bushing(K, 0.5 * K, at=tuple(at), orientation=R, deformation=d0).build()
    P = sd.lie.make_frame(R, at)
    ref = P @ sd.lie.exp_se3(-d0) @ np.linalg.inv(P) @ sd.lie.make_frame(None, (0.3, -0.2, 0.5))
    s = compile_model(model)
    z = np.zeros(s.nq)
    ev0 = evaluate(s, s.node_H0, s.joint_H0, z, z, z, z, np.zeros(0), step_inputs(s, 0.0))
    ev = evaluate(s, np.array([s.node_H0[0], ref]), s.joint_H0, z, z, z, z, np.zeros(0),
                  step_inputs(s, 0.0))
    E0 = 0.5 * d0 @ K @ d0
    assert abs(ev0.energy[2] - E0) < 1e-12 * E0
    assert np.abs(ev.r).max() < 1e-12 * np.abs(ev0.r).max() and ev.energy[2] < 1e-24 * E0
    res = sd.simulate(model, t_end=10.0, step=1e-2, rho_inf=0.5)
    err = np.abs(res.H[:, 1] - ref).max(axis=(1, 2))
    assert err[-1] < 1e-3 * err[0]
    E = res.kinetic + res.spring
    assert abs(E[0] - E[-1] - res.dissipation[-1]) < 5e-3 * E0  # trapezoidal rule, O(h^2)


def test_a_model_restarted_at_a_static_equilibrium_stays_at_rest():
    """StaticResult.model keeps the bushings loaded (their attached frames and the deformation
    reached), the points of spring-dampers and loads and the centres of mass on their bodies:
    simulated from there under the same loads the bodies do not move."""
    rng = np.random.default_rng(5)
    Bm = rng.normal(size=(6, 6))
    mb = _body_on_bushing(Bm @ Bm.T * 20 + np.diag(KD), at=(0.2, 0.0, 0.6),
                          gravity=(0.0, 0.0, -9.81))
    mb.spring_damper("s", "g", "b", at_a=(1.0, 0.0, 1.0), at_b=(0.4, -0.2, 0.6), stiffness=30.0,
                     length=0.3)
    mb.load("F", "b", force=(5.0, -3.0, 2.0), torque=(0.5, 0.2, -0.3), at=(0.35, -0.1, 0.5))
    mb.node("c", position=(0.3, -0.2, 0.0), mass=1.0, inertia=(0.01, 0.02, 0.02),
            com=(0.4, -0.1, -0.1))  # centre of mass off the node
    mb.bushing("hang", "b", "c", stiffness=(300, 300, 300, 20, 20, 20))
    st = static_equilibrium(mb.build(), load_steps=2)
    x_eq = st.node_position("b")
    assert np.linalg.norm(x_eq - (0.3, -0.2, 0.5)) > 0.05  # it moved and turned
    assert np.linalg.norm(sd.lie.log_so3(st.H[1, :3, :3])) > 0.05
    model = st.model
    assert np.any(model.bushings[0].deformation != 0)
    res = sd.simulate(model, t_end=0.5, step=1e-2, rho_inf=0.9)
    assert np.abs(res.H - st.H).max() < 1e-9
    # and the file form of the restarted model is the same model
    from se3dyn.io.modelfile import loads_model, save_model

    again, _ = loads_model(save_model(model))
    for f in ("at", "orientation", "deformation", "stiffness"):
        np.testing.assert_array_equal(getattr(again.bushings[0], f),
                                      getattr(model.bushings[0], f))


def test_driven_motion_on_a_bushing_inverse_dynamics_and_energy():
    """A body driven along x by a prismatic joint, x(t) = a sin(w t), held by a bushing
    K = diag(k, ...), D = diag(c, ...): the driver force is m x'' + c x' + k x and the elastic
    energy k x^2 / 2 (kinematics and inverse dynamics, :func:`se3dyn.kinematics`)."""
    k, c, a, w = KD[0], 4.0, 0.05, 3.0
    mb = _body_on_bushing(damping=np.diag([c, 1, 1, 1, 1, 1]))
    mb.joint("slide", "prismatic", "g", "b", axis=(1, 0, 0))
    t = np.linspace(0.0, 2.0, 41)
    res = sd.kinematics(mb.build(), {"slide": sd.Sine(a, w / (2 * math.pi))}, t)
    x = a * np.sin(w * t)
    xd = a * w * np.cos(w * t)
    xdd = -a * w * w * np.sin(w * t)
    np.testing.assert_allclose(res.efforts["slide"][:, 0], M * xdd + c * xd + k * x, rtol=0,
                               atol=1e-9)
    np.testing.assert_allclose(res.spring, 0.5 * k * x ** 2, rtol=0, atol=1e-12)
