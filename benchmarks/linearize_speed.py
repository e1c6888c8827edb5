"""Linearise a 600-coordinate beam about its static equilibrium and compute its 20 lowest
modes (issue 32's benchmark: <= 0.5 s), timed around each call; the frequencies of the first
two bending pairs beside Euler-Bernoulli's closed form (lumped masses: the discretisation's
error), and the whole companion spectrum's time for comparison. First call in a fresh process
and warm.

    python benchmarks/linearize_speed.py
"""

from __future__ import annotations

import math
import subprocess
import sys
import time

L, EI, MU = 2.0, (2e3, 1e3), 2.0

CODE = """
import time
t0 = time.perf_counter()
import se3dyn as sd
mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
mb.node("root", fixed=True)
mb.node("tip", ({L}, 0, 0))
mb.beam("b", "root", "tip", elements=100, EA=1e7, GA=1e7, GJ=1e3, EI={EI},
        mass_per_length={MU}, rotary_inertia=(1e-3, 5e-4, 5e-4))
model = mb.build()
st = sd.static_equilibrium(model)
t1 = time.perf_counter()
lin = sd.linearize(model, at=st)
t2 = time.perf_counter()
md = lin.modes(20)
t3 = time.perf_counter()
"""


def main() -> None:
    first = subprocess.run([sys.executable, "-c", CODE.format(L=L, EI=EI, MU=MU)
                            + "print(t1 - t0, t3 - t1)"], capture_output=True, text=True,
                           check=True).stdout.split()
    ns: dict = {}
    exec(CODE.format(L=L, EI=EI, MU=MU), ns)  # (warm-up: imports, compiled kernels)
    exec(CODE.format(L=L, EI=EI, MU=MU), ns)
    lin, md = ns["lin"], ns["md"]
    t0 = time.perf_counter()
    every = lin.modes()
    t_all = time.perf_counter() - t0
    print(f"600-coordinate cantilever ({len(lin.names)} minimal coordinates)")
    print(f"  static equilibrium {ns['t1'] - ns['t0']:.3f} s, linearize {ns['t2'] - ns['t1']:.3f}"
          f" s, modes(20) {ns['t3'] - ns['t2']:.3f} s: linearise + 20 modes "
          f"{ns['t3'] - ns['t1']:.3f} s (target 0.5 s)")
    print(f"  first call in a fresh process: set-up and statics {float(first[0]):.2f} s, "
          f"linearise + 20 modes {float(first[1]):.2f} s")
    print(f"  the whole companion spectrum (modes()): {t_all:.2f} s; its 20 lowest agree to "
          f"{max(abs(a / b - 1) for a, b in zip(md.omega, every.omega[:20], strict=True)):.1e}")
    for bl, i in ((1.87510407, 0), (4.69409113, 2)):
        ref = sorted(bl ** 2 * math.sqrt(e / (MU * L ** 4)) for e in EI)
        got = sorted(md.omega[i:i + 2])
        print(f"  bending pair {got[0]:.6g}, {got[1]:.6g} rad/s; Euler-Bernoulli {ref[0]:.6g}, "
              f"{ref[1]:.6g}")


if __name__ == "__main__":
    main()
