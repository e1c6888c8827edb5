"""Kinematic joint types: each is a constant 6 x k matrix A spanning a subalgebra (Table 1, Eq. 9).

A joint type is registered once, under a type key, with the parameters it takes and a function that
returns its matrix A (columns ``(e_U, e_Omega)``, axes in the inertial frame of the initial
configuration, Sec. 5.2). The generic kernel in :mod:`se3dyn.engine.layout` does everything else
(Eqs. (55)-(59)); nothing else needs editing to add a joint.

Built-in types: ``rigid`` (k=0), ``hinge``, ``prismatic``, ``screw`` (k=1), ``cylindrical`` (k=2),
``spherical``, ``planar`` (k=3), ``general`` (user-given A, checked to span a subalgebra), and the
composite ``universal`` (two hinges through an intermediate massless node, expanded by the builder).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from se3dyn.errors import ModelError
from se3dyn.lie import ad6

__all__ = ["JointType", "JOINT_TYPES", "register_joint", "check_subalgebra", "is_abelian"]

_UNIT_TOL = 1e-9


@dataclass(frozen=True)
class JointType:
    """A registered joint type.

    Attributes
    ----------
    key : str
        Type key used by the builder and the model file.
    params : tuple of str
        Keyword parameters it accepts (besides the force elements).
    make_A : callable
        ``make_A(item, **params) -> ndarray (6, k)``.
    doc : str
        One-line description (docs and ``se3dyn check``).
    """

    key: str
    params: tuple[str, ...]
    make_A: Callable[..., np.ndarray]
    doc: str = ""


JOINT_TYPES: dict[str, JointType] = {}

#: the names other tools give the joint types (URDF, MuJoCo, EXUDYN, Chrono, ADAMS), accepted
#: for se3dyn's own (models keep the se3dyn name)
JOINT_SYNONYMS: dict[str, str] = {
    "revolute": "hinge", "pin": "hinge", "continuous": "hinge",
    "slider": "prismatic", "slide": "prismatic", "translational": "prismatic",
    "ball": "spherical", "fixed": "rigid", "weld": "rigid",
    "helical": "screw", "cardan": "universal", "hooke": "universal",
}


def register_joint(key: str, params: tuple[str, ...], doc: str = ""):
    """Decorator registering ``make_A`` under ``key``."""

    def deco(fn):
        JOINT_TYPES[key] = JointType(key, params, fn, doc)
        return fn

    return deco


def unit_vector(v: Any, item: str, fld: str) -> np.ndarray:
    """Validate a unit 3-vector (zero and non-unit vectors are errors naming the item)."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, fld, "a unit 3-vector", v) from None
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ModelError(item, fld, "a unit 3-vector of 3 finite numbers", v)
    if np.any(np.abs(a) > 1e15):
        raise ModelError(item, fld, "a unit 3-vector", v, "normalise it")
    nrm = float(np.linalg.norm(a))
    if nrm == 0.0:
        raise ModelError(item, fld, "a unit 3-vector", v, "the axis has zero length")
    if abs(nrm - 1.0) > _UNIT_TOL:
        raise ModelError(item, fld, "a unit 3-vector", v,
                         f"its length is {nrm:.12g}; normalise it, e.g. "
                         f"({', '.join(f'{c:.12g}' for c in a / nrm)})")
    return a / nrm


def _orthonormal(axes: Any, item: str, fld: str, count: int) -> list[np.ndarray]:
    try:
        arr = np.asarray(axes, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, fld, f"{count} orthonormal unit 3-vectors", axes) from None
    if arr.shape != (count, 3):
        raise ModelError(item, fld, f"{count} orthonormal unit 3-vectors (shape ({count}, 3))",
                         axes)
    vs = [unit_vector(arr[i], item, f"{fld}[{i}]") for i in range(count)]
    G = np.array(vs) @ np.array(vs).T
    if np.abs(G - np.eye(count)).max() > 1e-9:
        raise ModelError(item, fld, f"{count} mutually orthogonal unit vectors", axes)
    return vs


def _z(*cols: np.ndarray) -> np.ndarray:
    return np.stack(cols, axis=1) if cols else np.zeros((6, 0))


def _col(u: np.ndarray | None, w: np.ndarray | None) -> np.ndarray:
    return np.concatenate([np.zeros(3) if u is None else u, np.zeros(3) if w is None else w])


@register_joint("rigid", (), "no relative motion (k = 0)")
def _rigid(item: str) -> np.ndarray:
    return np.zeros((6, 0))


@register_joint("hinge", ("axis",), "rotation about axis a through node B (k = 1)")
def _hinge(item: str, axis: Any = None) -> np.ndarray:
    a = unit_vector(axis, item, "axis")
    return _z(_col(None, a))


