"""O(N) sparse direct solver for the iteration matrices of se3dyn: block LU on supernodes.

The iteration matrices (index 3 and stabilized index 2, see :mod:`se3dyn.system`) are
saddle-point matrices with a zero diagonal in the multiplier blocks, so a scalar LU without
pivoting fails. They have, however, a natural block structure. Supernodes are

* every free node: its 6 unknowns (kind 0 when it has a nonsingular mass matrix, kind 1 when
  it is massless: its diagonal block may be zero until a neighbour has been eliminated);
* every joint: its k relative increments, its 6 multipliers and, for index 2, its 6 velocity
  multipliers xi (kind 2: the diagonal block is singular until a neighbouring node has been
  eliminated).

The block graph has node-joint edges where a joint attaches to a free node, and, for index 2,
joint-joint edges between joints sharing a free node. The elimination order is a greedy minimum
degree restricted by mechanical eligibility rules (see :func:`symbolic`): a block pivot is the
Schur complement of the supernodes eliminated before it, which is nonsingular only when those
form sub-assemblies with independent constraints and mass on every free motion (with the nodes
not yet eliminated held fixed). On trees whose leaves are bodies with mass the order creates no
fill; with massless nodes (joint points rigidly attached to bodies) or closed loops it creates a
bounded fill per body, so factorisation and solution cost O(N) for chains and trees.

Two phases:

1. :func:`symbolic` (plain Python/numpy, once per system and pattern): elimination order, fill
   pattern at block level, flat dense storage of every stored block, the map of the pattern
   values to their storage slot and the index lists of the Schur updates. :func:`from_system`
   builds the supernodes from a compiled :class:`~se3dyn.system.System`.
2. :func:`factor` and :func:`solve` (``numba.njit(cache=True)``, arrays and scalars only, no
   allocation): right-looking block elimination with dense LU and partial pivoting inside each
   diagonal block, then forward/backward substitution. They can be called from other njit code.

Calling convention of the njit kernels (``bl`` a :class:`BlockLU`)::

    code = factor(bl.sym, bl.vmask, bl.vone, values, bl.store, bl.piv)   # 0 = success
    solve(bl.sym, bl.store, bl.piv, b, x, bl.work)                      # x = A^-1 b
    matvec(bl.rows, bl.cols, bl.vmask, bl.vone, values, x, y)          # y = A x

``bl.sym`` is a tuple of 11 C-contiguous int64 arrays (see :class:`BlockLU` for the fields).
The Python methods ``bl.factor(values) -> bool`` and ``bl.solve(rhs) -> x`` wrap them.

Only block pivoting inside the diagonal blocks is done (no pivoting across supernodes): the
elimination order is chosen so that every diagonal block is nonsingular for the matrices of
se3dyn; a tiny or non-finite pivot is reported by :func:`factor` (return code p + 1) so the
caller can fall back to a general sparse LU.
"""

from __future__ import annotations

import heapq

import numba
import numpy as np

__all__ = ["BlockLU", "symbolic", "from_system", "supernodes", "factor", "solve", "matvec",
           "SYM_FIELDS", "PIVOT_RTOL"]

#: Relative pivot threshold: a pivot ``|u_ii| <= PIVOT_RTOL * max|D_p|`` fails the factorisation.
PIVOT_RTOL = 1e-14

#: Simpliciality (no fill on elimination) is only tested for supernodes of lower degree.
_SIMPLICIAL_MAX = 16

#: Names of the arrays in ``BlockLU.sym``, in order (all int64, C-contiguous).
SYM_FIELDS = ("bn", "bptr", "uidx", "dg", "nbptr", "nbsn", "nbup", "nblo", "updptr", "updoff",
              "slot")


