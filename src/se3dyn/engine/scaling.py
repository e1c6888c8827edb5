"""Dimensionless unknowns and constraint rows for rank decisions and minimum-norm corrections:
translations divided by the characteristic length L of the model (largest distance of a node from
the centroid of all nodes), rotations in radians; the SVD-based null space and rank cut-off.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule

if TYPE_CHECKING:
    from se3dyn.engine.system import System

sla = LazyModule("scipy.linalg")


_RCOND = 1e-10  # relative singular-value cut-off of the scaled Jacobians (rank decisions)


def _char_length(s: System, H: np.ndarray | None = None) -> float:
    """Characteristic length L: largest distance of a node from the centroid (1 if all coincide)."""
    x = (s.node_H0 if H is None else H)[:, :3, 3]
    if len(x) == 0:
        return 1.0
    L = float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1)))
    return L if L > 0 else 1.0


def _unknown_scale(s: System, L: float) -> np.ndarray:
    """(nq,) scale of each unknown: L for translations, 1 for rotations (and screw motions)."""
    cs = np.ones(s.nq)
    for i in s.node_free:
        d = s.node_dofadr[i]
        cs[d:d + 3] = L
    for g in s.groups:
        if not g.k:
            continue
        trans = np.linalg.norm(g.A[:, 3:, :], axis=1) == 0  # (nj, k): no rotation part
        cs[g.jdof[trans]] = L
    return cs


def _row_scale(s: System, L: float) -> np.ndarray:
    """(nm,) scale of the constraint rows: 1/L for the position rows 0-2 of Eq. (56)."""
    rs = np.ones(s.nm)
    for j in range(s.m):
        a = s.joint_multadr[j]
        rs[a:a + 3] = 1.0 / L
    return rs


def _describe(vec: np.ndarray, labels: tuple[str, ...] | list[str], limit: int = 6) -> str:
    """The labels of the dominant components of a (null) vector, joint coordinates first."""
    a = np.abs(vec)
    if a.size == 0 or a.max() == 0:
        return "(none)"
    big = np.flatnonzero(a >= 0.2 * a.max())
    big = sorted(big, key=lambda i: (not labels[i].startswith("joint"), -a[i]))
    out = [f"{labels[i]} ({vec[i] / vec[big[0]]:+.2g})" for i in big[:limit]]
    more = len(big) - limit
    return ", ".join(out) + (f" and {more} more" if more > 0 else "")


def _svd(A: np.ndarray, full: bool = False):
    """SVD by LAPACK gesvd (gesdd is 40x slower on these small matrices with a threaded BLAS on
    a busy machine: measured 47 ms vs 1.2 ms for 55 x 49)."""
    return sla.svd(A, full_matrices=full, check_finite=False, lapack_driver="gesvd")


def _null_space(Jsc: np.ndarray, rcond: float = _RCOND) -> tuple[int, np.ndarray]:
    """Rank and an orthonormal basis (ncols, nnull) of the null space of a scaled matrix."""
    n = Jsc.shape[1]
    if Jsc.shape[0] == 0 or n == 0:
        return 0, np.eye(n)
    _, sv, Vt = _svd(Jsc, full=True)
    r = int(np.sum(sv > rcond * sv[0])) if sv.size and sv[0] > 0 else 0
    return r, Vt[r:].T
