"""Structural analysis of a compiled system: mobility and redundant constraints by rank analysis.

The constraint Jacobian at the initial configuration is ``Phi_q = [Ad_{H_J^-1}, -I, A]`` per joint
(Eq. (58); ``[Ad_{H_J^-1} PA, -PB, A]`` for a joint with attachment offsets, ``PA = Ad(X_A^-1)``,
``PB = Ad(X_B^-1)``), a ``(6 m) x nq`` matrix. Its numerical rank r (SVD, relative tolerance) gives

* the mobility (degrees of freedom) ``nq - r``;
* the number of redundant constraint equations ``6 m - r``, named by a column-pivoted QR of
  ``Phi_q^T``: the equations left out of the first r pivots depend on the others.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.linsolve import LinearSolver

if TYPE_CHECKING:
    from se3dyn.engine.system import System

sla = LazyModule("scipy.linalg")


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


def constraint_jacobian(s: System, H: np.ndarray | None = None,
                        HJ: np.ndarray | None = None) -> np.ndarray:
    """Dense constraint Jacobian ``Phi_q`` (6 m, nq) (Eq. (58)) at the configuration (H, HJ),
    by default the initial one."""
    if s.nq == 0 or s.nm == 0:  # nothing to solve, or nothing constrained
        return np.zeros((s.nm, s.nq))
    return _jacobian(s, H, HJ).toarray()


def _jacobian(s: System, H=None, HJ=None):
    H = s.node_H0 if H is None else H
    HJ = s.joint_H0 if HJ is None else HJ
    zero = np.zeros(s.nq)
    ev = evaluate(s, H, HJ, zero, zero, zero, zero, np.zeros(s.nm), step_inputs(s, 0.0),
                  (0.0, 0.0, 0.0))
    A = LinearSolver(s, dense_max=0).matrix(ev.values).tocsr()
    return A[s.nq:, :s.nq]


def _jacobian_rows(s: System, rows: np.ndarray, H=None, HJ=None) -> np.ndarray:
    """Dense rows ``rows`` (into the 6 m constraints) of ``Phi_q`` restricted to the unknowns
    they touch, (len(rows), ncols), from the engine's values (no sparse matrix formed)."""
    H = s.node_H0 if H is None else H
    HJ = s.joint_H0 if HJ is None else HJ
    zero = np.zeros(s.nq)
    ev = evaluate(s, H, HJ, zero, zero, zero, zero, np.zeros(s.nm), step_inputs(s, 0.0),
                  (0.0, 0.0, 0.0))
    from se3dyn.engine.evaluate import pattern_entries

    _, prow, pcol = pattern_entries(s)
    local = -np.ones(s.nq + s.nm, np.int64)
    local[s.nq + rows] = np.arange(len(rows))
    sel = (local[prow] >= 0) & (pcol < s.nq)
    cols, cidx = np.unique(pcol[sel], return_inverse=True)
    P = np.zeros((len(rows), len(cols)))
    np.add.at(P, (local[prow[sel]], cidx), ev.values[sel])
    return P


