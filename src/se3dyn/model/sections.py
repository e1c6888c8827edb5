"""Beam section properties from geometry and material, for :meth:`se3dyn.ModelBuilder.beam`.

Each helper returns the keyword arguments of ``ModelBuilder.beam`` (``EA``, ``GA``, ``GJ``,
``EI``, ``mass_per_length``, ``rotary_inertia``), so a beam reads
``mb.beam("b", "A", "B", elements=8, **sections.circle(0.01, E=210e9, nu=0.3, density=7850))``.

Section axes: axis 1 along the beam, axes 2 and 3 the principal axes of the section
(``EI2`` bends about axis 2, ``GA2`` shears along axis 2). A rectangle has its ``width`` along
axis 2 and its ``height`` along axis 3, so ``I2 = width height^3 / 12``.

Shear correction factors are Cowper's (G. R. Cowper, "The shear coefficient in Timoshenko's
beam theory", J. Appl. Mech. 33 (1966) 335-340): solid circle ``6(1+nu)/(7+6nu)``, rectangle
``10(1+nu)/(12+11nu)``, hollow circle with ``m = r_i/r_o``
``6(1+nu)(1+m^2)^2 / ((7+6nu)(1+m^2)^2 + (20+12nu) m^2)``. The torsion constant of a rectangle
is the series of Saint-Venant's solution (e.g. Timoshenko & Goodier, Theory of Elasticity,
3rd ed., 1970, Sec. 109).
"""

from __future__ import annotations

import math

from se3dyn.errors import ModelError

__all__ = ["circle", "rectangle", "tube"]


def _material(what: str, E, nu, G) -> tuple[float, float, float]:
    for fld, v in (("E", E),):
        if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                and v > 0):
            raise ModelError(what, fld, "a positive Young's modulus (Pa)", v)
    if (nu is None) == (G is None):
        raise ModelError(what, "nu", "exactly one of nu (Poisson's ratio) or G (shear modulus)",
                         (nu, G))
    if G is None:
        if not (isinstance(nu, int | float) and -1 < nu < 0.5):
            raise ModelError(what, "nu", "a Poisson's ratio in (-1, 0.5)", nu)
        G = E / (2 * (1 + nu))
    else:
        if not (isinstance(G, int | float) and math.isfinite(G) and G > 0):
            raise ModelError(what, "G", "a positive shear modulus (Pa)", G)
        nu = E / (2 * G) - 1
    return float(E), float(nu), float(G)


def _positive(what: str, fld: str, v) -> float:
    if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            and v > 0):
        raise ModelError(what, fld, "a positive length (m)", v)
    return float(v)


def _density(what: str, rho) -> float:
    if not (isinstance(rho, int | float) and math.isfinite(rho) and rho >= 0):
        raise ModelError(what, "density", "a non-negative density (kg/m^3)", rho)
    return float(rho)


def _props(E, G, rho, A, k2, k3, J, I2, I3) -> dict:
    return dict(EA=E * A, GA=(k2 * G * A, k3 * G * A), GJ=G * J, EI=(E * I2, E * I3),
                mass_per_length=rho * A, rotary_inertia=(rho * (I2 + I3), rho * I2, rho * I3))


def circle(radius: float, *, E: float, nu: float | None = None, G: float | None = None,
           density: float = 0.0, shear_factor: float | None = None) -> dict:
    """Solid circular section of the given radius (m).

    Returns
    -------
    dict
        ``EA, GA (2,), GJ, EI (2,), mass_per_length, rotary_inertia (3,)`` with
        ``A = pi r^2``, ``I2 = I3 = pi r^4 / 4``, ``J = pi r^4 / 2``.
    """
    what = "section circle"
    r = _positive(what, "radius", radius)
    E, nu, G = _material(what, E, nu, G)
    k = 6 * (1 + nu) / (7 + 6 * nu) if shear_factor is None else float(shear_factor)
    I_ = math.pi * r ** 4 / 4
    return _props(E, G, _density(what, density), math.pi * r * r, k, k, 2 * I_, I_, I_)


def tube(outer_radius: float, inner_radius: float, *, E: float, nu: float | None = None,
         G: float | None = None, density: float = 0.0,
         shear_factor: float | None = None) -> dict:
    """Hollow circular section (radii in m, ``0 < inner < outer``)."""
    what = "section tube"
    ro = _positive(what, "outer_radius", outer_radius)
    ri = _positive(what, "inner_radius", inner_radius)
    if ri >= ro:
        raise ModelError(what, "inner_radius", "a radius below the outer radius", ri)
    E, nu, G = _material(what, E, nu, G)
    m2 = (ri / ro) ** 2
    k = (6 * (1 + nu) * (1 + m2) ** 2 / ((7 + 6 * nu) * (1 + m2) ** 2 + (20 + 12 * nu) * m2)
         if shear_factor is None else float(shear_factor))
    I_ = math.pi * (ro ** 4 - ri ** 4) / 4
    return _props(E, G, _density(what, density), math.pi * (ro * ro - ri * ri), k, k, 2 * I_,
                  I_, I_)


def rectangle(width: float, height: float, *, E: float, nu: float | None = None,
              G: float | None = None, density: float = 0.0,
              shear_factor: float | None = None) -> dict:
    """Solid rectangular section, ``width`` along section axis 2, ``height`` along axis 3.

    ``I2 = width height^3/12`` (bending about axis 2), ``I3 = height width^3/12``; torsion
    constant ``J = a b^3 (1/3 - 64 b/(pi^5 a) sum_{n odd} tanh(n pi a/(2b))/n^5)`` with
    ``a >= b`` the sides (Saint-Venant).
    """
    what = "section rectangle"
    w = _positive(what, "width", width)
    h = _positive(what, "height", height)
    E, nu, G = _material(what, E, nu, G)
    k = 10 * (1 + nu) / (12 + 11 * nu) if shear_factor is None else float(shear_factor)
    a, b = max(w, h), min(w, h)
    s = sum(math.tanh(n * math.pi * a / (2 * b)) / n ** 5 for n in range(1, 40, 2))
    J = a * b ** 3 * (1 / 3 - 64 * b / (math.pi ** 5 * a) * s)
    return _props(E, G, _density(what, density), w * h, k, k, J, w * h ** 3 / 12,
                  h * w ** 3 / 12)
