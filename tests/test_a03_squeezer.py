"""IFToMM benchmark A03, Andrews' squeezing mechanism (``examples/a03_andrews_squeezer.yaml``).

The "seven-body mechanism" of E. Hairer, G. Wanner, *Solving Ordinary Differential Equations
II*, Springer (1991, 1996), Sec. VII.7 (after W. Schiehlen (ed.), *Multibody Systems Handbook*,
Springer 1990; Manning & Andrews): seven rigid bodies in a plane, ten hinges, three closed
loops, a spring c0 = 4530 N/m and a driving torque of 0.033 N m, no gravity, 0 <= t <= 0.03 s.

Source of every number here: the Test Set for IVP Solvers (Bari; F. Mazzia, C. Magherini),
problem "andrews" (``andrews.F,v 1.2 2006/10/02``), as shipped in the R package deTestSet
(rforge bvpsolve): parameters and consistent initial values ``pkg/deTestSet/R/ex_andrews.R``,
equations of motion (mass matrix, constraints, spring) ``pkg/deTestSet/src/Ex_andrews.f``
(``andfunc``), reference solution at t = 0.03 s ``andsoln`` in the same file (PSIDE,
rtol = atol = 1e-14, Cray C90 double precision; 16 digits).

What is checked:

* the model file is the published mechanism: its hinge and spring points are those of the
  published geometry at the published initial angles, masses, inertias, spring and torque too,
  and the hinges of the seven published angles start at them (``initial``);
* the seven angles and rates at t = 0.03 s converge at order 2 (the generalized-alpha scheme,
  Eqs. (38)-(44)) to the published reference: errors at h and 2h in the ratio 4, and their
  Richardson extrapolation agrees with the reference a hundred times closer than the run at h,
  so the published solution is the limit of se3dyn's solutions; at the file's step the angles
  are within 1e-4 rad (the crank turns by 15.9 rad);
* energy: no gravity and no damping, so the work of the torque equals the change of kinetic plus
  spring energy; the published reference satisfies this with its own mass matrix M(q) and
  spring, and se3dyn's kinetic and spring energies at t = 0.03 s are those of the reference.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.engine.rank import rank_analysis
from se3dyn.io.modelfile import load_model, loads_model, save_model

FILE = Path(__file__).resolve().parents[1] / "examples" / "a03_andrews_squeezer.yaml"

#: published parameters (ex_andrews.R, ``parameter``): kg, kg m^2, m, N/m, N m
PAR = dict(m1=0.04325, m2=0.00365, m3=0.02373, m4=0.00706, m5=0.07050, m6=0.00706, m7=0.05498,
           xa=-0.06934, ya=-0.00227, xb=-0.03635, yb=0.03273, xc=0.014, yc=0.072, c0=4530.0,
           i1=2.194e-6, i2=4.410e-7, i3=5.255e-6, i4=5.667e-7, i5=1.169e-5, i6=5.667e-7,
           i7=1.912e-5, d=28e-3, da=115e-4, e=2e-2, ea=1421e-5, rr=7e-3, ra=92e-5, l0=7785e-5,
           ss=35e-3, sa=1874e-5, sb=1043e-5, sc=18e-3, sd=2e-2, ta=2308e-5, tb=916e-5, u=4e-2,
           ua=1228e-5, ub=449e-5, zf=2e-2, zt=4e-2, fa=1421e-5, mom=33e-3)
T_END = 0.03
#: the published angles, in the order of the test set: beta, Theta, gamma, Phi, delta, Omega,
#: epsilon; each is the coordinate of the hinge of that name in the model file
ANGLES = ("beta", "Theta", "gamma", "Phi", "delta", "Omega", "epsilon")
#: consistent initial angles (rad), the bodies at rest (ex_andrews.R, ``yini[1:7]``)
Q0 = np.array([-0.0617138900142764496358948458001, 0.0, 0.455279819163070380255912382449,
               0.222668390165885884674473185609, 0.487364979543842550225598953530,
               -0.222668390165885884674473185609, 1.23054744454982119249735015568])
#: reference solution at t = 0.03 s (Ex_andrews.f, ``andsoln``, y(1:7) and y(8:14))
Q_REF = np.array([0.1581077119629904e+2, -0.1575637105984298e+2, 0.4082224013073101e-1,
                  -0.5347301163226948e+0, 0.5244099658805304e+0, 0.5347301163226948e+0,
                  0.1048080741042263e+1])
QD_REF = np.array([0.1139920302151208e+4, -0.1424379294994111e+4, 0.1103291221937134e+2,
                   0.1929337464421385e+2, 0.5735699284790808e+0, -0.1929337464421385e+2,
                   0.3231791658026955e+0])
STEP = 1e-5  # the model file's step (checked below)


def _e(a):
    """Unit vector at angle a, shape (2,)."""
    return np.array([math.cos(a), math.sin(a)])


def _n(a):
    """Unit vector at angle a - pi/2, shape (2,)."""
    return np.array([math.sin(a), -math.cos(a)])


def points(q):
    """The published geometry at the angles q (7,): hinge and spring points (2,) by name.

    Read from the constraints g and the spring of ``andfunc``: E is reached through body 2
    (``E``), body 3 (``E3``), bodies 5 and 4 (``E4``) and bodies 7 and 6 (``E6``); the mass
    centres ``c2``, ``c4``, ``c6`` from the mass matrix M(q) (the other bodies turn about fixed
    points, so only their distances from them enter M).
    """
    p = PAR
    be, th, ga, ph, de, om, ep = q
    O, A, B, C = np.zeros(2), np.array([p["xa"], p["ya"]]), np.array([p["xb"], p["yb"]]), \
        np.array([p["xc"], p["yc"]])
    P = p["rr"] * _e(be)
    H = A + p["zt"] * _e(de)
    G = A + p["u"] * _n(ep)
    return dict(O=O, A=A, B=B, C=C, P=P, H=H, G=G,
                E=P - p["d"] * _e(be + th),
                E3=B + p["ss"] * _n(ga),
                E4=H + p["e"] * _n(ph + de),
                E6=G + p["zf"] * _e(om + ep),
                D=B + p["sd"] * _e(ga) + p["sc"] * _n(ga),
                c2=P - p["da"] * _e(be + th),
                c4=H + (p["e"] - p["ea"]) * _n(ph + de),
                c6=G + (p["zf"] - p["fa"]) * _e(om + ep))


def mass_matrix(q):
    """The published mass matrix M(q) (``andfunc``), shape (7, 7): kinetic energy qd.M.qd / 2."""
    p = PAR
    _, th, _, ph, _, om, _ = q
    e4, f6 = p["e"] - p["ea"], p["zf"] - p["fa"]
    M = np.zeros((7, 7))
    M[0, 0] = (p["m1"] * p["ra"] ** 2 + p["m2"] * (p["rr"] ** 2 - 2 * p["da"] * p["rr"]
               * math.cos(th) + p["da"] ** 2) + p["i1"] + p["i2"])
    M[1, 0] = p["m2"] * (p["da"] ** 2 - p["da"] * p["rr"] * math.cos(th)) + p["i2"]
    M[1, 1] = p["m2"] * p["da"] ** 2 + p["i2"]
    M[2, 2] = p["m3"] * (p["sa"] ** 2 + p["sb"] ** 2) + p["i3"]
    M[3, 3] = p["m4"] * e4 ** 2 + p["i4"]
    M[4, 3] = p["m4"] * (e4 ** 2 + p["zt"] * e4 * math.sin(ph)) + p["i4"]
    M[4, 4] = (p["m4"] * (p["zt"] ** 2 + 2 * p["zt"] * e4 * math.sin(ph) + e4 ** 2)
               + p["m5"] * (p["ta"] ** 2 + p["tb"] ** 2) + p["i4"] + p["i5"])
    M[5, 5] = p["m6"] * f6 ** 2 + p["i6"]
    M[6, 5] = p["m6"] * (f6 ** 2 - p["u"] * f6 * math.sin(om)) + p["i6"]
    M[6, 6] = (p["m6"] * (f6 ** 2 - 2 * p["u"] * f6 * math.sin(om) + p["u"] ** 2)
               + p["m7"] * (p["ua"] ** 2 + p["ub"] ** 2) + p["i6"] + p["i7"])
    return np.tril(M) + np.tril(M, -1).T


def spring_energy(q):
    """c0 (L - l0)^2 / 2 of the spring from D to C at the angles q (J)."""
    pt = points(q)
    return 0.5 * PAR["c0"] * (np.linalg.norm(pt["D"] - pt["C"]) - PAR["l0"]) ** 2


def angles(res):
    """The seven published angles and rates from se3dyn's hinge coordinates, shape (n, 7) each."""
    q = np.column_stack([res.joint_coordinates(a)[:, 0] for a in ANGLES])
    qd = np.column_stack([res.joint_velocities(a)[:, 0] for a in ANGLES])
    return q, qd