@register_joint("prismatic", ("axis",), "translation along axis a (k = 1)")
def _prismatic(item: str, axis: Any = None) -> np.ndarray:
    a = unit_vector(axis, item, "axis")
    return _z(_col(a, None))


@register_joint("cylindrical", ("axis",), "translation along and rotation about a (k = 2)")
def _cylindrical(item: str, axis: Any = None) -> np.ndarray:
    a = unit_vector(axis, item, "axis")
    return _z(_col(a, None), _col(None, a))


@register_joint("screw", ("axis", "pitch"),
                "rotation about a coupled with translation pitch*angle along a (k = 1); "
                "pitch in m/rad")
def _screw(item: str, axis: Any = None, pitch: Any = None) -> np.ndarray:
    a = unit_vector(axis, item, "axis")
    try:
        if isinstance(pitch, bool | str):
            raise TypeError(pitch)
        p = float(pitch)
    except (TypeError, ValueError):
        raise ModelError(item, "pitch", "a finite number (m/rad)", pitch) from None
    if not np.isfinite(p) or abs(p) > 1e15:
        raise ModelError(item, "pitch", "a finite number (m/rad) of magnitude at most 1e15",
                         pitch, "larger values overflow in the computation")
    return _z(_col(p * a, a))


@register_joint("spherical", ("axes",), "rotations about three orthonormal axes (k = 3)")
def _spherical(item: str, axes: Any = None) -> np.ndarray:
    vs = _orthonormal(np.eye(3) if axes is None else axes, item, "axes", 3)
    return _z(*[_col(None, v) for v in vs])


@register_joint("planar", ("normal", "axes"),
                "translations in the plane normal to n and rotation about n (k = 3)")
def _planar(item: str, normal: Any = None, axes: Any = None) -> np.ndarray:
    n = unit_vector(normal, item, "normal")
    if axes is None:
        trial = np.eye(3)[int(np.argmin(np.abs(n)))]
        u = np.cross(n, trial)
        u /= np.linalg.norm(u)
        w = np.cross(n, u)
    else:
        u, w = _orthonormal(axes, item, "axes", 2)
        if abs(u @ n) > 1e-9 or abs(w @ n) > 1e-9:
            raise ModelError(item, "axes", "two in-plane axes orthogonal to the normal", axes)
    return _z(_col(u, None), _col(w, None), _col(None, n))


@register_joint("general", ("A",), "user-given 6 x k matrix A spanning a subalgebra")
def _general(item: str, A: Any = None) -> np.ndarray:
    try:
        arr = np.asarray(A, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, "A", "a 6 x k matrix of numbers", A) from None
    if arr.ndim == 1 and arr.size == 6:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] != 6 or arr.shape[1] > 6 or not np.all(np.isfinite(arr)):
        raise ModelError(item, "A", "a finite 6 x k matrix with k <= 6", A)
    k = arr.shape[1]
    if k and np.linalg.matrix_rank(arr, tol=1e-10 * max(1.0, np.abs(arr).max())) < k:
        raise ModelError(item, "A", "linearly independent columns (full rank)", arr)
    bad = check_subalgebra(arr)
    if bad is not None:
        i, j, resid = bad
        raise ModelError(item, "A", "columns spanning a subalgebra of se(3)", arr,
                         f"the bracket [e{i + 1}, e{j + 1}] leaves the span by {resid:.3g}; "
                         "add that direction or choose other columns")
    return arr


def check_subalgebra(A: np.ndarray, tol: float = 1e-9) -> tuple[int, int, float] | None:
    """Check that the columns of A span a subalgebra: every bracket ``ad6(e_i) e_j`` in span(A).

    Returns ``None`` when closed, else ``(i, j, distance)`` of the first offending pair.
    """
    k = A.shape[1]
    if k == 0:
        return None
    Q, _ = np.linalg.qr(A)
    scale = max(1.0, float(np.abs(A).max(initial=0.0)) ** 2)
    for i in range(k):
        for j in range(i + 1, k):
            b = ad6(A[:, i]) @ A[:, j]
            resid = float(np.linalg.norm(b - Q @ (Q.T @ b)))
            if resid > tol * scale:
                return i, j, resid
    return None


def is_abelian(A: np.ndarray, tol: float = 1e-12) -> bool:
    """True when all brackets of the columns vanish (relative coordinates of Eq. (60) exist)."""
    k = A.shape[1]
    scale = max(1.0, float(np.abs(A).max(initial=0.0)) ** 2)
    return all(np.abs(ad6(A[:, i]) @ A[:, j]).max() <= tol * scale
               for i in range(k) for j in range(i + 1, k))
