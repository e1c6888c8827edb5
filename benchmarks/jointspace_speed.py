"""Per-call time of ``JointSpace.inverse_dynamics`` and ``JointSpace.mass_matrix`` against
Pinocchio's Python calls (``pin.rnea``, ``pin.crba``) on the same 6-axis arm (random offsets,
unaligned axes, rotated inertias: tests/_pinocchio_models.py), warm (median over 200 calls at
random states) and for a batch of 1000 states (per state); the first call in a fresh process
for each code; the two codes' agreement printed beside.

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


def main() -> None:
    import pinocchio as pin

    import se3dyn as sd

    chain = random_chain("RRRRRR", seed=7)
    pm, _ = pinocchio_model(chain)
    pd = pm.createData()
    js = sd.JointSpace(se3dyn_model(chain))
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
    for name, ours, theirs, args, err in rows:
        t_s, t_p = per_call(ours, args), per_call(theirs, args)
        print(f"  {name:26s} se3dyn {t_s * 1e6:8.1f} us   pinocchio {t_p * 1e6:6.2f} us   "
              f"ratio {t_s / t_p:7.1f} x   difference {err:.1e}")
    Qb, Vb, Ab, _ = random_states(pm, 1000, seed=2)
    t0 = time.perf_counter()
    js.inverse_dynamics(Qb, Vb, Ab)
    tb = (time.perf_counter() - t0) / 1000
    print(f"  batch of 1000 states: inverse_dynamics {tb * 1e6:.1f} us per state")
    print(f"first call in a fresh process (imports, model build, one call): se3dyn "
          f"{first_call('se3dyn'):.2f} s, pinocchio {first_call('pinocchio'):.2f} s")


if __name__ == "__main__":
    main()
