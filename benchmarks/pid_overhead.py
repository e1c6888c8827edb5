"""Cost of the built-in control laws in the compiled time loop (issue 30).

A 7-link serial arm (hinges about alternating axes, links of 0.3 m and 1.5 kg, gravity) runs
for 2 s at h = 1 ms at se3dyn's defaults, three ways: no control law (the arm swings under
gravity), a PD law on every joint, and a PID law (with a limit) on every joint, targets a
0.5 Hz sine per joint, and the PID law sampled at 1 kHz (every step) and at 100 Hz (zero-order
hold). Printed: the wall time of each, warm (median of 5 runs in this
process) and the first run in a fresh process, the ratios to the run without control (whose
motion differs: the arm falls) and of PID to PD (the same motion but for the integral: the
cost of the integral state).

    python benchmarks/pid_overhead.py
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time
import warnings

import numpy as np

import se3dyn as sd

N, L, M = 7, 0.3, 1.5
T, H = 2.0, 1e-3


def arm(law: str) -> sd.Model:
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81), name=f"arm7_{law}")
    mb.node("base", fixed=True)
    prev = "base"
    for i in range(N):
        name = f"l{i}"
        mb.node(name, (L * (i + 0.5), 0, 0), mass=M, inertia=(2e-3, M * L * L / 12,
                                                            M * L * L / 12))
        axis = (0, 1, 0) if i % 2 == 0 else (0, 0, 1)
        tgt = sd.Sine(0.3, 0.5, phase=0.0, offset=0.0)
        control = {"none": None,
                   "pd": sd.PD(kp=200.0, kd=20.0, target=tgt),
                   "pid": sd.PID(kp=200.0, ki=100.0, kd=20.0, target=tgt, limit=150.0),
                   "pid_1kHz": sd.PID(kp=200.0, ki=100.0, kd=20.0, target=tgt, limit=150.0,
                                      sample_time=1e-3),
                   "pid_100Hz": sd.PID(kp=200.0, ki=100.0, kd=20.0, target=tgt, limit=150.0,
                                       sample_time=1e-2)}[law]
        mb.joint(f"j{i}", "hinge", prev, name, axis=axis, at=(L * i, 0, 0), control=control)
        prev = name
    return mb.build()


def timed(law: str) -> float:
    m = arm(law)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        sd.simulate(m, T, H)
        return time.perf_counter() - t0


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--first":
        print(json.dumps(timed(sys.argv[2])))
        return
    out = {}
    for law in ("none", "pd", "pid", "pid_1kHz", "pid_100Hz"):
        first = float(subprocess.run([sys.executable, __file__, "--first", law],
                                     capture_output=True, text=True, check=True).stdout)
        timed(law)
        warm = statistics.median(timed(law) for _ in range(5))
        out[law] = dict(first=first, warm=warm)
    res = sd.simulate(arm("pid"), T, H)
    err = np.abs(res.joint_coordinates("j3")[:, 0] - 0.3 * np.sin(np.pi * res.t)).max()
    print(f"7-link arm, {T:g} s at h = {H:g} s ({int(T / H)} steps), se3dyn defaults")
    for law, r in out.items():
        print(f"  {law:9s} first run (fresh process) {r['first']:7.3f} s, warm {r['warm']:7.3f} s,"
              f" warm ratio to no control {r['warm'] / out['none']['warm']:5.2f}")
    print(f"  PID against PD (the integral state's cost): warm "
          f"{out['pid']['warm'] / out['pd']['warm']:.2f}, first run "
          f"{out['pid']['first'] / out['pd']['first']:.2f}")
    print(f"  (PID: largest tracking error of joint j3 over the run {err:.3e} rad)")


if __name__ == "__main__":
    main()
