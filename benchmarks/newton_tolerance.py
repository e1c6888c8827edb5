"""What the Newton tolerance buys: time, iterations and accuracy of the 1000-link chain.

The chain of ``chain_scaling.py`` (1 s, h = 1e-3, rho_inf = 0.9, se3dyn's defaults otherwise)
run at several ``tol_residual`` values (the default 1e-10 first; 1e-8 is EXUDYN's default
relative tolerance) and once at h / 8 with the default tolerance as the reference. For each
tolerance it prints the solve time (second ``simulate`` of the compiled system), the Newton
iterations per step, how far the link ends at t = 1 s moved from the default run's (the Newton
error the looser tolerance adds) and how far they are from the reference (the discretisation
error). Writes benchmarks/results/newton_tolerance.json. Timings are one run each on a shared
machine: compare them within the run.

Run:  python benchmarks/newton_tolerance.py [--n 1000] [--tols 1e-10 3e-10 1e-9 1e-8]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

import se3dyn as sd

sys.path.insert(0, str(Path(__file__).parent))
from chain_scaling import chain  # noqa: E402


def link_ends(res, n_links: int) -> np.ndarray:
    """End points (N, 3) of all links at the last stored time (as compare_exudyn.py)."""
    names = res.system.node_names
    H = res.H[-1, [names.index(f"b{i}") for i in range(n_links)]]
    return H[:, :3, 3] + 0.05 * H[:, :3, 0]


def run(system, n_links: int, h: float, tol: float) -> dict:
    """One timed 1-s run (the system's one-time set-up paid before)."""
    sd.simulate(system, h, h, rho_inf=0.9, tol_residual=tol)
    nsteps = round(1.0 / h)
    t0 = time.perf_counter()
    res = sd.simulate(system, 1.0, h, rho_inf=0.9, tol_residual=tol,
                      output_every=max(1, nsteps // 10))
    return {"h": h, "tol_residual": tol, "solve_s": time.perf_counter() - t0,
            "its_per_step": res.stats["newton_iterations"] / res.stats["steps"],
            "ends": link_ends(res, n_links)}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--tols", type=float, nargs="+", default=[1e-10, 3e-10, 1e-9, 1e-8])
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" /
                                          "newton_tolerance.json"))
    a = ap.parse_args(argv)
    system = sd.compile_model(chain(a.n))
    print(f"{a.n}-link chain, 1 s, h = 1e-3; load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    runs = [run(system, a.n, 1e-3, tol) for tol in a.tols]
    ref = run(system, a.n, 1e-3 / 8, 1e-10)
    print(f"reference: h = {ref['h']:g}, tol_residual 1e-10 ({ref['solve_s']:.1f} s)")
    base = runs[0]["ends"]
    print(f"{'tol_residual':>12s} {'solve s':>8s} {'its/step':>8s} {'moved: tip':>11s} "
          f"{'worst':>9s} {'error: tip':>11s} {'worst':>9s}")
    rows = []
    for r in runs:
        moved = np.linalg.norm(r["ends"] - base, axis=1)
        err = np.linalg.norm(r["ends"] - ref["ends"], axis=1)
        row = {k: v for k, v in r.items() if k != "ends"}
        row.update(moved_tip_m=float(moved[-1]), moved_max_m=float(moved.max()),
                   error_tip_m=float(err[-1]), error_max_m=float(err.max()))
        rows.append(row)
        print(f"{r['tol_residual']:12.0e} {r['solve_s']:8.2f} {r['its_per_step']:8.3f} "
              f"{moved[-1]:11.2e} {moved.max():9.2e} {err[-1]:11.2e} {err.max():9.2e}")
    Path(a.out).write_text(json.dumps({"n": a.n, "rows": rows, "reference_h": ref["h"],
                                       "reference_solve_s": ref["solve_s"]}, indent=1))
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
