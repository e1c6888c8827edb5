"""One assembler for every element type: the numbering of frames, the fixed block pattern built
from the elements' dof maps, and the tables of the compiled engine (:mod:`se3dyn._core._engine`).

Every configuration variable is a *frame* (Eq. (12)): frames ``0..M-1`` are the nodes, frames
``M..M+m-1`` the joint transformations. Frame f has ``k_f`` unknowns (6 for a free node, 0 for
a clamped node or a rigid joint, k of Table 1 for a joint) and the constant matrix ``A_f`` (the
identity for nodes, Eq. (9) for joints). Elements (:mod:`se3dyn.elements`, one module per type)
touch frames and, for constraint elements, own multiplier rows; the iteration matrix is a set of
dense blocks, one per pair of row and column groups (frame unknowns, multipliers, index-2
multipliers xi), registered here by the element modules and filled in place by their kernels.
The assembler knows no element type: it asks the registry.

The stabilized index-2 matrix has blocks that are products of element blocks:
``-(cM M + cC C_T) B_n^T`` (dynamic rows, xi columns: every velocity-level block the elements
declare times the constraint gradient at the step start) and ``-B B_n^T`` (xi rows and columns:
pairs of constraint elements sharing a frame). Their pattern and the list of products (``velprod``,
``xiprod``) are derived here from the dof maps, once.

Values are stored block after block, each block row-major, in the order the blocks were first
registered (index-3 blocks first, then those only the index-2 matrix has). The layout keeps one
row per block (``blocks``: first row, rows, first column, columns, offset), never one per value:
``rows``/``cols`` of every value and the compressed-column pattern are derived from it on demand
(:meth:`Layout.entries`, :meth:`Layout.csc`; the compiled stepper builds its own from
``blocks``).

Element modules declare their blocks element by element (:meth:`Layout.block` and the helpers
beside it) or, for whole batches, with arrays (:meth:`Layout.blocks`, :meth:`Layout.frame_groups`,
:meth:`Layout.mult_groups`, :meth:`Layout.xi_groups`, :meth:`Layout.velocity_blocks`,
:meth:`Layout.constraints`): both register in the order of the calls (array calls in the C order
of the arrays), so they can be mixed.
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie
from se3dyn.elements import REGISTRY

__all__ = ["Layout", "layout"]

_KIND = {"f": 0, "c": 1, "x": 2}


def _ragged(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For counts (n,): the owner (sum counts,) and the position within its owner of every item
    of the concatenation of ranges of those lengths."""
    counts = np.asarray(counts, np.int64)
    owner = np.repeat(np.arange(len(counts)), counts)
    start = np.cumsum(counts) - counts
    return owner, np.arange(int(counts.sum()), dtype=np.int64) - start[owner]