# ---------------------------------------------------------------------------------------------
class BlockLU:
    """Symbolic block factorisation and the work arrays of the numeric phase.

    Built by :func:`symbolic` or :func:`from_system`; the numeric phase is :meth:`factor` /
    :meth:`solve` or, from njit code, the module functions :func:`factor` / :func:`solve`.

    Elimination proceeds by *steps*: step p eliminates one supernode, or a compound of
    several (a massless node with the joints pinning it, where no single supernode is a
    nonsingular pivot; see :func:`symbolic`). Unknowns are renumbered by step, and inside a
    step by increasing original index ("positions"). ``nstep <= nsn``.

    Attributes
    ----------
    N : int
        Matrix size.
    nsn : int
        Number of supernodes (as given to :func:`symbolic`).
    nstep : int
        Number of elimination steps (pivot blocks).
    order : ndarray (nsn,) int64
        Supernodes in elimination order (the members of a compound step consecutive).
    step : ndarray (nsn,) int64
        Step of each supernode.
    kind : ndarray (nsn,) int64
        Kind of each supernode: 0 node with mass, 1 node without mass, 2 joint.
    sym : tuple of 11 ndarray int64
        The symbolic arrays of the numeric kernels, fields :data:`SYM_FIELDS`:

        ``bn`` (nstep,)
            Size n_p of the pivot block of step p.
        ``bptr`` (nstep + 1,)
            First position of step p; positions of step p are ``bptr[p]:bptr[p+1]``.
        ``uidx`` (N,)
            Original unknown at each position.
        ``dg`` (nstep,)
            Offset in ``store`` of the diagonal block of step p (n_p x n_p, row-major).
        ``nbptr`` (nstep + 1,)
            Later neighbours of step p are entries ``nbptr[p]:nbptr[p+1]`` of the next three.
        ``nbsn`` (nnb,)
            Step r of each later neighbour (r > p, increasing).
        ``nbup`` (nnb,)
            Offset of the block (p, r) (n_p x n_r): A_pr, overwritten by W_pr = D_p^-1 A_pr.
        ``nblo`` (nnb,)
            Offset of the block (r, p) (n_r x n_p): A_rp at step p (the block L factor).
        ``updptr`` (nstep + 1,)
            Schur updates of step p are entries ``updptr[p]:updptr[p+1]`` of ``updoff``,
            ``nnb_p**2`` of them, row-major over (q, r) in the later neighbours of p.
        ``updoff`` (nupd,)
            Offset of the block (q, r) updated by ``A_qr -= A_qp W_pr``.
        ``slot`` (nvals,)
            Storage offset of each pattern value (duplicates share a slot and are summed;
            -1 = value ignored).
    store : ndarray (nstore,) float64
        Flat storage of all stored blocks; holds the factors after :meth:`factor`.
    piv : ndarray (N,) int64
        Local row pivots of the diagonal blocks (LAPACK-like sequential swaps), by position.
    work : ndarray (N,) float64
        Work vector of :func:`solve`.
    vmask, vone : ndarray (nvals,) float64, or (0,)
        Dropped-equation masking: the value used is ``(values if vmask != 0 else 0) + vone``.
        Empty arrays: no masking.
    nvals : int
        Length of the value vectors accepted (= ``len(sym.slot)``).
    nblocks : int
        Stored blocks (diagonal + off-diagonal, after fill), at the level of the steps.
    nblocks_struct : int
        Blocks of the structural pattern at the level of the steps (symmetrised, diagonal
        included); ``nfill = nblocks - nblocks_struct``.
    info : int
        Return code of the last :meth:`factor` (0 success, p + 1 failed at step p, -1 never
        factored); :meth:`failed` names the supernodes.
    rows, cols : ndarray (nvals,) int32
        Row and column of each value (-1: ignored), for :func:`matvec`.
    drop : ndarray (nr,) int64
        Dropped constraint equations (:func:`from_system`; empty otherwise).
    index2 : bool or None
        Pattern of :func:`from_system` (None for :func:`symbolic`).
    """

    def __init__(self, N, nsn, order, step, kind, sym, nstore, nblocks, nblocks_struct,
                 rows, cols):
        self.N = int(N)
        self.nsn = int(nsn)
        self.nstep = len(sym[0])
        self.order = order
        self.step = step
        self.kind = kind
        self.sym = sym
        self.store = np.zeros(nstore)
        self.piv = np.zeros(self.N, np.int64)
        self.work = np.zeros(self.N)
        self.vmask = np.zeros(0)
        self.vone = np.zeros(0)
        self.drop = np.zeros(0, np.int64)
        self.index2 = None
        self.nblocks = int(nblocks)
        self.nblocks_struct = int(nblocks_struct)
        self.rows = rows
        self.cols = cols
        self.info = -1
        self._values = None
        self._r = np.zeros(self.N)
        self._dx = np.zeros(self.N)

    @property
    def nvals(self) -> int:
        return len(self.sym[10])

    def failed(self) -> np.ndarray:
        """Supernodes of the step whose pivot failed in the last :meth:`factor` (empty if
        none)."""
        if self.info <= 0:
            return np.zeros(0, np.int64)
        return np.flatnonzero(self.step == self.info - 1)

    @property
    def nfill(self) -> int:
        """Number of fill blocks (stored blocks not in the structural pattern)."""
        return self.nblocks - self.nblocks_struct

    def factor(self, values: np.ndarray) -> bool:
        """Assemble and factorise the matrix with the given pattern values.

        Parameters
        ----------
        values : ndarray (nvals,)
            Values in pattern order (for :func:`from_system`: the raw output of
            :func:`se3dyn.system.matrix_values`).

        Returns
        -------
        bool
            True on success; False when a pivot block was singular (``self.info`` = step + 1;
            :meth:`failed` gives its supernodes).
        """
        values = np.ascontiguousarray(values, dtype=np.float64)
        if values.shape != (self.nvals,):
            raise ValueError(f"values: expected shape ({self.nvals},), got {values.shape}")
        self.info = int(factor(self.sym, self.vmask, self.vone, values, self.store, self.piv))
        self._values = values.copy() if self.info == 0 else None
        return self.info == 0

    def solve(self, rhs: np.ndarray, refine: int = 0) -> np.ndarray:
        """Solve with the last successful factorisation.

        Parameters
        ----------
        rhs : ndarray (N,)
        refine : int
            Steps of iterative refinement (``x += A^-1 (b - A x)`` with the values of the last
            :meth:`factor`). Block pivoting restricted to the diagonal blocks may lose a few
            digits to element growth on badly scaled matrices (backward errors up to ~1e-12 instead
            of ~1e-16); one step restores the backward stability of a pivoted LU.

        Returns
        -------
        ndarray (N,)
        """
        if self.info != 0:
            raise RuntimeError("BlockLU.solve: no successful factorisation")
        b = np.ascontiguousarray(rhs, dtype=np.float64)
        if b.shape != (self.N,):
            raise ValueError(f"rhs: expected shape ({self.N},), got {b.shape}")
        x = np.empty(self.N)
        solve(self.sym, self.store, self.piv, b, x, self.work)
        for _ in range(int(refine)):
            matvec(self.rows, self.cols, self.vmask, self.vone, self._values, x, self._r)
            np.subtract(b, self._r, out=self._r)
            solve(self.sym, self.store, self.piv, self._r, self._dx, self.work)
            x += self._dx
        return x

    def __repr__(self) -> str:
        return (f"BlockLU(N={self.N}, supernodes={self.nsn}, steps={self.nstep}, "
                f"blocks={self.nblocks}, "
                f"fill={self.nfill}, store={len(self.store)})")


