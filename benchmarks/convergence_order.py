"""Measured order of accuracy of the generalized-alpha schemes in every variable.

Runs the paper's spatial slider-crank (Sec. 11) over [0, T] with steps h = 1e-2 ... 1.25e-3 and
a reference run at h_ref = 1.25e-3 / 8 (same formulation), and measures the largest error over
each run's own time grid of

* positions (node 6, the slider, m),
* velocities (all unknowns, material frame),
* accelerations (all unknowns),
* multipliers (all joints: the reaction wrenches, N and N m),

for the stabilized index-2 formulation (default) and the paper's index-3 form. Writes the
fitted log-log slopes to ``benchmarks/results/convergence_order.json`` and the plot to
``docs/convergence-order.png``. Usage::

    python benchmarks/convergence_order.py [--t-end 1.0]

The reference is a finer run of the same scheme (self-convergence): it measures the order, not
the absolute accuracy (that is what tests/test_gallery.py and tests/test_physics.py do against
analytic and published solutions).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

import se3dyn
from se3dyn import simulate
from se3dyn.model.examples import slider_crank

ROOT = Path(__file__).resolve().parents[1]
VARS = ("position", "velocity", "acceleration", "multiplier")


def errors(model, formulation: str, hs: list[float], href: float, t_end: float) -> dict:
    ref = simulate(model, t_end, href, formulation=formulation)
    out = {v: [] for v in VARS}
    for h in hs:
        r = simulate(model, t_end, h, formulation=formulation)
        k = round(h / href)
        out["position"].append(float(np.abs(r.node_position("6")
                                            - ref.node_position("6")[::k]).max()))
        out["velocity"].append(float(np.abs(r.v - ref.v[::k]).max()))
        out["acceleration"].append(float(np.abs(r.vd - ref.vd[::k]).max()))
        out["multiplier"].append(float(np.abs(r.lam - ref.lam[::k]).max()))
    return out


def slope(hs, e) -> float:
    return float(np.polyfit(np.log(hs), np.log(e), 1)[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=1.0)
    ap.add_argument("--no-plot", action="store_true")
    args = ap.parse_args()
    hs = [1e-2, 5e-3, 2.5e-3, 1.25e-3]
    href = hs[-1] / 8
    model = slider_crank()
    res = {"model": "paper slider-crank (Sec. 11), rho_inf = 0.9", "t_end": args.t_end,
           "steps": hs, "reference_step": href, "se3dyn": se3dyn.__version__,
           "machine": platform.platform(), "formulations": {}}
    t0 = time.perf_counter()
    for f in ("index2", "index3"):
        e = errors(model, f, hs, href, args.t_end)
        res["formulations"][f] = {"errors": e, "slopes": {v: slope(hs, e[v]) for v in VARS}}
        print(f"{f}: fitted orders " + ", ".join(
            f"{v} {res['formulations'][f]['slopes'][v]:.2f}" for v in VARS), flush=True)
    res["wall_time_s"] = time.perf_counter() - t0
    out = ROOT / "benchmarks" / "results" / "convergence_order.json"
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(f"wrote {out}")
    if not args.no_plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), sharey=True)
        for ax, f in zip(axes, ("index2", "index3"), strict=True):
            for v, mk in zip(VARS, "osd^", strict=True):
                e = res["formulations"][f]["errors"][v]
                ax.loglog(hs, e, mk + "-",
                          label=f"{v} (order {res['formulations'][f]['slopes'][v]:.2f})")
            h = np.array(hs)
            ax.loglog(h, 0.5 * res["formulations"][f]["errors"]["velocity"][0] * (h / h[0]) ** 2,
                      "k--", lw=0.8, label="slope 2")
            ax.set_xlabel("step h (s)")
            ax.set_title({"index2": "stabilized index-2 (default)",
                          "index3": "index-3 (paper, Eqs. 38-46)"}[f])
            ax.grid(True, which="both", lw=0.3)
            ax.legend(fontsize=8)
        axes[0].set_ylabel(f"max error over [0, {args.t_end:g}] s vs h_ref = {href:g}")
        fig.suptitle("Slider-crank: measured order of accuracy (SI units per variable)")
        fig.tight_layout()
        png = ROOT / "docs" / "convergence-order.png"
        fig.savefig(png, dpi=110)
        print(f"wrote {png}")


if __name__ == "__main__":
    main()
