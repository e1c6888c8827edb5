"""Buckling: the load factor at which the reduced stiffness of a loaded structure loses its
positive definiteness, and the buckled shape (issue 32, item 4).

The loads are the model's (gravity, nodal loads, actuator efforts), multiplied by a load factor
``lambda`` as :func:`~se3dyn.analysis.statics.static_equilibrium` applies them
(``load_factor=``). The stiffness is the tangent of the static equations in minimal
coordinates, ``K(lambda)`` of :func:`~se3dyn.analysis.linearize.linearize` at the equilibrium
under ``lambda`` (element stiffness, the geometric stiffness of the constraint forces
``d(B^T lambda)/dq`` and the load tangents), so every structure se3dyn models buckles by the
same rule: beams, joints with springs, mechanisms held by loads.

Two methods:

* ``"linear"`` (classical, or Euler, buckling): ``K(lambda) ~ K_0 + lambda K_g`` with ``K_0``
  the stiffness of the unloaded equilibrium and the geometric stiffness ``K_g`` the central
  difference ``(K(+d) - K(-d)) / (2 d)`` about it (the stiffness is affine in the stresses of
  the unloaded state, so the difference is exact up to O(d^2) prebuckling terms); the critical
  factors are the positive eigenvalues of ``K_0 phi = -lambda K_g phi``. This is the textbook
  analysis of the closed forms (Euler's columns, Prandtl's and Michell's lateral-torsional
  buckling), which neglect the deformation before buckling.
* ``"nonlinear"``: the load path itself: equilibria at increasing ``lambda`` (from the linear
  estimate on), the smallest eigenvalue of the symmetric part of ``K(lambda)`` bracketed
  through zero and the zero found by the Illinois variant of regula falsi. Prebuckling
  deformation included; a limit point (snap-through) is reported as the last equilibrium
  reached.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla

from se3dyn.analysis.common import _as_system
from se3dyn.analysis.linearize import linearize
from se3dyn.analysis.statics import static_equilibrium
from se3dyn.engine.system import System
from se3dyn.errors import ModelError, SimulationError
from se3dyn.model.specs import Model

_METHODS = ("linear", "nonlinear")


@dataclass(frozen=True)
class Buckling:
    """Critical load factors and buckled shapes.

    Attributes
    ----------
    load_factors : ndarray, shape (k,)
        Critical multiples of the model's loads, increasing.
    shapes : ndarray, shape (n, k)
        Buckled shapes in the minimal coordinates ``names`` (unit length, largest entry
        positive).
    full_shapes : ndarray, shape (nq, k)
        The same shapes as variations of all the model's unknowns (``T @ shapes``; node
        unknowns in the material frames, joint coordinates).
    names : tuple of str
        The minimal coordinates.
    method : str
        ``"linear"`` or ``"nonlinear"``.
    equilibria : tuple of StaticResult
        Linear: the equilibria at ``0, +d, -d``; nonlinear: the path computed.
    reference : StaticResult
        The equilibrium the shapes are variations of: the unloaded one (linear), the one
        nearest the critical load (nonlinear).
    """

    load_factors: np.ndarray
    shapes: np.ndarray
    full_shapes: np.ndarray
    names: tuple[str, ...]
    method: str
    system: System = field(repr=False)
    equilibria: tuple = field(default=(), repr=False)
    reference: Any = field(default=None, repr=False)

    def node_shape(self, mode: int, node: str) -> np.ndarray:
        """The buckled shape's variation of a node, shape (6,): its translation and rotation
        in the inertial frame (``R dU``, ``R dTheta`` with the node's material variations
        ``(dU, dTheta)`` and its rotation ``R`` at :attr:`reference`)."""
        s = self.system
        if node not in s.node_names:
            raise ModelError("Buckling.node_shape", "node", "a node of the model", node)
        if not (isinstance(mode, int | np.integer) and 0 <= mode < len(self.load_factors)):
            raise ModelError("Buckling.node_shape", "mode",
                             f"an index below {len(self.load_factors)}", mode)
        i = s.node_names.index(node)
        d = int(s.node_dofadr[i])
        if d < 0:
            return np.zeros(6)
        R = self.reference.H[i, :3, :3]
        x = self.full_shapes[d:d + 6, mode]
        return np.concatenate([R @ x[:3], R @ x[3:]])

    def __str__(self) -> str:
        rows = [f"  {i + 1}: load factor {f:.8g}" for i, f in enumerate(self.load_factors)]
        return f"Buckling ({self.method}), {len(self.names)} coordinates:\n" + "\n".join(rows)


def buckling(model_or_system: Model | System, *, k: int = 1, method: str = "linear",
             delta: float = 1e-3, load_steps: int = 1, tol: float = 1e-10) -> Buckling:
    """The critical load factors of a structure under the model's loads, and its buckled
    shapes (see the module docstring for the two methods).

    Parameters
    ----------
    model_or_system : Model or System
    k : int
        Number of critical factors (linear method; the nonlinear one finds the first).
    method : {"linear", "nonlinear"}
    delta : float
        Load factor of the central difference of the geometric stiffness (linear), and the
        relative tolerance on the critical factor (nonlinear: ``delta * 1e-6``).
    load_steps, tol :
        Of :func:`se3dyn.static_equilibrium`, for every equilibrium computed.

    Returns
    -------
    Buckling

    Raises
    ------
    ModelError
        Bad arguments.
    SimulationError
        No positive critical factor (the loads stiffen the structure), or the load path ends
        before the stiffness vanishes (a limit point: the message gives the last factor).
    """
    s = _as_system(model_or_system, "buckling")
    _check_args(k, method, delta)
    eq = dict(load_steps=load_steps, tol=tol)
    if method == "linear":
        return _linear(s, int(k), float(delta), eq)
    return _nonlinear(s, float(delta), eq)


def _check_args(k: Any, method: Any, delta: Any) -> None:
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
        raise ModelError("buckling", "k", "a positive integer", k)
    if method not in _METHODS:
        raise ModelError("buckling", "method", " or ".join(map(repr, _METHODS)), method)
    if (isinstance(delta, bool) or not isinstance(delta, int | float)
            or not (0 < delta < 0.5)):
        raise ModelError("buckling", "delta", "a load factor step in (0, 0.5)", delta)


def _stiffness(s: System, lf: float, eq: dict):
    """The equilibrium under ``lf`` times the loads and its reduced stiffness (symmetric
    part) with the linearisation."""
    st = static_equilibrium(s, load_factor=lf, stability=False, **eq)
    lin = linearize(s, at=st)
    return st, lin, 0.5 * (lin.K + lin.K.T)


def _linear(s: System, k: int, d: float, eq: dict) -> Buckling:
    st0, lin, K0 = _stiffness(s, 0.0, eq)
    stp, linp, Kp = _stiffness(s, d, eq)
    stm, linm, Km = _stiffness(s, -d, eq)
    if not (lin.names == linp.names == linm.names):  # pragma: no cover - trees, beams
        raise SimulationError("buckling: the minimal coordinates changed along the load path "
                              f"({lin.names} at 0, {linp.names} at {d})")
    Kg = (Kp - Km) / (2.0 * d)
    w, V = sla.eig(K0, -Kg)
    ok = np.isfinite(w) & (np.abs(w.imag) <= 1e-8 * np.abs(w)) & (w.real > 0)
    if not np.any(ok):
        raise SimulationError("buckling: no positive critical load factor: the loads do not "
                              "soften the structure (K_0 phi = -lambda K_g phi has no positive "
                              "eigenvalue)")
    idx = np.flatnonzero(ok)[np.argsort(w.real[ok])][:k]
    shapes = np.column_stack([_normalised(V[:, i].real) for i in idx])
    return Buckling(load_factors=w.real[idx], shapes=shapes, full_shapes=lin.T @ shapes,
                    names=tuple(lin.names), method="linear", system=s,
                    equilibria=(st0, stp, stm), reference=st0)


def _normalised(x: np.ndarray) -> np.ndarray:
    x = x / np.linalg.norm(x)
    return x if x[np.argmax(np.abs(x))] > 0 else -x


def _nonlinear(s: System, d: float, eq: dict) -> Buckling:
    first = _linear(s, 1, d, eq).load_factors[0]
    path = []

    def wmin(lf: float) -> float:
        st, lin, K = _stiffness(s, lf, eq)
        w, V = np.linalg.eigh(K)
        path.append((lf, st, lin, w[0], V[:, 0]))
        return float(w[0])

    lo, w_lo = 0.0, wmin(0.0)
    hi = 0.9 * first
    w_hi = _guarded(wmin, hi, lo)
    while w_hi > 0:
        lo, w_lo, hi = hi, w_hi, 1.25 * hi
        w_hi = _guarded(wmin, hi, lo)
    lf = _illinois(wmin, lo, w_lo, hi, w_hi, d * 1e-6)
    best = min(path, key=lambda p: abs(p[0] - lf))
    shape = _normalised(best[4])[:, None]
    return Buckling(load_factors=np.array([lf]), shapes=shape, full_shapes=best[2].T @ shape,
                    names=tuple(best[2].names), method="nonlinear", system=s,
                    equilibria=tuple(p[1] for p in path), reference=best[1])


def _guarded(wmin, lf: float, last: float) -> float:
    try:
        return wmin(lf)
    except SimulationError as exc:
        raise SimulationError(f"buckling: the load path ends before the stiffness vanishes "
                              f"(a limit point?): equilibria reached up to load factor "
                              f"{last:.8g}, none at {lf:.8g}: {exc}") from None


def _illinois(f, a: float, fa: float, b: float, fb: float, rtol: float) -> float:
    """The zero of ``f`` between ``a`` and ``b`` (``fa fb < 0``) by the Illinois variant of
    regula falsi: superlinear, and the bracket kept."""
    prev = None
    for _ in range(60):
        c = b - fb * (b - a) / (fb - fa)
        if prev is not None and abs(c - prev) <= rtol * abs(c):
            return c
        fc = f(c)
        if fc == 0.0:
            return c
        if fc * fb < 0:
            a, fa = b, fb
        else:
            fa *= 0.5  # (the end kept twice: halve its value)
        b, fb, prev = c, fc, c
    return b  # pragma: no cover - 60 steps of a superlinear method
