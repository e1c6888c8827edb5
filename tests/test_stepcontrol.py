"""The error norm of adaptive steps (:mod:`se3dyn.dynamics.stepcontrol`): the root mean square
over a
body's mass of the position errors of its material points, checked against the points of a
uniform box (two-point Gauss rule per axis, exact for the quadratic integrand), and the step
controller's rules."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import se3dyn as sd
from se3dyn import lie
from se3dyn.dynamics import stepcontrol

finite = st.floats(-1.0, 1.0, allow_nan=False)
vec3 = st.tuples(finite, finite, finite).map(np.array)
sizes = st.tuples(*(st.floats(0.05, 2.0),) * 3).map(np.array)


def _box_system(dims, com_offset, R0):
    """One free node at the origin, orientation R0, carrying a uniform box of mass 2 with its
    centre at ``com_offset`` (material frame), its edges along the material axes; a massless
    node and a fixed one beside it."""
    a, b, c = dims
    m = 2.0
    J = m / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    mb = sd.ModelBuilder()
    mb.node("g", (0, 0, 0), fixed=True)
    mb.node("box", (0, 0, 0), orientation=R0, mass=m, inertia=R0 @ J @ R0.T,
            com=tuple(R0 @ com_offset))
    mb.node("frame", (1, 0, 0))
    mb.joint("j", "rigid", "box", "frame")
    return sd.compile_model(mb.build())


def _box_points(dims, com_offset):
    """The 8 two-point Gauss points of the box (material frame): their mean of any quadratic
    function of the position is the box's mean."""
    g = np.array([-1.0, 1.0]) / np.sqrt(3.0)
    return np.array([com_offset + 0.5 * dims * np.array(p) for p in itertools.product(g, g, g)])


@settings(max_examples=60, deadline=None)
@given(dims=sizes, off=vec3, w0=vec3, dw=vec3, dx=vec3, x0=vec3)
def test_frame_error_is_the_rms_position_error_of_the_material_points(dims, off, w0, dw, dx,
                                                                     x0):
    R0 = lie.exp_so3(w0)
    s = _box_system(dims, off, R0)
    norm = stepcontrol.ErrorNorm(s)
    H_ref = np.array(s.node_H0, dtype=float)
    H_ref[:, :3, 3] += x0
    H = H_ref.copy()
    k = s.node_names.index("box")
    H[k, :3, :3] = H_ref[k, :3, :3] @ lie.exp_so3(dw)  # finite errors
    H[k, :3, 3] += dx
    X = _box_points(dims, off)
    p = H[k, :3, 3] + X @ H[k, :3, :3].T
    p_ref = H_ref[k, :3, 3] + X @ H_ref[k, :3, :3].T
    rms = np.sqrt(np.mean(np.sum((p - p_ref) ** 2, axis=1)))
    assert norm.frames(H, H_ref) == pytest.approx(rms, rel=1e-9, abs=1e-14)


@settings(max_examples=40, deadline=None)
@given(dims=sizes, off=vec3, e=st.tuples(*(finite,) * 6).map(np.array))
def test_increment_norm_is_the_frame_norm_to_first_order(dims, off, e):
    s = _box_system(dims, off, np.eye(3))
    norm = stepcontrol.ErrorNorm(s)
    H0 = np.array(s.node_H0, dtype=float)
    k = s.node_names.index("box")
    full = np.zeros(s.nq)
    for eps in (1e-4, 1e-5):
        full[s.node_dofadr[k]:s.node_dofadr[k] + 6] = eps * e
        H = H0.copy()
        H[k] = H0[k] @ lie.exp_se3(eps * e)
        # the increment's norm and the exact norm of the frames it gives agree to O(eps^2)
        assert abs(norm(full) - norm.frames(H, H0)) <= 10 * eps ** 2 * (1 + np.abs(e).sum())