@pytest.fixture(scope="module")
def runs():
    model, settings = load_model(FILE)
    s = sd.compile_model(model)
    return {h: sd.simulate(s, T_END, h, rho_inf=settings["rho_inf"]) for h in (STEP, 2 * STEP)}


def test_a03_model_file_is_the_published_mechanism():
    model, settings = load_model(FILE)
    assert settings["t_end"] == T_END and settings["step"] == STEP
    assert not np.any(model.gravity)
    pt = points(Q0)
    # the published initial angles close the three loops at E
    for k in ("E3", "E4", "E6"):
        np.testing.assert_allclose(pt[k], pt["E"], rtol=0, atol=1e-17)
    # bodies: masses, inertias about z, mass centres
    p = PAR
    for i in range(1, 8):
        nd = model.node(f"body{i}")
        assert nd.mass == p[f"m{i}"] and nd.inertia[2, 2] == p[f"i{i}"] and nd.com is None
        assert nd.position[2] == 0.0
    xy = {i: model.node(f"body{i}").position[:2] for i in range(1, 8)}
    for i in (2, 4, 6):
        np.testing.assert_allclose(xy[i], pt[f"c{i}"], rtol=0, atol=1e-17)
    for i, pivot, a, b in ((1, "O", "ra", None), (3, "B", "sa", "sb"), (5, "A", "ta", "tb"),
                           (7, "A", "ua", "ub")):
        r = math.hypot(p[a], p[b]) if b else p[a]
        assert np.linalg.norm(xy[i] - pt[pivot]) == pytest.approx(r, rel=1e-14)
    # hinges: bodies, points, axes, published initial angles, the torque on beta only
    hinges = {"beta": ("ground", "body1", "O"), "Theta": ("body1", "body2", "P"),
              "gamma": ("ground", "body3", "B"), "delta": ("ground", "body5", "A"),
              "Phi": ("body5", "body4", "H"), "epsilon": ("ground", "body7", "A"),
              "Omega": ("body7", "body6", "G"), "E3": ("body2", "body3", "E"),
              "E4": ("body2", "body4", "E"), "E6": ("body2", "body6", "E")}
    assert sorted(model.joint_names) == sorted(hinges)
    for name, (a, b, at) in hinges.items():
        j = model.joint(name)
        assert (j.type, j.node_a, j.node_b) == ("hinge", a, b)
        np.testing.assert_allclose(j.at, [*pt[at], 0.0], rtol=0, atol=1e-17)
        np.testing.assert_array_equal(j.params["axis"], [0.0, 0.0, 1.0])
        assert not (np.any(j.stiffness) or np.any(j.damping) or j.control)
        if name in ANGLES:
            assert j.initial[0] == pytest.approx(Q0[ANGLES.index(name)], abs=1e-17)
        assert (j.actuator is not None) == (name == "beta")
    t = np.linspace(0.0, T_END, 7)
    np.testing.assert_array_equal(model.joint("beta").actuator.sample(t).ravel(), p["mom"])
    # the spring from D on body 3 to the fixed point C
    (sp,) = model.springs
    assert (sp.node_a, sp.node_b) == ("body3", "ground")
    np.testing.assert_allclose(sp.at_a[:2], pt["D"], rtol=0, atol=1e-17)
    np.testing.assert_allclose(sp.at_b[:2], pt["C"], rtol=0, atol=1e-17)
    assert (sp.stiffness, sp.length, sp.damping) == (p["c0"], p["l0"], 0.0)
    # 7 bodies, 10 hinges: 42 unknowns, 50 equations in 3D, mobility 1, so 9 redundant
    rep = rank_analysis(sd.compile_model(model))
    assert rep.dof == 1 and len(rep.redundant) == 9
    # written back, the file keeps the initial angles and the attachment points
    again, _ = loads_model(save_model(model, settings=settings))
    for a, b in zip(model.joints, again.joints, strict=True):
        np.testing.assert_array_equal(a.at, b.at)
        assert (a.initial is None and b.initial is None) or np.array_equal(a.initial, b.initial)


