"""Global error estimate of adaptive runs (``simulate(..., tol=..., global_error=True)``).

A companion run takes the run's accepted steps two at a time; the scheme being second order,
the run's global position error is the difference of the two runs over 2^2 - 1 = 3 where they
meet (Richardson's global extrapolation,
:class:`se3dyn.dynamics.stepcontrol.GlobalEstimate`). Checked
against closed-form solutions (a damped oscillator, the IFToMM A01 pendulum) and, on a
mechanism that amplifies errors (the paper's slider-crank, global error above ``tol``),
against a converged reference run whose own error is 1/800 of the run's.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.dynamics.run import Checkpoint
from se3dyn.dynamics.stepcontrol import ErrorNorm
from se3dyn.errors import ModelError, Se3dynWarning
from se3dyn.io.modelfile import load_model, loads_model
from se3dyn.model.examples import slider_crank
from test_adaptive import _exact, _oscillator_model, _pendulum_exact_p1

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("tol", [1e-3, 1e-4])
def test_estimate_follows_the_closed_form_error_of_the_damped_oscillator(tol):
    r = sd.simulate(_oscillator_model(), 5.0, 1e-3, tol=tol, global_error=True)
    hist = r.stats["global_error_history"]
    assert hist.shape[1] == 2 and len(hist) == math.ceil(r.stats["steps"] / 2)
    assert r.stats["global_error_steps"] == len(hist)
    # every row is a step of the run (no output_step): the true error at the meeting times
    i = np.searchsorted(r.t, hist[:, 0])
    np.testing.assert_array_equal(r.t[i], hist[:, 0])
    true = np.abs(r.joint_coordinates("s")[i, 0] - _exact(hist[:, 0]))
    # the body is a point mass on a slider: the norm of tol is its position error
    assert 0.8 <= r.stats["global_error"] / true.max() <= 1.25, (r.stats["global_error"],
                                                                 true.max())
    # and along the run, not only at its largest: within a fifth of the largest error
    assert np.abs(hist[:, 1] - true).max() <= 0.2 * true.max()
    k = int(np.argmax(hist[:, 1]))
    assert r.stats["global_error_at"] == hist[k, 0]
    assert r.stats["global_error_final"] == hist[-1, 1]


def test_estimate_matches_the_closed_form_error_of_the_a01_pendulum():
    model, settings = load_model(ROOT / "examples" / "a01_simple_pendulum.yaml")
    r = sd.simulate(model, 10.0, 1e-3, tol=1e-3, output_step=0.01, rho_inf=settings["rho_inf"],
                    global_error=True)
    e = float(np.linalg.norm(r.node_position("P1")[:, :2] - _pendulum_exact_p1(r.t),
                             axis=1).max())
    assert 0.8 <= r.stats["global_error"] / e <= 1.25, (r.stats["global_error"], e)
    assert r.stats["global_error"] <= 1e-3  # errors neither grow nor decay: within tol


T_SC, N_OUT = 1.0, 200


@pytest.fixture(scope="module")
def crank():
    """The paper's slider-crank over 1 s and a converged reference on 200 output times (16,000
    fixed steps: its error is 1/800 of the runs' below, the fixed-step error being C h^2)."""
    s = sd.compile_model(slider_crank())
    return s, sd.simulate(s, T_SC, T_SC / 16000, output_every=16000 // N_OUT)


def test_estimate_finds_an_error_above_tol_where_the_motion_amplifies_it_and_warns(crank):
    # the slider-crank's rod whipping round amplifies the errors of the quiet phase before it:
    # the global error is about 2.4 tol (docs/accuracy.md); the estimate must see it
    s, ref = crank
    tol = 1e-5
    with pytest.warns(Se3dynWarning, match="global error estimate .* times tol"):
        r = sd.simulate(s, T_SC, 1e-3, tol=tol, output_step=T_SC / N_OUT, global_error=True)
    assert np.allclose(r.t, ref.t, rtol=0, atol=1e-12)
    e = float(ErrorNorm(s).frames(r.H, ref.H).max())
    assert e > 1.5 * tol  # (the property that makes the estimate worth having)
    assert 0.8 <= r.stats["global_error"] / e <= 1.25, (r.stats["global_error"], e)


def test_bound_repeats_the_run_on_refined_steps_until_the_error_is_within_tol(crank):
    s, ref = crank
    tol = 1e-5
    with warnings.catch_warnings():
        warnings.simplefilter("error", Se3dynWarning)  # (nothing left to warn about)
        r = sd.simulate(s, T_SC, 1e-3, tol=tol, output_step=T_SC / N_OUT,
                        global_error="bound")
    e = float(ErrorNorm(s).frames(r.H, ref.H).max())
    assert e <= tol, e  # the true error, against the converged reference
    runs = r.stats["global_error_runs"]
    assert len(runs) >= 2 and runs[0]["global_error"] > tol
    m = runs[-1]["refine"]
    assert runs[-1]["steps"] == m * runs[0]["steps"]  # every step of the first run split in m
    assert r.stats["global_error"] <= tol
    assert 0.8 <= r.stats["global_error"] / e <= 1.25, (r.stats["global_error"], e)
    # the refined run passes through every time of the first one
    first = sd.simulate(s, T_SC, 1e-3, tol=tol, output_step=T_SC / N_OUT)
    assert np.isin(first.stats["step_times"], r.stats["step_times"]).all()


def test_bound_keeps_a_first_run_already_within_tol():
    # (every setting reaches the runs: those of the first run are the ones given)
    kw = dict(tol=1e-3, output_step=0.01, rho_inf=0.8, formulation="index3", condense=False)
    a = sd.simulate(slider_crank(), 0.5, 1e-3, global_error=True, **kw)
    b = sd.simulate(slider_crank(), 0.5, 1e-3, global_error="bound", **kw)
    assert a.stats["global_error"] <= 1e-3
    np.testing.assert_array_equal(a.H, b.H)
    assert b.stats["global_error_runs"] == [dict(refine=1, steps=a.stats["steps"],
                                                 rejected=a.stats["rejected"],
                                                 global_error=a.stats["global_error"])]


def test_the_estimate_does_not_change_the_run():
    kw = dict(tol=1e-4, output_step=0.01)
    a = sd.simulate(slider_crank(), 0.5, 1e-3, **kw)
    b = sd.simulate(slider_crank(), 0.5, 1e-3, global_error=True, **kw)
    for name in ("t", "H", "v", "vd", "lam"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.stats["steps"] == b.stats["steps"] and "global_error" not in a.stats


def test_a_companion_that_fails_stops_the_estimate_and_says_where():
    # one Newton iteration per step: the run retries its failing steps at h / 4, while the
    # companion's double steps fail; the run completes, the estimate says it stopped
    r = sd.simulate(slider_crank(), 0.2, 0.02, tol=1e-3, max_iter=1, global_error=True)
    assert not r.stats["failed"] and r.t[-1] == 0.2
    assert r.stats["global_error_until"] == 0.0
    assert "max_iter=1" in r.stats["global_error_failure"]
    assert r.stats["global_error"] is None


def test_a_continued_run_estimates_the_error_from_where_it_starts():
    # the companion starts from the state the run continues from: the estimate is that of the
    # error made from there on (the state carries no companion)
    model = slider_crank()
    first = sd.simulate(model, 0.3, 1e-3, tol=1e-4)
    cp = Checkpoint(first.stats["final_state"], first.stats["steps"], 1e-3)
    r = sd.simulate(model, 0.5, 1e-3, tol=1e-4, initial_state=cp, global_error=True)
    assert r.stats["global_error_from"] == 0.3
    assert r.stats["global_error_history"][0, 0] > 0.3
    assert r.stats["global_error_history"][-1, 0] == 0.5


@pytest.mark.parametrize("kw, want", [
    (dict(global_error=True), "an adaptive run"),
    (dict(global_error="yes", tol=1e-3), "True, False or 'bound'"),
    (dict(global_error="bound"), "'bound' with an adaptive run"),
    (dict(global_error="bound", tol=1e-3, store=False), "'bound' with results kept in memory"),
])
def test_bad_global_error_settings_are_named(kw, want):
    with pytest.raises(ModelError, match=f"global_error.*{want}"):
        sd.simulate(slider_crank(), 0.1, 1e-3, **kw)


def test_command_line_and_model_file_report_the_estimate(tmp_path, capsys):
    from se3dyn.cli.commands import main

    text = (ROOT / "examples" / "slider_crank.yaml").read_text()
    assert "global_error" not in text
    with warnings.catch_warnings():
        warnings.simplefilter("error", Se3dynWarning)  # (the command reports, never warns)
        assert main(["run", str(ROOT / "examples" / "slider_crank.yaml"), "--out",
                     str(tmp_path), "--t-end", "0.3", "--tol", "1e-4",
                     "--global-error"]) == 0  # (not --quiet: the summary is read)
    out = capsys.readouterr().out
    assert "global error estimate" in out and " tol) at t = " in out
    from se3dyn.io.h5 import read_results

    info = read_results(tmp_path / "slider_crank.h5").stats
    assert info["global_error"] > 0 and info["global_error_steps"] > 0


def test_bound_keeps_the_last_run_when_a_refinement_fails(monkeypatch):
    # a refined run whose Newton iterations fail (as a step near a singular position may):
    # the results and the estimate are the first run's, and a warning names the failure
    import sys

    sim = sys.modules["se3dyn.dynamics.run"]  # (the package's `simulate` is the function)
    real = sim.simulate

    def failing(*args, _schedule=None, **kw):
        if _schedule is not None:
            raise sd.NewtonError("Newton failed at t=0.5 (step h=0.001); made up", t=0.5,
                                 h=1e-3, iterations=25, residual_norm=1.0,
                                 constraint_norm=0.0, item="node 'x'")
        return real(*args, **kw)

    monkeypatch.setattr(sim, "simulate", failing)
    kw = dict(tol=1e-5, output_step=0.01)
    with pytest.warns(Se3dynWarning, match="the refinement of the last failed: Newton failed"):
        r = sim.simulate(slider_crank(), 1.0, 1e-3, global_error="bound", **kw)
    with pytest.warns(Se3dynWarning, match="global error estimate"):
        first = real(slider_crank(), 1.0, 1e-3, global_error=True, **kw)
    np.testing.assert_array_equal(r.H, first.H)
    assert r.stats["global_error"] == first.stats["global_error"] > 1e-5
    assert r.stats["global_error_refine"] == 1
    assert r.stats["global_error_runs"][-1]["failure"] == "Newton failed at t=0.5 (step h=0.001)"


def test_bound_on_the_published_squeezer_divides_its_error_by_the_refinement_squared():
    """IFToMM A03, Andrews' squeezer (tests/test_a03_squeezer.py), against its published
    reference solution at t = 0.03 s (Test Set for IVP Solvers, PSIDE at 1e-14): at
    tol = 1e-6 m the motion amplifies the local errors to about 1.4 tol; the bound refines the
    steps m times, and the error of the seven published angles falls by m^2 (second order on
    steps refined alike, the law the bound relies on)."""
    from test_a03_squeezer import ANGLES, FILE, Q_REF, T_END

    model, _ = load_model(FILE)
    kw = dict(tol=1e-6, output_step=T_END / 100)
    with pytest.warns(Se3dynWarning, match="global error estimate"):
        first = sd.simulate(model, T_END, 3e-5, global_error=True, **kw)
    r = sd.simulate(model, T_END, 3e-5, global_error="bound", **kw)
    assert first.stats["global_error"] > 1e-6 >= r.stats["global_error"]
    m = r.stats["global_error_refine"]
    assert m >= 2

    def angle_error(res):
        q = np.array([res.joint_coordinates(a)[-1, 0] for a in ANGLES])
        return float(np.abs(q - Q_REF).max())

    assert 0.8 <= angle_error(first) / angle_error(r) / m**2 <= 1.25


def test_command_line_bound_writes_the_refined_run_and_refuses_to_resume_it(tmp_path, capsys):
    from se3dyn.cli.commands import main
    from se3dyn.io.h5 import read_results

    model = ROOT / "examples" / "slider_crank.yaml"
    assert main(["run", str(model), "--out", str(tmp_path), "--t-end", "1",
                 "--tol", "1e-5", "--global-error", "bound"]) == 0  # (the summary is read)
    out = capsys.readouterr().out
    assert "global error bound: the first run's estimate" in out
    res = read_results(tmp_path / "slider_crank.h5")
    st = res.stats
    assert st["global_error"] <= 1e-5 and st["global_error_refine"] >= 2
    assert st["steps"] == len(res.t) - 1  # every step of the refined run stored
    # the same run in the API: the file holds its rows
    api = sd.simulate(slider_crank(), 1.0, 0.01, tol=1e-5, global_error="bound")
    np.testing.assert_array_equal(res.t, api.t)
    assert main(["run", str(model), "--resume", str(tmp_path / "slider_crank.h5")]) == 2
    assert "cannot be continued" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # (argparse: one line, exit status 2)
        main(["run", str(model), "--out", str(tmp_path), "--overwrite", "--global-error",
              "maybe"])
    assert exc.value.code == 2
    assert "expected 'bound' or nothing, got 'maybe'" in capsys.readouterr().err


def test_model_file_global_error_takes_true_false_or_bound():
    text = (ROOT / "examples" / "slider_crank.yaml").read_text()
    sim = "simulation: {t_end: 5.0, step: 0.01, rho_inf: 0.9}"
    assert sim in text
    _, settings = loads_model(text.replace(sim, sim[:-1] + ", tol: 1.0e-4, global_error: "
                                              "bound}"))
    assert settings["global_error"] == "bound"
    with pytest.raises(ModelError, match="global_error.*true, false or bound.*'maybe'"):
        loads_model(text.replace(sim, sim[:-1] + ", global_error: maybe}"))


def test_command_line_bound_run_that_fails_keeps_its_rows(tmp_path, capsys):
    # kept in memory while it runs: a failing run still writes the rows it computed
    from se3dyn.cli.commands import main
    from se3dyn.io.h5 import read_results

    text = (ROOT / "examples" / "slider_crank.yaml").read_text()
    sim = "simulation: {t_end: 5.0, step: 0.01, rho_inf: 0.9}"
    f = tmp_path / "crank.yaml"
    f.write_text(text.replace(sim, "simulation: {t_end: 1.0, step: 0.01, tol: 1.0e-4, "
                                   "global_error: bound, max_iter: 2, h_min: 0.005}"))
    assert main(["run", str(f), "--out", str(tmp_path), "--quiet"]) == 1
    err = capsys.readouterr().err
    res = read_results(tmp_path / "crank.h5")
    assert len(res.t) > 1 and f"{len(res.t)} rows kept" in err
    assert res.stats["failed"]
