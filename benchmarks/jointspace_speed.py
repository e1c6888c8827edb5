"""Per-call time of ``JointSpace.inverse_dynamics`` and ``JointSpace.mass_matrix`` against
Pinocchio's Python calls (``pin.rnea``, ``pin.crba``) and MuJoCo's (``mj_inverse``;
``mj_fwdPosition`` + ``mj_fullM``) on the same 6-axis arm (random offsets, unaligned axes,
rotated inertias: tests/_pinocchio_models.py; MuJoCo's from an MJCF written here), warm
(median over 200 calls at random states) and for a batch of 1000 states (per state); the
first call in a fresh process for se3dyn and Pinocchio; each code's agreement with Pinocchio
printed beside; the general path (``compiled=False``: the engine's evaluations and the
minimal-coordinate map, what loops and elements beyond the compiled path's take) beside it.
MuJoCo is optional (``pip install se3dyn[bench]``).

    python benchmarks/jointspace_speed.py
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from _pinocchio_models import (  # noqa: E402
    pinocchio_model,
    random_chain,
    random_states,
    se3dyn_model,
)

FIRST = """
import sys, time
sys.path.insert(0, {tests!r})
t0 = time.perf_counter()
from _pinocchio_models import pinocchio_model, random_chain, se3dyn_model
import numpy as np
chain = random_chain("RRRRRR", seed=7)
q = np.full(6, 0.3)
if {which!r} == "se3dyn":
    import se3dyn as sd
    js = sd.JointSpace(se3dyn_model(chain))
    js.inverse_dynamics(q, q, q)
else:
    import pinocchio as pin
    pm, _ = pinocchio_model(chain)
    pin.rnea(pm, pm.createData(), q, q, q)
print(time.perf_counter() - t0)
"""


def per_call(fn, args, reps: int = 200) -> float:
    ts = []
    for i in range(reps):
        a = [x[i % len(x)] for x in args]
        t0 = time.perf_counter()
        fn(*a)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def first_call(which: str) -> float:
    out = subprocess.run([sys.executable, "-c", FIRST.format(tests=os.path.join(HERE, "..",
                                                                                "tests"),
                                                             which=which)],
                         capture_output=True, text=True, check=True)
    return float(out.stdout.split()[-1])


def _f(x: float) -> str:
    return f"{x:.17g}"


def mjcf(chain: dict) -> str:
    """The chain as MJCF: bodies at the joint placements, joints along the axes, full
    inertias at the centres of mass (MuJoCo's quaternions are (w, x, y, z))."""
    from scipy.spatial.transform import Rotation

    body, close = "", ""
    for i, lk in enumerate(chain["links"]):
        m, c, I = lk["body"]
        x, y, z, w = Rotation.from_matrix(lk["R"]).as_quat()
        full = " ".join(_f(I[a, b]) for a, b in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))
        body += (f'<body name="L{i}" pos="{" ".join(map(_f, lk["p"]))}" '
                 f'quat="{_f(w)} {_f(x)} {_f(y)} {_f(z)}"><joint name="j{i}" '
                 f'type="{"hinge" if lk["type"] == "R" else "slide"}" '
                 f'axis="{" ".join(map(_f, lk["axis"]))}"/><inertial '
                 f'pos="{" ".join(map(_f, c))}" mass="{_f(m)}" fullinertia="{full}"/>')
        close += "</body>"
    return (f'<mujoco><option gravity="0 0 -9.81"/><worldbody>{body}{close}</worldbody>'
            "</mujoco>")


def mujoco_rows(chain, pm, pd, Q, V, A) -> list:
    """MuJoCo's calls and their agreement with Pinocchio, or nothing if it is not installed."""
    try:
        import mujoco
    except ImportError:
        print("  (MuJoCo not installed: pip install mujoco)")
        return []
    import pinocchio as pin

    mm = mujoco.MjModel.from_xml_string(mjcf(chain))
    md = mujoco.MjData(mm)
    n = mm.nv
    Mf = np.zeros((n, n))

    def inverse(q, v, a):
        md.qpos[:], md.qvel[:], md.qacc[:] = q, v, a
        mujoco.mj_inverse(mm, md)
        return md.qfrc_inverse

    def full_m(q):
        md.qpos[:] = q
        mujoco.mj_fwdPosition(mm, md)
        mujoco.mj_fullM(mm, md, Mf)
        return Mf

    err_id = max(float(np.abs(inverse(q, v, a) - pin.rnea(pm, pd, q, v, a)).max()
                       / np.abs(pin.rnea(pm, pd, q, v, a)).max())
                 for q, v, a in zip(Q[:20], V[:20], A[:20], strict=True))
    err_m = 0.0
    for q in Q[:20]:
        Mp = pin.crba(pm, pd, q)
        Mp = np.triu(Mp) + np.triu(Mp, 1).T
        err_m = max(err_m, float(np.abs(full_m(q) - Mp).max() / np.abs(Mp).max()))
    return [("  mj_inverse", inverse, (Q, V, A), err_id),
            ("  mj_fwdPosition + mj_fullM", full_m, (Q,), err_m)]


