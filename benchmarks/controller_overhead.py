"""The cost of a controller written in Python around :class:`se3dyn.Simulator` (issue 30).

A 7-link serial arm (hinge joints, gravity) held at a pose by PD laws on its joints at 1 kHz
for ``T`` seconds, two ways:

* bare: ``sd.simulate`` of the arm whose joints carry the model's own ``sd.PD`` laws (the
  compiled loop; the same gains and set-points);
* loop: ``sd.Simulator`` of the arm whose joints carry actuators, a Python loop reading the
  joint angles and rates (``sim.read``), computing the PD torques and setting them
  (``sim.set_input``) before every step (``sim.step``), h = 1 ms.

Printed: the wall times and their ratio, for the first call in a fresh process (the median
over ``--fresh`` processes) and warm (the best of ``--repeat`` calls in each). Run:
``python benchmarks/controller_overhead.py [--t-end 2]``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np

import se3dyn as sd

H = 1e-3
N_LINKS = 7
KP, KD = 200.0, 20.0
#: the pose held: angles (rad) of the joints
TARGET = tuple(0.3 * (-1) ** i for i in range(N_LINKS))
#: hinge axes: a robot arm's alternation of vertical and horizontal axes
AXES = ((0, 0, 1), (0, 1, 0), (0, 1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1), (0, 1, 0))


def arm(control: str) -> sd.Model:
    """The arm: links of 0.3 m and 2 kg along x, hinge joints at their ends; ``control``
    "pd" (the model's own PD laws to TARGET) or "actuator" (actuators, zero by default)."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name=f"arm7_{control}")
    mb.node("base", position=(0.0, 0.0, 0.0), fixed=True)
    L = 0.3
    prev = "base"
    for i in range(N_LINKS):
        name = f"l{i + 1}"
        mb.node(name, position=(L * i + L / 2, 0.0, 0.0), mass=2.0,
                inertia=(2e-3, 2.0 * L * L / 12, 2.0 * L * L / 12))
        kw = (dict(control=sd.PD(kp=KP, kd=KD, target=TARGET[i])) if control == "pd"
              else dict(actuator=0.0))
        mb.joint(f"j{i + 1}", "hinge", prev, name, axis=AXES[i], at=(L * i, 0.0, 0.0), **kw)
        prev = name
    return mb.build()


def bare(t_end: float, out: list | None = None) -> float:
    model = arm("pd")
    tic = time.perf_counter()
    res = sd.simulate(model, t_end, H)
    if out is not None:
        out.append(res)
    return time.perf_counter() - tic


def loop(t_end: float, out: list | None = None) -> float:
    model = arm("actuator")
    tic = time.perf_counter()
    sim = sd.Simulator(model, step=H)
    q_names = [f"joint/j{i + 1}/alpha/0" for i in range(N_LINKS)]
    w_names = [f"joint/j{i + 1}/velocity/0" for i in range(N_LINKS)]
    u_names = [f"joint/j{i + 1}/actuator" for i in range(N_LINKS)]
    n = round(t_end / H)
    read, set_input, step = sim.read, sim.set_input, sim.step
    for _ in range(n):
        for q, w, u, ref in zip(q_names, w_names, u_names, TARGET, strict=True):
            set_input(u, -KP * (read(q) - ref) - KD * read(w))
        step()
    res = sim.results()
    if out is not None:
        out.append(res)
    return time.perf_counter() - tic


def _child(kind: str, t_end: float, repeat: int) -> dict:
    f = bare if kind == "bare" else loop
    first = f(t_end)
    warm = min(f(t_end) for _ in range(repeat))
    return dict(first=first, warm=warm)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--t-end", type=float, default=2.0)
    ap.add_argument("--repeat", type=int, default=5, help="warm calls per process (best)")
    ap.add_argument("--fresh", type=int, default=3,
                    help="fresh processes per kind (median of the first calls)")
    ap.add_argument("--child", choices=("bare", "loop"))
    a = ap.parse_args()
    if a.child:
        print(json.dumps(_child(a.child, a.t_end, a.repeat)))
        return
    runs = {"bare": [], "loop": []}
    for _ in range(a.fresh):  # fresh processes, alternated: a first call is a first call
        for kind in ("bare", "loop"):
            p = subprocess.run([sys.executable, __file__, "--child", kind, "--t-end",
                                str(a.t_end), "--repeat", str(a.repeat)],
                               capture_output=True, text=True, check=True)
            runs[kind].append(json.loads(p.stdout.strip().splitlines()[-1]))
    out = {k: dict(first=float(np.median([r["first"] for r in v])),
                   warm=min(r["warm"] for r in v)) for k, v in runs.items()}
    steps = round(a.t_end / H)
    res: list = []
    bare(a.t_end, res)
    loop(a.t_end, res)
    dq = max(float(np.abs(res[0].joint_coordinates(f"j{i + 1}")
                          - res[1].joint_coordinates(f"j{i + 1}")).max()) for i in range(N_LINKS))
    print(f"7-link arm, h = {H:g} s, {a.t_end:g} s ({steps} steps); "
          f"se3dyn {sd.__version__}")
    for which in ("first", "warm"):
        b, lp = out["bare"][which], out["loop"][which]
        print(f"  {which:5s}: bare simulate {b * 1e3:8.1f} ms ({b / steps * 1e6:5.1f} us/step), "
              f"Python PD loop {lp * 1e3:8.1f} ms ({lp / steps * 1e6:5.1f} us/step), "
              f"ratio {lp / b:.2f}")
    print(f"  (the same task: the joint angles of the two runs differ by at most {dq:.1e} rad, "
          "the PD law sampled at 1 kHz against the continuous one)")


if __name__ == "__main__":
    main()
