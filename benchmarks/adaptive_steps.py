"""Adaptive time stepping against the best fixed step of the same accuracy (issue 16).

Problems: the damped oscillator of tests/test_adaptive.py (5 s), the IFToMM gallery problems
A01 simple pendulum (10 s, rho_inf = 1 as in its model file), A02 N-four-bar (N = 40, 5 s),
A04 Bricard mechanism (5 s), A05 stiff flyball governor (2 s), a heavy top spinning at 50 rad/s
(benchmarks/top_step_guidance.py, 2 s), the paper's slider-crank (1 s) and A03 Andrews'
squeezing mechanism (0.03 s, the whole published run); se3dyn defaults otherwise. For every
tolerance (1e-3, 1e-4, 1e-5 m; 1e-5, 1e-6, 1e-7 m for A03, whose bodies are centimetres long and
whose published reference is given to 1e-14):

* the adaptive run (initial step min(1e-3, T / 1000), results on 200 output times by dense
  output);
* its global error: the largest over the output times of the mass-weighted error of the node
  frames (:meth:`se3dyn.dynamics.stepcontrol.ErrorNorm.frames`: per body the RMS over its mass
  of the position errors of its material points; the norm ``tol`` is given in) against a fixed-step
  run at h = T / 64000 (T / 256000 for the oscillator and A01, whose tightest runs need
  40,000 steps: at T / 64000 the reference's own error was 43 % of A01's at tol = 1e-5);
* ``sum``: the sum of the accepted local error estimates (``stats["error_estimate"]``);
* the best fixed step of the same accuracy: the fewest fixed steps N (on a grid 3 % apart from
  0.1 to 6 times the adaptive run's steps, found by bisection since the fixed-step error falls
  with N as C h^2; same 200 output times) whose error is at most the adaptive run's, and the
  ratio of the adaptive run's steps (rejected ones included) to N: below 1, adaptive stepping
  is cheaper;
* the global error estimate (``global_error=True``: a companion run on the run's steps two at
  a time, Richardson) against the true global error above, and the wall time of the run with
  the estimate over the run without (the same steps and rows);
* ``global_error="bound"``: its true error, whether it is within ``tol``, and its cost (the
  steps of every run, rejected and companion steps included) against the best fixed step of
  its own accuracy (the same bisection).

Writes ``benchmarks/results/adaptive_steps.json`` (named problems: their entries only).
Usage: ``python benchmarks/adaptive_steps.py [problem ...]`` (default: all).
"""

from __future__ import annotations

import json
import math
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import se3dyn as sd
from se3dyn.dynamics.stepcontrol import ErrorNorm
from se3dyn.errors import Se3dynWarning
from se3dyn.io.modelfile import load_model
from se3dyn.model.examples import slider_crank

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from top_step_guidance import top  # noqa: E402

from test_adaptive import _oscillator_model  # noqa: E402  (one model, one exact solution)

TOLS = (1e-3, 1e-4, 1e-5)
#: tolerances of the problems whose bodies are far smaller than a metre
OWN_TOLS = {"a03_andrews_squeezer": (1e-5, 1e-6, 1e-7)}
N_OUT = 200
#: reference runs finer than T / 64000 (problems whose tightest runs take 10^4 steps or more)
REF_FACTOR = {"oscillator": 4, "a01_simple_pendulum": 4}


def _file(name: str, t_end: float):
    model, settings = load_model(ROOT / "examples" / f"{name}.yaml")
    return model, t_end, {"rho_inf": settings.get("rho_inf", 0.9)}


PROBLEMS = {
    "oscillator": lambda: (_oscillator_model(), 5.0, {}),
    "a01_simple_pendulum": lambda: _file("a01_simple_pendulum", 10.0),
    "a02_n_four_bar": lambda: _file("a02_n_four_bar", 5.0),
    "a04_bricard": lambda: _file("a04_bricard", 5.0),
    "a05_flyball_governor": lambda: _file("a05_flyball_governor", 2.0),
    "heavy_top_50": lambda: (top(50.0)[0], 2.0, {}),
    "slider_crank": lambda: (slider_crank(), 1.0, {}),
    "a03_andrews_squeezer": lambda: _file("a03_andrews_squeezer", 0.03),
}


