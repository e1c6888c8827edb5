"""Cost per time step of an N-link spatial pendulum chain (the shape of issue 6's benchmark).

Links of 0.1 m and 1 kg (slender rod inertia), spherical joints, the first to a fixed node,
released horizontal under gravity; 0.05 s at h = 1e-3, rho_inf = 0.9. Prints ms per step, Newton
iterations per step and the fitted exponent of cost vs N (measured in this one run).

Run:  python benchmarks/chain_scaling.py [N ...]
"""

from __future__ import annotations

import platform
import sys
import time

import numpy as np
import scipy

import se3dyn as sd


def chain(n_links: int) -> sd.Model:
    """Chain model: per link a joint node, a body node at the centre, an end node (rigid)."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name=f"chain{n_links}")
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    J = 1.0 * 0.1**2 / 12.0
    prev = "ground"
    for i in range(n_links):
        x0 = 0.1 * i
        mb.node(f"p{i}", position=(x0, 0.0, 0.0))
        mb.node(f"b{i}", position=(x0 + 0.05, 0.0, 0.0), mass=1.0, inertia=(1e-4 * J, J, J))
        mb.node(f"e{i}", position=(x0 + 0.1, 0.0, 0.0))
        mb.joint(f"s{i}", "spherical", prev, f"p{i}")
        mb.joint(f"r{i}", "rigid", f"p{i}", f"b{i}")
        mb.joint(f"t{i}", "rigid", f"b{i}", f"e{i}")
        prev = f"e{i}"
    return mb.build()


def main(argv: list[str]) -> int:
    sizes = [int(a) for a in argv] or [10, 30, 100, 300, 1000]
    print(f"se3dyn {sd.__version__}, numpy {np.__version__}, scipy {scipy.__version__}, "
          f"Python {platform.python_version()}, {platform.machine()}")
    rows = []
    for n in sizes:
        system = sd.compile_model(chain(n))
        t0 = time.perf_counter()
        res = sd.simulate(system, t_end=0.05, step=1e-3, rho_inf=0.9)
        wall = time.perf_counter() - t0
        steps = res.stats["steps"]
        ms = 1e3 * wall / steps
        rows.append((n, ms))
        print(f"N = {n:5d} links: {system.N:7d} equations, {ms:8.2f} ms/step, "
              f"{res.stats['newton_iterations'] / steps:.2f} Newton iterations/step, "
              f"{res.stats['linear_solver']}")
    if len(rows) >= 2:
        n, ms = np.array(rows).T
        slope = np.polyfit(np.log(n), np.log(ms), 1)[0]
        print(f"fitted exponent of cost per step vs N: {slope:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