def main() -> None:
    import pinocchio as pin

    import se3dyn as sd

    chain = random_chain("RRRRRR", seed=7)
    pm, _ = pinocchio_model(chain)
    pd = pm.createData()
    js = sd.JointSpace(se3dyn_model(chain))
    slow = sd.JointSpace(se3dyn_model(chain), compiled=False)
    print(f"compiled path: {js.compiled}")
    Q, V, A, _ = random_states(pm, 200, seed=1)
    err_id = max(float(np.abs(js.inverse_dynamics(q, v, a) - pin.rnea(pm, pd, q, v, a)).max()
                       / np.abs(pin.rnea(pm, pd, q, v, a)).max())
                 for q, v, a in zip(Q[:20], V[:20], A[:20], strict=True))
    crba = lambda q: pin.crba(pm, pd, q)  # noqa: E731
    err_m = max(float(np.abs(js.mass_matrix(q) - (np.triu(crba(q)) + np.triu(crba(q), 1).T))
                      .max() / np.abs(crba(q)).max()) for q in Q[:20])
    rows = [("inverse_dynamics / rnea", lambda q, v, a: js.inverse_dynamics(q, v, a),
             lambda q, v, a: pin.rnea(pm, pd, q, v, a), (Q, V, A), err_id),
            ("mass_matrix / crba", lambda q: js.mass_matrix(q), crba, (Q,), err_m)]
    print("6-axis arm (nv = 6), warm median per call; max relative difference of the two "
          "codes over 20 states beside")
    pin_t = {}
    for name, ours, theirs, args, err in rows:
        t_s, t_p = per_call(ours, args), per_call(theirs, args)
        pin_t[len(args)] = t_p
        print(f"  {name:26s} se3dyn {t_s * 1e6:8.1f} us   pinocchio {t_p * 1e6:6.2f} us   "
              f"ratio {t_s / t_p:7.1f} x   difference {err:.1e}")
    t_g = per_call(lambda q, v, a: slow.inverse_dynamics(q, v, a), (Q, V, A), 50)
    err_g = max(float(np.abs(slow.inverse_dynamics(q, v, a) - js.inverse_dynamics(q, v, a)).max()
                      / np.abs(js.inverse_dynamics(q, v, a)).max())
                for q, v, a in zip(Q[:20], V[:20], A[:20], strict=True))
    print(f"  {'  general path, rnea':26s} se3dyn {t_g * 1e6:8.1f} us   "
          f"({t_g / pin_t[3]:.0f} x pinocchio's call)   difference from the compiled "
          f"{err_g:.1e}")
    for name, fn, args, err in mujoco_rows(chain, pm, pd, Q, V, A):
        t_m = per_call(fn, args)
        print(f"  {name:26s} mujoco {t_m * 1e6:8.2f} us   ({t_m / pin_t[len(args)]:.1f} x "
              f"pinocchio's call)   difference from pinocchio {err:.1e}")
    Qb, Vb, Ab, _ = random_states(pm, 1000, seed=2)
    t0 = time.perf_counter()
    js.inverse_dynamics(Qb, Vb, Ab)
    tb = (time.perf_counter() - t0) / 1000
    t0 = time.perf_counter()
    js.mass_matrix(Qb)
    tm = (time.perf_counter() - t0) / 1000
    print(f"  batch of 1000 states: inverse_dynamics {tb * 1e6:.2f} us, mass_matrix "
          f"{tm * 1e6:.2f} us per state")
    print(f"first call in a fresh process (imports, model build, one call): se3dyn "
          f"{first_call('se3dyn'):.2f} s, pinocchio {first_call('pinocchio'):.2f} s")


if __name__ == "__main__":
    main()
