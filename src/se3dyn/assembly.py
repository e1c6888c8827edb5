"""One assembler for every element type: the numbering of frames, the fixed block pattern built
from the elements' dof maps, and the tables of the compiled engine (:mod:`se3dyn._engine`).

Every configuration variable is a *frame* (Eq. (12)): frames ``0..M-1`` are the nodes, frames
``M..M+m-1`` the joint transformations. Frame f has ``k_f`` unknowns (6 for a free node, 0 for
a clamped node or a rigid joint, k of Table 1 for a joint) and the constant matrix ``A_f`` (the
identity for nodes, Eq. (9) for joints). Elements touch frames (their *dof map*) and, for
constraint elements, own multiplier rows; the iteration matrix is a set of dense blocks, one per
pair of row and column groups (frame unknowns, multipliers, index-2 multipliers xi), listed
once here and filled by the element kernels of the engine in place.

The matrix values are stored block after block, each block row-major; ``rows``/``cols`` give
the position of every value in the matrix (index-3 blocks first, then those that only the
stabilized index-2 matrix has).
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie

__all__ = ["Layout", "layout"]


class _Blocks:
    """Registry of the dense blocks of the iteration matrix."""

    def __init__(self, size):
        self.size = size  # group -> (first row, count)
        self.off: dict[tuple, int] = {}
        self.keys: list[tuple] = []
        self.n = 0

    def __call__(self, rg, cg) -> int:
        if rg is None or cg is None:
            return -1
        key = (rg, cg)
        o = self.off.get(key)
        if o is None:
            r = self.size(rg)[1]
            c = self.size(cg)[1]
            if r == 0 or c == 0:
                return -1
            o = self.n
            self.off[key] = o
            self.keys.append(key)
            self.n += r * c
        return o


class Layout:
    """Frames, element tables, block pattern and input slots of a compiled system.

    Attributes
    ----------
    tables : dict
        The arrays handed to :class:`se3dyn._engine.Engine`.
    nvals, nvals2 : int
        Number of values of the index-3 matrix and of the stabilized index-2 matrix.
    rows3, cols3, rows2, cols2 : ndarray (nvals,), (nvals2,)
        Matrix position of every value.
    groups3, groups2 : ndarray (N,)
        Block-group id of every matrix row (for the ordering of the sparse LU).
    """

    def __init__(self, s, inputs) -> None:
        M, m, nq, nm = s.M, s.m, s.nq, s.nm
        F = M + m
        dof = np.full(F, -1, np.int64)
        k = np.zeros(F, np.int64)
        node = np.zeros(F, np.int64)
        joint = np.zeros(F, np.int64)
        A = np.zeros((F, 6, 6))
        node[:M] = 1
        joint[M:] = 1
        A[:M] = np.eye(6)
        for i in range(M):
            if not s.node_fixed[i]:
                dof[i] = s.node_dofadr[i]
                k[i] = 6
        for g in s.groups:
            for row, j in enumerate(g.ids):
                f = M + j
                k[f] = g.k
                if g.k:
                    dof[f] = s.joint_dofadr[j]
                    A[f, :, :g.k] = g.A[row]
        self.F = F
        self.frame_dof, self.frame_k = dof, k

        def size(gr):
            kind, i = gr
            if kind == "f":
                return int(dof[i]), int(k[i])
            if kind == "c":
                return nq + int(s.joint_multadr[i]), 6
            return nq + nm + int(s.joint_multadr[i]), 6

        fg = lambda f: ("f", int(f)) if k[f] else None  # noqa: E731
        blk = _Blocks(size)
        t: dict = {}
        # every free frame has its diagonal block (structural diagonal for the LU)
        for f in range(F):
            blk(fg(f), fg(f))
        # rigid bodies (nodes with inertia), Eqs. (47)-(53)
        bodies = [i for i in range(M) if s.node_mass[i] > 0 or np.any(s.node_J[i] != 0)]
        bM = np.zeros((len(bodies), 6, 6))
        bmc = np.zeros((len(bodies), 3))
        for e, i in enumerate(bodies):
            m_i, c = s.node_mass[i], s.node_com[i]
            C = lie.hat3(c)
            bM[e, :3, :3] = m_i * np.eye(3)
            bM[e, :3, 3:] = -m_i * C
            bM[e, 3:, :3] = m_i * C
            bM[e, 3:, 3:] = s.node_J[i] - m_i * C @ C
            bmc[e] = m_i * c
        t.update(body_frame=np.array(bodies, np.int64), body_M=bM, body_mc=bmc,
                 body_m=np.array([s.node_mass[i] for i in bodies], float),
                 body_off=np.array([blk(fg(i), fg(i)) for i in bodies], np.int64))
        vel_blocks = [(i, i) for i in bodies]
        # joints (constraints), Eqs. (54)-(59)
        ja, jb = s.joint_a, s.joint_b
        jf = M + np.arange(m)
        cgr = lambda j: ("c", int(j))  # noqa: E731
        offs = {key: [] for key in ("ca", "cb", "cj", "ac", "bc", "jc", "aj", "cc")}
        for j in range(m):
            a, b, fj = ja[j], jb[j], jf[j]
            offs["ca"].append(blk(cgr(j), fg(a)))
            offs["cb"].append(blk(cgr(j), fg(b)))
            offs["cj"].append(blk(cgr(j), fg(fj)))
            offs["ac"].append(blk(fg(a), cgr(j)))
            offs["bc"].append(blk(fg(b), cgr(j)))
            offs["jc"].append(blk(fg(fj), cgr(j)))
            offs["aj"].append(blk(fg(a), fg(fj)))
            blk(cgr(j), cgr(j))
        PA = lie.adjoint_inv(s.joint_XA) if m else np.zeros((0, 6, 6))
        PB = lie.adjoint_inv(s.joint_XB) if m else np.zeros((0, 6, 6))
        offset = np.array([not (np.allclose(s.joint_XA[j], np.eye(4)) and
                                np.allclose(s.joint_XB[j], np.eye(4))) for j in range(m)],
                          np.int64)
        t.update(joint_fa=ja.astype(np.int64), joint_fb=jb.astype(np.int64),
                 joint_fj=jf.astype(np.int64), joint_mult=s.joint_multadr.astype(np.int64),
                 joint_XA=np.ascontiguousarray(s.joint_XA, float),
                 joint_XB=np.ascontiguousarray(s.joint_XB, float), joint_PA=PA, joint_PB=PB,
                 joint_offset=offset)
        for key in ("ca", "cb", "cj", "ac", "bc", "jc", "aj"):
            t["joint_off_" + key] = np.array(offs[key], np.int64)
        # force elements on joint coordinates, Eqs. (60)-(66)
        jfs = []
        nu_tau, nu_ref, nu_rate = {}, {}, {}
        for slot, _k, kind, j in inputs.joint_slots:
            {"tau": nu_tau, "ref": nu_ref, "rate": nu_rate}[kind][j] = slot
        for j in range(m):
            kj = int(s.joint_k[j])
            if not kj:
                continue
            d = s.joint_dofadr[j] + np.arange(kj)
            if (np.any(s.dof_stiffness[d] != 0) or np.any(s.dof_damping[d] != 0)
                    or j in nu_tau or j in nu_ref):
                jfs.append(j)
        nf = len(jfs)
        pad = lambda key: np.array([np.pad(getattr(s, key)[  # noqa: E731
            s.joint_dofadr[j] + np.arange(s.joint_k[j])], (0, 6 - s.joint_k[j])) for j in jfs],
            float).reshape(nf, 6)
        Apinv = np.zeros((nf, 6, 6))
        Aj = np.zeros((nf, 6, 6))
        nonab = np.zeros(nf, np.int64)
        for e, j in enumerate(jfs):
            kj = int(s.joint_k[j])
            Aj[e] = A[M + j]
            Apinv[e, :kj, :] = np.linalg.pinv(A[M + j][:, :kj])
            d = s.joint_dofadr[j] + np.arange(kj)
            nonab[e] = int((not s.joint_abelian[j]) and np.any(s.dof_stiffness[d] != 0))
        t.update(jforce_frame=np.array([M + j for j in jfs], np.int64),
                 jforce_K=pad("dof_stiffness"), jforce_ref=pad("dof_reference"),
                 jforce_C=pad("dof_damping"), jforce_kp=pad("dof_kp"), jforce_kd=pad("dof_kd"),
                 jforce_tau=np.array([nu_tau.get(j, -1) for j in jfs], np.int64),
                 jforce_pref=np.array([nu_ref.get(j, -1) for j in jfs], np.int64),
                 jforce_prate=np.array([nu_rate.get(j, -1) for j in jfs], np.int64),
                 jforce_nonab=nonab, jforce_Apinv=Apinv, jforce_A=Aj,
                 jforce_off=np.array([blk(fg(M + j), fg(M + j)) for j in jfs], np.int64))
        vel_blocks += [(M + j, M + j) for j in jfs]
        # loads at points of bodies (Eqs. (66)-(67))
        ld = inputs.load_slots  # (node, c, force slot, torque slot, force_body, torque_body)
        t.update(load_frame=np.array([x[0] for x in ld], np.int64),
                 load_c=np.array([x[1] for x in ld], float).reshape(len(ld), 3),
                 load_force=np.array([x[2] for x in ld], np.int64),
                 load_torque=np.array([x[3] for x in ld], np.int64),
                 load_force_body=np.array([x[4] for x in ld], np.int64),
                 load_torque_body=np.array([x[5] for x in ld], np.int64),
                 load_off=np.array([blk(fg(x[0]), fg(x[0])) for x in ld], np.int64))
        # point-to-point spring-dampers
        sp = s.springs  # (node a, node b, c_a, c_b, k, d, L0)
        sa = np.array([x[0] for x in sp], np.int64)
        sb = np.array([x[1] for x in sp], np.int64)
        t.update(spring_fa=sa, spring_fb=sb,
                 spring_ca=np.array([x[2] for x in sp], float).reshape(len(sp), 3),
                 spring_cb=np.array([x[3] for x in sp], float).reshape(len(sp), 3),
                 spring_k=np.array([x[4] for x in sp], float),
                 spring_d=np.array([x[5] for x in sp], float),
                 spring_L0=np.array([x[6] for x in sp], float))
        for key, (p, q) in (("aa", (sa, sa)), ("ab", (sa, sb)), ("ba", (sb, sa)),
                            ("bb", (sb, sb))):
            t["spring_off_" + key] = np.array(
                [blk(fg(x), fg(y)) for x, y in zip(p, q, strict=True)], np.int64)
        vel_blocks += [(x, y) for a_, b_ in zip(sa, sb, strict=True)
                       for x in (a_, b_) for y in (a_, b_)]
        self.nvals = blk.n
        # --- index-2 blocks: xi rows x frames, -(cM M + cC C) B_n^T, -B B_n^T
        xg = lambda j: ("x", int(j))  # noqa: E731
        ox = {"xa": [], "xb": [], "xj": []}
        for j in range(m):
            ox["xa"].append(blk(xg(j), fg(ja[j])))
            ox["xb"].append(blk(xg(j), fg(jb[j])))
            ox["xj"].append(blk(xg(j), fg(jf[j])))
        for key in ox:
            t["joint_off_" + key] = np.array(ox[key], np.int64)
        touch: dict[int, list[tuple[int, int]]] = {}  # frame -> [(joint, slot)]
        for j in range(m):
            for slot, f in enumerate((ja[j], jb[j], jf[j])):
                if k[f]:
                    touch.setdefault(int(f), []).append((j, slot))
        velprod = []
        for fi, fj_ in dict.fromkeys((int(x), int(y)) for x, y in vel_blocks):
            if not (k[fi] and k[fj_]):
                continue
            src = blk.off[(fg(fi), fg(fj_))]
            for j, slot in touch.get(fj_, ()):
                velprod.append((blk(fg(fi), xg(j)), src, k[fi], k[fj_], j, slot))
        xiprod = []
        for f, lst in touch.items():
            for c1, s1 in lst:
                for c2, s2 in lst:
                    xiprod.append((blk(xg(c1), xg(c2)), k[f], c1, s1, c2, s2))
        for j in range(m):
            blk(xg(j), xg(j))
        self.nvals2 = blk.n
        t["velprod"] = np.array(velprod, np.int64).reshape(-1, 6)
        t["xiprod"] = np.array(xiprod, np.int64).reshape(-1, 6)
        # log coordinates of non-abelian joints (outputs; springs inside the iterations)
        logs = [j for j in range(m) if s.joint_k[j] and not s.joint_abelian[j]]
        lA = np.zeros((len(logs), 6, 6))
        for e, j in enumerate(logs):
            lA[e, :s.joint_k[j], :] = np.linalg.pinv(A[M + j][:, :s.joint_k[j]])
        need = {int(t["jforce_frame"][e]) for e in range(nf) if nonab[e]}
        t.update(log_frame=np.array([M + j for j in logs], np.int64),
                 log_H0inv=np.ascontiguousarray(lie.inverse(s.joint_H0[logs]))
                 if logs else np.zeros((0, 4, 4)),
                 log_Apinv=lA, log_needed=np.array([int(M + j in need) for j in logs], np.int64))
        t.update(nq=nq, nm=nm, nu=inputs.nu, nvals=self.nvals, nvals2=self.nvals2,
                 frame_dof=dof, frame_k=k,
                 frame_node=node, frame_A=A, frame_joint=joint)
        self.tables = {key: (np.ascontiguousarray(v) if isinstance(v, np.ndarray) else v)
                       for key, v in t.items()}
        # positions of the values and row groups
        rows, cols = [], []
        gid = {}
        for rg, cg in blk.keys:
            r0, nr = size(rg)
            c0, nc = size(cg)
            rows.append(np.repeat(np.arange(r0, r0 + nr), nc))
            cols.append(np.tile(np.arange(c0, c0 + nc), nr))
            gid.setdefault(rg, len(gid))
        rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        cols = np.concatenate(cols) if cols else np.zeros(0, np.int64)
        self.rows2, self.cols2 = rows, cols
        self.rows3, self.cols3 = rows[:self.nvals], cols[:self.nvals]
        groups = np.zeros(nq + 2 * nm, np.int64)
        for g_, i in gid.items():
            r0, nr = size(g_)
            groups[r0:r0 + nr] = i
        self.groups2 = groups
        self.groups3 = groups[:nq + nm]


def layout(s, inputs) -> Layout:
    """The :class:`Layout` of a system (see the module docstring)."""
    return Layout(s, inputs)
