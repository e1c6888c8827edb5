"""Validation plots of the SE(3) beam for docs/beams.md (issue 13).

Writes, from fresh computations with se3dyn:

* ``docs/beam-rollup.png``: a cantilever (L = 1, EI = 100) under a material end moment
  M = f 2 pi EI / L, f = 0.25, 0.4, 0.75, 1 (GJ = 50), 16 elements, ``static_equilibrium``: the
  nodes against the exact Euler-Bernoulli circles of radius EI / M (the roll-up benchmark, e.g.
  Simo & Vu-Quoc 1986, Sec. 7.1).
* ``docs/beam-convergence.png``: (left) the small-tip-force deflection error against Timoshenko's
  P L^3/(3 EI) + P L/(GA) for n = 1 ... 32 elements, with the slope -2 line; (right) the flexible
  slider-crank (``examples/slider_crank_flexible.yaml``, 1 s, h = 1/6400 s): largest difference
  of the crank angle and slider position to the welded (rigid) rod, and the midpoint deflection,
  against the rod's stiffness factor (E x 0.01 ... 1), with the slope -1 line.

Run:  python benchmarks/beam_validation_plots.py [--out docs]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

import se3dyn as sd
from se3dyn.analysis.statics import static_equilibrium

ROOT = Path(__file__).resolve().parents[1]


def rollup(ax) -> None:
    L, EI, n = 1.0, 100.0, 16
    for f, c in zip((0.25, 0.4, 0.75, 1.0), ("C0", "C1", "C2", "C3"), strict=True):
        M = f * 2 * math.pi * EI / L
        mb = sd.ModelBuilder()
        mb.node("root", fixed=True)
        mb.node("tip", position=(L, 0.0, 0.0))
        mb.beam("b", "root", "tip", elements=n, EA=1e4, GA=1e4, GJ=50.0, EI=EI)
        mb.load("m", "tip", torque=(0.0, 0.0, M), torque_frame="body")
        st = static_equilibrium(mb.build(), load_steps=4)
        P = st.H[:, :3, 3]
        R = EI / M
        s = np.linspace(0.0, L, 200)
        ax.plot(R * np.sin(s / R), R * (1 - np.cos(s / R)), "-", color=c, lw=1.0,
                label=f"M = {f:g} x 2 pi EI/L: circle")
        ax.plot(P[:, 0], P[:, 1], "o", color=c, ms=3.5, mfc="none")
    ax.plot([], [], "ko", mfc="none", ms=3.5, label="beam nodes (16 elements)")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Roll-up under an end moment")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")


def tip_force(ax) -> None:
    L, EI, GA = 1.0, 10.0, 500.0
    P = 3e-4 * EI / L ** 2
    exact = P * L ** 3 / (3 * EI) + P * L / GA
    ns = [1, 2, 4, 8, 16, 32]
    err = []
    for n in ns:
        mb = sd.ModelBuilder()
        mb.node("root", fixed=True)
        mb.node("tip", position=(L, 0.0, 0.0))
        mb.beam("b", "root", "tip", elements=n, EA=1e5, GA=GA, GJ=50.0, EI=EI)
        mb.load("p", "tip", force=(0.0, -P, 0.0))
        st = static_equilibrium(mb.build())
        err.append(abs(-st.H[st.system.node_names.index("tip"), 1, 3] - exact) / exact)
    ns_ = np.array(ns, float)
    ax.loglog(ns_, err, "bo-", label="|deflection - Timoshenko| / Timoshenko")
    ax.loglog(ns_, err[0] * ns_ ** -2.0, "k--", lw=0.8, label="slope -2")
    ax.set_xlabel("elements n")
    ax.set_ylabel("relative error")
    ax.set_title("Small tip force: mesh convergence")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)


def slider_crank(ax) -> None:
    sys.path.insert(0, str(ROOT / "tests"))
    import test_flexible_slider_crank as t

    h = 1.0 / 6400.0
    rig = t._run(t._model(rigid=True), h)
    a_r, x_r = rig.joint_coordinates("1")[:, 0], rig.node_position("8")[:, 0]
    fs = np.array([0.01, 0.03, 0.1, 0.3, 1.0])
    da, dx, mid = [], [], []
    for f in fs:
        r = t._run(t._model(f), h)
        da.append(np.abs(r.joint_coordinates("1")[:, 0] - a_r).max())
        dx.append(np.abs(r.node_position("8")[:, 0] - x_r).max())
        cm = 0.5 * (r.node_position("5") + r.node_position("7"))
        mid.append(np.linalg.norm(r.node_position("rod/2") - cm, axis=1).max())
    E = 70e9 * fs
    ax.loglog(E, da, "ro-", label="crank angle difference [rad]")
    ax.loglog(E, dx, "gs-", label="slider position difference [m]")
    ax.loglog(E, mid, "b^-", label="rod midpoint deflection [m]")
    ax.loglog(E, da[0] * (fs / fs[0]) ** -1.0, "k--", lw=0.8, label="slope -1")
    ax.set_xlabel("Young's modulus of the rod [Pa]")
    ax.set_title("Flexible slider-crank: rigid limit (1 s)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs"))
    a = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    f, ax = plt.subplots(figsize=(5.6, 4.6), dpi=110)
    rollup(ax)
    f.tight_layout()
    f.savefig(out / "beam-rollup.png")
    plt.close(f)
    f, axs = plt.subplots(1, 2, figsize=(10.5, 4.2), dpi=110)
    tip_force(axs[0])
    slider_crank(axs[1])
    f.tight_layout()
    f.savefig(out / "beam-convergence.png")
    plt.close(f)
    print(f"wrote {out / 'beam-rollup.png'}, {out / 'beam-convergence.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