def test_a03_converges_at_order_two_to_the_published_solution(runs):
    (q1, qd1), (q2, qd2) = (angles(runs[h]) for h in (STEP, 2 * STEP))
    np.testing.assert_allclose(q1[0], Q0, rtol=0, atol=1e-15)  # the hinges start at Q0
    assert q1[-1, 0] - Q0[0] > 2.5 * 2 * math.pi  # the crank turns 2.5 times
    e1, e2 = np.abs(q1[-1] - Q_REF).max(), np.abs(q2[-1] - Q_REF).max()
    r1 = np.abs(qd1[-1] - QD_REF).max() / np.abs(QD_REF).max()
    r2 = np.abs(qd2[-1] - QD_REF).max() / np.abs(QD_REF).max()
    # second order: errors at 2h and h in the ratio 2^2
    assert 1.9 <= math.log2(e2 / e1) <= 2.1
    assert 1.9 <= math.log2(r2 / r1) <= 2.1
    # the published solution is the limit h -> 0: the Richardson extrapolation of the two runs
    # (q1 + (q1 - q2) / (2^2 - 1)) agrees with it a hundred times closer than the run at h
    extra = q1[-1] + (q1[-1] - q2[-1]) / 3
    assert np.abs(extra - Q_REF).max() <= 0.01 * e1
    extra_rate = qd1[-1] + (qd1[-1] - qd2[-1]) / 3
    assert np.abs(extra_rate - QD_REF).max() <= 0.01 * r1 * np.abs(QD_REF).max()
    # at the file's step: the angles within 1e-4 rad, the rates within 1e-4 of the largest
    assert e1 <= 1e-4 and r1 <= 1e-4
    # the loops stay closed
    assert runs[STEP].constraint.max() < 1e-12