def test_massless_nodes_do_not_count_and_a_slender_rod_spin_counts_by_its_gyration_radius():
    L, r, m = 1.0, 0.01, 3.0
    mb = sd.ModelBuilder()
    mb.node("g", (0, 0, 0), fixed=True)
    # a rod along x: inertia m r^2 / 2 about its axis, m L^2 / 12 across
    mb.node("rod", (0, 0, 0), mass=m, inertia=(m * r * r / 2, m * L * L / 12, m * L * L / 12))
    mb.node("frame", (1, 0, 0))
    mb.joint("j", "rigid", "rod", "frame")
    s = sd.compile_model(mb.build())
    norm = stepcontrol.ErrorNorm(s)
    e = np.zeros(s.nq)
    frame = s.node_dofadr[s.node_names.index("frame")]
    rod = s.node_dofadr[s.node_names.index("rod")]
    e[frame:frame + 6] = 1.0  # a massless node: not counted
    assert norm(e) == 0.0
    e[rod + 3] = 1e-3  # spin about the rod's axis: radius of gyration r / sqrt(2)
    assert norm(e) == pytest.approx(1e-3 * r / np.sqrt(2), rel=1e-12)
    e[rod + 3], e[rod + 4] = 0.0, 1e-3  # across: L / sqrt(12)
    assert norm(e) == pytest.approx(1e-3 * L / np.sqrt(12), rel=1e-12)
    assert s.labels[norm.worst(e)] == "node 'rod' Omega_y"


def test_share_is_the_tolerance_per_mean_step_and_the_controller_keeps_even_steps():
    # the shares of n equal steps add up to tol
    tol, span, h = 1e-3, 2.0, 0.01
    total = sum(stepcontrol.share(tol, span, k * h, 0.0, k, h) for k in range(200))
    assert total == pytest.approx(tol, rel=1e-12)
    # an error at its share keeps the step; a growth below 30 % is not taken; rejected steps
    # shrink; the step changes by at most a factor of 2 and at least 1/5
    # (the error-to-share ratio goes as h^6: error c h^3, share ~ h^-3)
    assert stepcontrol.next_step(h, stepcontrol.SAFETY ** 6, True) == h
    assert stepcontrol.next_step(h, 0.5, True) == h
    assert stepcontrol.next_step(h, 0.01, True) == pytest.approx(h * 0.9 * 100 ** (1 / 6))
    assert stepcontrol.next_step(h, 1e-12, True) == 2 * h
    assert stepcontrol.next_step(h, 1e12, True) == pytest.approx(0.2 * h)
    assert stepcontrol.next_step(h, 1.0001, False) <= 0.9 * h


@settings(max_examples=50, deadline=None)
@given(st.floats(1e-3, 1e3), st.floats(1e-3, 1e3))
def test_steps_at_their_share_go_as_the_error_coefficient_to_the_minus_sixth(c1, c2):
    # a step of error c h^3 exactly at its share (same mean step so far): h ~ c^(-1/6), so
    # a phase whose local errors are 64 times larger gets steps half as long
    tol, span, t, k = 1e-4, 1.0, 0.5, 7
    h_bar = t / k

    def at_share(c):
        return (tol * h_bar ** 4 / (span * c)) ** (1 / 6)

    for c in (c1, c2):
        h = at_share(c)
        assert c * h ** 3 == pytest.approx(stepcontrol.share(tol, span, t, 0.0, k, h), rel=1e-9)
    assert at_share(c1) / at_share(c2) == pytest.approx((c2 / c1) ** (1 / 6), rel=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.8, 1.25), min_size=1, max_size=30))
def test_tracked_steps_are_a_function_of_the_current_error_coefficient(factors):
    # while the error stays within [1.3^-6, 1] of its share, h c^(1/6) is kept: the step is
    # h_0 (c_0 / c_n)^(1/6) whatever the path of the coefficients (no history, no dead band)
    h0 = h = 1e-3
    c0 = c = 50.0
    for f in factors:
        h = stepcontrol.next_step(h, 0.5, True, c=(c, c * f))
        c *= f
    assert h == pytest.approx(h0 * (c0 / c) ** (1 / 6), rel=1e-9)


def test_the_rule_applies_where_tracking_has_no_footing():
    h = 1e-3
    rule = stepcontrol.next_step(h, 0.01, True)
    # an error far below its share (rescale), a jump of the coefficient, no coefficient
    assert stepcontrol.next_step(h, 0.01, True, c=(10.0, 10.0)) == rule
    assert stepcontrol.next_step(h, 0.5, True, c=(10.0, 1.0)) == h  # 47 % growth: rule's band
    assert stepcontrol.next_step(h, 0.5, True, c=(None, 1.0)) == h
    assert stepcontrol.next_step(h, 0.5, True, c=(10.0, 11.0)) == pytest.approx(
        h * (10 / 11) ** (1 / 6))


