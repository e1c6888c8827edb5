"""Validation gallery: problems of the IFToMM / Coruna library of MBS benchmark problems.

Library: M. Gonzalez, D. Dopico, U. Lugris, J. Cuadrado, "A benchmarking system for MBS simulation
software: problem standardization and performance measurement", Multibody System Dynamics 16
(2006) 179-190; http://lim.ii.udc.es/mbsbenchmark/ (now https://www.iftomm-multibody.org/benchmark/).
The model files are ``examples/a0*.yaml``; the pages are ``docs/gallery/``.

What is compared with what. The library states, per problem, the compared quantity and the
allowed errors, "1.0E-1 (low precision) and 1.0E-3 (high precision)" (A01, A02 specification
pages). Its reference time histories (``A0x_solution_data.txt``) could not be obtained, so no
number of them is used; instead every run is compared with an *exact or independently computed*
solution of the same specification, to the library's high-precision error 1e-3:

* A01: the simple pendulum in closed form (Jacobi elliptic functions) and its exact period
  ``4 sqrt(L/g) K(sin^2(theta0/2))``;
* A02: the N-four-bar is a parallelogram chain: every crank turns by the same angle and the
  couplers translate, so the exact motion is that of one physical pendulum, integrated here by
  scipy to 1e-12;
* A05: momentum about the shaft is conserved exactly, the energy balance holds, and the stiff
  spring-dampers (K = 8e5 N/m) must reproduce their rigid-strut limit (a one-dof pendulum with
  conserved momentum, integrated by scipy) to the strut deflection, well below 1e-3 m;
* A04: only energy conservation (as in the library's reproductions) plus the mobility.

Horizons are shortened to keep this file fast; the library's full runs are in the docs pages.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.special import ellipj, ellipk

import se3dyn as sd
from se3dyn.engine.rank import rank_analysis
from se3dyn.engine.system import compile_model
from se3dyn.io.modelfile import load_model

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
G = 9.81  # all specifications: 9.81 N/kg
# "The maximun allowed errors are 1.0E-1 (low precission) and 1.0E-3 (high precission)":
# http://lim.ii.udc.es/mbsbenchmark/dist/A01/A01_specification.xml and .../A02/A02_specification.xml
HIGH_PRECISION = 1e-3


def _load(name):
    return load_model(EXAMPLES / name)


def _crossings(t, y):
    """Times where y changes sign, linearly interpolated."""
    i = np.flatnonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


# ---------------------------------------------------------------------------------------------
# A01 simple pendulum: 1 kg lumped mass, massless link 1 m, gravity -y, released at rest from the
# horizontal with x(P1) = +1 m (http://lim.ii.udc.es/mbsbenchmark/dist/A01/A01_specification.xml)
# ---------------------------------------------------------------------------------------------
A01_L, A01_M, A01_THETA0 = 1.0, 1.0, math.pi / 2


def _pendulum_exact(t):
    """Angle from the downward vertical: sin(theta/2) = k sn(K - w0 t | k^2), k = sin(theta0/2)."""
    m = math.sin(A01_THETA0 / 2) ** 2  # scipy takes the parameter m = k^2
    w0 = math.sqrt(G / A01_L)
    sn = ellipj(ellipk(m) - w0 * t, m)[0]
    return 2.0 * np.arcsin(math.sqrt(m) * sn)


def test_a01_simple_pendulum_follows_the_exact_solution_and_period():
    model, settings = _load("a01_simple_pendulum.yaml")
    h, rho = settings["step"], settings["rho_inf"]
    assert rho == 1.0  # no numerical dissipation: the energy check below tests the scheme alone
    res = sd.simulate(model, 5.0, h, rho_inf=rho)  # library: 2000 s; here about 2 periods
    th = _pendulum_exact(res.t)
    p = res.node_position("P1")
    # the library's compared quantity: P1 (x, y), allowed error 1e-3 (high precision)
    assert np.abs(p[:, 0] - A01_L * np.sin(th)).max() <= HIGH_PRECISION
    assert np.abs(p[:, 1] + A01_L * np.cos(th)).max() <= HIGH_PRECISION
    assert np.abs(p[:, 2]).max() < 1e-12  # planar
    # exact period of a release from theta0: T = 4 sqrt(L/g) K(sin^2(theta0/2))
    T = 4.0 * math.sqrt(A01_L / G) * ellipk(math.sin(A01_THETA0 / 2) ** 2)
    tc = _crossings(res.t, p[:, 0])  # x = 0 at T/4, 3T/4, 5T/4, 7T/4
    assert len(tc) == 4
    T_num = (tc[-1] - tc[0]) / 1.5
    # second-order scheme: the trapezoidal rule (rho_inf = 1) lengthens the period of a linear
    # oscillator of rate w by (w h)^2 / 12; bound with the largest angular rate of the swing,
    # w_max = sqrt(2 g / L), and a factor 2 for the nonlinear swing
    assert abs(T_num - T) / T <= 2 * (math.sqrt(2 * G / A01_L) * h) ** 2 / 12
    # energy: with rho_inf = 1 there is no numerical dissipation; the (bounded) energy error of
    # the scheme must stay below the potential energy of the allowed position error
    E = res.total_energy
    assert np.abs(E - E[0]).max() <= A01_M * G * HIGH_PRECISION
    # the ball is an exact point mass: its free rotation is never excited
    assert np.abs(res.node_velocity("P1")[:, 3:]).max() < 1e-12


# ---------------------------------------------------------------------------------------------
# A02 N-four-bar mechanism: 2N+1 links of 1 m and 1 kg, gravity -y, 20 s, N = 40, B0 x-velocity
# 1 m/s (http://lim.ii.udc.es/mbsbenchmark/dist/A02/A02_specification.xml); cranks vertical at
# the start (the specification's figure, as in RehabEngGroup/MBSbenchmarksInOpenSim).
# ---------------------------------------------------------------------------------------------
def _n_four_bar(n):
    """The layout of ``examples/a02_n_four_bar.yaml`` for n windows (that file has n = 40)."""
    mb = sd.ModelBuilder(gravity=(0.0, -G, 0.0), name=f"a02_n_four_bar_{n}")
    rod = dict(mass=1.0, inertia=(1e-4, 1.0 / 12.0, 1.0 / 12.0))
    z = (0.0, 0.0, 1.0)
    mb.node("ground", fixed=True)
    for i in range(n + 1):
        mb.node(f"o{i}", (i, 0.0, 0.0))
        mb.node(f"c{i}", (i, 0.5, 0.0), **rod, principal_axes=[[0, 1, 0], [1, 0, 0], [0, 0, -1]],
                velocity=(0.5, 0.0, 0.0), angular_velocity=(0.0, 0.0, -1.0))
        mb.node(f"b{i}", (i, 1.0, 0.0))
    for j in range(1, n + 1):
        mb.node(f"k{j}", (j - 0.5, 1.0, 0.0), **rod, velocity=(1.0, 0.0, 0.0))
    for i in range(n + 1):
        mb.joint(f"A{i}", "hinge", "ground", f"o{i}", axis=z)
        mb.joint(f"crank{i}", "rigid", f"o{i}", f"c{i}")
        mb.joint(f"tip{i}", "rigid", f"c{i}", f"b{i}")
    for j in range(1, n + 1):
        mb.joint(f"L{j}", "hinge", f"k{j}", f"b{j - 1}", axis=z)
        mb.joint(f"R{j}", "hinge", f"k{j}", f"b{j}", axis=z)
    return mb.build()


def _four_bar_exact(n, t):
    """Crank angle psi from the upward vertical (clockwise) and its rate, exact reduction:
    J psi'' = g a sin psi with J = (n+1)/3 + n (cranks about their pivots, translating couplers)
    and a = (n+1)/2 + n (heights of the centres), psi(0) = 0, psi'(0) = 1 rad/s."""
    J, a = (n + 1) / 3 + n, (n + 1) / 2 + n
    sol = solve_ivp(lambda _, y: (y[1], G * a / J * math.sin(y[0])), (0.0, float(t[-1])),
                    (0.0, 1.0), t_eval=t, rtol=1e-12, atol=1e-12, method="DOP853")
    return sol.y


