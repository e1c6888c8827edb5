"""One simulated second of a 7-axis arm falling under gravity with no torque: se3dyn against
MuJoCo, each as its users run it (issue 31's benchmark).

The same arm in both codes (random offsets, unaligned axes, rotated inertias:
``tests/_pinocchio_models.py``; MuJoCo's MJCF from ``benchmarks/jointspace_speed.py``),
released at rest from its zero configuration (bent: random axes and offsets). se3dyn:
``sd.simulate(model, 1.0, 1e-3)`` at its defaults (generalized-alpha, every step stored, the
compiled loop); MuJoCo: ``mj_step`` at its
defaults (semi-implicit Euler, the model's default timestep 2 ms). Printed: the wall time of
the second and per step (warm; se3dyn's first call in a fresh process too), and each code's
error at 1 s against Pinocchio's ABA integrated by DOP853 at 1e-13 (the converged reference).
Needs ``pip install se3dyn[bench]`` (Pinocchio, MuJoCo).

    python benchmarks/arm_simulation.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
sys.path.insert(0, HERE)

from jointspace_speed import mjcf  # noqa: E402

from _pinocchio_models import pinocchio_model, random_chain, se3dyn_model  # noqa: E402

SEED, T, H = 11, 1.0, 1e-3
Q0 = np.zeros(7)

FIRST = """
import sys, time
sys.path.insert(0, {tests!r})
t0 = time.perf_counter()
import numpy as np, se3dyn as sd
from _pinocchio_models import random_chain, se3dyn_model
model = se3dyn_model(random_chain("RRRRRRR", seed={seed}))
sd.simulate(model, {T}, {H})
print(time.perf_counter() - t0)
"""


def reference(chain) -> np.ndarray:
    """Joint angles at T by Pinocchio's ABA and DOP853 (rtol = atol = 1e-13)."""
    import pinocchio as pin
    from scipy.integrate import solve_ivp

    pm, _ = pinocchio_model(chain)
    pd = pm.createData()
    n = pm.nv

    def rhs(t, y):
        return np.r_[y[n:], pin.aba(pm, pd, y[:n], y[n:], np.zeros(n))]

    return solve_ivp(rhs, (0.0, T), np.r_[Q0, np.zeros(n)], method="DOP853", rtol=1e-13,
                     atol=1e-13).y[:n, -1]


def run_se3dyn(chain):
    import se3dyn as sd

    model = se3dyn_model(chain)
    sd.simulate(model, T, H)  # (warm)
    t0 = time.perf_counter()
    res = sd.simulate(model, T, H)
    wall = time.perf_counter() - t0
    q = np.array([res.joint_coordinates(f"j{i}")[-1, 0] for i in range(len(Q0))])
    return wall, round(T / H), q


def run_mujoco(chain):
    import mujoco

    mm = mujoco.MjModel.from_xml_string(mjcf(chain))
    md = mujoco.MjData(mm)
    steps = round(T / mm.opt.timestep)
    for _pass in ("warm-up", "timed"):
        mujoco.mj_resetData(mm, md)
        md.qpos[:] = Q0
        t0 = time.perf_counter()
        for _ in range(steps):
            mujoco.mj_step(mm, md)
        wall = time.perf_counter() - t0
    return wall, steps, md.qpos.copy(), mm.opt.timestep


def main() -> None:
    chain = random_chain("RRRRRRR", seed=SEED)
    ref = reference(chain)
    w, n, q = run_se3dyn(chain)
    first = float(subprocess.run(
        [sys.executable, "-c", FIRST.format(tests=os.path.join(HERE, "..", "tests"),
                                            seed=SEED, T=T, H=H)],
        capture_output=True, text=True, check=True).stdout)
    print("7-axis arm, 1 s of a free fall (no torque), error of the angles at 1 s against "
          "Pinocchio ABA + DOP853 1e-13")
    print(f"  se3dyn  h = {H:g} (defaults)   {w * 1e3:8.1f} ms  {w / n * 1e6:7.1f} us/step  "
          f"error {np.abs(q - ref).max():.2e} rad   first call in a fresh process {first:.2f} s")
    try:
        wm, nm, qm, hm = run_mujoco(chain)
    except ImportError:
        print("  (MuJoCo not installed: pip install se3dyn[bench])")
        return
    print(f"  MuJoCo  h = {hm:g} (defaults)   {wm * 1e3:8.1f} ms  {wm / nm * 1e6:7.1f} us/step  "
          f"error {np.abs(qm - ref).max():.2e} rad")
    print(f"  ratio per step {w / n / (wm / nm):.2f}, per simulated second {w / wm:.2f}")


if __name__ == "__main__":
    main()
