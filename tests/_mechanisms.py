"""Mechanisms shared by several test files (closed forms in the tests that use them)."""

from __future__ import annotations

import se3dyn as sd

#: the parallelogram four-bar: crank and rocker of length a (centres of mass at c, moments J
#: about them, masses m1, m3), coupler of length d (mass mc) translating
FOURBAR = dict(a=0.5, d=0.9, c=0.2, m1=1.2, m3=0.8, mc=2.5, J1=0.03, J3=0.02)


def parallelogram_fourbar(g: float) -> sd.Model:
    """The four-bar of :data:`FOURBAR` hanging in the x-z plane under gravity ``g`` along -z,
    hinges A (ground-crank), B, C, D (rocker-ground) about y: 3 redundant equations."""
    a, d, c = FOURBAR["a"], FOURBAR["d"], FOURBAR["c"]
    J1, J3 = FOURBAR["J1"], FOURBAR["J3"]
    mb = sd.ModelBuilder(gravity=(0, 0, -g))
    mb.node("ground", fixed=True)
    mb.node("crank", position=(0, 0, -c), mass=FOURBAR["m1"], inertia=(J1, J1, J1 * 0.4))
    mb.node("rocker", position=(d, 0, -c), mass=FOURBAR["m3"], inertia=(J3, J3, J3 * 0.4))
    mb.node("coupler", position=(d / 2, 0, -a), mass=FOURBAR["mc"], inertia=(0.01, 0.2, 0.2))
    mb.joint("A", "hinge", "ground", "crank", axis=(0, 1, 0), at=(0, 0, 0))
    mb.joint("B", "hinge", "crank", "coupler", axis=(0, 1, 0), at=(0, 0, -a))
    mb.joint("C", "hinge", "coupler", "rocker", axis=(0, 1, 0), at=(d, 0, -a))
    mb.joint("D", "hinge", "ground", "rocker", axis=(0, 1, 0), at=(d, 0, 0))
    return mb.build()