def test_a02_model_file_is_the_n40_mechanism_with_mobility_one_and_3n_redundant_equations():
    model, _ = _load("a02_n_four_bar.yaml")
    ref = _n_four_bar(40)
    assert model.node_names == ref.node_names and model.joint_names == ref.joint_names
    for a, b in zip(model.nodes, ref.nodes, strict=True):
        np.testing.assert_allclose(a.position, b.position, atol=1e-15)
        np.testing.assert_allclose(a.inertia, b.inertia, atol=1e-15)
        np.testing.assert_allclose(a.velocity, b.velocity, atol=1e-15)
        assert a.mass == b.mass
    assert sum(nd.mass for nd in model.nodes) == 2 * 40 + 1  # 2N+1 links of 1 kg
    rep = rank_analysis(compile_model(model))
    # one dof at the start (cranks vertical); a planar loop of 3D hinges is overconstrained by 3
    assert rep.dof == 1
    assert len(rep.redundant) == 3 * 40


def test_a02_n_four_bar_passes_the_singular_positions_on_the_exact_motion():
    n = 4  # the library's N = 40, 20 s run: docs/gallery/make_plots.py a02
    model = _n_four_bar(n)
    assert rank_analysis(compile_model(model)).dof == 1
    h = 2e-3
    res = sd.simulate(model, 2.0, h, rho_inf=0.9)
    psi, psid = _four_bar_exact(n, res.t)
    # the motion passes the horizontal (singular) positions psi = pi/2 and 3 pi/2
    assert psi[-1] > 2 * math.pi
    B0 = res.node_position("b0")
    vB0 = res.node_velocity("b0", frame="inertial")[:, :3]
    # library's compared quantities: B0 position and velocity, allowed error 1e-3 (high
    # precision); velocities relative to the largest speed
    assert np.abs(B0[:, 0] - np.sin(psi)).max() <= HIGH_PRECISION
    assert np.abs(B0[:, 1] - np.cos(psi)).max() <= HIGH_PRECISION
    vmax = np.abs(psid).max()
    assert np.abs(vB0[:, 0] - np.cos(psi) * psid).max() <= HIGH_PRECISION * vmax
    assert np.abs(vB0[:, 1] + np.sin(psi) * psid).max() <= HIGH_PRECISION * vmax
    # the cranks stay parallel through the singular positions (no bifurcation)
    for i in range(1, n + 1):
        np.testing.assert_allclose(res.node_position(f"b{i}") - (i, 0.0, 0.0), B0, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# A04 Bricard mechanism: 5 rods of 1 m, 1 kg, 6 hinges, gravity -y, 10 s, from rest
# (http://rehabenggroup.github.io/MBSbenchmarksInOpenSim/benchmarks/A04_BricardsMechanism.html,
# reproducing http://lim.ii.udc.es/mbsbenchmark/dist/A04/A04_specification.xml)
# ---------------------------------------------------------------------------------------------
def test_a04_bricard_has_mobility_one_against_grubler_zero_and_conserves_energy():
    model, settings = _load("a04_bricard.yaml")
    s = compile_model(model)
    rep = rank_analysis(s)
    moving = sum(nd.mass > 0 for nd in model.nodes)
    hinges = sum(j.type == "hinge" for j in model.joints)
    assert 6 * moving - 5 * hinges == 0  # Grubler count
    assert rep.dof == 1 and len(rep.redundant) == 1
    res = sd.simulate(s, 3.0, settings["step"], rho_inf=settings["rho_inf"])
    P3 = res.node_position("p3")
    assert np.ptp(P3, axis=0).max() > 0.1  # it moves
    # no dissipation: the library's reproductions check the energy variation (zero exactly);
    # allowed: the potential energy of the 5 kg over the high-precision error 1e-3 m
    E = res.total_energy
    assert np.abs(E - E[0]).max() <= 5.0 * G * HIGH_PRECISION
    # the rods keep their lengths through the motion (constraints hold)
    pts = [res.node_position(f"p{i}") for i in range(6)]
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        np.testing.assert_allclose(np.linalg.norm(b - a, axis=1), 1.0, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# A05 stiff flyball governor (parameters: docs/gallery/a05_flyball_governor.md)
# ---------------------------------------------------------------------------------------------
A05_RHO = 3000.0
A05_MBAR, A05_MSL, A05_MP = A05_RHO * 1.0 * 0.01 * 0.01, A05_RHO * 0.1**3, 5.0


def _flyball_rigid_limit(t):
    """Rigid-strut limit (K -> infinity): rod angle theta below the horizontal, slider height
    s = 1 - sin(theta) (strut of 0.5 m between (0.05, s) and the rod midpoint), conserved
    momentum L = I_zz(theta) w; one-dof Lagrangian with the amended potential V + L^2/(2 I_zz).
    Returns (s, w) at the times t."""
    m = A05_MBAR + A05_MP
    lc = (A05_MBAR * 0.5 + A05_MP) / m  # rod + point mass centre, from the hinge
    J1 = A05_MBAR * 2e-4 / 12  # bar about its axis
    Jt = A05_MBAR * (1 + 1e-4) / 12 + A05_MBAR * (0.5 - lc) ** 2 + A05_MP * (1 - lc) ** 2
    JA = Jt + m * lc**2  # about the hinge

    def izz(th):
        rods = J1 * np.sin(th) ** 2 + Jt * np.cos(th) ** 2 + m * (0.05 + lc * np.cos(th)) ** 2
        return J1 + A05_MSL * 0.02 / 12 + 2 * rods  # shaft + slider + 2 rods

    def dizz(th):
        return 2 * ((J1 - Jt) * np.sin(2 * th) - 2 * m * lc * (0.05 + lc * np.cos(th))
                    * np.sin(th))

    th0 = math.radians(30.0)
    L = izz(th0) * 2 * math.pi

    def rhs(_, y):
        th, thd = y
        Jeff = 2 * JA + A05_MSL * math.cos(th) ** 2
        dJ = -2 * A05_MSL * math.cos(th) * math.sin(th)
        Q = G * (2 * m * lc + A05_MSL) * math.cos(th) + L**2 * dizz(th) / (2 * izz(th) ** 2)
        return thd, (Q - 0.5 * dJ * thd**2) / Jeff

    sol = solve_ivp(rhs, (0.0, float(t[-1])), (th0, 0.0), t_eval=t, rtol=1e-12, atol=1e-12,
                    method="DOP853")
    th = sol.y[0]
    return 1.0 - np.sin(th), L / izz(th), L


def _axial_momentum(model, res):
    """Angular momentum about the z axis of the bodies (massless nodes carry none)."""
    Lz = np.zeros(len(res.t))
    for nd in model.nodes:
        if nd.mass == 0:
            continue
        R = res.node_rotation(nd.name)
        v = res.node_velocity(nd.name)  # material (U, Omega)
        Jm = nd.orientation.T @ nd.inertia @ nd.orientation  # material-frame inertia
        spin = np.einsum("nij,jk,nk->ni", R, Jm, v[:, 3:])
        x, xd = res.node_position(nd.name), np.einsum("nij,nj->ni", R, v[:, :3])
        Lz += spin[:, 2] + nd.mass * (x[:, 0] * xd[:, 1] - x[:, 1] * xd[:, 0])
    return Lz


def test_a05_stiff_flyball_governor_conserves_momentum_and_follows_its_rigid_strut_limit():
    model, settings = _load("a05_flyball_governor.yaml")
    assert [nd.mass for nd in model.nodes if nd.mass] == pytest.approx(
        [A05_MBAR, A05_MSL, A05_MBAR + A05_MP, A05_MBAR + A05_MP])
    h = settings["step"]
    res = sd.simulate(model, 2.0, h, rho_inf=settings["rho_inf"])  # two swings of the balls
    s_ref, w_ref, L = _flyball_rigid_limit(res.t)
    # no axial moment on the system (gravity along the shaft, frictionless hinge): L_z constant;
    # second-order drift bound (Omega h)^2 with the shaft rate Omega = 2 pi rad/s
    Lz = _axial_momentum(model, res)
    assert Lz[0] == pytest.approx(L, rel=1e-12)
    assert np.abs(Lz - L).max() <= (2 * math.pi * h) ** 2 * L
    # energy balance E + dissipated = E0, to the potential energy of the total weight over the
    # high-precision error 1e-3 m
    eb = res.energy_balance
    weight = G * (2 * A05_MBAR + A05_MSL + 2 * (A05_MBAR + A05_MP))
    assert np.abs(eb - eb[0]).max() <= weight * HIGH_PRECISION
    # the slider swings by ~0.24 m; the stiff struts deflect by force / K < 1e-3 m, so the
    # motion must be the rigid-strut one to the library's high-precision error
    s = res.node_position("slider")[:, 2]
    assert np.ptp(s) > 0.2
    assert np.abs(s - s_ref).max() <= HIGH_PRECISION
    w = res.node_velocity("shaft")[:, 5]
    assert np.abs(w - w_ref).max() <= HIGH_PRECISION * 2 * math.pi