def test_the_state_coefficient_predicts_the_next_steps_local_error():
    # a - vd = (alpha_m - alpha_f) h q''' of a state gives the error c h^3 that the next
    # step's estimate (1/6 - beta - (alpha_m - alpha_f)/2) h^2 (a_{n+1} - a_n) measures
    s = sd.compile_model(sd.examples.slider_crank())
    integ = sd.GeneralizedAlpha(rho_inf=0.9)
    norm = stepcontrol.ErrorNorm(s)
    h = 2e-4
    st0 = integ.init(s, 0.0)
    ratios = []
    for k in range(400):
        st1, info = integ.step(s, st0, h)
        if k >= 20:  # (past the start, where a - vd has not settled)
            ratios.append(stepcontrol.coefficient(norm, st0, integ.params) * h ** 3
                          / norm(info.error))
        st0 = dataclasses.replace(st1, t=st0.t + h)
    assert np.median(ratios) == pytest.approx(1.0, abs=0.05)
    assert stepcontrol.coefficient(norm, integ.init(s, 0.0), integ.params) is None
    assert stepcontrol.coefficient(norm, st0, sd.GeneralizedAlpha(rho_inf=1.0).params) is None


def _controlled_run(c, span, tol, h, allowance):
    """The adaptive loop of ``simulate`` on a model whose local error is exactly ``c(t) h^3``
    and whose states give ``c`` exactly: the times and steps of the rejections."""
    t, n, rejected = 0.0, 0, []
    while t < span - 1e-12:
        h = min(h, span - t)
        err = c(t + h / 2) * h ** 3 / stepcontrol.share(tol, span, t, 0.0, n, h)
        lim = allowance(t, 0.0, n, h)
        if err > lim:
            rejected.append((t, h, (t / n if n else h)))
            h = stepcontrol.next_step(h, err, False)
            continue
        t, n = t + h, n + 1
        h = stepcontrol.next_step(h, err, True, c=(c(t - h), c(t)), limit=lim)
    return n, rejected


def test_a_violent_phase_is_crossed_without_rejection_and_rescaled_in_the_quiet_one():
    # a swing from rest like A02's: the coefficient 30 times larger at the peak (t = 1, 3)
    # than in the quiet phases (t = 0, 2, 4). Tracked steps keep h c^(1/6) = k, so their
    # error-to-share ratio k^6 span / (tol h_bar^4) climbs as the mean step h_bar falls
    # through the first swing; held to 1 everywhere the run rejects (a step change) in the
    # violent phase, with the allowance only where a step is at least 1.2 h_bar: in the quiet
    # phase, where the coefficient is small
    def c(t):
        return 1.0 + 29.0 * np.sin(0.5 * np.pi * t) ** 2

    span, tol = 5.0, 1e-5
    h0 = (tol / (span * c(0.0) ** (2 / 3))) ** 0.5 / 2  # ratio 0.5 ** 4 of the first share

    def one(*_):
        return 1.0

    _, held = _controlled_run(c, span, tol, h0, one)
    assert held and all(h < stepcontrol.QUIET * h_bar for _, h, h_bar in held)
    assert any(c(t) > 10.0 for t, _, _ in held)
    n, rejected = _controlled_run(c, span, tol, h0, stepcontrol.allowance)
    assert all(h >= stepcontrol.QUIET * h_bar for _, h, h_bar in rejected)
    assert all(c(t) < 10.0 for t, _, _ in rejected)
    assert len(rejected) <= len(held)


def test_the_allowance_and_the_band_of_a_violent_phase():
    h_bar = 1e-3
    assert stepcontrol.allowance(1.0, 0.0, 1000, stepcontrol.QUIET * h_bar) == 1.0
    assert stepcontrol.allowance(1.0, 0.0, 1000, h_bar) == stepcontrol.ALLOWANCE
    h, cs = 1e-3, (10.0, 11.0)
    tracked = h * (10 / 11) ** (1 / 6)
    # a violent phase: tracked above the share (up to the allowance) and far below it
    for ratio in (3.9, 0.5, 1.3 ** -11):
        assert stepcontrol.next_step(h, ratio, True, c=cs, limit=4.0) == pytest.approx(tracked)
    # a quiet phase: the rule rescales outside [1.3^-6, 1]
    for ratio in (1.3 ** -11, 1.3 ** -7):
        assert stepcontrol.next_step(h, ratio, True, c=cs) == stepcontrol.next_step(h, ratio, True)