def _pivoted_qr(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Householder QR with column pivoting (Businger & Golub 1965) of A (m, n) by LAPACK's
    geqp3 (``scipy.linalg.qr``, imported here: only models whose loop equations are not
    proven independent by :func:`_independent_rows` get this far): the column order ``piv``
    (n,) and ``|diag(R)|`` (min(m, n),). (A step-by-step version in numpy took 4-5 s on the
    1218 x 1099 loop Jacobian of the 40-bay four-bar chain, A02; LAPACK 0.1-0.7 s.)"""
    from scipy.linalg import qr

    A = np.asarray(A, dtype=float)
    if A.size == 0:
        return np.arange(A.shape[1]), np.zeros(0)
    R, piv = qr(A, mode="r", pivoting=True, check_finite=False)
    return np.asarray(piv), np.abs(np.diagonal(R)).copy()


def _independent_rows(P: np.ndarray, rtol: float) -> bool:
    """Whether the pivoted QR of ``P^T`` (:func:`_pivoted_qr`) is sure to find all rows of P
    (k, n) independent, i.e. ``|R_jj| > rtol |R_11|`` for every j < k: one singular value
    decomposition instead of k Householder steps in Python. The diagonal of the triangular R
    holds its eigenvalues, whose moduli lie between the extreme singular values of R, which
    are those of P; and ``|R_11|`` (the largest column norm) is at most the largest. So
    ``sigma_min > rtol sigma_max`` suffices, with a margin for the rounding of both
    factorisations (relative errors ~ n eps of sigma_max). Fewer columns than rows or values
    that are not finite: False (the QR decides, as before)."""
    k, n = P.shape
    if k == 0 or n < k or not np.all(np.isfinite(P)):
        return False
    sv = np.linalg.svd(P, compute_uv=False)
    return bool(sv[-1] > (2.0 * rtol + 64.0 * n * np.finfo(float).eps) * sv[0])


def loop_joints(s: System) -> np.ndarray:
    """Indices of the joints that lie on closed loops (the 2-core of the joint graph, clamped
    nodes merged into one ground node). Only these can carry redundant constraints: a joint on
    a tree branch is the only path of its wrench to the rest of the system."""
    node = np.where(s.node_fixed, -1, np.arange(s.M))
    a = node[s.joint_a].tolist()
    b = node[s.joint_b].tolist()
    inc: dict[int, list[int]] = {}
    for j in range(s.m):
        inc.setdefault(a[j], []).append(j)
        inc.setdefault(b[j], []).append(j)
    deg = {v: len(js) for v, js in inc.items()}
    alive = np.ones(s.m, dtype=bool)
    # peel leaves (nodes of degree 1) one at a time: O(m) in all
    queue = [v for v, d in deg.items() if d == 1]
    while queue:
        v = queue.pop()
        if deg[v] != 1:
            continue
        j = next(j for j in inc[v] if alive[j])
        alive[j] = False
        for w in (a[j], b[j]):
            deg[w] -= 1
            if deg[w] == 1:
                queue.append(w)
    return np.flatnonzero(alive)


def redundant_equations(s: System, H: np.ndarray | None = None, HJ: np.ndarray | None = None,
                        rtol: float = 1e-9) -> np.ndarray:
    """Constraint equations (indices into the 6 m multipliers) that depend on the others at the
    configuration (H, HJ), by column-pivoted QR of ``Phi_q^T`` restricted to the joints on closed
    loops (:func:`loop_joints`); empty for tree-structured systems (no Jacobian is formed)."""
    # cached for the initial configuration of the system (keyed by its frames and rtol)
    initial = (rtol, hash(s.node_H0.tobytes()), hash(s.joint_H0.tobytes())) \
        if H is None and HJ is None else None
    if initial and s.pattern.get("redundant0", (None,))[0] == initial:
        return s.pattern["redundant0"][1].copy()
    loops = loop_joints(s)
    if loops.size == 0:
        out = np.zeros(0, dtype=np.int64)
        if initial:
            s.pattern["redundant0"] = (initial, out)
        return out.copy()
    rows = (6 * loops[:, None] + np.arange(6)).ravel()
    P = _jacobian_rows(s, rows, H, HJ)
    if _independent_rows(P, rtol):
        out = np.zeros(0, dtype=np.int64)
    else:
        piv, d = _pivoted_qr(P.T)
        r = int(np.sum(d > rtol * d[0])) if d.size and d[0] > 0 else 0
        out = np.sort(rows[piv[r:]])
    if initial:
        s.pattern["redundant0"] = (initial, out)
    return out.copy()


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
        The redundant equations named are those :func:`redundant_equations` finds, i.e. the
        ones a simulation leaves out (with zero multipliers).
    """
    P = constraint_jacobian(s)
    nm, nq = P.shape
    if nm == 0 or nq == 0:
        return RankReport(nq, nm, 0, nq, (), np.zeros(0))
    sv = np.linalg.svd(P, compute_uv=False)
    r = int(np.sum(sv > rtol * sv[0])) if sv.size and sv[0] > 0 else 0
    redundant = [equation_name(s, int(row)) for row in redundant_equations(s)]
    return RankReport(nq, nm, r, nq - r, tuple(redundant), sv)


def equation_name(s: System, row: int) -> str:
    """``joint 'J' constraint c (component)`` for a multiplier index."""
    j, c = divmod(int(row), 6)
    return f"joint '{s.joint_names[j]}' constraint {c} ({_COMPONENT[c]})"


def massless_message(items: list[str]) -> str:
    """One sentence naming the items of :func:`massless_motions` (at most four) and the cure."""
    return (", ".join(items[:4]) + (f" and {len(items) - 4} more" if len(items) > 4 else "")
            + " can move with no mass and no joint determining the motion (a node meant as "
            "ground needs 'fixed: true'; a massless node needs joints that fix its motion)")


def massless_motions(s: System, rtol: float = 1e-10) -> list[str]:
    """Items (nodes, joint coordinates) that can move with neither inertia nor constraint to
    determine their motion: the iteration matrix ``[M B^T; B 0]`` of the initial accelerations
    (Eqs. (36)-(37)) is then singular and a simulation stops at t0 (a ground node not marked
    fixed, a massless chain left free).

    Parameters
    ----------
    s : System
    rtol : float
        Singular values below ``rtol`` times the largest count as zero.

    Returns
    -------
    list of str
        The items (``node 'name'``, ``joint 'name'``) in the motions found (the null space of
        ``[M; B]``: velocities with no kinetic energy that every joint allows), largest share
        first; empty when there are none.
    """
    from se3dyn.engine.evaluate import evaluate
    from se3dyn.engine.inputs import step_inputs

    nq = s.nq
    if nq == 0:
        return []
    z = np.zeros(nq)
    ev = evaluate(s, s.node_H0, s.joint_H0, z, z, z, z, np.zeros(s.nm), step_inputs(s, 0.0),
                  (1.0, 0.0, 0.0), accel=True)
    from se3dyn.engine.evaluate import pattern_entries

    N, rows, cols = pattern_entries(s, False)
    A = np.zeros((N, N))
    np.add.at(A, (rows, cols), ev.values)
    M, B = A[:nq, :nq], A[nq:, :nq]
    dropped = redundant_equations(s) if s.nm else np.zeros(0, np.int64)
    keep = np.setdiff1d(np.arange(s.nm), dropped)
    S = np.vstack([M, B[keep]])
    _, sv, Vt = np.linalg.svd(S, full_matrices=True)
    top = sv[0] if sv.size and sv[0] > 0 else 1.0
    rank = int(np.sum(sv > rtol * top))
    null = Vt[rank:]
    if not len(null):
        return []
    share = np.sqrt((null ** 2).sum(axis=0))  # (nq,) weight of each unknown in the null space
    order = np.argsort(-share)
    out: list[str] = []
    for q in order:
        if share[q] < 1e-6 * share.max():
            break
        item = s.items[q]
        if item not in out:
            out.append(item)
    return out
