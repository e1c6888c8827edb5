"""Ready-made models built with the public builder.

``slider_crank()`` is the case study of Sec. 11 of the paper, exactly: Tables 2-4, Fig. 2.
``slider_crank_bodies()`` is the same mechanism with one node per body and joints placed by their
attachment points (``at=``), without the auxiliary nodes and rigid joints of the paper.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from se3dyn.model.builder import ModelBuilder
from se3dyn.model.timefunc import Step

if TYPE_CHECKING:
    from se3dyn.model.specs import Model

__all__ = ["slider_crank", "slider_crank_bodies", "SLIDER_CRANK_SETTINGS"]

#: Simulation settings of Sec. 11.2: 5 s, h = 1e-2 s, rho_inf = 0.9.
SLIDER_CRANK_SETTINGS = {"t_end": 5.0, "step": 1e-2, "rho_inf": 0.9}


def slider_crank() -> Model:
    """The spatial slider-crank mechanism of Sec. 11 (Fig. 2).

    Nodes "1".."9" at the positions of Table 2 (3, 6 and 8 at the mass centres of crank, rod and
    slider, with the inertias of Table 3; 1 and 9 clamped); joints "1".."8": hinge (1) between
    1 and 2 about x driven by 0.015 N m during the first 2 s, rigid (2) 2-3, rigid (3) 3-4,
    spherical (4) 4-5, rigid (5) 5-6, rigid (6) 6-7, hinge (7) 7-8 about
    (0, 0.2, -0.1)/sqrt(0.05), cylindrical (8) 8-9 along x with 1 N s/m damping on its
    translation (Table 4). Gravity 9.81 m/s^2 along -z. Sizes: 49 unknowns, 48 multipliers,
    iteration matrix 97 (Sec. 11.1).
    """
    mb = ModelBuilder(gravity=(0.0, 0.0, -9.81), name="slider_crank")
    mb.node("1", position=(0.0, 0.1, 0.12), fixed=True)
    mb.node("2", position=(0.0, 0.1, 0.12))
    mb.node("3", position=(0.0, 0.1, 0.16), mass=0.12, inertia=(1e-4, 1e-4, 1e-5))
    mb.node("4", position=(0.0, 0.1, 0.2))
    mb.node("5", position=(0.0, 0.1, 0.2))
    mb.node("6", position=(0.1, 0.05, 0.1), mass=0.5, inertia=(4e-3, 4e-4, 4e-3))
    mb.node("7", position=(0.2, 0.0, 0.0))
    mb.node("8", position=(0.2, 0.0, 0.0), mass=2.0, inertia=(1e-4, 1e-4, 1e-4))
    mb.node("9", position=(0.2, 0.0, 0.0), fixed=True)
    s = math.sqrt(0.05)
    mb.joint("1", "hinge", "1", "2", axis=(1.0, 0.0, 0.0), torque=Step(0.015, 0.0, 2.0))
    mb.joint("2", "rigid", "2", "3")
    mb.joint("3", "rigid", "3", "4")
    mb.joint("4", "spherical", "4", "5")
    mb.joint("5", "rigid", "5", "6")
    mb.joint("6", "rigid", "6", "7")
    mb.joint("7", "hinge", "7", "8", axis=(0.0, 0.2 / s, -0.1 / s))
    mb.joint("8", "cylindrical", "8", "9", axis=(1.0, 0.0, 0.0), damping=(1.0, 0.0))
    return mb.build()


def slider_crank_bodies() -> Model:
    """The slider-crank of Sec. 11 (Fig. 2) with one node per body and joint offsets.

    The three bodies of the paper, crank "3", rod "6" and slider "8" (nodes at their mass centres,
    positions of Table 2, masses and inertias of Table 3), and the clamped ground nodes "1" and
    "9"; the four joints of Table 4 that are not rigid, with the paper's names, each placed by its
    attachment point (``at=``, inertial frame at t0): hinge "1" ground-crank at (0, 0.1, 0.12)
    about x, driven by 0.015 N m during the first 2 s; spherical "4" crank-rod at (0, 0.1, 0.2);
    hinge "7" rod-slider at (0.2, 0, 0) about (0, 0.2, -0.1)/sqrt(0.05); cylindrical "8"
    slider-ground at (0.2, 0, 0) along x with 1 N s/m damping on its translation. Gravity
    9.81 m/s^2 along -z.

    The rigid joints (2), (3), (5), (6) of the paper and its massless nodes 2, 4, 5, 7 are exact
    constraints, so this model has the same dynamics as :func:`slider_crank` (same positions
    and orientations of nodes 3, 6, 8, same joint coordinates) with 18 + 7 = 25 unknowns and
    24 multipliers instead of 49 and 48.
    """
    mb = ModelBuilder(gravity=(0.0, 0.0, -9.81), name="slider_crank_bodies")
    mb.node("1", position=(0.0, 0.1, 0.12), fixed=True)
    mb.node("3", position=(0.0, 0.1, 0.16), mass=0.12, inertia=(1e-4, 1e-4, 1e-5))
    mb.node("6", position=(0.1, 0.05, 0.1), mass=0.5, inertia=(4e-3, 4e-4, 4e-3))
    mb.node("8", position=(0.2, 0.0, 0.0), mass=2.0, inertia=(1e-4, 1e-4, 1e-4))
    mb.node("9", position=(0.2, 0.0, 0.0), fixed=True)
    s = math.sqrt(0.05)
    mb.joint("1", "hinge", "1", "3", axis=(1.0, 0.0, 0.0), torque=Step(0.015, 0.0, 2.0),
             at=(0.0, 0.1, 0.12))
    mb.joint("4", "spherical", "3", "6", at=(0.0, 0.1, 0.2))
    mb.joint("7", "hinge", "6", "8", axis=(0.0, 0.2 / s, -0.1 / s), at=(0.2, 0.0, 0.0))
    mb.joint("8", "cylindrical", "8", "9", axis=(1.0, 0.0, 0.0), damping=(1.0, 0.0),
             at=(0.2, 0.0, 0.0))
    return mb.build()
