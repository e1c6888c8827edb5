"""Projection of given initial velocities onto the velocity constraints ``B v = 0`` (B: Eq. (58)),
minimum kinetic-energy change in the mass metric, dense or sparse; shared by :func:`se3dyn.simulate`
(initial velocities) and :func:`se3dyn.assemble`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.engine.scaling import _RCOND, _row_scale, _svd, _unknown_scale
from se3dyn.errors import SimulationError

if TYPE_CHECKING:
    from se3dyn.engine.system import System

sla = LazyModule("scipy.linalg")


def _held_rows(s: System, v0: np.ndarray) -> np.ndarray:
    """Rows ``E`` (h, nq) selecting the given parts of ``v0``: per free node with mass, the three
    components of its linear velocity and of its angular velocity where that part is nonzero
    (a zero part counts as not given)."""
    cols = []
    for i in s.node_free:
        if s.node_mass[i] <= 0 and not np.any(s.node_J[i]):
            continue
        d = s.node_dofadr[i]
        for a in (d, d + 3):
            if np.any(v0[a:a + 3] != 0):
                cols += [a, a + 1, a + 2]
    E = np.zeros((len(cols), s.nq))
    E[np.arange(len(cols)), cols] = 1.0
    return E


def project_velocities(s: System, Wm, B, v0: np.ndarray, *, L: float | None = None,
                       dropped=(), prescribed=(), couplings=None) -> tuple[np.ndarray, bool]:
    """Initial velocities satisfying the velocity constraints ``B v = 0``, keeping the given
    speeds.

    ``v = v0 + dv`` with ``dv`` the smallest change in the kinetic-energy norm ``dv^T M dv``
    (Eq. (47)) such that ``B v = 0`` (the time derivative of Eq. (55), B of Eq. (58)) and that
    every node with mass keeps the parts of its velocity that were given: its linear velocity
    if nonzero, its angular velocity if nonzero (a zero part counts as not given). A crank
    given only ``angular_velocity: [0, 0, w]`` keeps ``w`` and gets the linear velocity its
    hinge implies; the other links follow. Consistent velocities are kept exactly. When the
    given parts conflict with the joints (a velocity the joints do not allow, or two links
    given speeds the mechanism cannot have together), they are released and the closest
    consistent velocities in the kinetic-energy norm are taken (``kept`` False).
    Unknowns without mass (massless nodes, joint coordinates) are solved for, minimum norm
    where the joints leave them free (translations scaled by ``L``). Redundant equations
    (``dropped``) are left out: they hold whenever the others do.

    Solved as one sparse saddle-point system first (:func:`_project_sparse`, milliseconds),
    and by rank-revealing dense factorisations (:func:`_project_dense`, up to 3000 unknowns)
    when that does not satisfy the constraints (conflicting given parts, dependent rows):
    the A02 N-four-bar (1099 unknowns) starts in 0.03 s instead of the 5 s of the dense
    solution alone.

    Parameters
    ----------
    s : System
    Wm : ndarray or sparse, shape (nq, nq)
        Mass matrix (material frame, Eq. (47)).
    B : ndarray or sparse, shape (nm, nq)
        Velocity constraint gradient.
    v0 : ndarray, shape (nq,)
        Given velocities (material frame, Eq. (4)); joint coordinates' entries are ignored.
    L : float, optional
        Characteristic length (default ``s.length_scale``).
    dropped : sequence of int
        Redundant constraint equations (indices into the nm rows).
    prescribed : sequence of int
        Unknowns whose given velocities are kept exactly, never released (driven joint
        coordinates, :meth:`se3dyn.ModelBuilder.drive`).
    couplings : (leaders, followers, ratios) arrays, optional
        Velocity constraints ``v_b = ratio v_a`` of coupled coordinates
        (:meth:`se3dyn.ModelBuilder.coupling`), rows added to ``B``.

    Returns
    -------
    v : ndarray, shape (nq,)
    kept : bool
        Whether the given parts were kept.

    Raises
    ------
    SimulationError
        The velocity constraints have no solution (a non-finite matrix).
    """
    import scipy.sparse as sp

    nq, nm = s.nq, s.nm
    L = float(s.length_scale if L is None else L)
    v0 = np.asarray(v0, dtype=float).copy()
    fixed = np.zeros(nq, bool)
    fixed[np.asarray(prescribed, np.int64)] = True
    v0[s.dof_is_joint & ~fixed] = 0.0
    Ep = np.zeros((int(fixed.sum()), nq))
    Ep[np.arange(len(Ep)), np.flatnonzero(fixed)] = 1.0
    E = np.vstack([_held_rows(s, v0), Ep])
    if nm == 0:
        return v0, True
    rows = np.setdiff1d(np.arange(nm), np.asarray(dropped, dtype=np.int64))
    Bs = _row_scale(s, L)[rows, None] * (B[rows].toarray() if sp.issparse(B) else B[rows])
    if couplings is not None and len(couplings[0]):
        a, b, r = (np.asarray(x) for x in couplings)
        C = np.zeros((len(a), nq))
        C[np.arange(len(a)), b] = 1.0
        C[np.arange(len(a)), a] = -r
        Bs = np.vstack([Bs, C])
    if not np.all(np.isfinite(Bs)):
        raise SimulationError("initial velocities: the velocity constraints are not finite")
    # first the whole problem as one sparse solve (milliseconds); the rank-revealing dense
    # solution below when it fails (dependent rows the regularisation does not settle)
    v = _project_sparse(s, Wm, Bs, v0, E)
    if v is not None:
        return v, True
    if nq > 3000:
        v = _project_sparse(s, Wm, Bs, v0, Ep)
        if v is None:
            raise SimulationError("initial velocities: the velocity constraints of the joints "
                                  "have no solution (check 'se3dyn check' for singular "
                                  "configurations)")
        return v, False
    return _project_dense(s, Wm.toarray() if sp.issparse(Wm) else np.asarray(Wm), Bs, v0,
                          E[:len(E) - len(Ep)], L, fixed)


def _project_dense(s: System, Wd: np.ndarray, Bs: np.ndarray, v0: np.ndarray, E: np.ndarray,
                   L: float, fixed: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
    """The problem of :func:`project_velocities` by rank-revealing dense factorisations (SVD of
    the massless columns, least squares on the body velocities in ``M^-1/2`` coordinates), with
    the held parts ``E`` first and without them when they conflict with the joints; the
    ``fixed`` (nq,) unknowns keep their values (no column of theirs is solved for)."""
    import scipy.sparse as sp

    nq = s.nq
    cs = _unknown_scale(s, L)
    # body directions (M^-1/2 of each node's mass block) and massless ones (scaled by cs)
    bi, bj, bv, ui, uj, uv = [], [], [], [], [], []
    nodal = np.zeros(nq, dtype=bool)
    for i in s.node_free:
        idx = s.node_dofadr[i] + np.arange(6)
        nodal[idx] = True
        w, Q = np.linalg.eigh(Wd[np.ix_(idx, idx)])
        pos = w > 1e-12 * max(float(w.max()), 0.0) if w.max() > 0 else np.zeros(6, bool)
        for k in range(6):
            if pos[k]:
                bi += list(idx)
                bj += [len(bj) // 6] * 6
                bv += list(Q[:, k] / np.sqrt(w[k]))
            else:
                ui += list(idx)
                uj += [len(uj) // 6] * 6
                uv += list(Q[:, k] * cs[idx])
    kb, ku0 = len(bj) // 6, len(uj) // 6
    rest = np.flatnonzero(~nodal if fixed is None else ~nodal & ~fixed)
    Tb = sp.csc_matrix((bv, (bi, bj)), shape=(nq, kb))
    Tu = sp.hstack([sp.csc_matrix((uv, (ui, uj)), shape=(nq, ku0)),
                    sp.csc_matrix((cs[rest], (rest, np.arange(len(rest)))),
                                  shape=(nq, len(rest)))]).tocsc()
    Pb = np.asarray((Tb.T @ Bs.T).T)
    Pu = np.asarray((Tu.T @ Bs.T).T)
    r0 = Bs @ v0
    if Pu.shape[1]:
        U, sv, _ = _svd(Pu)
        r = int(np.sum(sv > _RCOND * sv[0])) if sv.size and sv[0] > 0 else 0
        Ur = U[:, :r]
    else:
        Ur = np.zeros((Bs.shape[0], 0))
    C = Pb - Ur @ (Ur.T @ Pb)  # the conditions on the body velocities alone
    c = -(r0 - Ur @ (Ur.T @ r0))
    EB = np.asarray((Tb.T @ E.T).T) if len(E) else np.zeros((0, kb))
    for kept in (True, False):
        A = np.vstack([C, EB]) if kept else C
        rhs = np.concatenate([c, np.zeros(len(EB))]) if kept else c
        z = sla.lstsq(A, rhs, cond=_RCOND, lapack_driver="gelsd")[0] if A.size else np.zeros(kb)
        vb = v0 + Tb @ z
        y = (sla.lstsq(Pu, -(Bs @ vb), cond=_RCOND, lapack_driver="gelsd")[0] if Pu.size
             else np.zeros(0))
        v = vb + Tu @ y
        if not kept or (_solves(Bs, v, np.zeros(Bs.shape[0])) and _solves(E, v, E @ v0)):
            break
    return v, kept


def _solves(A, x: np.ndarray, b: np.ndarray, rtol: float = 1e-9) -> bool:
    """Whether ``A x = b`` holds row by row to ``rtol`` of the row's terms ``|A| |x| + |b|``
    (plus round-off of the largest term: ``1e-3 rtol max|A| max|x|``)."""
    x = np.asarray(x)
    if not np.all(np.isfinite(x)):
        return False
    if A.shape[0] == 0:
        return True
    aA = abs(A)
    floor = 1e-3 * rtol * (float(aA.max()) * float(np.abs(x).max(initial=0.0))
                           + float(np.abs(b).max(initial=0.0)))
    return bool(np.all(np.abs(A @ x - b) <= rtol * (aA @ np.abs(x) + np.abs(b)) + floor))


def _project_sparse(s: System, Wm, Bs: np.ndarray, v0: np.ndarray, E: np.ndarray
                    ) -> np.ndarray | None:
    """The problem of :func:`project_velocities` as one sparse saddle point system
    ``[[W, G^T], [G, -d I]]`` with ``G = [B; E]`` (W: M plus 1e-12 of its largest entry on the
    diagonal, so massless unknowns take the smallest change; ``d`` a relative 1e-13 that makes
    dependent rows of G, e.g. a held part that a joint already fixes, harmless), by SuperLU.
    Returns the velocities when they satisfy ``G v = g`` row by row, else None."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    nq = s.nq
    Wm = sp.csc_matrix(Wm)
    wmax = max(float(np.abs(Wm.diagonal()).max(initial=0.0)), 1e-300)
    W = (Wm + 1e-12 * wmax * sp.identity(nq)).tocsc()
    G = sp.vstack([sp.csr_matrix(Bs), sp.csr_matrix(E)]).tocsr()
    g = np.concatenate([np.zeros(Bs.shape[0]), E @ v0])
    d = 1e-13 * max(float(abs(G).max()) if G.nnz else 0.0, 1e-300) ** 2 / wmax
    K = sp.bmat([[W, G.T], [G, -d * sp.identity(G.shape[0])]], format="csc")
    try:
        sol = spla.splu(K).solve(np.concatenate([W @ v0, g]))
    except RuntimeError:  # exactly singular
        return None
    v = np.asarray(sol[:nq])
    return v if _solves(G, v, g) else None
