"""One assembler for every element type: the numbering of frames, the fixed block pattern built
from the elements' dof maps, and the tables of the compiled engine (:mod:`se3dyn._engine`).

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

Values are stored block after block, each block row-major; ``rows``/``cols`` give the matrix
position of every value (index-3 blocks first, then those only the index-2 matrix has).
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie
from se3dyn.elements import REGISTRY

__all__ = ["Layout", "layout"]


class Layout:
    """Frames, element tables, block pattern and products of a compiled system.

    Attributes
    ----------
    tables : dict
        What :class:`se3dyn._engine.Engine` is built from: frame arrays, ``elements`` (list of
        (type key, arrays)), ``velprod``/``xiprod`` and the log-coordinate tables.
    nvals, nvals2 : int
        Number of values of the index-3 matrix and of the stabilized index-2 matrix.
    rows3, cols3, rows2, cols2 : ndarray (nvals,), (nvals2,)
        Matrix position of every value.
    groups3, groups2 : ndarray (N,)
        Block-group id of every matrix row (for the ordering of the sparse LU).
    """

    def __init__(self, s) -> None:
        self.s = s
        M, m, nq, nm = s.M, s.m, s.nq, s.nm
        F = M + m
        dof = np.full(F, -1, np.int64)
        k = np.zeros(F, np.int64)
        A = np.zeros((F, 6, 6))
        A[:M] = np.eye(6)
        for i in range(M):
            if not s.node_fixed[i]:
                dof[i] = s.node_dofadr[i]
                k[i] = 6
        for g in s.groups:
            for row, j in enumerate(g.ids):
                k[M + j] = g.k
                if g.k:
                    dof[M + j] = s.joint_dofadr[j]
                    A[M + j, :, :g.k] = g.A[row]
        self.F, self.frame_dof, self.frame_k, self.frame_A = F, dof, k, A
        self._off: dict[tuple, int] = {}
        self._keys: list[tuple] = []
        self.n = 0
        self._vel: dict[tuple[int, int], None] = {}
        self._con: list[tuple[int, tuple[int, int, int]]] = []
        self._logs: set[int] = set()
        for f in range(F):  # every free frame has its diagonal block (for the LU)
            self.frame_block(f, f)
        elements = []
        for key, mod in REGISTRY.items():
            elements.append((key, mod.tables(s, self)))
        self.nvals = self.n
        # --- index-2 blocks
        for key, mod in REGISTRY.items():
            if hasattr(mod, "index2_tables"):
                mod.index2_tables(s, self, dict(elements)[key])
        touch: dict[int, list[tuple[int, int]]] = {}  # frame -> [(constraint, slot)]
        for c, frames in self._con:
            for slot, f in enumerate(frames):
                if k[f]:
                    touch.setdefault(int(f), []).append((c, slot))
        velprod = []
        for fi, fj in self._vel:
            if not (k[fi] and k[fj]):
                continue
            src = self._off[(self.frame_group(fi), self.frame_group(fj))]
            for c, slot in touch.get(fj, ()):
                velprod.append((self.block(self.frame_group(fi), self.xi_group(c)), src, k[fi],
                                k[fj], c, slot))
        xiprod = []
        for f, lst in touch.items():
            for c1, s1 in lst:
                for c2, s2 in lst:
                    xiprod.append((self.block(self.xi_group(c1), self.xi_group(c2)), k[f], c1,
                                   s1, c2, s2))
        for c, _ in self._con:
            self.block(self.xi_group(c), self.xi_group(c))
        self.nvals2 = self.n
        # --- relative coordinates of non-abelian joints: log coordinates
        logs = [j for j in range(m) if s.joint_k[j] and not s.joint_abelian[j]]
        lA = np.zeros((len(logs), 6, 6))
        for e, j in enumerate(logs):
            lA[e, :s.joint_k[j], :] = np.linalg.pinv(A[M + j][:, :s.joint_k[j]])
        self.tables = dict(
            nq=nq, nm=nm, nu=s.inputs.nu, nvals=self.nvals, nvals2=self.nvals2,
            frame_dof=dof, frame_k=k, frame_node=(np.arange(F) < M).astype(np.int64),
            frame_A=A, frame_joint=(np.arange(F) >= M).astype(np.int64),
            elements=[(key, {n: np.ascontiguousarray(v) for n, v in t.items()})
                      for key, t in elements],
            velprod=np.array(velprod, np.int64).reshape(-1, 6),
            xiprod=np.array(xiprod, np.int64).reshape(-1, 6),
            log_frame=np.array([M + j for j in logs], np.int64),
            log_H0inv=(np.ascontiguousarray(lie.inverse(s.joint_H0[logs])) if logs
                       else np.zeros((0, 4, 4))),
            log_Apinv=lA,
            log_needed=np.array([int(M + j in self._logs) for j in logs], np.int64))
        # --- positions of the values and row groups
        rows, cols, gid = [], [], {}
        for rg, cg in self._keys:
            r0, nr = self._size(rg)
            c0, nc = self._size(cg)
            rows.append(np.repeat(np.arange(r0, r0 + nr), nc))
            cols.append(np.tile(np.arange(c0, c0 + nc), nr))
            gid.setdefault(rg, len(gid))
        rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        cols = np.concatenate(cols) if cols else np.zeros(0, np.int64)
        self.rows2, self.cols2 = rows, cols
        self.rows3, self.cols3 = rows[:self.nvals], cols[:self.nvals]
        # ordering hint for the sparse LU: each constraint element's rows (multipliers, xi) go in
        # one group with the frames it couples that no earlier constraint took (for a tree or a
        # chain: a joint with its own coordinates and its child node), so the ordering sees the
        # pivots that make its zero diagonal blocks nonsingular together
        owner = {g_: i for g_, i in gid.items()}
        taken: set = set()
        for c, frames in self._con:
            target = owner.get(self.mult_group(c))
            if target is None:
                continue
            for f in frames[1:]:
                fgr = self.frame_group(f)
                if fgr is not None and fgr not in taken:
                    owner[fgr] = target
                    taken.add(fgr)
            owner[self.xi_group(c)] = target
        groups = np.zeros(nq + 2 * nm, np.int64)
        for g_ in gid:
            r0, nr = self._size(g_)
            groups[r0:r0 + nr] = owner[g_]
        self.groups2, self.groups3 = groups, groups[:nq + nm]

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

    def block(self, rg, cg) -> int:
        """Offset of the block (row group, column group) in the values, registering it on
        first use; -1 when either group is None or empty."""
        if rg is None or cg is None:
            return -1
        key = (rg, cg)
        o = self._off.get(key)
        if o is None:
            r, c = self._size(rg)[1], self._size(cg)[1]
            if r == 0 or c == 0:
                return -1
            o = self.n
            self._off[key] = o
            self._keys.append(key)
            self.n += r * c
        return o

    def frame_block(self, f: int, g: int) -> int:
        """:meth:`block` of the unknowns of frames f (rows) and g (columns)."""
        return self.block(self.frame_group(f), self.frame_group(g))

    def velocity_block(self, f: int, g: int) -> None:
        """Declare that an element writes velocity-level terms (``cM M + cC C_T``) into the block
        (f, g): the index-2 matrix then has ``-(cM M + cC C_T) B_n^T`` there."""
        self._vel[(int(f), int(g))] = None

    def constraint(self, c: int, frames: tuple[int, int, int]) -> None:
        """Declare constraint element c acting on the frames (node A, node B, joint)."""
        self._con.append((int(c), tuple(int(f) for f in frames)))

    def log_needed(self, f: int) -> None:
        """The log coordinates of joint frame f are needed inside the Newton iterations."""
        self._logs.add(int(f))

    def _size(self, gr) -> tuple[int, int]:
        kind, i = gr
        s = self.s
        if kind == "f":
            return int(self.frame_dof[i]), int(self.frame_k[i])
        if kind == "c":
            return s.nq + int(s.joint_multadr[i]), 6
        return s.nq + s.nm + int(s.joint_multadr[i]), 6


def layout(s) -> Layout:
    """The :class:`Layout` of a compiled system (see the module docstring)."""
    return Layout(s)
