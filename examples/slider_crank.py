"""The paper's case study (Sec. 11): simulate the spatial slider-crank and write Figs. 3a-4b.

Run:  python examples/slider_crank.py [--out DIR]

Writes DIR/fig3a_node6_displacements.png, fig3b_hinge1_coordinate.png,
fig4a_node3_velocity_material.png, fig4b_node3_velocity_inertial.png (default DIR: out/).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import se3dyn as sd


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out", help="folder for the figures (default: out)")
    ap.add_argument("--no-plots", action="store_true", help="simulate and summarise only")
    args = ap.parse_args(argv)

    model = sd.examples.slider_crank()
    system = sd.compile_model(model)
    cfg = sd.examples.SLIDER_CRANK_SETTINGS
    print(f"se3dyn {sd.__version__}: spatial slider-crank of Sec. 11 "
          f"({len(model.nodes)} nodes, {len(model.joints)} joints)")
    print(f"  unknowns {system.nq} (paper: 49), multipliers {system.nm} (paper: 48), "
          f"iteration matrix {system.N} (paper: 97)")
    t0 = time.perf_counter()
    res = sd.simulate(system, **cfg)
    wall = time.perf_counter() - t0
    eb = res.energy_balance
    a1 = res.joint_coordinates("1")[:, 0]
    print(f"  {res.stats['steps']} steps of h = {cfg['step']} s to t = {cfg['t_end']} s, "
          f"rho_inf = {cfg['rho_inf']}: {res.stats['newton_iterations']} Newton iterations "
          f"(max {res.iterations.max()} per step), wall time {wall:.2f} s")
    print(f"  max constraint violation {res.constraint.max():.2e}; energy balance "
          f"(E - W_act + D) drift {np.ptp(eb):.2e} J of E_max {res.total_energy.max():.3f} J")
    print(f"  hinge (1) relative coordinate at t = 5 s: {a1[-1]:.4f} rad "
          f"({a1[-1] / (2 * np.pi):.2f} turns; passes 2 pi at t = "
          f"{res.t[np.argmax(a1 > 2 * np.pi)]:.2f} s)")
    x6 = res.node_position("6")[-1]
    print(f"  node 6 at t = 5 s: x = {x6[0]:.5f}, y = {x6[1]:.5f}, z = {x6[2]:.5f} m")
    if args.no_plots:
        return 0
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: pip install 'se3dyn[plot]' for the figures",
              file=sys.stderr)
        return 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t = res.t
    style = [("x", "r*", "red stars"), ("y", "go", "green circles"), ("z", "b-", "blue line")]

    def fig(name, title, ylabel, curves, every=10):
        f, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
        for label, y, st in curves:
            if st.endswith("-"):
                ax.plot(t, y, st, label=label, lw=1.4)
            else:  # line with sparse markers: stars (red) x, circles (green) y, as in Fig. 4
                ax.plot(t, y, st[0] + "-", marker=st[1], markevery=every, label=label, lw=0.9,
                        ms=5, mfc="none")
        ax.set_xlabel("time [s]")
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend()
        f.tight_layout()
        f.savefig(out / name)
        plt.close(f)
        print(f"  wrote {out / name}")

    d6 = res.node_position("6") - res.node_position("6")[0]
    fig("fig3a_node6_displacements.png", "Fig. 3a: displacements of node 6", "displacement [m]",
        [(c, d6[:, i], s) for i, (c, s, _) in enumerate(style)])
    f, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
    ax.plot(t, a1, "b-", lw=1.4, label="alpha (hinge 1)")
    for kk in range(1, int(a1.max() // (2 * np.pi)) + 1):
        ax.axhline(2 * np.pi * kk, color="0.6", ls="--", lw=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("relative coordinate [rad]")
    ax.set_title("Fig. 3b: relative coordinate of hinge joint (1)")
    ax.grid(alpha=0.3)
    ax.legend()
    f.tight_layout()
    f.savefig(out / "fig3b_hinge1_coordinate.png")
    plt.close(f)
    print(f"  wrote {out / 'fig3b_hinge1_coordinate.png'}")
    vm = res.node_velocity("3", frame="material")
    vi = res.node_velocity("3", frame="inertial")
    fig("fig4a_node3_velocity_material.png", "Fig. 4a: velocity of node 3, material frame",
        "v_U [m/s]", [(c, vm[:, i], s) for i, (c, s, _) in enumerate(style)])
    fig("fig4b_node3_velocity_inertial.png", "Fig. 4b: velocity of node 3, inertial frame (R v_U)",
        "R v_U [m/s]", [(c, vi[:, i], s) for i, (c, s, _) in enumerate(style)])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
