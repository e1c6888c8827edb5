"""Collision shapes, contact materials and the contact pairs they make (issue 33, compliant
contact; the kernel is :mod:`se3dyn.elements.contact`, the laws in docs/contact.md).

Shapes (:class:`CollisionSpec`) sit on nodes: a ``"sphere"`` (``size``: its radius, ``at``:
its centre) or a ``"plane"`` (the half-space below the plane through ``at`` with the outward
unit ``normal``; ``size`` unused), given in the inertial frame of the initial configuration and
moving with their nodes.

A ``"capsule"`` (``size``: its radius, ``length``: its segment's, along ``normal`` through
``at``) touches planes with its two end spheres (the deepest point of a segment below a plane
is an end) and spheres at the closest point of its segment.

**Pair rule** (:func:`contact_pairs`): every sphere touches every plane, sphere and capsule of
another node and every capsule every plane, unless both nodes are fixed, either shape names
the other or its node in its ``exclude``, or a
:meth:`~se3dyn.model.builder.ModelBuilder.contact_pair` disables the pair. Plane-plane pairs do
not exist (a half-space has no extent to touch with), capsule-capsule pairs not yet.

**Material of a pair**: :func:`combine` of the shapes' materials, or of the material given by
``contact_pair(a, b, material=...)`` with itself (both bodies of that material).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from se3dyn.errors import ModelError

#: gravity used to scale the default bristle damping time (m/s^2)
G0 = 9.81
SHAPES = ("sphere", "plane", "capsule")
#: smallest restitution coefficient (c(0.01) = 100: the damping of slower impacts than the
#: touch-down speed would clip the force to zero)
E_MIN = 0.01


def _number(item: str, fld: str, v: Any, *, positive: bool = False, upper: float | None = None,
            allow_none: bool = False) -> float | None:
    if v is None and allow_none:
        return None
    what = "a positive number" if positive else "a non-negative number"
    if upper is not None:
        what += f" <= {upper:g}"
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ModelError(item, fld, what, v) from None
    bad = isinstance(v, bool) or not math.isfinite(x) or x < 0 or (positive and x == 0)
    if bad or (upper is not None and x > upper) or x > 1e15:
        raise ModelError(item, fld, what, v)
    return x


@dataclass(frozen=True)
class ContactMaterial:
    """The contact law's parameters of a shape or a pair (docs/contact.md).

    Parameters
    ----------
    stiffness : float, optional
        Hertz constant ``k`` of ``F_n = k delta^{3/2}`` (N/m^1.5): the pair's when both shapes
        have it (:func:`combine` otherwise).
    young, poisson : float, optional
        Young's modulus (Pa) and Poisson's ratio: ``k = 4/3 E* sqrt(R)`` of Hertz's theory,
        ``1/E* = (1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b``, ``R`` the pair's effective radius.
        One of ``stiffness`` and ``young`` is required (``young=1e9`` when neither).
    restitution : float
        Coefficient of restitution ``e`` in [0.01, 1]: the rebound speed is ``e`` times the impact
        speed, exactly, for any stiffness, mass and impact speed above ``min_impact_speed``.
    friction : float
        Coulomb coefficient ``mu`` >= 0 (stick below ``mu F_n``, slide at it).
    stiction_length : float
        Elastic slip of the bristle at the onset of sliding (m): the tangential stiffness is
        ``mu F_n / stiction_length``. Small against the motion of interest.
    stiction_damping : float, optional
        Damping time ``tau`` of the bristle (s): ``F_t = -k_t (s + tau w_t)`` in stick. By
        default ``2 sqrt(stiction_length / (mu g0))``, critical for a body resting on its
        contacts under g0 = 9.81 m/s^2.
    min_impact_speed : float
        Floor of the impact speed in the damping law (m/s): touch-downs slower than it (a body
        placed on a surface) are damped as if they came at this speed.
    """

    stiffness: float | None = None
    young: float | None = None
    poisson: float = 0.3
    restitution: float = 0.5
    friction: float = 0.5
    stiction_length: float = 1e-5
    stiction_damping: float | None = None
    min_impact_speed: float = 1e-3

    def __post_init__(self):
        item = "ContactMaterial"
        st = object.__setattr__
        st(self, "stiffness", _number(item, "stiffness", self.stiffness, positive=True,
                                      allow_none=True))
        st(self, "young", _number(item, "young", self.young, positive=True, allow_none=True))
        if self.stiffness is None and self.young is None:
            st(self, "young", 1e9)
        st(self, "poisson", _number(item, "poisson", self.poisson, upper=0.5))
        st(self, "restitution", _number(item, "restitution", self.restitution, upper=1.0))
        if self.restitution < E_MIN:
            raise ModelError(item, "restitution", f"a coefficient in [{E_MIN:g}, 1]",
                             self.restitution, "the damping constant c(e) grows as 1/e: "
                             "a perfectly plastic impact needs the rigid contact of a later "
                             "stage")
        st(self, "friction", _number(item, "friction", self.friction))
        st(self, "stiction_length", _number(item, "stiction_length", self.stiction_length,
                                            positive=True))
        st(self, "stiction_damping", _number(item, "stiction_damping", self.stiction_damping,
                                             allow_none=True))
        st(self, "min_impact_speed", _number(item, "min_impact_speed", self.min_impact_speed,
                                             positive=True))

    def as_dict(self) -> dict:
        """The fields (model files)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class CollisionSpec:
    """A collision shape on a node (:meth:`~se3dyn.model.builder.ModelBuilder.collision`).

    Attributes
    ----------
    name, node, shape : str
    size : float
        Radius of a sphere (m); 0 for a plane.
    at : ndarray (3,)
        Centre of a sphere, a point of a plane (inertial frame, initial configuration).
    normal : ndarray (3,)
        Outward unit normal of a plane, unit axis of a capsule (inertial frame, initial
        configuration).
    material : ContactMaterial
    exclude : tuple of str
        Shapes or nodes this shape does not touch.
    """

    name: str
    node: str
    shape: str
    size: float
    at: np.ndarray
    normal: np.ndarray
    material: ContactMaterial = field(default_factory=ContactMaterial)
    exclude: tuple = ()
    #: length of a capsule's segment (m): the capsule is the set of points within ``size`` of
    #: the segment of this length along ``normal`` through ``at``
    length: float = 0.0

    def ends(self) -> tuple:
        """A capsule's two end spheres (as sphere shapes named ``<name>:0``, ``<name>:1``)."""
        half = 0.5 * self.length * self.normal
        return tuple(CollisionSpec(f"{self.name}:{i}", self.node, "sphere", self.size,
                                   self.at + sg * half, self.normal, self.material,
                                   self.exclude) for i, sg in enumerate((-1.0, 1.0)))


@dataclass(frozen=True)
class ContactPairSpec:
    """A pair of shapes given its own material, or disabled (``material`` None)."""

    a: str
    b: str
    material: ContactMaterial | None
    enabled: bool = True


def restitution_constant(e: float) -> float:
    """The constant ``c(e)`` of the dissipation law ``F_n = k delta^{3/2} (1 + c delta'/v_in)``
    (Carvalho & Martins 2019): the root ``c >= 0`` of ``c - ln(1 + c) = -c e - ln(1 - c e)``,
    which makes the rebound speed ``e v_in`` exactly (integrate ``m v dv/(1 + c v/v_in) =
    -k delta^{3/2} d delta`` over loading and unloading). ``c(1) = 0``; ``c(0) = inf``.
    """
    if e >= 1.0:
        return 0.0
    if e <= 0.0:
        return math.inf

    def f(c):
        return c - math.log1p(c) + c * e + math.log1p(-c * e)

    lo, hi = 0.0, 1.0 / e  # f(0+) > 0 (f ~ (1 - e^2) c^2 / 2), f -> -inf as c -> 1/e
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if f(mid) > 0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def combine(a: ContactMaterial, b: ContactMaterial) -> ContactMaterial:
    """The material of a pair of shapes (``a`` and ``b`` may be the same): Hertz's
    ``E* = 1/((1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b)`` of both moduli (as ``young`` with
    ``poisson`` 0); two stiffnesses as the pair's own when equal, as two Hertz springs in series
    sharing the penetration otherwise, ``k = ((k_a^-2/3 + k_b^-2/3) / 2)^-3/2``; a stiffness
    and a modulus: the stiffness; the smaller restitution, the geometric mean of the friction
    coefficients, the larger stiction length and impact-speed floor."""
    ys = [m.young / (1 - m.poisson ** 2) for m in (a, b) if m.stiffness is None]
    ks = [m.stiffness for m in (a, b) if m.stiffness is not None]
    kw = {}
    if len(ks) == 2:
        kw["stiffness"] = ((ks[0] ** (-2 / 3) + ks[1] ** (-2 / 3)) / 2) ** -1.5
    elif ks:
        kw["stiffness"] = ks[0]
    else:  # E* as one modulus with poisson 0
        kw["young"], kw["poisson"] = 1.0 / (1.0 / ys[0] + 1.0 / ys[1]), 0.0
    return ContactMaterial(**kw, restitution=min(a.restitution, b.restitution),
                           friction=math.sqrt(a.friction * b.friction),
                           stiction_length=max(a.stiction_length, b.stiction_length),
                           stiction_damping=_max_none(a.stiction_damping, b.stiction_damping),
                           min_impact_speed=max(a.min_impact_speed, b.min_impact_speed))


def _max_none(x, y):
    vals = [v for v in (x, y) if v is not None]
    return max(vals) if vals else None


@dataclass(frozen=True)
class Pair:
    """A contact pair: shape ``a`` (the plane, or the first sphere) and sphere ``b``, the
    Hertz constant ``k``, the damping constant ``c`` and the rest of the law."""

    a: CollisionSpec
    b: CollisionSpec
    k: float
    c: float
    mu: float
    slen: float
    tau: float
    vmin: float
    e: float = 1.0

    @property
    def name(self) -> str:
        return f"{self.a.name}/{self.b.name}"


def _hertz(m: ContactMaterial, a: CollisionSpec, b: CollisionSpec) -> float:
    if m.stiffness is not None:
        return m.stiffness
    R = b.size if a.shape == "plane" else a.size * b.size / (a.size + b.size)
    # (a sphere on a capsule's cylinder: the sphere's Hertz radius with the cylinder's)
    return 4.0 / 3.0 * m.young / (1 - m.poisson ** 2) * math.sqrt(R)


def pair_of(a: CollisionSpec, b: CollisionSpec, m: ContactMaterial) -> Pair:
    """The pair's law from its material and the shapes' radii."""
    tau = m.stiction_damping
    if tau is None:
        tau = 2.0 * math.sqrt(m.stiction_length / (max(m.friction, 1e-12) * G0))
    return Pair(a, b, _hertz(m, a, b), restitution_constant(m.restitution), m.friction,
                m.stiction_length, tau, m.min_impact_speed, m.restitution)


def contact_pairs(model) -> list[Pair]:
    """The contact pairs of a model by the pair rule of this module, in shape order."""
    shapes = getattr(model, "collisions", ())
    if not shapes:
        return []
    fixed = {n.name: n.fixed for n in model.nodes}
    over = {frozenset((p.a, p.b)): p for p in getattr(model, "contact_pairs", ())}
    out = []
    for i, s1 in enumerate(shapes):
        for s2 in shapes[i + 1:]:
            if s1.node == s2.node or (fixed[s1.node] and fixed[s2.node]):
                continue
            kinds = {s1.shape, s2.shape}
            if kinds in ({"plane"}, {"capsule"}):
                continue
            if {s2.name, s2.node} & set(s1.exclude) or {s1.name, s1.node} & set(s2.exclude):
                continue
            order = {"plane": 0, "capsule": 1, "sphere": 2}
            a, b = (s2, s1) if order[s2.shape] < order[s1.shape] else (s1, s2)
            ov = over.get(frozenset((a.name, b.name)))
            if ov is not None and not ov.enabled:
                continue
            if ov is not None and ov.material is not None:
                mat = combine(ov.material, ov.material)
            else:
                mat = combine(a.material, b.material)
            for bb in (b.ends() if b.shape == "capsule" else (b,)):  # (a plane and a capsule)
                out.append(pair_of(a, bb, mat))
    return out


def describe(model, pairs, show: int = 12) -> list[str]:
    """Lines for ``se3dyn check``: the shapes and the contact pairs with their laws."""
    shapes = model.collisions
    out = [f"collision shapes: {len(shapes)} (" + ", ".join(
        f"{c.name}: {c.shape}" + (f" r={c.size:g}" if c.shape != "plane" else "")
        + (f" L={c.length:g}" if c.shape == "capsule" else "")
        + f" on {c.node}" for c in shapes[:show]) + (", ..." if len(shapes) > show else "")
        + ")"]
    out.append(f"contact pairs: {len(pairs)}" + (" (" + ", ".join(
        f"{p.name}: k={p.k:.3g} N/m^1.5, e={p.e:.3g}, mu={p.mu:g}" for p in pairs[:show])
        + (", ..." if len(pairs) > show else "") + ")" if pairs else
        " (no sphere meets a plane or a sphere of another node: nothing can touch)"))
    return out
