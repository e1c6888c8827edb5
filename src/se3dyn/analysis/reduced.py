"""Minimal coordinates of a model at a configuration: the independent unknowns, the velocity map
``T`` and the acceleration term ``Tdot z_dot`` (shared by :mod:`se3dyn.analysis.jointspace` and
:mod:`se3dyn.analysis.linearize`).

The engine's unknowns (Sec. 3.3, Eq. (14)) are the increments of the free nodes (6 each, material
velocities ``(U, Omega)``, Eq. (4)) and of the joint coordinates (k each, Eq. (60)); the joints
impose ``Phi = 0`` (Eq. (55)) whose Jacobian ``B`` (Eq. (58)) gives the velocity constraints
``B v = 0``. The unknowns are split into independent ones ``z`` and dependent ones (coordinate
partitioning): ``B = [B_I, B_D]`` with ``B_D`` of full column rank ``rank B``. Then

    v = T z_dot,   T_I = identity,   T_D = -B_D^+ B_I          (so that B T = 0)
    vd = T z_ddot + w,   w_I = 0,   B_D w_D = arhs(v)

with ``arhs`` the right-hand side of the acceleration-level constraints ``B vd = arhs`` (the
time derivative of ``B v = 0``, exact, from the joint kernel). With redundant constraints the
rows of ``B_D`` are dependent but consistent: ``B_D^+`` is the least-squares inverse, exact.
Couplings (``v_follower = ratio v_leader``) and locked coordinates are rows of ``B`` too
(:class:`Constraints`), their unknowns dependent first.

Choice of the independent unknowns: columns of the scaled ``B`` (translations divided by the
model's length L) taken greedily as dependent, by an orthogonal projection on those already taken
(a QR factorisation whose pivots follow a preference order), in the order: node unknowns of nodes
that are node B of a joint (children), other node unknowns, joint coordinates from the last joint
to the first. On a tree this leaves exactly the joint coordinates and the 6 unknowns of every
floating root node independent; on closed loops, the first joints' coordinates stay independent
and the last ones of each loop become dependent (reported by name).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from se3dyn.analysis.common import _Blocks, _joint_ids
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.scaling import _RCOND, _char_length, _row_scale, _unknown_scale
from se3dyn.errors import ModelError, SimulationError

if TYPE_CHECKING:
    from se3dyn.engine.system import System


__all__ = ["Partition", "ReducedMap", "partition", "reduced_map"]


@dataclass(frozen=True, eq=False)
class Partition:
    """Independent and dependent unknowns of a system.

    Attributes
    ----------
    independent : ndarray (nz,) int   unknown indices of ``z``, increasing
    dependent : ndarray (nd,) int     the others that ``B`` determines (``nd = rank B``)
    names : tuple of str              labels of the independent unknowns (``System.labels``)
    rank : int                        rank of ``B``; ``nm - rank`` equations are redundant
    """

    independent: np.ndarray
    dependent: np.ndarray
    names: tuple[str, ...]
    rank: int


def _preference(s: System, first=()) -> np.ndarray:
    """Unknowns in the order they are taken as dependent (see the module docstring), the
    unknowns ``first`` (couplings' followers, locked coordinates) before all."""
    child = set(int(b) for b in s.joint_b)
    nodes = [int(i) for i in s.node_free]
    order = [i for i in nodes if i in child] + [i for i in nodes if i not in child]
    cols = [int(c) for c in first]
    cols += [int(s.node_dofadr[i]) + c for i in order for c in range(6)]
    for j in range(s.m - 1, -1, -1):
        cols += [int(s.joint_dofadr[j]) + c for c in range(int(s.joint_k[j]))]
    _, idx = np.unique(cols, return_index=True)
    return np.array(cols, dtype=np.int64)[np.sort(idx)]


def _given_independent(s: System, names) -> np.ndarray:
    """Unknown indices of the joints named in ``names`` (all their coordinates)."""
    out = []
    for n in names:
        for j in _joint_ids(s, n, "linearize", "independent"):
            out += [int(s.joint_dofadr[j]) + c for c in range(int(s.joint_k[j]))]
    return np.array(out, dtype=np.int64)


def partition(s: System, B: np.ndarray, independent=None, first=()) -> Partition:
    """Coordinate partitioning of the unknowns by a QR factorisation of the scaled ``B`` with
    pivots in the preference order of :func:`_preference`.

    Parameters
    ----------
    s : System
    B : ndarray (nm, nq)
        Constraint Jacobian at the configuration (Eq. (58)).
    independent : sequence of joint names, optional
        Joints whose coordinates must be independent (their columns are never pivots); refused
        when the others cannot determine the rest.
    first : sequence of int
        Unknowns to take as dependent first (the rows of :class:`Constraints` beyond the
        joints' fix them: couplings' followers, locked coordinates).

    Returns
    -------
    Partition
    """
    L = _char_length(s)
    cs = _unknown_scale(s, L)
    E = np.abs(B[s.nm:]) * cs  # rows beyond the joints': scaled by their largest entry
    rs = np.concatenate([_row_scale(s, L), 1.0 / np.maximum(E.max(axis=1, initial=0.0),
                                                            1e-300)])
    Bs = rs[:, None] * B * cs
    order = _preference(s, first)
    keep = np.zeros(0, np.int64) if independent is None else _given_independent(s, independent)
    order = order[~np.isin(order, keep)]
    tol = _RCOND * max(float(np.abs(Bs).max(initial=0.0)), 1e-300) * max(1, len(B)) ** 0.5
    Q = np.zeros((len(B), 0))
    dep = []
    for c in order:
        x = Bs[:, c].copy()
        for _ in range(2):  # (twice is enough: Kahan-Parlett)
            x -= Q @ (Q.T @ x)
        nx = float(np.linalg.norm(x))
        if nx > tol:
            Q = np.column_stack([Q, x / nx])
            dep.append(int(c))
    rank = len(dep)
    if keep.size and np.linalg.matrix_rank(Bs, tol=tol) > rank:
        raise ModelError("linearize", "independent", "joints whose coordinates may be "
                         "chosen freely", list(independent), "the other unknowns cannot "
                         "satisfy the constraints with these held (choose other joints)")
    dep_a = np.array(sorted(dep), dtype=np.int64)
    ind = np.setdiff1d(np.arange(s.nq), dep_a)
    return Partition(independent=ind, dependent=dep_a,
                     names=tuple(s.labels[i] for i in ind), rank=rank)


@dataclass(eq=False)
class ReducedMap:
    """The minimal-coordinate maps at one configuration.

    Attributes
    ----------
    part : Partition
    B : ndarray (nm, nq)     constraint Jacobian (Eq. (58))
    T : ndarray (nq, nz)     velocities of all unknowns ``v = T z_dot``; ``B T = 0``, identity on
                             the independent rows
    """

    part: Partition
    B: np.ndarray
    T: np.ndarray
    _qr: tuple

    def solve_dependent(self, rhs: np.ndarray) -> np.ndarray:
        """The unknowns ``x`` (nq,) with ``x_I = 0`` and ``B_D x_D = rhs`` (nm,) (least squares,
        exact for a consistent right-hand side)."""
        Q, R = self._qr
        x = np.zeros(self.B.shape[1])
        x[self.part.dependent] = np.linalg.solve(R, Q.T @ rhs)
        return x

    def velocities(self, zd: np.ndarray) -> np.ndarray:
        """Velocities of all unknowns ``T z_dot``, (nq,) from (nz,)."""
        return self.T @ zd

    def full(self, dz: np.ndarray) -> np.ndarray:
        """Increments of all unknowns from increments of the independent ones, to first order
        (the same map as the velocities: ``T dz``)."""
        return self.T @ dz


def reduced_map(s: System, B: np.ndarray, part: Partition,
                cs: np.ndarray | None = None) -> ReducedMap:
    """``T`` of a configuration's ``B`` for a partition (SimulationError when the dependent
    unknowns are no longer determined there: a singular configuration of the partition);
    ``cs``: the unknowns' scales (:func:`se3dyn.engine.scaling._unknown_scale`) if known."""
    D, ind = part.dependent, part.independent
    T = np.zeros((s.nq, len(ind)))
    T[ind, np.arange(len(ind))] = 1.0
    if len(D) == 0:
        return ReducedMap(part=part, B=B, T=T, _qr=(np.zeros((len(B), 0)), np.zeros((0, 0))))
    if cs is None:
        cs = _unknown_scale(s, _char_length(s))
    Q, R = np.linalg.qr(B[:, D] * cs[D])
    d = np.abs(np.diag(R))
    if d.min() <= 1e-10 * d.max():
        raise SimulationError(
            "minimal coordinates: the independent unknowns " + ", ".join(part.names)
            + " no longer determine the others at this configuration (a singular "
            "configuration of the partition); choose other independent joints")
    R = R / cs[D][None, :]  # B_D = Q (R / cs): solves in physical units
    T[D] = -np.linalg.solve(R, Q.T @ B[:, ind])
    return ReducedMap(part=part, B=B, T=T, _qr=(Q, R))


def held_rows(s: System, dofs) -> np.ndarray:
    """Linear velocity constraints beyond the joints', (len(dofs) + ncpl, nq): a row ``e_d``
    per held unknown ``d`` (driven, PID-held or locked coordinates), then a row
    ``e_follower - ratio e_leader`` per coupling (``ModelBuilder.coupling``)."""
    dofs = np.asarray(dofs, np.int64)
    nc = len(s.cpl_follow)
    E = np.zeros((len(dofs) + nc, s.nq))
    E[np.arange(len(dofs)), dofs] = 1.0
    E[len(dofs) + np.arange(nc), s.cpl_follow] = 1.0
    E[len(dofs) + np.arange(nc), s.cpl_lead] = -s.cpl_ratio
    return E


class Constraints:
    """Evaluations of ``B`` and ``arhs`` for one system (one block extractor, zero inputs),
    with rows beyond the joints' (``E``, ne rows, linear and constant): the couplings
    ``v_follower - ratio v_leader = 0`` (``ModelBuilder.coupling``) and, if asked, locked
    coordinates ``v_d = 0`` (drives held at their values)."""

    def __init__(self, s: System, locked=()):
        self.s = s
        self.blocks = _Blocks(s)
        self.zq = np.zeros(s.nq)
        self.lam0 = np.zeros(s.nm)
        self.zin = dict(u=np.zeros(s.inputs.nu))
        self.cs = _unknown_scale(s, _char_length(s))
        self.nlocked = len(locked)
        self.E = held_rows(s, locked)
        #: unknowns the extra rows determine (taken as dependent first)
        self.first = np.concatenate([np.asarray(locked, np.int64), s.cpl_follow]).astype(
            np.int64)

    def rows(self, B: np.ndarray) -> np.ndarray:
        """``[B; E]`` (nm + ne, nq)."""
        return np.vstack([B, self.E]) if len(self.E) else B

    def jacobian(self, H, HJ, alpha) -> np.ndarray:
        """``[B; E]`` at a configuration (frames (M, 4, 4), (m, 4, 4), coordinates (nq,))."""
        z = self.zq
        ev = evaluate(self.s, H, HJ, alpha, z, z, z, self.lam0, self.zin, (0.0, 0.0, 0.0),
                      full_alpha=False)
        return self.rows(self.blocks.split(ev.values)[2])

    def residual(self, ev) -> np.ndarray:
        """The constraints of an evaluation and the extra rows' (the couplings' ``alpha_b -
        ratio alpha_a - offset``; 0 for locked rows), (nm + ne,)."""
        s = self.s
        cpl = ev.alpha[s.cpl_follow] - s.cpl_ratio * ev.alpha[s.cpl_lead] - s.cpl_offset
        return np.concatenate([ev.phi, np.zeros(self.nlocked), cpl])

    def arhs(self, H, HJ, alpha, v: np.ndarray) -> np.ndarray:
        """The acceleration-level right-hand side ``arhs(v)`` (nm + ne,): ``B vd = arhs``
        (zero on the extra rows: they are linear)."""
        z = self.zq
        a = evaluate(self.s, H, HJ, alpha, z, v, z, self.lam0, self.zin, None,
                     full_alpha=False, accel=True).arhs
        return np.concatenate([a, np.zeros(len(self.E))])

    def map_at(self, H, HJ, alpha, part: Partition | None = None,
               independent=None) -> ReducedMap:
        """The :class:`ReducedMap` at a configuration (a partition chosen there if not given)."""
        B = self.jacobian(H, HJ, alpha)
        if part is None:
            part = partition(self.s, B, independent, self.first)
        return reduced_map(self.s, B, part, self.cs)

    def accel_term(self, rm: ReducedMap, H, HJ, alpha, v: np.ndarray) -> np.ndarray:
        """``w = Tdot z_dot`` (nq,): the accelerations of all unknowns when the independent ones
        have none, at velocities ``v = T z_dot`` (nq,)."""
        if not np.any(v):
            return np.zeros(self.s.nq)
        return rm.solve_dependent(self.arhs(H, HJ, alpha, v))