def _problem(name: str) -> dict:
    """The rows of one problem: its adaptive runs and the best fixed steps of their accuracy."""
    model, T, kw = PROBLEMS[name]()
    s = sd.compile_model(model)
    norm = ErrorNorm(s)
    n_ref = 64000 * REF_FACTOR.get(name, 1)
    ref = sd.simulate(s, T, T / n_ref, output_every=n_ref // N_OUT, **kw)
    cache: dict[int, float] = {}

    def err(r) -> float:
        assert np.allclose(r.t, ref.t, rtol=0, atol=1e-9 * T)
        return float(norm.frames(r.H, ref.H).max())

    def fixed(n: int) -> float:
        if n not in cache:
            try:
                cache[n] = err(sd.simulate(s, T, T / n, output_step=T / N_OUT, **kw))
            except sd.SimulationError:  # (a fixed step that fails is not accurate)
                cache[n] = math.inf
        return cache[n]

    def best_fixed(e: float, cost: int) -> int | None:
        grid = [max(10, int(0.1 * cost))]  # 3 % apart, 0.1 to 6 times the cost
        while grid[-1] < 6 * cost:
            grid.append(int(grid[-1] * 1.03) + 1)
        hi = len(grid) - 1
        while hi > 0 and fixed(grid[hi]) == math.inf:  # a fixed step that fails (A02 at
            hi -= 1  # 51,090 steps did before a failing condensed step fell back to the model)
        if not fixed(grid[hi]) <= e:
            return None
        lo = 0  # bisection: the fixed-step error falls with N (C h^2)
        while lo < hi:
            mid = (lo + hi) // 2
            lo, hi = (lo, mid) if fixed(grid[mid]) <= e else (mid + 1, hi)
        return grid[lo]

    rows = []
    for tol in OWN_TOLS.get(name, TOLS):
        h0 = min(1e-3, T / 1000)
        t0 = time.perf_counter()
        r = sd.simulate(s, T, h0, tol=tol, output_step=T / N_OUT, **kw)
        wall = time.perf_counter() - t0
        t0 = time.perf_counter()
        rg = sd.simulate(s, T, h0, tol=tol, output_step=T / N_OUT, global_error=True, **kw)
        wall_g = time.perf_counter() - t0
        assert np.array_equal(rg.H, r.H)  # (the estimate does not change the run)
        e = err(r)
        cost = r.stats["steps"] + r.stats["rejected"]
        best = best_fixed(e, cost)
        rb = sd.simulate(s, T, h0, tol=tol, output_step=T / N_OUT, global_error="bound", **kw)
        eb = err(rb)
        runs = rb.stats["global_error_runs"]
        cost_b = (cost + rg.stats["global_error_steps"]
                  + sum(x["steps"] + x["rejected"] for x in runs[1:]))
        best_b = best_fixed(eb, cost_b) if len(runs) > 1 else best
        bound = dict(error=eb, error_over_tol=eb / tol, estimate=rb.stats["global_error"],
                     runs=runs, cost_steps=cost_b, best_fixed_steps=best_b,
                     cost_over_best_fixed=cost_b / best_b if best_b else None)
        row = dict(tol=tol, steps=r.stats["steps"], rejected=r.stats["rejected"],
                   newton_iterations=r.stats["newton_iterations"], error=e,
                   error_over_tol=e / tol,
                   estimate_sum_over_tol=r.stats["error_estimate"] / tol,
                   h_min=r.stats["h_min_used"], h_max=r.stats["h_max_used"], wall_s=wall,
                   best_fixed_steps=best, best_fixed_error=cache.get(best),
                   steps_over_best_fixed=cost / best if best else None,
                   global_error_estimate=rg.stats["global_error"],
                   estimate_over_error=rg.stats["global_error"] / e,
                   companion_steps=rg.stats["global_error_steps"],
                   wall_with_estimate_over_without=wall_g / wall, bound=bound)
        rows.append(row)
        ratio = f"{cost / best:.2f}" if best else "n/a"
        ratio_b = f"{cost_b / best_b:.2f}" if best_b else "n/a"
        print(f"{name} tol {tol:g}: {r.stats['steps']} steps + {r.stats['rejected']} "
              f"rejected, error {e:.2e} m = {e / tol:.2f} tol (sum of estimates "
              f"{r.stats['error_estimate'] / tol:.2f} tol); best fixed step of that "
              f"accuracy: {best} steps -> adaptive/fixed {ratio}; global error estimate "
              f"{rg.stats['global_error'] / e:.2f} x the error (wall x{wall_g / wall:.2f}); "
              f"bound: {len(runs)} run(s), refined x{rb.stats['global_error_refine']}, error "
              f"{eb / tol:.2f} tol, cost {cost_b} steps -> /best fixed of that accuracy "
              f"{ratio_b}", flush=True)
    return dict(t_end=T, settings=kw, rows=rows)


def main(argv: list[str]) -> None:
    names = argv or list(PROBLEMS)
    out = {"se3dyn": sd.__version__, "machine": platform.platform(), "problems": {}}
    path = ROOT / "benchmarks" / "results" / "adaptive_steps.json"
    warnings.simplefilter("ignore", Se3dynWarning)
    for name in names:
        out["problems"][name] = _problem(name)
    if argv and path.exists():  # named problems: replace their entries, keep the others
        old = json.loads(path.read_text())
        old["problems"].update(out["problems"])
        out["problems"] = old["problems"]
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1:])
