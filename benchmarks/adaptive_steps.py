"""Adaptive time stepping against fixed steps of the same accuracy.

1. Damped oscillator on a prismatic joint (m = 1 kg, k = 400 N/m, c = 4 N s/m, v0 = 2 m/s, 5 s;
   closed-form solution): adaptive runs with tol = 1e-4, 1e-5, 1e-6 (m), the global error of the
   joint coordinate against the exact solution, and the number of fixed steps that reaches the
   same error (fixed-step error C h^2 with C measured by one fixed run, checked by a run).
2. The paper's slider-crank over 1 s: adaptive tol = 1e-4, 1e-5 against a fixed-step reference
   (h = 2.5e-4) and fixed steps 2e-3, 1e-3 (honest: here the mechanism amplifies local errors).

Writes ``benchmarks/results/adaptive_steps.json``. Usage: ``python benchmarks/adaptive_steps.py``.
"""

from __future__ import annotations

import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

import se3dyn as sd
from se3dyn.examples import slider_crank

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from test_adaptive import _err, _oscillator_model  # noqa: E402  (one model, one exact solution)


def main() -> None:
    out = {"se3dyn": sd.__version__, "machine": platform.platform(), "oscillator": [],
           "slider_crank": []}
    T = 5.0
    m = _oscillator_model()
    hf = 1e-3
    rf = sd.simulate(m, T, hf, output_step=1e-2)
    ef = _err(rf)
    for tol in (1e-4, 1e-5, 1e-6):
        t0 = time.perf_counter()
        r = sd.simulate(m, T, 1e-3, tol=tol, output_step=1e-2)
        wall = time.perf_counter() - t0
        e = _err(r)
        h_same = hf * math.sqrt(e / ef)
        n_same = math.ceil(T / h_same)
        check = _err(sd.simulate(m, T, T / n_same, output_step=1e-2))
        row = dict(tol=tol, steps=r.stats["steps"], rejected=r.stats["rejected"], error=e,
                   h_min=r.stats["h_min_used"], h_max=r.stats["h_max_used"], wall_s=wall,
                   fixed_steps_same_error=n_same, fixed_error_check=check)
        out["oscillator"].append(row)
        print(f"oscillator tol {tol:g}: {row['steps']} steps ({row['rejected']} rejected), "
              f"error {e:.2e}; fixed step of the same error: {n_same} steps (error {check:.2e})"
              f" -> {n_same / row['steps']:.1f}x more", flush=True)
    T = 1.0
    ref = sd.simulate(slider_crank(), T, 2.5e-4, output_every=40)

    def errs(r):
        return (max(float(np.abs(r.node_position(n) - ref.node_position(n)).max())
                    for n in "3468"),
                float(np.abs(r.joint_coordinates("1") - ref.joint_coordinates("1")).max()))

    for kw in (dict(tol=1e-4), dict(tol=1e-5), dict(), dict()):
        h = 1e-3 if kw else (2e-3 if not out["slider_crank"][-1].get("fixed") else 1e-3)
        r = sd.simulate(slider_crank(), T, h, output_step=1e-2, **kw)
        ep, ea = errs(r)
        row = dict(tol=kw.get("tol"), fixed=not kw, step=None if kw else h,
                   steps=r.stats["steps"], position_error_m=ep, crank_angle_error_rad=ea)
        out["slider_crank"].append(row)
        label = f"tol {kw['tol']:g}" if kw else f"fixed h {h:g}"
        print(f"slider-crank {label}: "
              f"{row['steps']} steps, position error {ep:.2e} m, crank angle error {ea:.2e} rad",
              flush=True)
    p = ROOT / "benchmarks" / "results" / "adaptive_steps.json"
    p.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {p}")


if __name__ == "__main__":
    main()
