"""Size of the viewer page for the 1000-link chain with 1000 stored times (issue 14: <= 20 MB).

Two pages: the chain of ``chain_scaling.py`` simulated for 0.999 s at h = 1e-3 (1000 stored
times, released horizontal under gravity), and the same layout with every frame a random pose
(incompressible: the worst case of the quantised, deflated frames). Prints sizes and times.

Run:  python benchmarks/viewer_size.py [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

import se3dyn as sd
from se3dyn.viewer import write_html

sys.path.insert(0, str(Path(__file__).resolve().parent))
from chain_scaling import chain  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out", help="folder of the pages (default: out)")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    model = chain(1000)
    t0 = time.perf_counter()
    res = sd.simulate(model, t_end=0.999, step=1e-3, formulation="index3")
    print(f"chain N = 1000: {len(res.t)} stored times, simulated in "
          f"{time.perf_counter() - t0:.1f} s")
    t0 = time.perf_counter()
    p = write_html(res, out / "chain1000.html")
    print(f"  simulated motion: {p} {p.stat().st_size / 1e6:.2f} MB "
          f"(written in {time.perf_counter() - t0:.1f} s)")
    n, M = res.H.shape[:2]
    rng = np.random.default_rng(0)
    H = np.zeros_like(res.H)
    H[..., :3, :3] = Rotation.random(n * M, random_state=rng).as_matrix().reshape(n, M, 3, 3)
    H[..., :3, 3] = rng.uniform(-100.0, 100.0, size=(n, M, 3))
    H[..., 3, 3] = 1.0
    res.H = H
    p = write_html(res, out / "chain1000_random.html", model=model)
    print(f"  random frames (worst case): {p} {p.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
