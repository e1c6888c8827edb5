"""Adaptive time stepping (``simulate(..., tol=...)``) and dense output.

The step-size control (:mod:`se3dyn.dynamics.stepcontrol`) holds every step's local error estimate
``(1/6 - beta - (alpha_m - alpha_f) / 2) h^2 (a_{n+1} - a_n)``, measured per body as the RMS
over its mass of the errors of its material points, to the step's share
``tol (h_bar / span) (h_bar / h)^3`` of the tolerance, so that the local errors of a run of
even difficulty add up to ``tol`` (steps ~ local error^(-1/6)). Where errors neither grow nor decay
along the motion (the undamped pendulum) the global error is then a fixed fraction of ``tol``;
with damping it is smaller. Checked against closed-form solutions and a converged reference;
tolerances here are those of the run, not fitted to our output.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.dynamics.stepcontrol import ErrorNorm
from se3dyn.io.modelfile import loads_model
from se3dyn.model.examples import slider_crank

G = 9.81
M, K, C, V0 = 1.0, 400.0, 4.0, 2.0  # w0 = 20 rad/s, damping ratio 0.1


def _oscillator_model():
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))  # gravity across the axis: no effect
    mb.node("A", (0, 0, 0), fixed=True)
    mb.node("B", (0, 0, 0), mass=M, inertia=(1e-2, 1e-2, 1e-2), velocity=(V0, 0, 0))
    mb.joint("s", "prismatic", "A", "B", axis=(1, 0, 0), stiffness=K, damping=C)
    return mb.build()


def _exact(t):
    w0 = math.sqrt(K / M)
    z = C / (2 * math.sqrt(K * M))
    wd = w0 * math.sqrt(1 - z * z)
    return np.exp(-z * w0 * t) * V0 / wd * np.sin(wd * t)


def _err(r):
    return float(np.abs(r.joint_coordinates("s")[:, 0] - _exact(r.t)).max())


@pytest.mark.parametrize("tol", [1e-4, 1e-5])
def test_adaptive_run_meets_its_tolerance_with_fewer_steps_than_a_fixed_step(tol):
    T = 5.0
    r = sd.simulate(_oscillator_model(), T, 1e-3, tol=tol, output_step=1e-2)
    e = _err(r)
    assert e <= tol, e
    # a fixed step reaching the same error: the fixed-step error is C h^2 (second order),
    # C measured from one fixed run; the adaptive run needs fewer steps than that step
    hf = 1e-3
    ef = _err(sd.simulate(_oscillator_model(), T, hf, output_step=1e-2))
    n_fixed = T / (hf * math.sqrt(e / ef))
    assert r.stats["steps"] < 0.7 * n_fixed, (r.stats["steps"], n_fixed)
    # the step grows as the oscillation decays: the local error coefficient ~ the amplitude
    # exp(-zeta w0 t), which falls by exp(-10) over the run, and the steps go as its -1/6th
    # power (se3dyn.dynamics.stepcontrol): exp(10 / 6) = 5.3 from the first to the last oscillations
    z_w0 = C / (2 * M)
    assert r.stats["h_max_used"] > 0.7 * math.exp(z_w0 * T / 6) * r.stats["h_min_used"]


def test_results_are_on_the_requested_output_grid():
    r = sd.simulate(_oscillator_model(), 1.0, 1e-3, tol=1e-5, output_step=0.05)
    np.testing.assert_allclose(r.t, np.linspace(0.0, 1.0, 21), rtol=0, atol=1e-15)
    assert r.stats["steps"] != 20
    # dense output between steps keeps the accuracy of the steps
    assert _err(r) <= 1e-5
    # velocities too: closed-form derivative
    w0 = math.sqrt(K / M)
    z = C / (2 * math.sqrt(K * M))
    wd = w0 * math.sqrt(1 - z * z)
    vex = np.exp(-z * w0 * r.t) * V0 * (np.cos(wd * r.t) - z * w0 / wd * np.sin(wd * r.t))
    assert np.abs(r.joint_velocities("s")[:, 0] - vex).max() < 50 * 1e-5 * w0


def test_adaptive_slider_crank_error_is_proportional_to_the_tolerance():
    # on the slider-crank the global error is the local errors propagated by a mechanism that
    # speeds up and amplifies them (fixed steps show the same growth), so it is not bounded by
    # tol; what a sound controller must give is tolerance proportionality: the local error of
    # the second-order scheme is c h^3 and a step's share tol (h_bar / T)(h_bar / h)^3, so with
    # every step scaled alike h ~ tol^(1/2) and the global error ~ h^2 ~ tol once the steps
    # are many; this short run (a few hundred steps, from a first step of 1 ms) must lose at
    # least the square root of a ten times tighter tol (3.2) and not gain beyond 10^0.85
    T = 0.5
    ref = sd.simulate(slider_crank(), T, 2.5e-4, output_every=40)
    errs = []
    for tol in (1e-4, 1e-5):
        r = sd.simulate(slider_crank(), T, 1e-3, tol=tol, output_step=1e-2)
        assert len(r.t) == len(ref.t) and r.constraint.max() < 1e-10
        errs.append(max(np.abs(r.node_position(n) - ref.node_position(n)).max()
                        for n in "3468"))
    assert 3.0 <= errs[0] / errs[1] <= 7.0, errs


def _pendulum_exact_p1(t):
    """A01 simple pendulum (tests/test_gallery.py): position of the bob in closed form."""
    from test_gallery import _pendulum_exact

    th = _pendulum_exact(t)
    return np.stack([np.sin(th), -np.cos(th)], axis=1)


@pytest.mark.parametrize("tol", [1e-3, 1e-4])
def test_undamped_pendulum_error_is_a_fixed_fraction_of_tol_with_fewer_steps(tol):
    """The IFToMM A01 pendulum (1 kg bob on a 1 m massless link, released horizontal; its
    model file, rho_inf = 1: no numerical damping) over 10 s (4.2 periods) against the
    closed-form solution: the local errors neither grow nor decay along the motion, so the
    global error is the sum of the local errors, which the controller holds to tol."""
    from se3dyn.io.modelfile import load_model

    model, settings = load_model(
        Path(__file__).parents[1] / "examples" / "a01_simple_pendulum.yaml")
    T = 10.0
    r = sd.simulate(model, T, 1e-3, tol=tol, output_step=0.01, rho_inf=settings["rho_inf"])
    e = float(np.linalg.norm(r.node_position("P1")[:, :2] - _pendulum_exact_p1(r.t), axis=1).max())
    # the bob is the only body: the error norm is its position error
    assert 0.2 * tol <= e <= tol, e
    assert 0.3 * tol <= r.stats["error_estimate"] <= tol, r.stats["error_estimate"]
    # fewer steps (rejected ones included) than the fixed step of the same error, which is
    # C h^2 with C measured by one fixed run of the same horizon
    hf = 2.5e-3
    rf = sd.simulate(model, T, hf, output_step=0.01, rho_inf=settings["rho_inf"])
    ef = float(np.linalg.norm(rf.node_position("P1")[:, :2] - _pendulum_exact_p1(rf.t),
                              axis=1).max())
    n_fixed = T / (hf * math.sqrt(e / ef))
    assert r.stats["steps"] + r.stats["rejected"] < 0.85 * n_fixed, (r.stats, n_fixed)


def test_newton_failures_are_retried_with_a_smaller_step():
    # one Newton iteration allowed: large steps fail and are retried with h / 4
    r = sd.simulate(slider_crank(), 0.2, 0.02, tol=1e-3, max_iter=1)
    assert r.stats["rejected"] > 0 and not r.stats["failed"]
    assert r.t[-1] == 0.2


def test_error_at_the_minimum_step_names_time_and_unknown_and_keeps_results():
    with pytest.raises(sd.SimulationError, match=r"minimum step h_min=0.01; worst: ") as ei:
        sd.simulate(_oscillator_model(), 1.0, 0.05, tol=1e-9, h_min=1e-2)
    assert ei.value.result is not None and len(ei.value.result.t) >= 1


@pytest.mark.parametrize("kw", [dict(tol=-1.0), dict(tol=float("nan")), dict(h_min=0.0, tol=1),
                                dict(output_step="x"), dict(h_min=1.0, h_max=0.1, tol=1e-3)])
def test_bad_adaptive_settings_are_named(kw):
    with pytest.raises(sd.ModelError, match="simulate"):
        sd.simulate(_oscillator_model(), 1.0, 1e-2, **kw)


def _four_bars(n: int):
    """The IFToMM A02 N-four-bar (examples/a02_n_four_bar.yaml) cut to its first n loops: the
    links passing together through the horizontal, singular position (the mobility jumps)."""
    keep = []
    for line in (Path(__file__).resolve().parents[1] / "examples"
                 / "a02_n_four_bar.yaml").read_text().splitlines(keepends=True):
        name = re.match(r"  (\w+): \{", line)
        idx = re.findall(r"\b[a-zA-Z]+(\d+)\b", line.split("axis")[0]) if name else []
        if all(int(k) <= n for k in idx):
            keep.append(line)
    return sd.compile_model(loads_model("".join(keep))[0])


def test_a_step_change_leaves_an_error_first_order_in_the_change_of_h_squared():
    # Even steps leave local errors that add up to a boundary term, a change of the step from
    # h0 to h1 one of first order in h1^2 - h0^2; on the four-bar it grows through the
    # singular passage: far larger at the acceleration peak (t = 1 s) than in the quiet phase
    # before it, although it has longer to grow from there
    s = _four_bars(1)
    norm = ErrorNorm(s)
    T, h0 = 2.0, 2e-3
    even = sd.simulate(s, T, h0)
    per_dh2 = {}
    for tc in (0.2, 1.0):
        start = sd.simulate(s, tc, h0).stats["final_state"]
        d = {}
        for r in (0.8, 1.25):
            run = sd.simulate(s, T, r * h0, t_start=tc, initial_state=start)
            d[r] = run.node_position("c0")[-1, :2] - even.node_position("c0")[-1, :2]
            per_dh2[tc, r] = float(norm.frames(run.H[-1], even.H[-1])) / abs(r * r - 1)
        np.testing.assert_allclose(d[1.25] / d[0.8], (1.25 ** 2 - 1) / (0.8 ** 2 - 1), rtol=0.02)
        assert per_dh2[tc, 0.8] == pytest.approx(per_dh2[tc, 1.25], rel=0.02)
    assert per_dh2[1.0, 0.8] > 10 * per_dh2[0.2, 0.8]


def test_steps_that_follow_the_state_lose_nothing_to_even_steps_through_singular_positions():
    # steps shrinking before the acceleration peak and growing after it as functions of the
    # run's history leave step-change errors that add up at every passage (14 times the error
    # of even steps with the rule of 2026-11-23); tracking the state, they cancel
    s = _four_bars(1)
    norm = ErrorNorm(s)
    T, tol = 5.0, 1e-3
    ref = sd.simulate(s, T, T / 32000, output_step=T / 100)
    r = sd.simulate(s, T, 1e-3, tol=tol, output_step=T / 100)
    n = r.stats["steps"] + r.stats["rejected"]
    even = sd.simulate(s, T, T / n, output_step=T / 100)
    assert r.stats["h_max_used"] > 1.5 * r.stats["h_min_used"]  # the steps do vary
    err = norm.frames(r.H, ref.H).max()
    assert err <= norm.frames(even.H, ref.H).max()
    assert err <= tol
