"""The linear solver of the analyses (statics, assembly, kinematics, rank): the iteration matrix
of an :class:`~se3dyn.engine.evaluate.Evaluation` factorised dense (small systems) or sparse
(scipy's SuperLU), knowing no mechanics.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.engine.evaluate import pattern, pattern_entries
from se3dyn.errors import SimulationError

if TYPE_CHECKING:
    from se3dyn.engine.system import System

sla = LazyModule("scipy.linalg")
sp = LazyModule("scipy.sparse")
spla = LazyModule("scipy.sparse.linalg")


# ---------------------------------------------------------------------------------------------
class LinearSolver:
    """Factorise and solve the iteration matrix in the fixed pattern.

    Dense LU (LAPACK) for N <= ``dense_max``, sparse LU (SuperLU, COLAMD ordering) above. The
    threshold is low on purpose: a multithreaded BLAS on a busy machine makes dense LU of a few
    hundred unknowns 20-30 times slower (measured: 83 ms vs 3 ms for N = 390 on 2 cores).

    Parameters
    ----------
    s : System
    dense_max : int
    index2 : bool
        The stabilized index-2 matrix (size ``nq + 2 nm``) instead of the index-3 one.
    drop : sequence of int
        Constraint equations (indices into the nm multipliers) left out as redundant: their
        rows and columns are replaced by the identity, so their multipliers stay zero.
    """

    def __init__(self, s: System, dense_max: int = 150, *, index2: bool = False,
                 drop=()):
        self.s = s
        self.index2 = index2
        self.N = s.nq + (2 * s.nm if index2 else s.nm)
        self.dense = self.N <= dense_max
        self._lu = None
        self.drop = np.array(sorted(set(np.asarray(drop, dtype=np.int64).tolist())), np.int64)
        self._pat = None  # built on first use: the compiled engine may never need it
        self._dense_key = None

    @property
    def pat(self) -> dict:
        """The (cached) :func:`pattern` of this matrix, with the masks of dropped equations."""
        if self._pat is None:
            self._pat = pattern(self.s, self.index2)
            self._setup_drop()
        return self._pat

    def _setup_drop(self) -> None:
        s, index2 = self.s, self.index2
        self._mask = None
        if self.drop.size:
            nq, nm = s.nq, s.nm
            dropped = np.zeros(self.N, dtype=bool)
            dropped[nq + self.drop] = True
            if index2:
                dropped[nq + nm + self.drop] = True
            _, rows, cols = pattern_entries(s, index2)
            self._mask = ~(dropped[rows] | dropped[cols])
            self._one = (dropped[rows] & (rows == cols)).astype(float)

    def matrix(self, values: np.ndarray):
        """The matrix (dense ndarray or scipy CSC) from the values in pattern order."""
        p = self.pat
        v = np.asarray(values)[:p["nvals"]]
        if self._mask is not None:
            v = np.where(self._mask, v, 0.0) + self._one
        if self.dense:
            if self._dense_key is None:
                _, rows, cols = pattern_entries(self.s, self.index2)
                self._dense_key = rows * self.N + cols
            return np.bincount(self._dense_key, weights=v, minlength=self.N * self.N).reshape(
                self.N, self.N)
        data = np.bincount(p["inv"], weights=v, minlength=p["nnz"])
        return sp.csc_matrix((data, p["indices"], p["indptr"]), shape=(self.N, self.N))

    def factor(self, values: np.ndarray, where: str) -> None:
        A = self.matrix(values)
        try:
            if self.dense:
                with np.errstate(all="ignore"):
                    lu = sla.lu_factor(A, check_finite=True)
                piv = np.abs(np.diag(lu[0]))
                if not np.all(np.isfinite(piv)) or piv.min() <= 1e-14 * max(piv.max(), 1e-300):
                    raise RuntimeError("singular")
                self._lu = lu
            else:
                self._lu = spla.splu(A, permc_spec="COLAMD")
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as exc:
            raise SimulationError(
                f"{where}: the iteration matrix is singular ({exc}); typical causes: redundant "
                "constraints not detected at the start (a mechanism started in a singular "
                "configuration), a free massless node whose motion no joint determines, or a "
                "non-finite state") from None

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if self.dense:
            return sla.lu_solve(self._lu, rhs, check_finite=False)
        return self._lu.solve(rhs)