def test_a03_work_of_the_torque_is_the_change_of_kinetic_and_spring_energy(runs):
    # the published reference: W = mom (beta - beta0) = T + V - V0 with its own M(q) and spring
    W_ref = PAR["mom"] * (Q_REF[0] - Q0[0])
    T_ref = 0.5 * QD_REF @ mass_matrix(Q_REF) @ QD_REF
    V0, V_ref = spring_energy(Q0), spring_energy(Q_REF)
    assert T_ref + V_ref - V0 == pytest.approx(W_ref, rel=1e-8)
    # se3dyn: energies of the bodies and the spring element, work of the hinge actuator
    res = runs[STEP]
    assert res.kinetic[0] == 0.0 and res.spring[0] == pytest.approx(V0, rel=1e-14)
    assert not np.any(res.potential) and not np.any(res.dissipation)
    # the work of a constant torque is mom times the turn of the crank (trapezoidal quadrature
    # of the power: second order)
    beta = res.joint_coordinates("beta")[:, 0]
    assert res.work_actuators[-1] == pytest.approx(PAR["mom"] * (beta[-1] - beta[0]), rel=1e-5)
    # balance W = T + V - V0 along the run: an O(h^2) error, within 2e-4 of the work at the
    # file's step, and converging at order 2
    gap = {h: np.abs(r.kinetic + r.spring - r.spring[0] - r.work_actuators).max()
           for h, r in runs.items()}
    assert gap[STEP] <= 2e-4 * W_ref
    assert 1.9 <= math.log2(gap[2 * STEP] / gap[STEP]) <= 2.1
    # the energies at t = 0.03 s are those of the published state
    assert res.kinetic[-1] == pytest.approx(T_ref, rel=1e-4)
    assert res.spring[-1] == pytest.approx(V_ref, rel=1e-4)
    assert res.work_actuators[-1] == pytest.approx(W_ref, rel=1e-4)
