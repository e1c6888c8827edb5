"""Step-size guidance for fast-spinning bodies (docs/accuracy.md): a heavy symmetric top on a
spherical joint at its fixed point (node at the pivot, centre of mass 0.2 m up the tilted axis
through ``com=``), spinning at OMEGA rad/s, 2 s, defaults (index 2, rho_inf = 0.9). Error of
the centre of mass at t = 2 s against a run at h = H_REF, for several steps and spin rates.

Run: python benchmarks/top_step_guidance.py [--out benchmarks/results/top_step_guidance.json]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

import se3dyn as sd

H_REF = 2.5e-5


def top(spin: float):
    m, L = 2.0, 0.2
    axis = np.array([math.sin(0.3), 0.0, math.cos(0.3)])
    z = np.array([0.0, 0.0, 1.0])
    k = np.cross(z, axis)
    Rp = sd.lie.exp_so3(k / np.linalg.norm(k) * math.acos(axis @ z))
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("ground", fixed=True)
    mb.node("top", position=(0, 0, 0), com=tuple(L * axis), mass=m, inertia=(0.02, 0.02, 0.03),
            principal_axes=Rp, angular_velocity=tuple(spin * axis))
    mb.joint("pivot", "spherical", "ground", "top")
    return mb.build(), L * axis


def com_end(spin: float, h: float, t_end: float = 2.0) -> np.ndarray:
    model, c0 = top(spin)
    res = sd.simulate(model, t_end=t_end, step=h, output_every=10 ** 9)
    i = res.system.node_names.index("top")
    return res.H[-1, i, :3, :3] @ c0 + res.H[-1, i, :3, 3]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" /
                                         "top_step_guidance.json"))
    args = ap.parse_args(argv)
    rows = []
    for spin in (30.0, 150.0):
        t0 = time.perf_counter()
        ref = com_end(spin, H_REF)
        print(f"spin {spin:5.0f} rad/s: reference h = {H_REF:g} ({time.perf_counter() - t0:.1f} s)")
        for h in (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4):
            e = float(np.linalg.norm(com_end(spin, h) - ref))
            rows.append(dict(spin=spin, h=h, error_m=e, spin_angle_per_step=spin * h))
            print(f"  h = {h:8.2e}  spin per step {spin * h:6.3f} rad  COM error at 2 s "
                  f"{e:.3e} m")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(dict(h_ref=H_REF, rows=rows), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
