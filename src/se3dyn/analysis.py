"""Structural analysis of a compiled system: mobility and redundant constraints by rank analysis.

The constraint Jacobian at the initial configuration is ``Phi_q = [Ad_{H_J^-1}, -I, A]`` per joint
(Eq. (58)), a ``(6 m) x nq`` matrix. Its numerical rank r (SVD, relative tolerance) gives

* the mobility (degrees of freedom) ``nq - r``;
* the number of redundant constraint equations ``6 m - r``, named by a column-pivoted QR of
  ``Phi_q^T``: the equations left out of the first r pivots depend on the others.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from se3dyn.integrator import step_inputs
from se3dyn.system import LinearSolver, System, evaluate

__all__ = ["RankReport", "rank_analysis", "constraint_jacobian"]

_COMPONENT = ("x-translation", "y-translation", "z-translation", "x-rotation", "y-rotation",
              "z-rotation")


@dataclass(frozen=True)
class RankReport:
    """Outcome of :func:`rank_analysis`.

    Attributes
    ----------
    unknowns, constraints : int
        ``nq`` and ``6 m``.
    rank : int
        Numerical rank of the constraint Jacobian.
    dof : int
        Mobility ``nq - rank``.
    redundant : tuple of str
        Names of redundant constraint equations (``joint 'J' constraint c (component)``).
    singular_values : ndarray
        Singular values of the constraint Jacobian, descending.
    """

    unknowns: int
    constraints: int
    rank: int
    dof: int
    redundant: tuple[str, ...]
    singular_values: np.ndarray


def constraint_jacobian(s: System) -> np.ndarray:
    """Dense constraint Jacobian ``Phi_q`` (6 m, nq) at the initial configuration (Eq. (58))."""
    zero = np.zeros(s.nq)
    ev = evaluate(s, s.node_H0, s.joint_H0, zero, zero, zero, zero, np.zeros(s.nm),
                  step_inputs(s, 0.0), (1.0, 0.0, 0.0))
    A = LinearSolver(s, dense_max=0).matrix(ev.values).tocsr()
    return A[s.nq:, :s.nq].toarray()


def rank_analysis(s: System, rtol: float = 1e-10) -> RankReport:
    """Mobility and redundant constraints of a system at its initial configuration.

    Parameters
    ----------
    s : System
    rtol : float
        Singular values below ``rtol * max(singular value)`` count as zero.

    Returns
    -------
    RankReport
    """
    P = constraint_jacobian(s)
    nm, nq = P.shape
    if nm == 0 or nq == 0:
        return RankReport(nq, nm, 0, nq, (), np.zeros(0))
    sv = np.linalg.svd(P, compute_uv=False)
    r = int(np.sum(sv > rtol * sv[0])) if sv.size and sv[0] > 0 else 0
    redundant: list[str] = []
    if r < nm:
        _, _, piv = sla.qr(P.T, mode="economic", pivoting=True)
        for row in sorted(piv[r:]):
            j, c = divmod(int(row), 6)
            redundant.append(f"joint '{s.joint_names[j]}' constraint {c} ({_COMPONENT[c]})")
    return RankReport(nq, nm, r, nq - r, tuple(redundant), sv)