# ---------------------------------------------------------------------------------------------
def _order(adj: list[set], kind: np.ndarray, jk: np.ndarray | None
           ) -> tuple[list[list[int]], list[list[int]]]:
    """Greedy minimum degree on the supernode graph with the eligibility tiers of
    :func:`symbolic`. ``adj`` (consumed) is the symmetric block graph without self loops.

    Returns the supernodes eliminated at each step (one, or a compound: a massless node and
    joints) and the later neighbours of each step (supernodes, the numbering of ``adj``)."""
    nsn = len(adj)
    kind_l = kind.tolist()
    is_node = [k != 2 for k in kind_l]
    pref = [0 if k == 0 else 1 for k in kind_l]
    jk_l = None if jk is None else jk.tolist()
    # mechanical structure: node-joint edges of the original graph
    sides = [sorted(u for u in adj[v] if is_node[u]) if kind_l[v] == 2 else [] for v in range(nsn)]
    njoints = [[u for u in adj[v] if kind_l[u] == 2] if is_node[v] else [] for v in range(nsn)]
    nground = [max(0, 2 - len(sides[v])) if kind_l[v] == 2 else 0 for v in range(nsn)]
    # sub-mechanisms: connected components over node-joint edges
    sub = [-1] * nsn
    remaining = []  # nodes not yet eliminated, per sub-mechanism
    gjoints: list[list[int]] = []  # joints with a clamped side, per sub-mechanism
    for v0 in range(nsn):
        if sub[v0] >= 0:
            continue
        c = len(remaining)
        sub[v0] = c
        stack = [v0]
        nn = 0
        gj = []
        while stack:
            v = stack.pop()
            if is_node[v]:
                nn += 1
                nxt = njoints[v]
            else:
                nxt = sides[v]
                if nground[v] and sides[v]:
                    gj.append(v)
            for u in nxt:
                if sub[u] < 0:
                    sub[u] = c
                    stack.append(u)
        remaining.append(nn)
        gjoints.append(gj)

    elim = [False] * nsn
    uf = list(range(nsn))
    npins = [0] * nsn  # per component root: eliminated joint sides outside the component
    dof = [0] * nsn  # per component root: 6 per node + k per joint - 6 per joint
    pinned = [0] * nsn  # without jk: number of eliminated joints at a massless node
    ver = [0] * nsn

    def find(v):
        r = v
        while uf[r] != r:
            r = uf[r]
        while uf[v] != r:
            uf[v], v = r, uf[v]
        return r

    def contrib(j, u, depth, seen):
        """How many of the 6 motions of node u the eliminated joint j at u ties to mass or to
        nodes held fixed (clamped, or not yet eliminated): 6 - k through a clamped or not
        eliminated side, ``rank - k`` through an eliminated node of mass rank ``rank``."""
        kj = jk_l[j]
        c = 6 - kj if nground[j] else 0
        for w in sides[j]:
            if w != u:
                c = max(c, 6 - kj if not elim[w] else rank(w, j, depth + 1, seen) - kj)
        return max(c, 0)

    def rank(u, via, depth, seen):
        """Mass rank of node u (0..6): how many of its motions move mass, through the
        eliminated joints at u other than ``via`` (generic count, capped at 6)."""
        if kind_l[u] == 0:
            return 6
        if u in seen or depth > 64:
            return 0
        seen.add(u)
        tot = 0
        for j in njoints[u]:
            if j != via and elim[j]:
                tot += contrib(j, u, depth, seen)
                if tot >= 6:
                    return 6
        return tot

    def tier(v):
        k = kind_l[v]
        if k == 0:
            return 0
        if k == 1:
            if jk_l is None:
                return 0 if pinned[v] >= 1 else 2
            return 0 if rank(v, -1, 0, set()) >= 6 else 2
        sd = sides[v]
        if not sd:
            return 0
        if nground[v] and remaining[sub[v]] > 0:
            return 2  # a clamped joint grounds its component for good: only at the end
        roots = [find(u) for u in sd if elim[u]]
        if not roots:
            return 2
        nout = len(sd) - len(roots)
        floating = any(npins[r] == 0 for r in roots)
        distinct = len(set(roots)) == len(roots)
        if nout == 0 and not nground[v] and not distinct:
            return 1  # closes a loop inside one component
        if floating and distinct:
            return 0
        if nout:
            return 2
        if distinct and jk_l is not None and sum(dof[r] for r in roots) + jk_l[v] < 6:
            return 2  # joins pinned components with too few free motions: singular
        return 1

    def nonsimplicial(v):
        """0 when the neighbours of v form a clique (eliminating v creates no fill)."""
        nb = adj[v]
        if len(nb) > _SIMPLICIAL_MAX:
            return 1
        lst = list(nb)
        for i, u in enumerate(lst):
            au = adj[u]
            for w in lst[i + 1:]:
                if w not in au:
                    return 1
        return 0

    def key(v, version):
        return (tier(v), nonsimplicial(v), len(adj[v]), pref[v], v, version)

    def compound(v):
        """Joints to eliminate together with the massless node v so that it is pinned (and not
        over-constrained): a list, or None."""
        if kind_l[v] != 1 or jk_l is None:
            return None
        need = 6 - rank(v, -1, 0, set())
        tot = 0
        chosen = []
        for kj, _d, j in sorted((jk_l[j], len(adj[j]), j) for j in njoints[v] if not elim[j]):
            if tot >= need:
                break
            if tot + 6 - kj <= 6:
                chosen.append(j)
                tot += 6 - kj
        return chosen if chosen and tot >= need else None

    def pop_valid():
        while heap:
            top = heapq.heappop(heap)
            v, ver_v = top[4], top[5]
            if elim[v] or ver_v != ver[v]:
                continue
            now = key(v, ver_v)
            if now > top:  # got worse since pushed (improvements are pushed when they occur)
                heapq.heappush(heap, now)
                continue
            return now
        return None

    def eliminate_node(v):
        js = [j for j in njoints[v] if elim[j]]
        roots = {find(j) for j in js}
        pins = sum(npins[r] for r in roots) - len(js)
        dof[v] = sum(dof[r] for r in roots) + 6
        for r in roots:
            uf[r] = v
        npins[v] = pins
        elim[v] = True
        remaining[sub[v]] -= 1
        if remaining[sub[v]] == 0:
            for j in gjoints[sub[v]]:
                if not elim[j]:
                    ver[j] += 1
                    heapq.heappush(heap, key(j, ver[j]))

    def eliminate_joint(v):
        roots = {find(u) for u in sides[v] if elim[u]}
        out = [u for u in sides[v] if not elim[u]]
        pins = sum(npins[r] for r in roots) + len(out) + nground[v]
        dof[v] = sum(dof[r] for r in roots) + (jk_l[v] if jk_l is not None else 0) - 6
        for r in roots:
            uf[r] = v
        npins[v] = pins
        elim[v] = True
        for u in out:
            pinned[u] += 1

    heap = [key(v, 0) for v in range(nsn)]
    heapq.heapify(heap)
    groups: list[list[int]] = []
    later: list[list[int]] = []
    left = nsn
    while left:
        top = pop_valid()
        group = [top[4]]
        if top[0] == 2:
            # nothing safe is left: a massless node with the joints that pin it is a valid
            # compound pivot where no single supernode is (e.g. a massless link whose rotation
            # only a joint to the ground determines)
            popped = [top]
            while len(popped) < 64:
                t = pop_valid()
                if t is None:
                    break
                popped.append(t)
            for t in popped:
                js = compound(t[4])
                if js is not None:
                    group = [t[4], *js]
                    break
            for t in popped:
                if t[4] != group[0]:
                    heapq.heappush(heap, t)
        # --- mechanical bookkeeping (the node of a compound first)
        for v in group:
            if is_node[v]:
                eliminate_node(v)
            else:
                eliminate_joint(v)
        left -= len(group)
        # --- elimination graph: the neighbours of the group become a clique
        gset = set(group)
        nb = set()
        for v in group:
            nb |= adj[v]
        nb -= gset
        groups.append(group)
        later.append(sorted(nb))
        for u in nb:
            au = adj[u]
            au -= gset
            au |= nb
            au.discard(u)
        for v in group:
            adj[v] = set()
        for u in nb:
            ver[u] += 1
            heapq.heappush(heap, key(u, ver[u]))
    return groups, later