def _first_order(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct values of x in order of first appearance, and the rank (in that order) of
    every element of x."""
    if len(x) == 0:
        return x[:0], np.zeros(0, np.int64)
    u, first, inv = np.unique(x, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty(len(u), np.int64)
    rank[order] = np.arange(len(u))
    return u[order], rank[inv.reshape(-1)]


def _frames(s) -> tuple:
    """The frames of a system (Eq. (12)): their number F, first unknown, number of unknowns k
    and constant matrix A (the identity for nodes, Eq. (9) for joints)."""
    M, m = s.M, s.m
    F = M + m
    dof = np.full(F, -1, np.int64)
    k = np.zeros(F, np.int64)
    A = np.zeros((F, 6, 6))
    A[:M] = np.eye(6)
    free = np.flatnonzero(~np.asarray(s.node_fixed, bool))
    dof[free] = np.asarray(s.node_dofadr)[free]
    k[free] = 6
    for g in s.groups:
        ids = np.asarray(g.ids, np.int64)
        k[M + ids] = g.k
        if g.k:
            dof[M + ids] = np.asarray(s.joint_dofadr)[ids]
            A[M + ids, :, :g.k] = g.A
    return F, dof, k, A


def _group_codes(dof: np.ndarray, k: np.ndarray, m: int, nq: int, nm: int,
                 madr: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """The number G of codes per kind and the first row and size of every group code."""
    F = len(dof)
    # group codes: kind * G + index (kind 0 frame unknowns, 1 multipliers, 2 xi), -1 none
    G = max(F, m, 1)
    gstart = np.full(3 * G, -1, np.int64)
    gsize = np.zeros(3 * G, np.int64)
    gstart[:F], gsize[:F] = dof, k
    gstart[G:G + m], gsize[G:G + m] = nq + madr, 6
    gstart[2 * G:2 * G + m], gsize[2 * G:2 * G + m] = nq + nm + madr, 6
    return G, gstart, gsize


def _touch(con_c: np.ndarray, con_f: np.ndarray, k: np.ndarray, F: int) -> tuple:
    """(constraint, slot, frame) of the constrained frames with unknowns, grouped by frame
    (frames in order of first appearance, each frame's entries in declaration order), with the
    count and start of each group, by group and by frame."""
    tc = np.repeat(con_c, 3)
    ts = np.tile(np.arange(3, dtype=np.int64), len(con_c))
    tf = con_f.reshape(-1)
    keep = k[tf] > 0
    tc, ts, tf = tc[keep], ts[keep], tf[keep]
    tframes, trank = _first_order(tf)
    o = np.argsort(trank, kind="stable")
    tc, ts, tf = tc[o], ts[o], tf[o]
    tcount = np.bincount(trank, minlength=len(tframes)).astype(np.int64)
    tstart = np.cumsum(tcount) - tcount
    fcount = np.zeros(F, np.int64)
    fstart = np.zeros(F, np.int64)
    fcount[tframes], fstart[tframes] = tcount, tstart
    return tc, ts, tf, tcount, tstart, fcount, fstart


def _log_tables(s, A: np.ndarray, F: int, needed_frames: list) -> dict:
    """The tables of the relative coordinates of non-abelian joints (log coordinates)."""
    M, m = s.M, s.m
    jk = np.asarray(s.joint_k, np.int64)
    logs = np.flatnonzero((jk > 0) & ~np.asarray(s.joint_abelian, bool)) if m \
        else np.zeros(0, np.int64)
    lA = np.zeros((len(logs), 6, 6))
    for kk in sorted(set(jk[logs].tolist())):  # (not np.unique: it imports numpy.ma)
        sel = np.flatnonzero(jk[logs] == kk)
        lA[sel, :kk, :] = np.linalg.pinv(A[M + logs[sel]][:, :, :kk])
    needed = np.zeros(F, bool)
    if needed_frames:
        needed[np.concatenate(needed_frames)] = True
    return dict(
        log_frame=(M + logs).astype(np.int64),
        log_H0inv=(np.ascontiguousarray(lie.inverse(s.joint_H0[logs])) if len(logs)
                   else np.zeros((0, 4, 4))),
        log_Apinv=lA,
        log_needed=needed[M + logs].astype(np.int64))


class Layout:
    """Frames, element tables, block pattern and products of a compiled system.

    Attributes
    ----------
    tables : dict
        What :class:`se3dyn._core._engine.Engine` is built from: frame arrays, ``elements`` (list of
        (type key, arrays)), ``velprod``/``xiprod`` and the log-coordinate tables.
    nvals, nvals2 : int
        Number of values of the index-3 matrix and of the stabilized index-2 matrix.
    blocks : ndarray (nb, 5) int64
        Every block in value order: first row, rows, first column, columns, offset of its
        values (row-major); the first ``nblocks3`` are those of the index-3 matrix.
    rows3, cols3, rows2, cols2 : ndarray (nvals,), (nvals2,)
        Matrix position of every value (computed on first access, not kept by the layout's
        own users: see :meth:`entries`).
    groups3, groups2 : ndarray (N,)
        Block-group id of every matrix row (for the ordering of the sparse LU).
    """

    def __init__(self, s) -> None:
        self.s = s
        M, m, nq, nm = s.M, s.m, s.nq, s.nm
        self.F, self.frame_dof, self.frame_k, self.frame_A = _frames(s)
        madr = np.asarray(s.joint_multadr, np.int64)
        self._G, self._gstart, self._gsize = _group_codes(self.frame_dof, self.frame_k, m, nq, nm,
                                                          madr)
        # registered blocks: key = row code * 3G + column code -> offset; sorted arrays plus
        # the blocks registered one by one since they were last merged
        self._sk = np.zeros(0, np.int64)
        self._so = np.zeros(0, np.int64)
        self._pending: dict[int, int] = {}
        self.n = 0
        self._vel: list = []        # arrays (f, g) of velocity-level blocks, in call order
        self._con: list = []        # arrays (c, frames (., 3)) of constraint elements
        self._logs: list = []       # arrays of joint frames whose logs Newton needs
        fr = self.frame_groups(np.arange(self.F))  # every free frame has its diagonal block (LU)
        self.blocks(fr, fr)
        elements = []
        for key, mod in REGISTRY.items():
            elements.append((key, mod.tables(s, self)))
        self._coupling_blocks(s)
        self.nvals = self.n
        # --- index-2 blocks
        for key, mod in REGISTRY.items():
            if hasattr(mod, "index2_tables"):
                mod.index2_tables(s, self, dict(elements)[key])
        con_c, con_f = self._constraint_arrays()
        touch = _touch(con_c, con_f, self.frame_k, self.F)
        velprod = self._velprod(touch)
        xiprod = self._xiprod(touch)
        xc = self.xi_groups(con_c)
        self.blocks(xc, xc)
        self._coupling_blocks(s)
        self.nvals2 = self.n
        self.tables = dict(
            nq=nq, nm=nm, nu=s.inputs.nu, nvals=self.nvals, nvals2=self.nvals2,
            frame_dof=self.frame_dof, frame_k=self.frame_k,
            frame_node=(np.arange(self.F) < M).astype(np.int64),
            frame_A=self.frame_A, frame_joint=(np.arange(self.F) >= M).astype(np.int64),
            elements=[(key, {n: np.ascontiguousarray(v) for n, v in t.items()})
                      for key, t in elements],
            velprod=np.ascontiguousarray(velprod, np.int64).reshape(-1, 6),
            xiprod=np.ascontiguousarray(xiprod, np.int64).reshape(-1, 6),
            drive=_drive_table(s),
            cpl_lead=s.cpl_lead, cpl_follow=s.cpl_follow, cpl_ratio=s.cpl_ratio,
            cpl_offset=s.cpl_offset,
            ctrl_slot=np.array(s.inputs.pid_slots, np.int64),
            ctrl_ts=np.array([s.dof_ts[d] for _, d in s.inputs.pid_ref], float),
            ctrl_dof=np.array([d for _, d in s.inputs.pid_ref], np.int64),
            cs_slot=np.array(s.inputs.contact_slots, np.int64),
            law_size=_law_size(s), law_t=int(s.inputs.time_slot),
            **_log_tables(s, self.frame_A, self.F, self._logs))
        rg = self._blocks_in_value_order()
        self.groups2, self.groups3 = self._lu_groups(rg, con_c, con_f)
        self.tables.update(self._merges(s))

    def _coupling_blocks(self, s) -> None:
        """Register the blocks the couplings' merges write (engine.hpp): for every block in a
        follower's column group the same block in its leader's column group, then likewise for
        the rows (after the columns: the blocks the column merges made count too)."""
        if not len(s.cpl_follow):
            return
        fa = self.frame_groups(self._frame_of_unknown(s.cpl_lead))
        fb = self.frame_groups(self._frame_of_unknown(s.cpl_follow))
        G3 = 3 * self._G
        for axis in (1, 0):  # columns, then rows
            self._merge()
            rg, cg = self._sk // G3, self._sk % G3
            for ga, gb in zip(fa, fb, strict=True):
                if axis == 1:
                    sel = cg == gb
                    self.blocks(rg[sel], ga)
                else:
                    sel = rg == gb
                    self.blocks(ga, cg[sel])

    def _frame_of_unknown(self, dofs) -> np.ndarray:
        """The frame (joint frame) of joint unknowns."""
        d = np.asarray(dofs, np.int64)
        first = np.asarray(self.frame_dof, np.int64)
        k = np.asarray(self.frame_k, np.int64)
        f = np.flatnonzero(k > 0)
        owner = f[np.searchsorted(first[f], d, side="right") - 1]
        return owner

    def _merges(self, s) -> dict:
        """The couplings' merges of values (src, dst) and factors, columns first, for the
        index-3 (``merge3``) and the index-2 matrix (``merge2``)."""
        out = {}
        for tag, index2 in (("3", False), ("2", True)):
            rows, cols = self.entries(index2) if len(s.cpl_follow) else (None, None)
            out["merge" + tag], out["mfac" + tag] = _merge_list(
                rows, cols, s.cpl_lead, s.cpl_follow, s.cpl_ratio)
        return out

    def _velprod(self, touch: tuple) -> np.ndarray:
        """Register the index-2 blocks ``-(cM M + cC C_T) B_n^T`` (dynamic rows, xi columns) and
        return their products: the velocity-level blocks (distinct, in declaration order) times
        B_n^T of every constraint element touching their column frame."""
        tc, ts, _, _, _, fcount, fstart = touch
        k = self.frame_k
        vf, vg = self._velocity_pairs()
        ok = (k[vf] > 0) & (k[vg] > 0)
        vf, vg = vf[ok], vg[ok]
        src = self._lookup(self._key(self.frame_groups(vf), self.frame_groups(vg)))
        if np.any(src < 0):
            raise KeyError("velocity-level block not registered")
        pair, within = _ragged(fcount[vg])
        ent = fstart[vg][pair] + within
        tgt = self.blocks(self.frame_groups(vf[pair]), self.xi_groups(tc[ent]))
        return np.stack([tgt, src[pair], k[vf][pair], k[vg][pair], tc[ent], ts[ent]],
                        axis=1) if len(ent) else np.zeros((0, 6), np.int64)

    def _xiprod(self, touch: tuple) -> np.ndarray:
        """Register the index-2 blocks ``-B B_n^T`` (xi rows and columns) of the pairs of
        constraint elements sharing a frame and return their products."""
        tc, ts, tf, tcount, tstart, _, _ = touch
        grp, w = _ragged(tcount * tcount)
        i, j = w // tcount[grp], w % tcount[grp]
        e1, e2 = tstart[grp] + i, tstart[grp] + j
        tgt = self.blocks(self.xi_groups(tc[e1]), self.xi_groups(tc[e2]))
        return np.stack([tgt, self.frame_k[tf[e1]], tc[e1], ts[e1], tc[e2], ts[e2]], axis=1) \
            if len(e1) else np.zeros((0, 6), np.int64)

    def _blocks_in_value_order(self) -> np.ndarray:
        """Set ``blocks_table`` and ``nblocks3`` from the registered blocks (ending the
        registration); returns the row group code of every block."""
        G, gstart, gsize = self._G, self._gstart, self._gsize
        self._merge()
        order = np.argsort(self._so, kind="stable")
        keys, offs = self._sk[order], self._so[order]
        rg, cg = keys // (3 * G), keys % (3 * G)
        self.blocks_table = np.ascontiguousarray(np.stack(
            [gstart[rg], gsize[rg], gstart[cg], gsize[cg], offs], axis=1), np.int64) \
            if len(keys) else np.zeros((0, 5), np.int64)
        self.nblocks3 = int(np.searchsorted(offs, self.nvals))
        del self._sk, self._so, self._pending
        return rg

    def _lu_groups(self, rg: np.ndarray, con_c: np.ndarray, con_f: np.ndarray) -> tuple:
        """The block-group id of every row of the index-2 and of the index-3 matrix."""
        G, gstart, gsize = self._G, self._gstart, self._gsize
        nq, nm = self.s.nq, self.s.nm
        # ordering hint for the sparse LU: each constraint element's rows (multipliers, xi) go in
        # one group with the frames it couples that no earlier constraint took (for a tree or a
        # chain: a joint with its own coordinates and its child node), so the ordering sees the
        # pivots that make its zero diagonal blocks nonsingular together
        gid, _ = _first_order(rg)               # row groups in order of first registration
        owner = np.full(3 * G, -1, np.int64)
        owner[gid] = np.arange(len(gid))
        target = owner[self.mult_groups(con_c)]
        cf = con_f[:, 1:]
        fgr = self.frame_groups(cf.reshape(-1))
        tg = np.repeat(target, 2)
        ok = (tg >= 0) & (fgr >= 0)
        fu, first = np.unique(fgr[ok], return_index=True)
        owner[fu] = tg[ok][first]
        ok = target >= 0
        owner[self.xi_groups(con_c[ok])] = target[ok]
        groups = np.zeros(nq + 2 * nm, np.int64)
        idx = np.repeat(gstart[gid], gsize[gid]) + _ragged(gsize[gid])[1]
        groups[idx] = np.repeat(owner[gid], gsize[gid])
        return groups, groups[:nq + nm]

    # --- what element modules call -----------------------------------------------------------
    def frame_group(self, f: int):
        """The row/column group of frame f's unknowns, None without unknowns."""
        return ("f", int(f)) if self.frame_k[f] else None

    @staticmethod
    def mult_group(c: int):
        """The multiplier rows of constraint element c (its 6 rows of Eq. (55))."""
        return ("c", int(c))

    @staticmethod
    def xi_group(c: int):
        """The index-2 velocity-constraint rows (multipliers xi) of constraint element c."""
        return ("x", int(c))

    def frame_groups(self, f) -> np.ndarray:
        """:meth:`frame_group` of an array of frames, as group codes (-1: no unknowns)."""
        f = np.asarray(f, np.int64)
        return np.where(self.frame_k[f] > 0, f, -1)

    def mult_groups(self, c) -> np.ndarray:
        """:meth:`mult_group` of an array of constraint elements, as group codes."""
        return self._G + np.asarray(c, np.int64)

    def xi_groups(self, c) -> np.ndarray:
        """:meth:`xi_group` of an array of constraint elements, as group codes."""
        return 2 * self._G + np.asarray(c, np.int64)

    def _code(self, g) -> int:
        if g is None:
            return -1
        if isinstance(g, tuple):
            return _KIND[g[0]] * self._G + int(g[1])
        return int(g)

    def _key(self, rg, cg):
        rg, cg = np.asarray(rg, np.int64), np.asarray(cg, np.int64)
        ok = (rg >= 0) & (cg >= 0)
        ok &= (self._gsize[np.maximum(rg, 0)] > 0) & (self._gsize[np.maximum(cg, 0)] > 0)
        return np.where(ok, rg * (3 * self._G) + cg, -1)

    def _merge(self) -> None:
        if self._pending:
            k = np.fromiter(self._pending.keys(), np.int64, len(self._pending))
            o = np.fromiter(self._pending.values(), np.int64, len(self._pending))
            self._pending = {}
            sk, so = np.concatenate([self._sk, k]), np.concatenate([self._so, o])
            p = np.argsort(sk, kind="stable")
            self._sk, self._so = sk[p], so[p]

    def _lookup(self, keys: np.ndarray) -> np.ndarray:
        """Offsets of the blocks of keys (-1 for -1 keys or blocks not registered)."""
        self._merge()
        keys = np.asarray(keys, np.int64)
        if len(self._sk) == 0:
            return np.full(keys.shape, -1, np.int64)
        i = np.minimum(np.searchsorted(self._sk, keys), len(self._sk) - 1)
        return np.where((self._sk[i] == keys) & (keys >= 0), self._so[i], -1)

    def blocks(self, rg, cg) -> np.ndarray:
        """:meth:`block` of arrays of row and column groups (codes of :meth:`frame_groups`,
        :meth:`mult_groups`, :meth:`xi_groups`; broadcast together): the offsets, the new
        blocks registered in the C order of the broadcast arrays."""
        rg, cg = np.broadcast_arrays(np.asarray(rg, np.int64), np.asarray(cg, np.int64))
        shape = rg.shape
        keys = self._key(rg.reshape(-1), cg.reshape(-1))
        off = self._lookup(keys)
        new = (off < 0) & (keys >= 0)
        if np.any(new):
            nk, _ = _first_order(keys[new])
            G3 = 3 * self._G
            size = self._gsize[nk // G3] * self._gsize[nk % G3]
            no = self.n + np.cumsum(size) - size
            self.n += int(size.sum())
            sk, so = np.concatenate([self._sk, nk]), np.concatenate([self._so, no])
            p = np.argsort(sk, kind="stable")
            self._sk, self._so = sk[p], so[p]
            off = self._lookup(keys)
        return off.reshape(shape)

    def block(self, rg, cg) -> int:
        """Offset of the block (row group, column group) in the values, registering it on
        first use; -1 when either group is None or empty."""
        r, c = self._code(rg), self._code(cg)
        if r < 0 or c < 0:
            return -1
        nr, nc = int(self._gsize[r]), int(self._gsize[c])
        if nr == 0 or nc == 0:
            return -1
        key = r * (3 * self._G) + c
        o = self._pending.get(key)
        if o is not None:
            return o
        if len(self._sk):
            i = int(np.searchsorted(self._sk, key))
            if i < len(self._sk) and self._sk[i] == key:
                return int(self._so[i])
        o = self.n
        self._pending[key] = o
        self.n += nr * nc
        return o

    def frame_block(self, f: int, g: int) -> int:
        """:meth:`block` of the unknowns of frames f (rows) and g (columns)."""
        return self.block(self.frame_group(f), self.frame_group(g))

    def velocity_block(self, f: int, g: int) -> None:
        """Declare that an element writes velocity-level terms (``cM M + cC C_T``) into the block
        (f, g): the index-2 matrix then has ``-(cM M + cC C_T) B_n^T`` there."""
        self.velocity_blocks([f], [g])

    def velocity_blocks(self, f, g) -> None:
        """:meth:`velocity_block` of arrays of frames (broadcast together, C order)."""
        f, g = np.broadcast_arrays(np.asarray(f, np.int64), np.asarray(g, np.int64))
        self._vel.append((f.reshape(-1).copy(), g.reshape(-1).copy()))

    def constraint(self, c: int, frames: tuple[int, int, int]) -> None:
        """Declare constraint element c acting on the frames (node A, node B, joint)."""
        self.constraints([c], [frames])

    def constraints(self, c, frames) -> None:
        """:meth:`constraint` of an array of constraint elements (n,) and their frames (n, 3)."""
        c = np.asarray(c, np.int64).reshape(-1)
        self._con.append((c, np.asarray(frames, np.int64).reshape(len(c), 3)))

    def log_needed(self, f) -> None:
        """The log coordinates of joint frame f (or of an array of them) are needed inside the
        Newton iterations."""
        self._logs.append(np.asarray(f, np.int64).reshape(-1))

    def _constraint_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        if not self._con:
            return np.zeros(0, np.int64), np.zeros((0, 3), np.int64)
        return (np.concatenate([c for c, _ in self._con]),
                np.concatenate([f for _, f in self._con]))

    def _velocity_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The distinct velocity-level blocks (f, g) in order of first declaration."""
        if not self._vel:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        f = np.concatenate([a for a, _ in self._vel])
        g = np.concatenate([b for _, b in self._vel])
        u, _ = _first_order(f * self.F + g)
        return u // self.F, u % self.F

    # --- the pattern, derived from the blocks ------------------------------------------------
    def block_table(self, index2: bool) -> np.ndarray:
        """The rows of :attr:`blocks_table` of the index-3 or the stabilized index-2 matrix."""
        return self.blocks_table if index2 else np.ascontiguousarray(
            self.blocks_table[:self.nblocks3])

    def entries(self, index2: bool) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) (nvals,) of every value of the index-3 or index-2 matrix."""
        b = self.block_table(index2)
        nv = self.nvals2 if index2 else self.nvals
        rows = np.empty(nv, np.int64)
        cols = np.empty(nv, np.int64)
        for (nr, nc), sel in _by_shape(b):
            ii, jj = np.divmod(np.arange(nr * nc, dtype=np.int64), nc)
            pos = b[sel, 4][:, None] + np.arange(nr * nc)
            rows[pos] = b[sel, 0][:, None] + ii
            cols[pos] = b[sel, 2][:, None] + jj
        return rows, cols

    def csc(self, index2: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Compressed-column pattern of the index-3 or index-2 matrix: ``indptr`` (N+1,),
        ``indices`` (nnz,) (int32, rows increasing in every column) and ``perm`` (nvals,): the
        position of every value in it (blocks do not overlap: nnz = nvals), by the compiled
        ``block_csc`` (``_core/block_pattern.hpp``, which the stepper uses too)."""
        from se3dyn.engine.compiled import compiled

        s = self.s
        N = s.nq + (2 * s.nm if index2 else s.nm)
        nv = self.nvals2 if index2 else self.nvals
        indptr = np.empty(N + 1, np.int32)
        indices = np.empty(nv, np.int32)
        src = np.empty(nv, np.int64)  # the value of every entry
        compiled().block_csc(N, self.block_table(index2), nv, indptr, indices, src)
        perm = np.empty(nv, np.int64)
        perm[src] = np.arange(nv, dtype=np.int64)
        return indptr, indices, perm

    @property
    def rows2(self):
        return self.entries(True)[0]

    @property
    def cols2(self):
        return self.entries(True)[1]

    @property
    def rows3(self):
        return self.entries(False)[0]

    @property
    def cols3(self):
        return self.entries(False)[1]


def _by_shape(b: np.ndarray):
    """(rows, columns) and the indices of the blocks of that shape, for every shape in b."""
    if len(b) == 0:
        return []
    shp = b[:, 1] * 64 + b[:, 3] if b[:, 3].max(initial=0) < 64 else b[:, 1] * (
        int(b[:, 3].max()) + 1) + b[:, 3]
    u, inv = np.unique(shp, return_inverse=True)
    out = []
    for t in range(len(u)):
        sel = np.flatnonzero(inv.reshape(-1) == t)
        out.append(((int(b[sel[0], 1]), int(b[sel[0], 3])), sel))
    return out


def layout(s) -> Layout:
    """The :class:`Layout` of a compiled system (see the module docstring)."""
    return Layout(s)


def _law_size(s) -> int:
    """Values of the user's laws' buffer (engine.hpp, ``Engine::law_out``)."""
    from se3dyn.elements.joint_force import law_table

    return law_table(s)[1]


def _drive_table(s) -> np.ndarray:
    """(nd, 5) per driven coordinate: its unknown, its kind (0 position, 1 velocity) and the
    input slots of its position (-1 for a velocity driver), rate and acceleration
    (newton.hpp, Stepper::prescribe)."""
    slots = np.array(s.inputs.drive_slots, np.int64).reshape(-1, 3)
    return np.ascontiguousarray(np.column_stack([s.drive_dof, s.drive_kind, slots]),
                                np.int64).reshape(-1, 5)


def _merge_list(rows, cols, lead, follow, ratio) -> tuple[np.ndarray, np.ndarray]:
    """(src, dst) value pairs (., 2) and factors of the couplings' merges over the values at
    (rows, cols): every value in a follower's column into its leader's column, then every
    value in a follower's row into its leader's row (engine.hpp, ``Stepper::apply_merges``)."""
    if not len(follow):
        return np.zeros((0, 2), np.int64), np.zeros(0)
    N = int(max(rows.max(), cols.max())) + 1
    key = rows * N + cols
    order = np.argsort(key)
    skey = key[order]
    src, dst, fac = [], [], []
    for axis in (1, 0):
        for a, b, r in zip(lead, follow, ratio, strict=True):
            sel = np.flatnonzero((cols if axis else rows) == b)
            k = (rows[sel] * N + a) if axis else (a * N + cols[sel])
            i = np.searchsorted(skey, k)
            if np.any(i >= len(skey)) or np.any(skey[np.minimum(i, len(skey) - 1)] != k):
                raise KeyError("coupling merge: a block not registered")  # (a layout bug)
            src.append(sel)
            dst.append(order[i])
            fac.append(np.full(len(sel), float(r)))
    return (np.ascontiguousarray(np.column_stack([np.concatenate(src), np.concatenate(dst)]),
                                 np.int64), np.concatenate(fac))
