"""Cost of an actuator law of the user's (``torque=lambda t, q, v: ...``) against the built-in
PD law: a rotor, 2 s at h = 1 ms (2000 steps), warm (median of 5 runs), se3dyn defaults.

    python benchmarks/law_cost.py
"""

from __future__ import annotations

import statistics
import time
import warnings

import numpy as np

import se3dyn as sd

J, KP, KD, R = 0.5, 20.0, 4.0, 1.0


def rotor(**joint_kw) -> sd.Model:
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("rotor", mass=1.0, inertia=(J, J, J))
    mb.joint("axle", "hinge", "g", "rotor", axis=(0, 0, 1), **joint_kw)
    return mb.build()


def law(t, q, v):
    return -KP * (q - R) - KD * v


def main() -> None:
    cases = {
        "built-in PD": rotor(control=sd.PD(KP, KD, target=R)),
        "law, tangents by differences": rotor(torque=law),
        "law with jacobian=": rotor(torque=sd.Law(law, jacobian=lambda t, q, v: (
            np.array([[-KP]]), np.array([[-KD]])))),
    }
    print("a rotor, 2 s at h = 1 ms (2000 steps), warm median of 5")
    base = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, m in cases.items():
            sd.simulate(m, 0.1, 1e-3)
            ts = []
            for _ in range(5):
                t0 = time.perf_counter()
                res = sd.simulate(m, 2.0, 1e-3)
                ts.append(time.perf_counter() - t0)
            w = statistics.median(ts)
            base = base or w
            print(f"  {name:30s} {w * 1e3:7.1f} ms ({w / 2000 * 1e6:6.1f} us/step, "
                  f"{w / base:5.1f} x), Newton iterations {res.stats['newton_iterations']}")


if __name__ == "__main__":
    main()
