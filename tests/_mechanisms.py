"""Mechanisms shared by several test files (closed forms in the tests that use them)."""

from __future__ import annotations

import numpy as np

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


#: a delta robot: base and platform radii, arm and forearm lengths, the arms' directions
DELTA = dict(R=0.20, r=0.05, La=0.25, Lb=0.55, phi=np.radians([90.0, 210.0, 330.0]))
_Z = np.array([0.0, 0.0, 1.0])


def _radial(phi):
    return np.array([np.cos(phi), np.sin(phi), 0.0])


def delta_elbow(i: int, th: float) -> np.ndarray:
    """Elbow of arm i turned down by ``th`` about its base axis (tangent to the base circle)."""
    u = _radial(DELTA["phi"][i])
    return DELTA["R"] * u + DELTA["La"] * (np.cos(th) * u - np.sin(th) * _Z)


def delta_platform(th) -> np.ndarray:
    """Closed-form forward kinematics of the delta: the platform centre P (3,) below the base
    with ``|P + r u_i - E_i| = Lb`` for the three arms (intersection of three spheres)."""
    C = [delta_elbow(i, th[i]) - DELTA["r"] * _radial(DELTA["phi"][i]) for i in range(3)]
    d = np.linalg.norm(C[1] - C[0])
    ex = (C[1] - C[0]) / d
    i_ = ex @ (C[2] - C[0])
    ey = C[2] - C[0] - i_ * ex
    ey /= np.linalg.norm(ey)
    j = ey @ (C[2] - C[0])
    x = d / 2
    y = (i_ * i_ + j * j) / (2 * j) - i_ * x / j
    z = np.sqrt(DELTA["Lb"] ** 2 - x * x - y * y)
    base = C[0] + x * ex + y * ey
    return min(base + z * np.cross(ex, ey), base - z * np.cross(ex, ey), key=lambda p: p[2])


def delta_robot(th0=(0.3, 0.3, 0.3)) -> sd.Model:
    """The delta with RUU legs: motor hinges m_i (coordinates absolute, ``th0`` initially),
    forearms on universal joints whose outer axes stay parallel to the motor axes (the
    kinematics of the parallelograms: the platform translates)."""
    P = delta_platform(th0)
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("base", fixed=True)
    mb.node("platform", P, mass=0.3, inertia=(1e-3, 1e-3, 2e-3))
    for i, phi in enumerate(DELTA["phi"]):
        u, t = _radial(phi), np.array([-np.sin(phi), np.cos(phi), 0.0])
        B, E, Q = DELTA["R"] * u, delta_elbow(i, th0[i]), P + DELTA["r"] * u
        mb.node(f"arm{i}", (B + E) / 2, mass=0.1, inertia=(1e-4, 1e-4, 1e-4))
        mb.node(f"rod{i}", (E + Q) / 2, mass=0.05, inertia=(1e-4, 1e-4, 1e-4))
        mb.joint(f"m{i}", "hinge", "base", f"arm{i}", axis=t, at=B, initial=th0[i])
        w = np.cross(t, (Q - E) / np.linalg.norm(Q - E))
        mb.joint(f"e{i}", "universal", f"arm{i}", f"rod{i}", axes=[t, w], at=E)
        mb.joint(f"p{i}", "universal", f"rod{i}", "platform", axes=[w, t], at=Q)
    return mb.build()
