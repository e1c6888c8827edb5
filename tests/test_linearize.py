"""Linearisation in minimal coordinates against closed forms: natural frequencies of pendulums
and a parallelogram four-bar (closed loop, redundant constraints), a pendulum built as a free
body and a hinge (the geometric stiffness of the constraint forces d(B^T lambda)/dq), one mode
pair per degree of freedom; an LQR designed with python-control on the exported cart-pole
stabilises the nonlinear simulation."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

import se3dyn as sd
from _mechanisms import FOURBAR, parallelogram_fourbar
from se3dyn.errors import ModelError

G = 9.81


def point_double_pendulum(l: float, m: float) -> sd.Model:
    """Two point masses on massless rods: each bob on a spherical joint at its centre (the bob's
    rotation is free and uncoupled: three rigid-body modes per bob, no inertia in the swing)."""
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    mb.node("rod1")
    mb.node("rod2", position=(0, 0, -l))
    for i in (1, 2):
        mb.node(f"bob{i}", position=(0, 0, -i * l), mass=m, inertia=(0.01, 0.02, 0.025))
    mb.joint("h1", "hinge", "ground", "rod1", axis=(0, 1, 0))
    mb.joint("s1", "spherical", "rod1", "bob1", at=(0, 0, -l))
    mb.joint("h2", "hinge", "rod1", "rod2", axis=(0, 1, 0))
    mb.joint("s2", "spherical", "rod2", "bob2", at=(0, 0, -2 * l))
    return mb.build()


def test_point_double_pendulum():
    l, m = 0.7, 1.3
    lin = sd.linearize(point_double_pendulum(l, m))  # the initial state of a run: at rest
    md = lin.modes()
    assert len(md) == len(lin.names) == 8  # one pair per degree of freedom
    assert np.sum(md.rigid) == 6  # the bobs' free rotations
    ref = np.sqrt(np.array([2 - math.sqrt(2), 2 + math.sqrt(2)]) * G / l)
    assert np.abs(md.omega[~md.rigid] / ref - 1).max() <= 1e-10
    assert np.all(md.damping == 0) or np.abs(md.damping).max() <= 1e-12
    assert lin.symmetric


def compound_double(m1, m2, l1, c1, c2, J1, J2) -> sd.Model:
    """Two bars on hinges about y, nodes at the centres of mass (the hinges at points)."""
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    mb.node("bar1", position=(0, 0, -c1), mass=m1, inertia=(J1 * 1.1, J1, J1 * 0.6))
    mb.node("bar2", position=(0, 0, -l1 - c2), mass=m2, inertia=(J2 * 0.9, J2, J2 * 0.5))
    mb.joint("h1", "hinge", "ground", "bar1", axis=(0, 1, 0), at=(0, 0, 0))
    mb.joint("h2", "hinge", "bar1", "bar2", axis=(0, 1, 0), at=(0, 0, -l1))
    return mb.build()


def test_compound_double_pendulum():
    m1, m2, l1, c1, c2, J1, J2 = 2.0, 1.5, 0.8, 0.35, 0.45, 0.11, 0.07
    model = compound_double(m1, m2, l1, c1, c2, J1, J2)
    eq = sd.static_equilibrium(model)
    lin = sd.linearize(model, at=eq)
    # absolute angles: T = 1/2 p^T M p, V = 1/2 p^T K p about the hanging position
    M = np.array([[J1 + m1 * c1**2 + m2 * l1**2, m2 * l1 * c2], [m2 * l1 * c2, J2 + m2 * c2**2]])
    K = G * np.diag([m1 * c1 + m2 * l1, m2 * c2])
    ref = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(M, K)).real))
    md = lin.modes()
    assert len(md) == 2 and not np.any(md.rigid)
    assert np.abs(md.omega / ref - 1).max() <= 1e-10
    assert lin.symmetric
    assert np.abs(lin.K - lin.K.T).max() <= 1e-12 * np.abs(lin.K).max()
    # the geometric stiffness of the constraint forces d(B^T lambda)/dq matters here (the
    # second hinge's reaction on bar 1, Ad_{H_J^-1} of Eq. (58)): without the multipliers K is
    # not even symmetric
    s = eq.system
    z = np.zeros(s.nq)
    no_lam = sd.State(t=0.0, H=eq.H, HJ=eq.HJ, v=z, vd=z, a=z, lam=0 * eq.lam, alpha=eq.alpha)
    assert not sd.linearize(model, at=no_lam).symmetric


def test_parallelogram_four_bar():
    """Crank and rocker of length a (centres of mass at c), coupler of length d translating:
    omega^2 = g (m1 c + m3 c + mc a) / (I1 + I3 + mc a^2) with I about the pivots."""
    a, c, m1, m3, mc, J1, J3 = (FOURBAR[k] for k in ("a", "c", "m1", "m3", "mc", "J1", "J3"))
    model = parallelogram_fourbar(G)
    eq = sd.static_equilibrium(model)
    lin = sd.linearize(model, at=eq)
    assert lin.partition.rank == 4 * 6 - 1 - 2  # 21 of 24 equations: 3 redundant
    assert lin.names == ("joint 'A' alpha_0",)  # the first joint stays independent
    md = lin.modes()
    assert len(md) == 1  # no spurious constraint modes
    w2 = G * (m1 * c + m3 * c + mc * a) / (J1 + m1 * c**2 + J3 + m3 * c**2 + mc * a**2)
    assert abs(md.omega[0] / math.sqrt(w2) - 1) <= 1e-10
    # another independent joint, the same frequency
    lin2 = sd.linearize(model, at=eq, independent=["C"])
    assert lin2.names == ("joint 'C' alpha_0",)
    assert abs(lin2.modes().omega[0] / math.sqrt(w2) - 1) <= 1e-10


@pytest.mark.parametrize("body_is", ["B", "A"])
def test_free_body_and_hinge(body_is):
    """A body as a free node (6 unknowns) and a hinge at a point away from it, the body as node
    B or as node A of the hinge: omega^2 = m g c / (J + m c^2)."""
    m, c, J = 1.7, 0.6, 0.05
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    mb.node("body", position=(0.3, 0.2, -c), mass=m, inertia=(0.08, J, 0.03))
    ends = ("ground", "body") if body_is == "B" else ("body", "ground")
    mb.joint("pin", "hinge", *ends, axis=(0, 1, 0), at=(0.3, 0.2, 0))
    model = mb.build()
    eq = sd.static_equilibrium(model)
    lin = sd.linearize(model, at=eq)
    md = lin.modes()
    assert len(md) == 1 and lin.names == ("joint 'pin' alpha_0",)
    assert abs(md.omega[0] / math.sqrt(m * G * c / (J + m * c**2)) - 1) <= 1e-10


def cart_pole(theta0: float = 0.0) -> sd.Model:
    mc, mp, lp = 1.0, 0.3, 0.5
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    mb.node("cart", mass=mc, inertia=(0.01, 0.01, 0.01))
    R = np.array([[math.cos(theta0), 0, math.sin(theta0)], [0, 1, 0],
                  [-math.sin(theta0), 0, math.cos(theta0)]])
    mb.node("pole", position=R @ (0, 0, lp), orientation=R, mass=mp,
            inertia=R @ np.diag([mp * lp**2 / 3, mp * lp**2 / 3, 1e-4]) @ R.T)
    mb.joint("cart", "prismatic", "ground", "cart", axis=(1, 0, 0), force=0.0)
    mb.joint("pole", "hinge", "cart", "pole", axis=(0, 1, 0), at=(0, 0, 0), initial=theta0)
    return mb.build()


def test_cart_pole_lqr_stabilises_the_nonlinear_run():
    lin = sd.linearize(cart_pole(), inputs=["cart"], outputs=["cart", "pole"])
    md = lin.modes()
    # upright: the pole diverges at s^2 = mp g l / (I + mp l^2 mc / (mc + mp)) (I = mp l^2 / 3
    # about its centre), the cart's position is a rigid-body mode
    mc, mp, lp = 1.0, 0.3, 0.5
    s2 = mp * G * lp / (mp * lp**2 / 3 + mp * lp**2 * mc / (mc + mp))
    assert np.sum(md.rigid) == 1 and np.sum(~md.stable) == 1
    assert abs(md.omega[~md.stable][0] / math.sqrt(s2) - 1) <= 1e-10
    sys = lin.state_space()
    assert sys.input_labels == ["cart"] and sys.output_labels == ["cart", "pole"]
    Kx, _, E = control.lqr(sys, np.diag([10.0, 50.0, 1.0, 1.0]), np.array([[0.1]]))
    assert np.all(E.real < 0)
    # a Simulator's state at the start is the initial state of a run (at=None)
    start = sd.Simulator(cart_pole(), step=2e-3).state
    assert np.array_equal(sd.linearize(cart_pole(), at=start, inputs=["cart"]).A, lin.A)
    sim = sd.Simulator(cart_pole(math.radians(5)), step=2e-3)
    chans = ["joint/cart/alpha/0", "joint/pole/alpha/0", "joint/cart/velocity/0",
             "joint/pole/velocity/0"]
    peak = 0.0
    while sim.t < 6.0:
        x = np.array([sim.read(c) for c in chans])
        peak = max(peak, abs(x[1]))
        sim.set_input("joint/cart/actuator", float(-(Kx @ x)[0]))
        sim.step()
    x = np.array([sim.read(c) for c in chans])
    assert peak <= math.radians(5) + 1e-9  # no larger excursion than the start
    assert np.abs(x).max() <= 1e-3  # at rest upright, over the origin


def test_bad_arguments():
    model = point_double_pendulum(1.0, 1.0)
    with pytest.raises(ModelError, match="inputs"):
        sd.linearize(model, inputs=["nope"])
    with pytest.raises(ModelError, match="outputs"):
        sd.linearize(model, outputs=["nope"])
    with pytest.raises(ModelError, match="at"):
        sd.linearize(model, at=3)


@pytest.mark.parametrize("formulation", ["index2", "index3"])
def test_discrete_step_against_finite_differences(formulation):
    """lin.discrete(h) against central differences of one step of the nonlinear scheme from
    perturbed states (configuration by the joint coordinates, velocities, accelerations, the
    scheme's variable a, the actuator input) about the equilibrium of a compound double
    pendulum with a damper and an actuator."""
    mb2 = sd.ModelBuilder(gravity=(0, 0, -G))
    mb2.node("ground", fixed=True)
    mb2.node("bar1", position=(0, 0, -0.35), mass=2.0, inertia=(0.12, 0.11, 0.07))
    mb2.node("bar2", position=(0, 0, -1.25), mass=1.5, inertia=(0.06, 0.07, 0.035))
    mb2.joint("h1", "hinge", "ground", "bar1", axis=(0, 1, 0), at=(0, 0, 0), torque=0.0,
              damping=0.3)
    mb2.joint("h2", "hinge", "bar1", "bar2", axis=(0, 1, 0), at=(0, 0, -0.8))
    model = mb2.build()
    eq = sd.static_equilibrium(model)
    h, rho = 0.01, 0.8
    dis = sd.linearize(model, at=eq, inputs=["h1"]).discrete(h, rho_inf=rho)
    s = eq.system
    js = sd.JointSpace(s)
    ga = sd.GeneralizedAlpha(rho_inf=rho, formulation=formulation, tol_residual=1e-15,
                             tol_constraint=1e-15, newton="full")
    slot = [nm[3] for nm in s.inputs.names if nm[1] == "h1"][0]
    T = js._mass_and_map(eq.H, eq.HJ, eq.alpha)[1].T
    ind = js.partition.independent

    def step(x, u):
        z, zd, zdd, a = x[:2], x[2:4], x[4:6], x[6:]
        q = eq.alpha[ind] + z
        H = np.array([js.frame_pose(q, n) for n in s.node_names])
        alpha = eq.alpha.copy()
        alpha[ind] = q
        st = sd.State(t=0.0, H=H, HJ=_joint_frames(s, H), v=T @ zd,
                      vd=T @ zdd, a=T @ a, lam=eq.lam, alpha=alpha)
        inputs = dict(u=np.zeros(s.inputs.nu))
        inputs["u"][:3] = s.gravity
        inputs["u"][slot] = u
        new = ga.step(s, st, h, inputs=inputs)[0]
        return np.concatenate([new.alpha[ind] - eq.alpha[ind], new.v[ind], new.vd[ind],
                               new.a[ind]])

    eps = 1e-5
    x0 = np.zeros(8)
    for k in range(8):
        e = np.zeros(8)
        e[k] = eps
        fd = (step(x0 + e, 0.0) - step(x0 - e, 0.0)) / (2 * eps)
        assert np.abs(fd - dis.Phi[:, k]).max() <= 1e-7 * np.abs(dis.Phi).max()
    fd = (step(x0, eps) - step(x0, -eps)) / (2 * eps)
    assert np.abs(fd - dis.Gamma[:, 0]).max() <= 1e-7 * np.abs(dis.Gamma).max()


def _joint_frames(s, H):
    from se3dyn.engine.system import joint_frames

    return joint_frames(s, H[None])[0]


def spinning_top(spin: float, m=1.0, l=0.1, A=0.002, C=0.004) -> sd.Model:
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    mb.node("top", com=(0, 0, l), mass=m, inertia=(A, A, C), angular_velocity=(0, 0, spin))
    mb.joint("pivot", "spherical", "ground", "top")
    return mb.build()


def test_heavy_top_sleeping_threshold():
    """A heavy top spinning upright is a relative equilibrium: in material velocities its state
    is time-invariant, and the linearisation about it (the initial state of a run) holds for
    all times. Closed form (inertial frame, xi = theta_x + i theta_y): I0 xi'' - i C W xi' -
    m g l xi = 0, stable iff C^2 W^2 >= 4 I0 m g l (I0 = A + m l^2); the material coordinates
    turn with the top, so their eigenvalues are the inertial ones shifted by -i W."""
    m, l, A, C = 1.0, 0.1, 0.002, 0.004
    I0 = A + m * l * l
    Wc = 2 * math.sqrt(I0 * m * G * l) / C

    def eig(W):
        return np.linalg.eigvals(sd.linearize(spinning_top(W, m, l, A, C)).A)

    lam = eig((1 - 1e-8) * Wc)
    assert np.abs(lam.real).max() > 1e-9 * np.abs(lam).max()  # just below: unstable
    for f in (1 + 1e-8, 1.5, 3.0):
        W = f * Wc
        lam = eig(W)
        assert np.abs(lam.real).max() <= 1e-9 * np.abs(lam).max()  # purely imaginary
        ref = (1j * C * W + np.array([1, -1]) * np.sqrt(complex(4 * I0 * m * G * l
                                                                - (C * W) ** 2))) / (2 * I0)
        ref = np.abs((ref - 1j * W).imag)
        got = np.sort(np.abs(lam.imag))[-4::2]  # the two conjugate pairs (and a double 0)
        assert np.abs(np.sort(ref) / got - 1).max() <= 1e-8
    md = sd.linearize(spinning_top(2 * Wc, m, l, A, C)).modes()
    assert len(md) == 3 and np.sum(md.rigid) == 1  # the spin angle: no stiffness


def test_cli_linearize_exports_the_linear_model(tmp_path, capsys):
    """``se3dyn linearize MODEL --export x.npz``: the compound double pendulum's frequencies
    (closed form as above) in the printed table and the file."""
    from se3dyn.cli.commands import main
    from se3dyn.io.modelfile import save_model

    m1, m2, l1, c1, c2, J1, J2 = 2.0, 1.5, 0.8, 0.35, 0.45, 0.11, 0.07
    path = tmp_path / "pendulum.yaml"
    save_model(compound_double(m1, m2, l1, c1, c2, J1, J2), path)
    out = tmp_path / "lin.npz"
    assert main(["linearize", str(path), "--input", "h1", "--output", "h2", "--export",
                 str(out)]) == 0
    assert "2 minimal coordinates about the static equilibrium" in capsys.readouterr().out
    data = np.load(out)
    M = np.array([[J1 + m1 * c1**2 + m2 * l1**2, m2 * l1 * c2], [m2 * l1 * c2, J2 + m2 * c2**2]])
    K = G * np.diag([m1 * c1 + m2 * l1, m2 * c2])
    ref = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(M, K)).real))
    assert np.abs(data["omega"] / ref - 1).max() <= 1e-10
    assert list(data["input_names"]) == ["h1"] and list(data["output_names"]) == ["h2"]
    assert data["A"].shape == (4, 4) and data["T"].shape[1] == 2
    assert main(["linearize", str(path), "--input", "nope"]) == 2


def two_pendulums(ratio: float = 0.0, drive: bool = False) -> sd.Model:
    """Two pendulums on parallel hinges (bars with nodes at their centres of mass), coupled
    by ``alpha_b = ratio alpha_a`` (a gear, a URDF mimic), or the second carried by the first
    and held by a position drive."""
    mb = sd.ModelBuilder(gravity=(0, 0, -G))
    mb.node("ground", fixed=True)
    mb.node("a", position=(0, 0, -0.3), mass=1.5, inertia=(0.05, 0.04, 0.02))
    mb.node("b", position=(1.0, 0, -0.5) if not drive else (0, 0, -0.9), mass=0.7,
            inertia=(0.03, 0.02, 0.01))
    mb.joint("ja", "hinge", "ground", "a", axis=(0, 1, 0), at=(0, 0, 0))
    if drive:
        mb.joint("jb", "hinge", "a", "b", axis=(0, 1, 0), at=(0, 0, -0.6))
        mb.drive("hold", "jb", position=0.0)
    else:
        mb.joint("jb", "hinge", "ground", "b", axis=(0, 1, 0), at=(1.0, 0, 0))
        mb.coupling("gear", leader="ja", follower="jb", ratio=ratio)
    return mb.build()


def test_coupled_pendulums():
    """A coupling's follower is dependent: omega^2 = g (m_a c_a + r^2 m_b c_b) / (I_a + r^2
    I_b), I about the pivots (the follower's virtual work r times the leader's); in joint space
    the mass matrix and gravity torque of the same closed form."""
    r = -1.6
    model = two_pendulums(r)
    Ia, Ib = 0.04 + 1.5 * 0.3**2, 0.02 + 0.7 * 0.5**2
    lin = sd.linearize(model, at=sd.static_equilibrium(model))
    assert lin.names == ("joint 'ja' alpha_0",)
    w2 = G * (1.5 * 0.3 + r * r * 0.7 * 0.5) / (Ia + r * r * Ib)
    assert abs(lin.modes().omega[0] / math.sqrt(w2) - 1) <= 1e-10
    js = sd.JointSpace(model)
    th = np.array([[0.4], [-1.1]])
    assert np.abs(js.mass_matrix(th)[:, 0, 0] / (Ia + r * r * Ib) - 1).max() <= 1e-10
    g_ref = G * (1.5 * 0.3 * np.sin(th[:, 0]) + r * 0.7 * 0.5 * np.sin(r * th[:, 0]))
    assert np.abs(js.gravity(th)[:, 0] - g_ref).max() <= 1e-10 * np.abs(g_ref).max()


def test_driven_coordinate_is_held():
    """A position drive holds its coordinate: the double pendulum with its second hinge driven
    swings as one compound pendulum, omega^2 = g (m_a c_a + m_b c_b) / (I_a + I_b) about the
    pivot (c_b = 0.9)."""
    model = two_pendulums(drive=True)
    lin = sd.linearize(model, at=sd.static_equilibrium(model))
    assert lin.names == ("joint 'ja' alpha_0",)
    Ia, Ib = 0.04 + 1.5 * 0.3**2, 0.02 + 0.7 * 0.9**2
    w2 = G * (1.5 * 0.3 + 0.7 * 0.9) / (Ia + Ib)
    assert abs(lin.modes().omega[0] / math.sqrt(w2) - 1) <= 1e-10


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_free_body_spinning_about_a_principal_axis(axis):
    """A free body spinning about a principal axis (a relative equilibrium of a floating node:
    its 6 unknowns independent, the coordinate rates of Eq. (27)'s ad term): Euler's equations
    linearised give s^2 = -W^2 (I_a - I_j)(I_a - I_k) / (I_j I_k): oscillation about the
    largest and the smallest axes, divergence about the intermediate one."""
    I = np.array([1.0, 2.0, 2.6])
    W = 1.7
    mb = sd.ModelBuilder()
    w = np.zeros(3)
    w[axis] = W
    mb.node("body", position=(0.3, -0.2, 0.5), mass=2.0, inertia=tuple(I), angular_velocity=w)
    lin = sd.linearize(mb.build())
    assert len(lin.names) == 6
    lam = np.linalg.eigvals(lin.A)
    j, k = (i for i in range(3) if i != axis)
    ref = np.sqrt(complex(-W * W * (I[axis] - I[j]) * (I[axis] - I[k]) / (I[j] * I[k])))
    for r in (ref, -ref):
        assert np.abs(lam - r).min() <= 1e-10 * abs(ref)
    assert np.all(lin.modes().stable) == (axis != 1)


def test_modes_page_plays_the_closed_form_mode_shapes(tmp_path, capsys):
    """``se3dyn modes MODEL --mode N``: the page's motion is the mode's shape, a cos(theta) times
    the eigenvector of the compound double pendulum's M^-1 K (absolute angles p; the joint
    coordinates are p1 and p2 - p1), every frame, for both modes."""
    from se3dyn.cli.commands import main
    from se3dyn.io.modelfile import save_model
    from se3dyn.viewer.modes import mode_results

    m1, m2, l1, c1, c2, J1, J2 = 2.0, 1.5, 0.8, 0.35, 0.45, 0.11, 0.07
    model = compound_double(m1, m2, l1, c1, c2, J1, J2)
    M = np.array([[J1 + m1 * c1**2 + m2 * l1**2, m2 * l1 * c2], [m2 * l1 * c2, J2 + m2 * c2**2]])
    K = G * np.diag([m1 * c1 + m2 * l1, m2 * c2])
    w2, V = np.linalg.eig(np.linalg.solve(M, K))
    lin = sd.linearize(model, at=sd.static_equilibrium(model))
    for mode, col in enumerate(np.argsort(w2)):
        v = V[:, col]
        shape = np.array([v[0], v[1] - v[0]])  # (joint coordinates)
        res = mode_results(lin, mode, frames=16, amplitude=0.01)
        q = np.column_stack([res.joint_coordinates(j)[:, 0] for j in ("h1", "h2")])
        big = np.abs(q[:, 0]) > 1e-3
        np.testing.assert_allclose(q[big, 1] / q[big, 0], shape[1] / shape[0], rtol=1e-10)
        theta = 2 * np.pi * res.t / res.t[-1]
        np.testing.assert_allclose(np.abs(q[:, 0]), np.abs(q[0, 0] * np.cos(theta)),
                                   atol=1e-14)
    path = tmp_path / "pendulum.yaml"
    save_model(model, path)
    page = tmp_path / "mode2.html"
    assert main(["modes", str(path), "--mode", "2", "-o", str(page)]) == 0
    assert "wrote" in capsys.readouterr().out and "mode 2" in page.read_text()
    assert main(["modes", str(path), "--mode", "3"]) == 2


def test_modes_of_a_long_cantilever_with_a_wide_spectrum():
    """A 60-element cantilever whose rotary inertia is tiny (frequencies from 20 to 1e8 rad/s
    in one model): the two lowest bending pairs from the scaled companion form approach
    Euler-Bernoulli's (beta L)^2 sqrt(EI / m L^4), beta L = 1.87510, 4.69409 (lumped masses:
    within 2e-3; the unscaled symmetric problem in w^2 loses 0.35 % there), and modes(k) is
    the first k of the whole spectrum (the fast path of large conservative models: 1e-6)."""
    L, EI, m = 2.0, (2e3, 1e3), 2.0
    mb = sd.ModelBuilder()
    mb.node("root", fixed=True)
    mb.node("tip", (L, 0, 0))
    mb.beam("b", "root", "tip", elements=60, EA=1e7, GA=1e8, GJ=1e3, EI=EI,
            mass_per_length=m, rotary_inertia=(2e-9, 1e-9, 1e-9))
    lin = sd.linearize(mb.build())
    few, every = lin.modes(6), lin.modes()  # (the 6 slowest by shift-invert Lanczos)
    np.testing.assert_allclose(few.omega, every.omega[:6], rtol=1e-6)
    K, M = lin.K, lin.M  # its shapes are eigenvectors of K x = w^2 M x
    x = few.shapes.real
    res = np.linalg.norm(K @ x - (M @ x) * few.omega ** 2, axis=0)
    assert np.all(res <= 1e-6 * np.linalg.norm(M @ x, axis=0) * few.omega ** 2)
    for bl, pair in ((1.87510407, few.omega[:2]), (4.69409113, few.omega[2:4])):
        ref = np.sort([bl ** 2 * math.sqrt(e / (m * L ** 4)) for e in EI])
        np.testing.assert_allclose(np.sort(pair), ref, rtol=2e-3)
