"""A cart-pole balanced by an LQR designed on se3dyn's exact linear model.

1. **Linearise** the cart (a prismatic joint, force input) and the pole (a hinge on the cart)
   about the upright equilibrium: ``sd.linearize`` gives M, C, K, B in the joint coordinates
   and ``lin.state_space()`` the python-control system with named signals.
2. **Design** the LQR gain with ``control.lqr``.
3. **Simulate** the nonlinear model from a 10 degree offset with ``sd.Simulator``, the gain
   applied to the joint coordinates and rates read at every step (a zero-order hold at the
   step).

Prints the open-loop modes and the pole angle and cart position along the run::

    pip install se3dyn[analysis]
    python examples/cart_pole_lqr.py
"""

from __future__ import annotations

import math

import control
import numpy as np

import se3dyn as sd

MC, MP, LP, G = 1.0, 0.3, 0.5, 9.81  # cart mass, pole mass, pole half-length, gravity
CHANNELS = ["joint/cart/alpha/0", "joint/pole/alpha/0", "joint/cart/velocity/0",
            "joint/pole/velocity/0"]


def cart_pole(theta0: float = 0.0) -> sd.Model:
    """The cart on a rail along x, the pole (a uniform rod) on a hinge about y at the cart,
    tilted by ``theta0`` (its hinge coordinate is absolute: 0 upright)."""
    mb = sd.ModelBuilder(gravity=(0, 0, -G), name="cart_pole")
    mb.node("ground", fixed=True)
    mb.node("cart", mass=MC, inertia=(0.01, 0.01, 0.01))
    c, s = math.cos(theta0), math.sin(theta0)
    R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    mb.node("pole", position=R @ (0, 0, LP), orientation=R, mass=MP,
            inertia=R @ np.diag([MP * LP**2 / 3, MP * LP**2 / 3, 1e-4]) @ R.T)
    mb.joint("cart", "prismatic", "ground", "cart", axis=(1, 0, 0), force=0.0)
    mb.joint("pole", "hinge", "cart", "pole", axis=(0, 1, 0), at=(0, 0, 0), initial=theta0)
    return mb.build()


def main() -> None:
    lin = sd.linearize(cart_pole(), inputs=["cart"], outputs=["cart", "pole"])
    modes = lin.modes()
    print("open loop, about the upright equilibrium:")
    for s, stable, rigid in zip(modes.eigenvalues, modes.stable, modes.rigid, strict=True):
        print(f"  s = {s:.4f}  {'rigid' if rigid else 'stable' if stable else 'UNSTABLE'}")
    sys = lin.state_space()
    K, _, E = control.lqr(sys, np.diag([10.0, 50.0, 1.0, 1.0]), np.array([[0.1]]))
    print("LQR gain on", sys.state_labels, ":", np.round(K[0], 3))
    print("closed-loop eigenvalues:", np.round(np.sort_complex(E), 3))
    sim = sd.Simulator(cart_pole(math.radians(10)), step=2e-3)
    print("   t [s]   pole [deg]   cart [m]")
    while sim.t < 6.0 + 1e-9:
        x = np.array([sim.read(c) for c in CHANNELS])
        if sim.steps % 500 == 0:
            print(f"  {sim.t:6.2f}   {math.degrees(x[1]):10.4f}   {x[0]:8.4f}")
        sim.set_input("joint/cart/actuator", float(-(K @ x)[0]))
        sim.step()


if __name__ == "__main__":
    main()
