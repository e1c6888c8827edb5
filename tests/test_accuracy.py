"""Accuracy of the integrator in every variable, and redundant constraints.

Order of accuracy: the stabilized index-2 formulation of the Lie-group generalized-alpha method
(Arnold, Brüls & Cardona, Numer. Math. 129 (2015) 149-179) converges with order 2 in positions,
velocities, accelerations and multipliers, with no O(h) transient (the index-3 form has one in
the accelerations and, in general, in velocities and multipliers). Errors are measured as the
largest deviation over each run's own time grid from a reference run of the same scheme at a
step 8x smaller (self-convergence), and the slope of log(error) against log(h) is fitted over a
factor 4 in h; a second-order scheme gives 2 up to the O(h^3) terms (we accept 1.85..2.3).

Redundant constraints: a planar four-bar built from four spatial hinges has 3 redundant
constraint equations (18 body freedoms, 4 x 5 hinge equations, mobility 1); they are left out
with zero multipliers, and the motion equals that of the same four-bar built without redundancy
(a spherical and a universal joint replacing two hinges).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import se3dyn as sd
from se3dyn import lie
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.rank import rank_analysis
from se3dyn.engine.system import compile_model
from se3dyn.model.examples import slider_crank

G = 9.81


def _slope(h, err):
    return float(np.polyfit(np.log(h), np.log(err), 1)[0])


@functools.cache
def _crank(h: float, formulation: str, t_end: float = 0.32, rho: float = 0.9):
    return sd.simulate(slider_crank(), t_end, h, formulation=formulation, rho_inf=rho)


HS = (8e-3, 4e-3, 2e-3)
HREF = 2.5e-4


def _errors(formulation):
    ref = _crank(HREF, formulation)
    out = {"position": [], "velocity": [], "acceleration": [], "multiplier": []}
    for h in HS:
        r = _crank(h, formulation)
        k = round(h / HREF)
        out["position"].append(np.abs(r.node_position("6") - ref.node_position("6")[::k]).max())
        out["velocity"].append(np.abs(r.v - ref.v[::k]).max())
        out["acceleration"].append(np.abs(r.vd - ref.vd[::k]).max())
        out["multiplier"].append(np.abs(r.lam - ref.lam[::k]).max())
    return out


@pytest.mark.parametrize("var", ["position", "velocity", "acceleration", "multiplier"])
def test_index2_is_second_order_in_every_variable_on_the_slider_crank(var):
    e = _errors("index2")[var]
    assert 1.85 <= _slope(HS, e) <= 2.3, (var, e)


def test_index2_satisfies_the_velocity_constraints_at_every_step():
    r = _crank(4e-3, "index2")
    s = compile_model(slider_crank())
    zero = np.zeros(s.nq)
    worst = 0.0
    for i in range(0, len(r.t), 5):
        # H_J = H_A^-1 H_B where the constraints hold (Eq. (7))
        HJ = lie.compose(lie.inverse(r.H[i][s.joint_a]), r.H[i][s.joint_b])
        ev = evaluate(s, r.H[i], HJ, zero, zero, r.v[i], zero, np.zeros(s.nm),
                      step_inputs(s, r.t[i]), velocity=True)
        worst = max(worst, float(np.abs(ev.psi).max()))
    # Newton tolerance on psi / gamma' (an increment, <= 1e-11 m): |psi| <= 1e-11 gamma'
    assert r.stats["formulation"] == "index2"
    # Newton tolerance on psi / gamma' (an increment): |psi| <= tol_constraint * gamma';
    # gamma' = gamma / (beta h) = 0.6 / (0.3025 h) for rho_inf = 0.9; plus the round-off of
    # recomputing H_J from the stored frames (1e-15 m on a 1e-1 m mechanism, times |v| / h)
    assert worst <= 1e-11 * 0.6 / (0.3025 * 4e-3) + 1e-9


def test_index2_with_rho_inf_one_runs_where_index3_diverges():
    # rho_inf = 1 (no numerical damping): the index-3 multipliers of the massless nodes are
    # undamped and Newton diverges at t = 1.81 s (h = 1e-2); the index-2 form stays bounded
    with pytest.raises(sd.NewtonError):
        sd.simulate(slider_crank(), 2.5, 1e-2, rho_inf=1.0, formulation="index3")
    r1 = sd.simulate(slider_crank(), 2.5, 1e-2, rho_inf=1.0)
    r9 = sd.simulate(slider_crank(), 2.5, 1e-2, rho_inf=0.9)
    assert np.abs(r1.lam).max() < 1.2 * np.abs(r9.lam).max()
    # energy: no numerical dissipation, the balance error stays at the O(h^2) truncation
    # level measured for rho_inf = 0.9 (0.02 J of ~0.7 J at h = 1e-2)
    assert np.ptp(r1.energy_balance) < 0.05


# ---------------------------------------------------------------------------------------------
def _four_bar(redundant: bool, w0: float = 2.0):
    """Planar four-bar (ground 2 m, crank 1 m, coupler 2 m, rocker 1 m) in the x-y plane, bodies
    at the link centres, released with crank angular velocity w0 about z, gravity -y."""
    mb = sd.ModelBuilder(gravity=(0.0, -G, 0.0))
    mb.node("A0", (0, 0, 0), fixed=True)
    mb.node("D0", (2, 0, 0), fixed=True)
    # crank A0->B (0,1), coupler B->C (2,1), rocker D0->C; parallelogram: coupler translates
    J = (1 / 12, 1 / 12, 1 / 12)
    mb.node("crank", (0, 0.5, 0), mass=1.0, inertia=J, velocity=(-0.5 * w0, 0, 0),
            angular_velocity=(0, 0, w0))
    mb.node("coupler", (1, 1, 0), mass=2.0, inertia=(0.1, 2 / 3, 2 / 3),
            velocity=(-w0, 0, 0))
    mb.node("rocker", (2, 0.5, 0), mass=1.0, inertia=J, velocity=(-0.5 * w0, 0, 0),
            angular_velocity=(0, 0, w0))
    for n, p in (("Aj", (0, 0, 0)), ("Bj", (0, 1, 0)), ("Bj2", (0, 1, 0)), ("Cj", (2, 1, 0)),
                 ("Cj2", (2, 1, 0)), ("Dj", (2, 0, 0))):
        mb.node(n, p)
    z = (0, 0, 1)
    mb.joint("hA", "hinge", "A0", "Aj", axis=z)
    mb.joint("rA", "rigid", "Aj", "crank")
    mb.joint("rB", "rigid", "crank", "Bj")
    if redundant:
        mb.joint("hB", "hinge", "Bj", "Bj2", axis=z)
        mb.joint("hC", "hinge", "Cj", "Cj2", axis=z)
    else:
        mb.joint("hB", "spherical", "Bj", "Bj2")
        mb.joint("hC", "universal", "Cj", "Cj2", axes=((0, 0, 1), (0, 1, 0)))
    mb.joint("rB2", "rigid", "Bj2", "coupler")
    mb.joint("rC", "rigid", "coupler", "Cj")
    mb.joint("rC2", "rigid", "Cj2", "rocker")
    mb.joint("rD", "rigid", "rocker", "Dj")
    mb.joint("hD", "hinge", "Dj", "D0", axis=z)
    return mb.build()


def test_overconstrained_four_bar_names_three_redundant_equations_and_mobility_one():
    rep = rank_analysis(compile_model(_four_bar(True)))
    assert rep.dof == 1 and len(rep.redundant) == 3
    rep2 = rank_analysis(compile_model(_four_bar(False)))
    assert rep2.dof == 1 and rep2.redundant == ()


def test_independence_shortcut_agrees_with_the_pivoted_qr():
    """redundant_equations skips the pivoted QR when one SVD proves every loop equation
    independent; it may only say so when the QR keeps them all (the QR decides otherwise)."""
    from se3dyn.engine.rank import _independent_rows, _jacobian_rows, _pivoted_qr, loop_joints

    def qr_keeps_all(P, rtol):
        piv, d = _pivoted_qr(P.T)
        return P.shape[1] >= P.shape[0] and bool(np.all(d > rtol * d[0]))

    cases = []
    for model in (slider_crank(), sd.examples.slider_crank_bodies(), _four_bar(True),
                  _four_bar(False)):
        s = compile_model(model)
        loops = loop_joints(s)
        cases.append(_jacobian_rows(s, (6 * loops[:, None] + np.arange(6)).ravel()))
    rng = np.random.default_rng(3)
    for k, n in ((5, 8), (6, 6), (8, 5)):  # graded singular values down to ~1e-12
        U, _ = np.linalg.qr(rng.standard_normal((k, k)))
        V, _ = np.linalg.qr(rng.standard_normal((n, n)))
        for smin in (1e-6, 2e-9, 1e-9, 5e-10, 1e-12):
            S = np.zeros((k, n))
            np.fill_diagonal(S, np.geomspace(1.0, smin, min(k, n)))
            cases.append(U @ S @ V.T)
    shortcuts = 0
    for P in cases:
        for rtol in (1e-9, 1e-10):
            if _independent_rows(P, rtol):
                shortcuts += 1
                assert qr_keeps_all(P, rtol)
    assert shortcuts >= 8  # the slider-crank forms and the isostatic four-bar among them
    assert _independent_rows(cases[0], 1e-9) and not _independent_rows(cases[2], 1e-9)


@pytest.mark.parametrize("formulation", ["index2", "index3"])
def test_overconstrained_four_bar_moves_like_the_isostatic_one(formulation):
    r = sd.simulate(_four_bar(True), 2.0, 2e-3, formulation=formulation)
    q = sd.simulate(_four_bar(False), 2.0, 2e-3, formulation=formulation)
    assert len(r.stats["redundant"]) == 3
    # same constraint manifold and the same dynamics. Index 3: the same discrete equations, so
    # identical motion up to the Newton tolerances amplified over 1000 steps. Index 2: the
    # correction direction B_n^T xi depends on how the constraints are written, so the two
    # discrete solutions differ at the truncation level (|xi| = O(h^3) per step, h = 2e-3)
    tol = 1e-8 if formulation == "index3" else 2e-6
    for n in ("crank", "coupler", "rocker"):
        assert np.abs(r.node_position(n) - q.node_position(n)).max() < tol
    # the left-out equations keep zero multipliers; the constraints all hold, those left
    # out included (they are implied by the others)
    s = compile_model(_four_bar(True))
    dropped = [s.joint_names.index(name.split("'")[1]) * 6 + int(name.split()[3])
               for name in r.stats["redundant"]]
    assert np.all(r.lam[:, dropped] == 0.0)
    assert r.constraint.max() < 1e-10
    # the crank turns past the top dead centre of the parallelogram
    assert np.ptp(r.joint_coordinates("hA")) > 1.0


def test_redundant_error_mode_names_the_equations():
    with pytest.raises(sd.ModelError, match=r"3 redundant: joint '.*' constraint \d"):
        sd.simulate(_four_bar(True), 0.1, 1e-2, redundant="error")


def test_joint_duplicated_by_mistake_simulates_like_the_single_joint():
    def pend(dup):
        mb = sd.ModelBuilder(gravity=(0, 0, -G))
        mb.node("ground", (0, 0, 0), fixed=True)
        mb.node("pivot", (0, 0, 0))
        mb.node("bob", (0, 0.5, 0), mass=1.0, inertia=(0.01, 0.01, 0.01))
        mb.joint("h", "hinge", "ground", "pivot", axis=(1, 0, 0))
        if dup:
            mb.joint("h_again", "hinge", "ground", "pivot", axis=(1, 0, 0))
        mb.joint("arm", "rigid", "pivot", "bob")
        return mb.build()

    r = sd.simulate(pend(True), 1.0, 5e-3)
    q = sd.simulate(pend(False), 1.0, 5e-3)
    # 12 hinge equations on 6 + 2 unknowns with 1 freedom: 5 redundant
    assert len(r.stats["redundant"]) == 5
    assert np.abs(r.node_position("bob") - q.node_position("bob")).max() < 1e-9
    assert np.abs(r.joint_coordinates("h") - q.joint_coordinates("h")).max() < 1e-9
