"""A two-link arm tracking a trajectory: inverse dynamics from drives, then PID with feedforward.

1. **Inverse dynamics by a driven run.** The arm with both joints *driven* along the
   trajectory (``ModelBuilder.drive``): the torques the drives supply are the exact inverse
   dynamics of the trajectory (``Results.drive_effort``, second order in the step).
2. **Tracking.** The same arm with a PID law on each joint (``sd.PID``, torque limit 60 N m)
   following the trajectory, without and with those torques fed forward (``torque=`` a
   ``Table`` of them): the feedforward leaves the PID laws only the errors to correct.

Writes ``docs/control-tracking.png`` and prints the largest tracking errors::

    python examples/arm_tracking.py
"""

from __future__ import annotations

import pathlib
import warnings

import numpy as np

import se3dyn as sd

L1, L2, M1, M2 = 0.5, 0.4, 2.0, 1.2
T, H = 3.0, 1e-3
# the trajectory: each joint from 0 to its goal along a quintic (zero rate and acceleration at
# both ends), then held
GOAL = (1.2, -0.9)


def quintic(goal: float, duration: float = 2.0) -> sd.Callable:
    """``goal (10 s^3 - 15 s^4 + 6 s^5)``, ``s = t / duration``, held after: smooth to the second
    derivative, as a drive's position must be for finite torques (a piecewise-linear ``Table``
    has rate jumps at its knots: impulses)."""
    def f(t):
        s = min(max(t / duration, 0.0), 1.0)
        return goal * (10 * s**3 - 15 * s**4 + 6 * s**5)
    return sd.Callable(f)


def arm(joint_kw: dict | None = None) -> sd.ModelBuilder:
    """The planar arm (hinges about z, gravity along -y); ``joint_kw[i]``: keywords of joint i."""
    joint_kw = joint_kw or {}
    mb = sd.ModelBuilder(gravity=(0, -9.81, 0), name="two_link_arm")
    mb.node("base", fixed=True)
    mb.node("upper", (L1 / 2, 0, 0), mass=M1, inertia=(1e-3, M1 * L1**2 / 12, M1 * L1**2 / 12))
    mb.node("fore", (L1 + L2 / 2, 0, 0), mass=M2,
            inertia=(1e-3, M2 * L2**2 / 12, M2 * L2**2 / 12))
    mb.joint("shoulder", "hinge", "base", "upper", axis=(0, 0, 1), at=(0, 0, 0),
             **joint_kw.get(0, {}))
    mb.joint("elbow", "hinge", "upper", "fore", axis=(0, 0, 1), at=(L1, 0, 0),
             **joint_kw.get(1, {}))
    return mb


def main() -> None:
    traj = [quintic(g) for g in GOAL]
    # 1. inverse dynamics: drive both joints along the trajectory
    mb = arm()
    for name, f in zip(("shoulder", "elbow"), traj, strict=True):
        mb.drive(f"{name}_motion", name, position=f)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        inv = sd.simulate(mb.build(), T, H)
    tau_ff = [inv.drive_effort(f"{n}_motion")[:, 0] for n in ("shoulder", "elbow")]
    # 2. tracking under PID, without and with the feedforward torques
    runs = {}
    for label, ff in (("PID", False), ("PID + feedforward", True)):
        kw = {i: dict(control=sd.PID(kp=400.0, ki=200.0, kd=40.0, target=traj[i], limit=60.0),
                      **({"torque": sd.Table(inv.t, tau_ff[i])} if ff else {}))
              for i in range(2)}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            runs[label] = sd.simulate(arm(kw).build(), T, H)
    t = inv.t
    ref = np.array([[f(x) for x in t] for f in traj]).T
    for label, res in runs.items():
        err = np.abs(np.concatenate([res.joint_coordinates("shoulder"),
                                     res.joint_coordinates("elbow")], axis=1) - ref)
        print(f"{label:18s} largest tracking error: shoulder {err[:, 0].max():.2e} rad, "
              f"elbow {err[:, 1].max():.2e} rad")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # (the plot extra)
        print("matplotlib missing: pip install 'se3dyn[plot]' for the figure")
        return
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    for i, name in enumerate(("shoulder", "elbow")):
        ax[0].plot(t, tau_ff[i], label=f"{name}: inverse dynamics (drive effort)")
        for label, res in runs.items():
            e = res.joint_coordinates(name)[:, 0] - ref[:, i]
            ax[1].plot(res.t, np.degrees(e), label=f"{name}, {label}")
    ax[0].set(xlabel="time [s]", ylabel="torque [N m]", title="torques of the driven run")
    ax[1].set(xlabel="time [s]", ylabel="tracking error [deg]", title="tracking under PID")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    out = pathlib.Path(__file__).resolve().parent.parent / "docs" / "control-tracking.png"
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