_CHUNK = 1 << 18  # values per chunk in the vectorised parts of symbolic()


def symbolic(N: int, rows: np.ndarray, cols: np.ndarray, sn: np.ndarray,
             kind: np.ndarray, jk: np.ndarray | None = None) -> BlockLU:
    """Symbolic phase: elimination order, block fill, storage layout and update lists.

    Elimination order: greedy minimum degree on the supernode graph (degrees updated with the
    fill) among the supernodes of the best eligibility tier, those whose elimination creates no
    fill (simplicial: their neighbours form a clique; tested up to degree 16) first; ties:
    kind 0 first, then lowest index. Tiers (0 best) follow the mechanics, so that every
    diagonal block is nonsingular: a block pivot is the Schur complement of the eliminated
    set, which is nonsingular when the eliminated sub-assemblies, with the not yet eliminated
    nodes held fixed, have independent constraints and mass on every free motion (generic
    counts: special geometry is caught by the pivot test of :func:`factor`, redundant loop
    equations must be dropped). "Components" are the connected sets of
    eliminated supernodes over node-joint edges; a component is *floating* when none of its
    eliminated joints attaches it to a clamped node or to a node not yet eliminated.

    * kind 0 (node with mass): tier 0.
    * kind 1 (node without mass): tier 0 once its motions all move mass or are held:
      its *mass rank* ``sum_j c_j >= 6`` over the eliminated joints j at it, with
      ``c_j = 6 - k_j`` when the other side of j is clamped or not yet eliminated and
      ``c_j = rank - k_j`` through an eliminated node of mass rank ``rank`` (6 for a node
      with mass; computed recursively away from j); without ``jk``: one eliminated joint at
      it. Else tier 2.
    * kind 2 (joint; its sides are its node neighbours, 2 minus their number are clamped):
      tier 0 when a side belongs to a floating component (and, for a joint with a clamped
      side, when all nodes of its sub-mechanism are eliminated: grounding comes last); tier 1
      when it closes a loop (all free sides eliminated, in one component, or joining pinned
      components whose free motions, ``6 per node + k per joint - 6 per joint``, plus its k
      are at least 6); tier 2 otherwise.

    When only tier 2 is left, a massless node is eliminated together with the fewest joints
    at it that complete its mass rank to 6 (their ``sum(6 - k) <= 6``, so as not to
    over-constrain it) as one compound pivot, e.g. a massless link whose rotation only a
    joint to the ground determines (a massless rod between a hinge and a point mass);
    without such a compound the best tier-2 supernode alone (its pivot may then be singular
    and :func:`factor` report it). On a tree whose leaves are nodes with mass this eliminates
    from the leaves (body, joint to its parent, parent body, ...) without fill.

    Parameters
    ----------
    N : int
        Matrix size.
    rows, cols : ndarray (nvals,) int
        Row and column of each pattern value (entries with a negative row or column are
        ignored: their slot is -1). Duplicates are allowed (summed on assembly).
    sn : ndarray (N,) int
        Supernode of each unknown, in ``0..nsn-1``; every supernode must own an unknown.
    kind : ndarray (nsn,) int
        0 node with mass, 1 node without mass, 2 joint.
    jk : ndarray (nsn,) int, optional
        Number k of relative coordinates of each joint supernode (entries of nodes ignored).

    Returns
    -------
    BlockLU
    """
    rows = np.asarray(rows, dtype=np.int64).ravel()
    cols = np.asarray(cols, dtype=np.int64).ravel()
    sn = np.asarray(sn, dtype=np.int64).ravel()
    kind = np.asarray(kind, dtype=np.int64).ravel()
    N = int(N)
    nsn = len(kind)
    if rows.shape != cols.shape:
        raise ValueError("rows and cols must have the same length")
    if sn.shape != (N,):
        raise ValueError(f"sn: expected shape ({N},), got {sn.shape}")
    if N and (sn.min() < 0 or sn.max() >= nsn):
        raise ValueError("sn: supernode indices must be in 0..len(kind)-1")
    if np.any((kind < 0) | (kind > 2)):
        raise ValueError("kind: values must be 0, 1 or 2")
    if np.any(rows >= N) or np.any(cols >= N):
        raise ValueError("rows/cols: index out of range")
    size = np.bincount(sn, minlength=nsn)
    if np.any(size == 0):
        raise ValueError(f"supernode {int(np.flatnonzero(size == 0)[0])} owns no unknown")

    # supernode edges, in chunks of the values (bounded temporaries on big models)
    parts = []
    for c0 in range(0, len(rows), _CHUNK):
        rr, cc = rows[c0:c0 + _CHUNK], cols[c0:c0 + _CHUNK]
        ok = (rr >= 0) & (cc >= 0)
        a = sn[rr[ok]]
        b = sn[cc[ok]]
        off = a != b
        parts.append(np.unique(np.concatenate([a[off] * nsn + b[off], b[off] * nsn + a[off]])))
    e = np.unique(np.concatenate(parts)) if parts else np.zeros(0, np.int64)
    del parts
    ea, eb = e // nsn, e % nsn
    nblocks_struct = nsn + len(e)
    adj: list[set] = [set() for _ in range(nsn)]
    for i, j in zip(ea.tolist(), eb.tolist(), strict=True):
        adj[i].add(j)

    if jk is not None:
        jk = np.asarray(jk, dtype=np.int64).ravel()
        if jk.shape != (nsn,):
            raise ValueError(f"jk: expected shape ({nsn},), got {jk.shape}")
    groups, later = _order(adj, kind, jk)
    nstep = len(groups)
    step = np.empty(nsn, np.int64)
    for p, g in enumerate(groups):
        step[g] = p
    order = np.concatenate([np.asarray(g, np.int64) for g in groups]) if nsn else np.zeros(
        0, np.int64)
    # structural blocks at the level of the steps (compound pivots merge supernodes)
    se = np.unique(step[ea] * nstep + step[eb])
    se = se[se // nstep != se % nstep]
    nblocks_struct = nstep + len(se)

    # positions: by step, then by original index
    perm = np.lexsort((np.arange(N), step[sn]))  # position -> unknown
    bn = np.bincount(step[sn], minlength=nstep).astype(np.int64)
    bptr = np.zeros(nstep + 1, np.int64)
    np.cumsum(bn, out=bptr[1:])
    local = np.empty(N, np.int64)  # local index of each unknown inside its step
    local[perm] = np.arange(N) - bptr[step[sn[perm]]]

    # later neighbours by step: nbsn[nbptr[p]:nbptr[p+1]], increasing, unique
    cnt0 = np.array([len(x) for x in later], dtype=np.int64)
    own = np.repeat(np.arange(nstep), cnt0)
    nbs = step[np.fromiter((u for x in later for u in x), np.int64, int(cnt0.sum()))]
    key = np.unique(own * nstep + nbs)
    own, nbsn = key // nstep, key % nstep
    assert np.all(nbsn > own)
    cnt = np.bincount(own, minlength=nstep).astype(np.int64)
    nbptr = np.zeros(nstep + 1, np.int64)
    np.cumsum(cnt, out=nbptr[1:])
    nnb = int(nbptr[-1])

    # storage, per step: the diagonal block, then (p, r) and (r, p) for each later neighbour r
    seq_size = np.empty(nstep + 2 * nnb, np.int64)  # blocks in storage order
    seq_key = np.empty(nstep + 2 * nnb, np.int64)  # i * nstep + j of block (i, j)
    first = np.arange(nstep) + 2 * nbptr[:-1]  # storage-order index of the diagonal block of p
    seq_size[first] = bn * bn
    seq_key[first] = np.arange(nstep) * (nstep + 1)
    e_pos = first[own] + 1 + 2 * (np.arange(nnb) - nbptr[own])
    seq_size[e_pos] = bn[own] * bn[nbsn]
    seq_key[e_pos] = own * nstep + nbsn
    seq_size[e_pos + 1] = seq_size[e_pos]
    seq_key[e_pos + 1] = nbsn * nstep + own
    seq_off = np.zeros(len(seq_size), np.int64)
    np.cumsum(seq_size[:-1], out=seq_off[1:])
    nstore = int(seq_size.sum())
    dg = seq_off[first]
    nbup = seq_off[e_pos]
    nblo = seq_off[e_pos + 1]
    ksrt = np.argsort(seq_key)
    keys, koff = seq_key[ksrt], seq_off[ksrt]
    nblocks = len(keys)
    assert nblocks >= nblocks_struct

    def offset(i, j):
        k = np.searchsorted(keys, i * nstep + j)
        assert np.all(keys[np.minimum(k, nblocks - 1)] == i * nstep + j)
        return koff[k]

    # Schur updates of step p: blocks (q, r) for q, r in its later neighbours, row-major
    c2 = cnt * cnt
    updptr = np.zeros(nstep + 1, np.int64)
    np.cumsum(c2, out=updptr[1:])
    P = np.repeat(np.arange(nstep), c2)
    w = np.arange(int(updptr[-1])) - updptr[P]
    q = nbsn[nbptr[P] + w // cnt[P]]
    r = nbsn[nbptr[P] + w % cnt[P]]
    updoff = offset(q, r)

    # slot of every pattern value (in chunks: bounded temporaries)
    slot = -np.ones(len(rows), np.int64)
    for c0 in range(0, len(rows), _CHUNK):
        rr, cc = rows[c0:c0 + _CHUNK], cols[c0:c0 + _CHUNK]
        ok = np.flatnonzero((rr >= 0) & (cc >= 0))
        r_, c_ = rr[ok], cc[ok]
        pi, pj = step[sn[r_]], step[sn[c_]]
        slot[c0 + ok] = offset(pi, pj) + local[r_] * bn[pj] + local[c_]

    def arr(x):
        return np.ascontiguousarray(np.asarray(x, dtype=np.int64))

    sym = tuple(arr(x) for x in (bn, bptr, perm, dg, nbptr, nbsn, nbup, nblo, updptr, updoff,
                                 slot))
    rc_ok = (rows >= 0) & (cols >= 0)
    return BlockLU(N, nsn, order, step, kind, sym, nstore, nblocks, nblocks_struct,
                   np.where(rc_ok, rows, -1), np.where(rc_ok, cols, -1))


def supernodes(s, index2: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Supernodes of the iteration matrix of a compiled system.

    Free node f (position in ``s.node_free``) is supernode f; joint j is supernode
    ``nf + j`` (its increments ``jdof``, multipliers ``nq + mult`` and, for index 2,
    ``nq + nm + mult``).

    Parameters
    ----------
    s : System
    index2 : bool

    Returns
    -------
    sn : ndarray (N,) int64
    kind : ndarray (nf + m,) int64
        0 for a free node with a nonsingular mass matrix ``diag(m I, J)`` (mass > 0 and J
        positive definite), 1 for other free nodes, 2 for joints.
    jk : ndarray (nf + m,) int64
        k of each joint supernode (0 for nodes).
    """
    nq, nm = s.nq, s.nm
    N = nq + (2 * nm if index2 else nm)
    nf = len(s.node_free)
    sn = -np.ones(N, np.int64)
    sn[s.node_dofidx.ravel()] = np.repeat(np.arange(nf), 6)
    for g in s.groups:
        jsn = nf + g.ids
        if g.k:
            sn[g.jdof.ravel()] = np.repeat(jsn, g.k)
        sn[(nq + g.mult).ravel()] = np.repeat(jsn, 6)
        if index2:
            sn[(nq + nm + g.mult).ravel()] = np.repeat(jsn, 6)
    assert np.all(sn >= 0)
    mass = s.node_mass[s.node_free]
    J = s.node_J[s.node_free]
    kind = np.full(nf + s.m, 2, np.int64)
    if nf:
        ev = np.linalg.eigvalsh(0.5 * (J + np.swapaxes(J, 1, 2)))
        massive = (mass > 0) & (ev[:, 0] > 1e-12 * np.maximum(ev[:, -1], 1e-300))
        kind[:nf] = np.where(massive, 0, 1)
    jk = np.zeros(nf + s.m, np.int64)
    jk[nf:] = s.joint_k
    return sn, kind, jk


def from_system(s, index2: bool = False, drop=()) -> BlockLU:
    """Block LU of the iteration matrix of a compiled system, for its fixed pattern.

    The value vectors accepted by :meth:`BlockLU.factor` / :func:`factor` are the raw output
    of :func:`se3dyn.system.matrix_values` (length ``pattern(s, index2)["nvals"]``; the values
    the pattern does not keep, on clamped nodes, have slot -1 and are ignored), so no gather is
    needed.

    Parameters
    ----------
    s : System
    index2 : bool
        Pattern of the stabilized index-2 matrix instead of the index-3 one.
    drop : sequence of int
        Redundant constraint equations (indices into the nm multipliers), as for
        :class:`se3dyn.system.LinearSolver`: their rows and columns (multiplier and, for
        index 2, xi) are replaced by the identity. This sets ``vmask``/``vone``, applied by
        :func:`factor` (the caller only passes them).

    Returns
    -------
    BlockLU
    """
    from se3dyn.system import pattern_entries

    # only the (row, col) of every value: the CSC map of system.pattern is not needed here
    N, rows_all, cols_all, _ = pattern_entries(s, index2)
    nvals = len(rows_all)
    keep = np.flatnonzero((rows_all >= 0) & (cols_all >= 0))
    rows, cols = rows_all[keep], cols_all[keep]
    sn, kind, jk = supernodes(s, index2)
    bl = symbolic(N, rows, cols, sn, kind, jk)
    slot = -np.ones(nvals, np.int64)
    slot[keep] = bl.sym[10]
    bl.sym = bl.sym[:10] + (slot,)
    bl.rows = rows_all.astype(np.int32)
    bl.cols = cols_all.astype(np.int32)
    del rows_all, cols_all
    drop = np.unique(np.asarray(drop, dtype=np.int64))
    bl.drop = drop
    bl.index2 = bool(index2)
    if drop.size:
        nq, nm = s.nq, s.nm
        dropped = np.zeros(N, dtype=bool)
        dropped[nq + drop] = True
        if index2:
            dropped[nq + nm + drop] = True
        vmask = np.ones(nvals)
        vone = np.zeros(nvals)
        vmask[keep] = ~(dropped[rows] | dropped[cols])
        vone[keep] = dropped[rows] & (rows == cols)
        bl.vmask, bl.vone = vmask, vone
    return bl


# ---------------------------------------------------------------------------------------------
@numba.njit(cache=True)
def factor(sym, vmask, vone, values, store, piv):
    """Assemble and factorise in place (njit).

    Parameters
    ----------
    sym : tuple of 11 ndarray int64
        ``BlockLU.sym`` (fields :data:`SYM_FIELDS`).
    vmask, vone : ndarray (nvals,) float64, or (0,) for no masking
        A value i is taken as ``(values[i] if vmask[i] != 0 else 0) + vone[i]``.
    values : ndarray (nvals,) float64
        Matrix values in pattern order (duplicates summed; slot -1 ignored).
    store : ndarray (nstore,) float64
        Block storage (``BlockLU.store``); overwritten with the factors.
    piv : ndarray (N,) int64
        Pivots (``BlockLU.piv``), overwritten.

    Returns
    -------
    int
        0 on success; p + 1 when the pivot block of step p has a pivot
        ``|u_ii| <= PIVOT_RTOL * max|D_p|`` or a non-finite entry (the factors are then
        incomplete and must not be used).
    """
    bn, bptr, uidx, dg, nbptr, nbsn, nbup, nblo, updptr, updoff, slot = sym
    nstep = bn.shape[0]
    store[:] = 0.0
    masked = vmask.shape[0] > 0
    for i in range(values.shape[0]):
        s = slot[i]
        if s < 0:
            continue
        v = values[i]
        if masked:
            if vmask[i] == 0.0:
                v = 0.0
            v += vone[i]
        store[s] += v
    for p in range(nstep):
        n = bn[p]
        o = dg[p]
        b0 = bptr[p]
        # --- dense LU with partial pivoting of D_p
        dmax = 0.0
        for t in range(n * n):
            a = abs(store[o + t])
            if not (a < np.inf):
                return p + 1
            if a > dmax:
                dmax = a
        tol = PIVOT_RTOL * dmax
        for j in range(n):
            ip = j
            amax = abs(store[o + j * n + j])
            for i in range(j + 1, n):
                a = abs(store[o + i * n + j])
                if a > amax:
                    amax = a
                    ip = i
            piv[b0 + j] = ip
            if not (amax > tol):
                return p + 1
            if ip != j:
                for c in range(n):
                    tmp = store[o + j * n + c]
                    store[o + j * n + c] = store[o + ip * n + c]
                    store[o + ip * n + c] = tmp
            u = store[o + j * n + j]
            for i in range(j + 1, n):
                lij = store[o + i * n + j] / u
                store[o + i * n + j] = lij
                if lij != 0.0:
                    for c in range(j + 1, n):
                        store[o + i * n + c] -= lij * store[o + j * n + c]
        # --- W_pr = D_p^-1 A_pr for the later neighbours r
        k0 = nbptr[p]
        nn = nbptr[p + 1] - k0
        for t in range(nn):
            m = bn[nbsn[k0 + t]]
            w = nbup[k0 + t]
            for j in range(n):
                ip = piv[b0 + j]
                if ip != j:
                    for c in range(m):
                        tmp = store[w + j * m + c]
                        store[w + j * m + c] = store[w + ip * m + c]
                        store[w + ip * m + c] = tmp
            for i in range(1, n):
                for c in range(i):
                    lic = store[o + i * n + c]
                    if lic != 0.0:
                        for cc in range(m):
                            store[w + i * m + cc] -= lic * store[w + c * m + cc]
            for i in range(n - 1, -1, -1):
                for c in range(i + 1, n):
                    uic = store[o + i * n + c]
                    if uic != 0.0:
                        for cc in range(m):
                            store[w + i * m + cc] -= uic * store[w + c * m + cc]
                d = 1.0 / store[o + i * n + i]
                for cc in range(m):
                    store[w + i * m + cc] *= d
        # --- Schur updates A_qr -= A_qp W_pr
        u0 = updptr[p]
        for a_ in range(nn):
            mq = bn[nbsn[k0 + a_]]
            lo = nblo[k0 + a_]
            for b_ in range(nn):
                mr = bn[nbsn[k0 + b_]]
                w = nbup[k0 + b_]
                tgt = updoff[u0 + a_ * nn + b_]
                for i in range(mq):
                    for c in range(n):
                        lic = store[lo + i * n + c]
                        if lic != 0.0:
                            for cc in range(mr):
                                store[tgt + i * mr + cc] -= lic * store[w + c * mr + cc]
    return 0


@numba.njit(cache=True)
def solve(sym, store, piv, b, x, y):
    """Solve ``A x = b`` with the factors of :func:`factor` (njit).

    Parameters
    ----------
    sym : tuple of 11 ndarray int64
        ``BlockLU.sym``.
    store : ndarray (nstore,) float64
        Factors from a successful :func:`factor` (return code 0).
    piv : ndarray (N,) int64
        Pivots from the same :func:`factor`.
    b : ndarray (N,) float64
        Right-hand side, original numbering; not modified.
    x : ndarray (N,) float64
        Solution, original numbering (written; may be the same array as ``b``).
    y : ndarray (N,) float64
        Work vector (``BlockLU.work``), overwritten.
    """
    bn, bptr, uidx, dg, nbptr, nbsn, nbup, nblo, updptr, updoff, slot = sym
    nstep = bn.shape[0]
    N = uidx.shape[0]
    for t in range(N):
        y[t] = b[uidx[t]]
    # forward: y_p = D_p^-1 y_p; y_q -= A_qp y_p
    for p in range(nstep):
        n = bn[p]
        o = dg[p]
        b0 = bptr[p]
        for j in range(n):
            ip = piv[b0 + j]
            if ip != j:
                tmp = y[b0 + j]
                y[b0 + j] = y[b0 + ip]
                y[b0 + ip] = tmp
        for i in range(1, n):
            acc = y[b0 + i]
            for c in range(i):
                acc -= store[o + i * n + c] * y[b0 + c]
            y[b0 + i] = acc
        for i in range(n - 1, -1, -1):
            acc = y[b0 + i]
            for c in range(i + 1, n):
                acc -= store[o + i * n + c] * y[b0 + c]
            y[b0 + i] = acc / store[o + i * n + i]
        for t in range(nbptr[p], nbptr[p + 1]):
            q = nbsn[t]
            mq = bn[q]
            lo = nblo[t]
            q0 = bptr[q]
            for i in range(mq):
                acc = 0.0
                for c in range(n):
                    acc += store[lo + i * n + c] * y[b0 + c]
                y[q0 + i] -= acc
    # backward: x_p = y_p - sum_r W_pr x_r
    for p in range(nstep - 1, -1, -1):
        n = bn[p]
        b0 = bptr[p]
        for t in range(nbptr[p], nbptr[p + 1]):
            r = nbsn[t]
            mr = bn[r]
            w = nbup[t]
            r0 = bptr[r]
            for i in range(n):
                acc = 0.0
                for c in range(mr):
                    acc += store[w + i * mr + c] * y[r0 + c]
                y[b0 + i] -= acc
    for t in range(N):
        x[uidx[t]] = y[t]


@numba.njit(cache=True)
def matvec(rows, cols, vmask, vone, values, x, y):
    """``y = A x`` from the pattern values (njit), e.g. for residuals or iterative refinement.

    Parameters
    ----------
    rows, cols : ndarray (nvals,) int64
        ``BlockLU.rows``, ``BlockLU.cols`` (-1: value ignored).
    vmask, vone : ndarray (nvals,) float64, or (0,)
        As for :func:`factor`.
    values : ndarray (nvals,) float64
    x : ndarray (N,) float64
    y : ndarray (N,) float64
        Written (must not be ``x``).
    """
    y[:] = 0.0
    masked = vmask.shape[0] > 0
    for i in range(values.shape[0]):
        r = rows[i]
        c = cols[i]
        if r < 0 or c < 0:
            continue
        v = values[i]
        if masked:
            if vmask[i] == 0.0:
                v = 0.0
            v += vone[i]
        y[r] += v * x[c]
