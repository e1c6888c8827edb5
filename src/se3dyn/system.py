"""Compiled system: numbered unknowns, struct-of-arrays element batches, fixed sparsity pattern,
and the vectorised evaluation of the residual (Eq. (39)), the constraints (Eqs. (54)-(56)) and the
iteration matrix (Eq. (46)).

Unknowns (Sec. 3.3, Eq. (14)): for every free node 6 increments ``n_I = (n_U, n_Omega)`` and for
every joint its k relative increments ``n_j`` -> ``nq = 6 M_free + sum k``. Multipliers: 6 per joint
(Eq. (55)) -> ``nm = 6 m``. The iteration matrix has size ``N = nq + nm``.

Naming follows MuJoCo's struct-of-arrays style: ``node_dofadr[i]`` is the first unknown of node i
(-1 for a clamped node), ``joint_dofadr[j]`` the first relative increment of joint j, and
``joint_multadr[j]`` its first multiplier row (in the multiplier vector).

Scaling (the "scaled" iteration matrix). With ``beta' = (1-alpha_m)/(beta h^2 (1-alpha_f))`` the
dynamic rows are divided by beta' and the multiplier columns multiplied by beta' (multipliers
solved as ``lambda / beta'``). The matrix then reads

    [[M + (gamma'/beta') C_T + K_T T / beta',  Phi_q^T],
     [Phi_q* T,                                0      ]]

whose entries are O(1) whatever the step, so Newton converges alike for h = 1e-1 and h = 1e-6
(the unscaled matrix of Eq. (46) has a condition number growing like h^-4).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from se3dyn import lie
from se3dyn.errors import ModelError, SimulationError
from se3dyn.model import Model

__all__ = ["System", "JointGroup", "compile_model", "Evaluation", "evaluate", "matrix_values",
           "LinearSolver", "pattern"]

_COMP6 = ("U_x", "U_y", "U_z", "Omega_x", "Omega_y", "Omega_z")


@dataclass(frozen=True)
class JointGroup:
    """All joints with the same number k of relative coordinates, as arrays.

    Attributes
    ----------
    k : int
    ids : ndarray (nj,)        joint indices
    A : ndarray (nj, 6, k)     subalgebra bases in the material frame of node B (Eq. (9))
    Apinv : ndarray (nj, k, 6) pseudo-inverses of A
    a, b : ndarray (nj,)       node indices of A and B
    dof_a, dof_b : ndarray (nj, 6)  unknown indices of nodes A and B (-1 when clamped)
    jdof : ndarray (nj, k)     unknown indices of the relative increments
    mult : ndarray (nj, 6)     multiplier indices (into the multiplier vector)
    abelian : ndarray (nj,) bool
    H0 : ndarray (nj, 4, 4)    initial joint transformations H_J0 = H_A0^-1 H_B0 (Sec. 5.2);
                               the identity for joints with an attachment point
    has_nonabelian_spring : bool
    XA, XB : ndarray (nj, 4, 4)
        Constant attachment frames of the joint on nodes A and B (the identity for joints
        without ``at``): the joint imposes ``H_B X_B = H_A X_A H_J``, constraints
        ``Phi = vect(G)``, ``G = (H_B X_B)^-1 (H_A X_A) H_J`` (Eq. (55) between the attachment
        frames).
    PA, PB : ndarray (nj, 6, 6)
        ``Ad(X_A^-1)`` and ``Ad(X_B^-1)`` (Eq. (57)): they map node velocities and variations
        (material frame of the node) to those of the attachment frames, ``v_XA = PA v_A``.
    offset : bool
        Some joint of the group has an attachment point (XA, XB not all the identity); when
        False the products with the identity are skipped, so the computation is that of
        Eqs. (55)-(59) exactly.

    The constraint gradient at ``Phi = 0`` (Eq. (58) between the attachment frames) is
    ``[Ad_{H_J^-1} PA, -PB, A]`` (node A, node B, joint coordinates).
    """

    k: int
    ids: np.ndarray
    A: np.ndarray
    Apinv: np.ndarray
    a: np.ndarray
    b: np.ndarray
    dof_a: np.ndarray
    dof_b: np.ndarray
    jdof: np.ndarray
    mult: np.ndarray
    abelian: np.ndarray
    H0: np.ndarray
    has_nonabelian_spring: bool
    XA: np.ndarray
    XB: np.ndarray
    PA: np.ndarray
    PB: np.ndarray
    offset: bool = False


class LayoutCounts:
    """Node and joint counts of anything with ``node_names`` and ``joint_names``."""

    @property
    def M(self) -> int:
        """Number of nodes."""
        return len(self.node_names)

    @property
    def m(self) -> int:
        """Number of joints."""
        return len(self.joint_names)


@dataclass(frozen=True)
class System(LayoutCounts):
    """Frozen arrays describing a compiled model (see the module docstring for the numbering).

    Shapes: M nodes, m joints, nq unknowns, nm = 6 m multipliers, N = nq + nm.
    """

    model: Model
    nq: int
    nm: int
    node_names: tuple[str, ...]
    node_fixed: np.ndarray  # (M,) bool
    node_dofadr: np.ndarray  # (M,) int
    node_free: np.ndarray  # (nf,) node indices of free nodes
    node_dofidx: np.ndarray  # (nf, 6) unknowns of free nodes
    node_mass: np.ndarray  # (M,)
    node_J: np.ndarray  # (M, 3, 3) inertia in the material frame
    node_H0: np.ndarray  # (M, 4, 4)
    node_v0: np.ndarray  # (M, 6) material initial velocities
    joint_names: tuple[str, ...]
    joint_type: tuple[str, ...]
    joint_k: np.ndarray  # (m,)
    joint_dofadr: np.ndarray  # (m,)
    joint_multadr: np.ndarray  # (m,)
    joint_a: np.ndarray  # (m,)
    joint_b: np.ndarray  # (m,)
    joint_H0: np.ndarray  # (m, 4, 4)
    joint_XA: np.ndarray  # (m, 4, 4) attachment frame on node A (identity without ``at``)
    joint_XB: np.ndarray  # (m, 4, 4) attachment frame on node B
    joint_abelian: np.ndarray  # (m,) bool
    groups: tuple[JointGroup, ...]
    # force elements on joint unknowns, (nq,) arrays, zero on node unknowns
    dof_stiffness: np.ndarray
    dof_reference: np.ndarray
    dof_damping: np.ndarray
    dof_kp: np.ndarray
    dof_kd: np.ndarray
    dof_is_joint: np.ndarray  # (nq,) bool
    gravity: np.ndarray  # (3,)
    actuators: tuple  # ((dof indices (k,), TimeFunction, item name), ...)
    controls: tuple  # ((dof indices, target, target_rate or None, item name), ...)
    loads: tuple  # ((node index, force TF or None, torque TF or None, item name), ...)
    labels: tuple[str, ...]  # (N,) item and component of each unknown / constraint row
    items: tuple[str, ...]  # (N,) item name of each row
    length_scale: float
    pattern: dict = field(repr=False)

    @property
    def N(self) -> int:
        return self.nq + self.nm

    @property
    def composites(self) -> dict:
        """Composite joints (e.g. universal): name -> names of their parts."""
        return self.model.composites



# ---------------------------------------------------------------------------------------------
def compile_model(model: Model) -> System:
    """Number the unknowns, batch the elements by type and compute the sparsity pattern once.

    Parameters
    ----------
    model : Model

    Returns
    -------
    System
    """
    if not isinstance(model, Model):
        raise ModelError("compile", "model", "an se3dyn.Model (from ModelBuilder.build())",
                         type(model).__name__)
    nodes = model.nodes
    M = len(nodes)
    nidx = {n.name: i for i, n in enumerate(nodes)}
    node_fixed = np.array([n.fixed for n in nodes], dtype=bool)
    node_dofadr = -np.ones(M, dtype=np.int64)
    nq = 0
    labels: list[str] = []
    items: list[str] = []
    for i, n in enumerate(nodes):
        if not n.fixed:
            node_dofadr[i] = nq
            nq += 6
            labels += [f"node '{n.name}' {c}" for c in _COMP6]
            items += [f"node '{n.name}'"] * 6
    node_free = np.flatnonzero(~node_fixed)
    node_dofidx = node_dofadr[node_free][:, None] + np.arange(6)
    R0 = np.array([n.orientation for n in nodes])
    H0 = lie.make_frame(R0, np.array([n.position for n in nodes]))
    node_mass = np.array([n.mass for n in nodes])
    # inertia to the material frame of the initial configuration: J_mat = R0^T J_in R0 (Sec. 6)
    node_J = np.einsum("nji,njk,nkl->nil", R0, np.array([n.inertia for n in nodes]), R0)
    vin = np.array([n.velocity for n in nodes]).reshape(M, 6)
    node_v0 = np.concatenate([np.einsum("nji,nj->ni", R0, vin[:, :3]),
                              np.einsum("nji,nj->ni", R0, vin[:, 3:])], axis=1)

    joints = model.joints
    m = len(joints)
    joint_k = np.array([j.k for j in joints], dtype=np.int64)
    joint_dofadr = -np.ones(m, dtype=np.int64)
    for jj, j in enumerate(joints):
        if j.k:
            joint_dofadr[jj] = nq
            nq += j.k
            labels += [f"joint '{j.name}' alpha_{c}" for c in range(j.k)]
            items += [f"joint '{j.name}'"] * j.k
    nm = 6 * m
    for j in joints:
        labels += [f"joint '{j.name}' constraint {c}" for c in range(6)]
        items += [f"joint '{j.name}'"] * 6
    joint_multadr = 6 * np.arange(m, dtype=np.int64)
    ja = np.array([nidx[j.node_a] for j in joints], dtype=np.int64)
    jb = np.array([nidx[j.node_b] for j in joints], dtype=np.int64)
    joint_H0 = lie.compose(lie.inverse(H0[ja]), H0[jb]) if m else np.zeros((0, 4, 4))
    # attachment frames: X_A = H_A0^-1 P, X_B = H_B0^-1 P with P = H(I, at); H_J0 = I
    joint_XA = np.broadcast_to(np.eye(4), (m, 4, 4)).copy()
    joint_XB = joint_XA.copy()
    has_at = np.array([j.at is not None for j in joints], dtype=bool)
    if has_at.any():
        sel = np.flatnonzero(has_at)
        P = lie.make_frame(None, np.array([joints[i].at for i in sel]))
        joint_XA[sel] = lie.inverse(H0[ja[sel]]) @ P
        joint_XB[sel] = lie.inverse(H0[jb[sel]]) @ P
        joint_H0[sel] = np.eye(4)
    # A in the material frame of node B: e -> (R_B0^T e_U, R_B0^T e_Omega); with ``at`` the
    # attachment frame of B has the inertial orientation at t0, so A is already material
    A_mat = []
    for jj, j in enumerate(joints):
        if has_at[jj]:
            A_mat.append(np.array(j.A, dtype=float))
            continue
        Rb = R0[jb[jj]]
        A_mat.append(np.concatenate([Rb.T @ j.A[:3], Rb.T @ j.A[3:]], axis=0))
    abelian = np.array([j.abelian for j in joints], dtype=bool)

    dof_K = np.zeros(nq)
    dof_ref = np.zeros(nq)
    dof_C = np.zeros(nq)
    dof_kp = np.zeros(nq)
    dof_kd = np.zeros(nq)
    dof_is_joint = np.zeros(nq, dtype=bool)
    actuators, controls = [], []
    for jj, j in enumerate(joints):
        if not j.k:
            continue
        d = joint_dofadr[jj] + np.arange(j.k)
        dof_is_joint[d] = True
        dof_K[d] = j.stiffness
        dof_ref[d] = j.reference
        dof_C[d] = j.damping
        if j.actuator is not None:
            actuators.append((d, j.actuator, f"joint '{j.name}' actuator"))
        if j.control is not None:
            dof_kp[d] = j.control.kp
            dof_kd[d] = j.control.kd
            controls.append((d, j.control.target, j.control.target_rate,
                             f"joint '{j.name}' control target"))

    groups = []
    for k in sorted(set(joint_k.tolist())):
        ids = np.flatnonzero(joint_k == k)
        A = np.array([A_mat[i] for i in ids]).reshape(len(ids), 6, k)
        dof_a = np.where(node_fixed[ja[ids]][:, None], -1,
                         node_dofadr[ja[ids]][:, None] + np.arange(6))
        dof_b = np.where(node_fixed[jb[ids]][:, None], -1,
                         node_dofadr[jb[ids]][:, None] + np.arange(6))
        jdof = joint_dofadr[ids][:, None] + np.arange(k)
        nonab_spring = bool(np.any([(not abelian[i]) and np.any(joints[i].stiffness != 0)
                                    for i in ids]))
        groups.append(JointGroup(
            k=k, ids=ids, A=A, Apinv=np.linalg.pinv(A) if k else np.zeros((len(ids), 0, 6)),
            a=ja[ids], b=jb[ids], dof_a=dof_a, dof_b=dof_b, jdof=jdof.reshape(len(ids), k),
            mult=joint_multadr[ids][:, None] + np.arange(6), abelian=abelian[ids],
            H0=joint_H0[ids], has_nonabelian_spring=nonab_spring,
            XA=joint_XA[ids], XB=joint_XB[ids], PA=lie.adjoint_inv(joint_XA[ids]),
            PB=lie.adjoint_inv(joint_XB[ids]), offset=bool(np.any(has_at[ids]))))

    loads = tuple((nidx[ld.node], ld.force, ld.torque, f"load '{ld.name}'") for ld in model.loads)
    pos = H0[:, :3, 3]
    L = float(np.max(np.linalg.norm(pos - pos.mean(axis=0), axis=1))) if M else 1.0
    sysd = dict(
        model=model, nq=nq, nm=nm, node_names=tuple(n.name for n in nodes),
        node_fixed=node_fixed, node_dofadr=node_dofadr, node_free=node_free,
        node_dofidx=node_dofidx, node_mass=node_mass, node_J=node_J, node_H0=H0,
        node_v0=node_v0, joint_names=tuple(j.name for j in joints),
        joint_type=tuple(j.type for j in joints), joint_k=joint_k, joint_dofadr=joint_dofadr,
        joint_multadr=joint_multadr, joint_a=ja, joint_b=jb, joint_H0=joint_H0,
        joint_XA=joint_XA, joint_XB=joint_XB,
        joint_abelian=abelian, groups=tuple(groups), dof_stiffness=dof_K, dof_reference=dof_ref,
        dof_damping=dof_C, dof_kp=dof_kp, dof_kd=dof_kd, dof_is_joint=dof_is_joint,
        gravity=model.gravity.copy(), actuators=tuple(actuators), controls=tuple(controls),
        loads=loads, labels=tuple(labels), items=tuple(items), length_scale=max(L, 1.0),
        pattern={})
    return System(**sysd)


# ---------------------------------------------------------------------------------------------
def _block(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row/col indices of a batch of dense blocks: rows (nb, r), cols (nb, c) -> (nb, r, c)."""
    nb, r = rows.shape
    c = cols.shape[1]
    R = np.broadcast_to(rows[:, :, None], (nb, r, c))
    C = np.broadcast_to(cols[:, None, :], (nb, r, c))
    return R.ravel(), C.ravel()


def _joint_pairs(s: System) -> np.ndarray:
    """Pairs of joints sharing a free node, for the block ``B_{n+1} B_n^T`` of the stabilized
    index-2 matrix: rows ``(i, side_i, j, side_j)`` with side 0 = node A, 1 = node B."""
    att: dict[int, list[tuple[int, int]]] = {}
    for j in range(s.m):
        for side, node in ((0, s.joint_a[j]), (1, s.joint_b[j])):
            if not s.node_fixed[node]:
                att.setdefault(int(node), []).append((j, side))
    pairs = [(i, si, j, sj) for lst in att.values() for i, si in lst for j, sj in lst]
    return np.array(pairs, dtype=np.int64).reshape(-1, 4)


def _pattern(s: System, index2: bool = False) -> dict:
    """Fixed sparsity pattern: the (row, col) of every value produced by :func:`matrix_values`, in
    the same order, and the map of each value to its slot in CSC storage (duplicates summed).

    The index-3 matrix has ``N = nq + nm`` rows (unknowns, multipliers); the stabilized index-2
    matrix ``nq + 2 nm`` (unknowns, multipliers, velocity-constraint multipliers xi)."""
    N, rows, cols, pairs = pattern_entries(s, index2)
    keep = np.flatnonzero((rows >= 0) & (cols >= 0))
    key = cols[keep] * N + rows[keep]  # column-major: CSC order after sorting
    uniq, inv = np.unique(key, return_inverse=True)
    indices = (uniq % N).astype(np.int32)
    colnum = uniq // N
    indptr = np.searchsorted(colnum, np.arange(N + 1)).astype(np.int32)
    dense_key = rows[keep] * N + cols[keep]
    return dict(keep=keep, inv=inv, nnz=len(uniq), indices=indices, indptr=indptr,
                dense_key=dense_key, nvals=len(rows), N=N, rows=rows[keep], cols=cols[keep],
                pairs=pairs)


def pattern_entries(s: System, index2: bool = False) -> tuple:
    """(N, rows, cols, pairs) of :func:`_pattern` without the CSC map: the row and column
    (nvals,) of every value of :func:`matrix_values` in order, -1 for values on clamped
    nodes, which are ignored (what the block LU of :mod:`se3dyn.blocklu` needs)."""
    nq, nm = s.nq, s.nm
    N = nq + (2 * nm if index2 else nm)
    rows, cols = [], []

    def add(rr, cc):
        r, c = _block(rr, cc)
        rows.append(r)
        cols.append(c)

    add(s.node_dofidx, s.node_dofidx)
    for g in s.groups:
        mrow = nq + g.mult
        for rr, cc in ((mrow, g.dof_a), (mrow, g.dof_b), (mrow, g.jdof), (g.dof_a, mrow),
                       (g.dof_b, mrow), (g.jdof, mrow), (g.dof_a, g.jdof), (g.jdof, g.jdof)):
            add(rr, cc)
    diag = np.arange(nq, nq + nm)[:, None]
    add(diag, diag)  # zero, or 1 for dropped redundant equations
    pairs = np.zeros((0, 4), np.int64)
    if index2:
        X = nq + nm
        for g in s.groups:
            xrow = X + g.mult
            for rr, cc in ((g.dof_a, xrow), (g.dof_b, xrow), (g.jdof, xrow), (xrow, g.dof_a),
                           (xrow, g.dof_b), (xrow, g.jdof)):
                add(rr, cc)
        pairs = _joint_pairs(s)
        mult6 = 6 * np.arange(s.m)[:, None] + np.arange(6)
        add(X + mult6[pairs[:, 0]], X + mult6[pairs[:, 2]])
        add(X + mult6, X + mult6)  # A A^T of each joint
        add(diag + nm, diag + nm)
    return N, np.concatenate(rows), np.concatenate(cols), pairs


def pattern(s: System, index2: bool = False) -> dict:
    """The (cached) pattern of the index-3 or the stabilized index-2 iteration matrix."""
    key = "index2" if index2 else "index3"
    if key not in s.pattern:
        s.pattern[key] = _pattern(s, index2)
    return s.pattern[key]


# ---------------------------------------------------------------------------------------------
@dataclass
class Evaluation:
    """Everything evaluated at one Newton iterate.

    Attributes
    ----------
    H : (M, 4, 4) node frames; HJ : (m, 4, 4) joint transformations
    r : (nq,) residual of Eq. (39); phi : (nm,) constraints Eq. (55)
    alpha : (nq,) relative coordinates (joint unknowns; zero on node unknowns)
    f_scale : float, magnitude of the forces entering r (for relative tolerances)
    values : (nvals,) iteration-matrix values in pattern order, or None
    psi : (nm,) velocity constraints ``Phi_q v`` (only when asked for), or None
    """

    H: np.ndarray
    HJ: np.ndarray
    r: np.ndarray
    phi: np.ndarray
    alpha: np.ndarray
    f_scale: float
    values: np.ndarray | None = None
    cache: dict | None = field(default=None, repr=False)
    psi: np.ndarray | None = None


def _lam_matrix(lam: np.ndarray) -> np.ndarray:
    """(nj, 6) -> (nj, 6, 6): the matrix Lambda with ad6(d)^T lam = Lambda d."""
    out = np.zeros(lam.shape[:-1] + (6, 6))
    LU = lie.hat3(lam[..., :3])
    out[..., :3, 3:] = LU
    out[..., 3:, :3] = LU
    out[..., 3:, 3:] = lie.hat3(lam[..., 3:])
    return out


def evaluate(s: System, Hn: np.ndarray, HJn: np.ndarray, alpha_n: np.ndarray, n: np.ndarray,
             v: np.ndarray, vd: np.ndarray, lam: np.ndarray, inputs: dict,
             coef: tuple[float, float, float] | None = None, *,
             full_alpha: bool = True, velocity: bool = False) -> Evaluation:
    """Evaluate the residual, the constraints and (if ``coef``) the scaled iteration matrix.

    Parameters
    ----------
    s : System
    Hn : (M, 4, 4), HJn : (m, 4, 4)
        Frames at the start of the step; the iterate is ``H = Hn exp(n)`` (Eq. (38)).
    alpha_n : (nq,)
        Relative coordinates at the start of the step (joint unknowns).
    n, v, vd : (nq,)
        Increments (Eq. (41)), velocities and accelerations of the iterate.
    lam : (nm,)
        Multipliers.
    inputs : dict
        Time-dependent loads at the end of the step: ``f`` (M, 3) inertial forces incl. gravity,
        ``m`` (M, 3) material torques, ``tau`` (nq,) actuator forces, ``ref`` and ``rate`` (nq,)
        PD targets.
    coef : (cM, cC, cK) or None
        Coefficients of M, C_T and K_T T in the iteration matrix (``(1, gamma'/beta', 1/beta')``
        for the scaled Newton matrix; ``(1, 0, 0)`` for the initial accelerations). When None,
        the matrix is not evaluated; :func:`matrix_values` evaluates it later from the cached
        intermediates.
    full_alpha : bool
        Compute the log coordinates of non-abelian joints even where no spring needs them
        (False inside Newton iterations; see :func:`fill_log_coordinates`).
    velocity : bool
        Also evaluate the velocity constraints ``psi = Phi_q v`` (nm,) (Eq. (58) applied to v:
        ``Ad_{H_J^-1} PA v_A - PB v_B + A v_J`` per joint, ``PA = Ad(X_A^-1)``,
        ``PB = Ad(X_B^-1)``, the identity for joints without offsets) for the stabilized index-2
        formulation.

    Notes
    -----
    Joints (Eqs. (55)-(58)) act between the attachment frames ``H_A X_A`` and ``H_B X_B``
    (``X = I`` without ``at``): ``G = (H_B X_B)^-1 (H_A X_A) H_J``, ``Phi = vect(G)``; the
    forces ``Phi_q^T lambda`` are ``PA^T Ad_{H_J^-1}^T lambda`` on node A, ``-PB^T lambda`` on
    node B and ``A^T lambda`` on the joint coordinates (Eq. (58), at ``Phi = 0``).

    Returns
    -------
    Evaluation
    """
    nq = s.nq
    M = s.M
    # --- nodes: H = Hn exp(n_I) (Eq. (38)), T_SE(3)(n_I) (Eq. (21))
    n_node = np.zeros((M, 6))
    n_node[s.node_free] = n[s.node_dofidx]
    H = Hn.copy()
    E, Tf = lie.exp_tangent_se3(n_node[s.node_free])
    H[s.node_free] = Hn[s.node_free] @ E
    Tn = np.broadcast_to(np.eye(6), (M, 6, 6)).copy()
    Tn[s.node_free] = Tf
    R = H[:, :3, :3]
    vb = v[s.node_dofidx]  # (nf, 6)
    vdb = vd[s.node_dofidx]
    mass = s.node_mass[s.node_free]
    J = s.node_J[s.node_free]
    vU, vO = vb[:, :3], vb[:, 3:]
    JO = np.einsum("nij,nj->ni", J, vO)
    # inertia forces, Eq. (51)
    fin = np.concatenate([mass[:, None] * (vdb[:, :3] + np.cross(vO, vU)),
                          np.einsum("nij,nj->ni", J, vdb[:, 3:]) + np.cross(vO, JO)], axis=1)
    # external forces, Eq. (66): g_ext,I = (R^T f, m)
    RtF = np.einsum("nji,nj->ni", R[s.node_free], inputs["f"][s.node_free])
    gext = np.concatenate([RtF, inputs["m"][s.node_free]], axis=1)
    r = np.zeros(nq + 1)  # last slot collects contributions to clamped nodes
    r[s.node_dofidx] = fin - gext
    f_scale = max(float(np.abs(fin).max(initial=0.0)), float(np.abs(gext).max(initial=0.0)))
    cache: dict = {"nodes": (Tn, RtF, mass, J, vU, vO, JO), "groups": []}

    # --- joints, generic kernel over the batches of equal k
    m = s.m
    HJ = np.zeros((m, 4, 4))
    phi = np.zeros(s.nm)
    psi = np.zeros(s.nm) if velocity else None
    alpha = np.zeros(nq)
    lam_max = float(np.abs(lam).max(initial=0.0))
    gint_max = 0.0
    for g in s.groups:
        k, nj = g.k, len(g.ids)
        if k:
            nJ = np.einsum("jik,jk->ji", g.A, n[g.jdof])
            EJ, TJ6 = lie.exp_tangent_se3(nJ)
            HJg = HJn[g.ids] @ EJ
            TJ = TJ6 @ g.A  # Eqs. (27), (59)
        else:
            HJg = HJn[g.ids].copy()
            TJ = np.zeros((nj, 6, 0))
        HJ[g.ids] = HJg
        Ad = lie.adjoint_inv(HJg)  # Eq. (57)
        lg = lam[g.mult]  # (nj, 6)
        if g.offset:
            # attachment frames H_A X_A, H_B X_B: G = (H_B X_B)^-1 H_A X_A H_J; a variation
            # H_A exp(d_a) gives G exp(Ad PA d_a), H_B exp(d_b) gives G exp(-Ad(G^-1) PB d_b)
            G = lie.inverse(H[g.b] @ g.XB) @ (H[g.a] @ g.XA) @ HJg
            AdP = Ad @ g.PA
            rb = np.einsum("jki,jk->ji", g.PB, lg)  # PB^T lambda
        else:
            G = lie.inverse(H[g.b]) @ H[g.a] @ HJg
            AdP = Ad
            rb = lg
        phi[g.mult] = lie.vect_se3(G)  # Eq. (55)
        AdT = np.swapaxes(AdP, 1, 2)  # (Ad PA)^T: node-A block of Phi_q^T
        ra = np.einsum("jik,jk->ji", AdT, lg)  # Phi_q^T lambda, Eq. (58)
        r += np.bincount(np.where(g.dof_a < 0, nq, g.dof_a).ravel(), ra.ravel(), nq + 1)
        r -= np.bincount(np.where(g.dof_b < 0, nq, g.dof_b).ravel(), rb.ravel(), nq + 1)
        TA = TAinvT = None
        K = C = kp = kd = None
        if k:
            jd = g.jdof
            rj = np.einsum("jik,ji->jk", g.A, lg)
            # relative coordinates: Eq. (60) for abelian joints; log coordinates otherwise
            a_ab = alpha_n[jd] + n[jd]
            if np.all(g.abelian) or not (full_alpha or g.has_nonabelian_spring):
                a_g = a_ab  # non-abelian entries filled by log_coordinates() when asked
            else:
                a_g = np.where(g.abelian[:, None], a_ab, log_coordinates(g, HJg))
            alpha[jd] = a_g
            K = s.dof_stiffness[jd]
            C = s.dof_damping[jd]
            kp = s.dof_kp[jd]
            kd = s.dof_kd[jd]
            vj = v[jd]
            fs = K * (a_g - s.dof_reference[jd])
            if g.has_nonabelian_spring:
                # g = T_A(alpha)^-T K (alpha - alpha0) for non-abelian joints
                TA = g.Apinv @ lie.tangent_se3(np.einsum("jik,jk->ji", g.A, a_g)) @ g.A
                TAinvT = np.swapaxes(np.linalg.inv(TA), 1, 2)
                fs = np.where(g.abelian[:, None], fs, np.einsum("jkl,jl->jk", TAinvT, fs))
            gint = fs + C * vj + kp * (a_g - inputs["ref"][jd]) + kd * (vj - inputs["rate"][jd])
            gint_max = max(gint_max, float(np.abs(gint).max(initial=0.0)))
            r[jd] += rj + gint - inputs["tau"][jd]  # Eqs. (62), (64), (66)
        w = None
        if velocity:
            vA = np.where(g.dof_a < 0, 0.0, v[np.maximum(g.dof_a, 0)])
            vB = np.where(g.dof_b < 0, 0.0, v[np.maximum(g.dof_b, 0)])
            w = np.einsum("jik,jk->ji", AdP, vA)
            if g.offset:
                vB = np.einsum("jik,jk->ji", g.PB, vB)
            psi[g.mult] = w - vB + (np.einsum("jik,jk->ji", g.A, v[g.jdof]) if k else 0.0)
        # per group: G, Ad PA (node-A constraint block), its transpose, T_J A, lambda, force
        # elements, spring tangents, w = Ad PA v_A
        cache["groups"].append((G, AdP, AdT, TJ, lg, K, C, kp, kd, TA, TAinvT, w))
    f_scale = max(f_scale, lam_max, gint_max,
                  float(np.abs(inputs["tau"]).max(initial=0.0)))
    ev = Evaluation(H=H, HJ=HJ, r=r[:nq], phi=phi, alpha=alpha, f_scale=f_scale, psi=psi)
    ev.cache = cache
    if coef is not None:
        ev.values = matrix_values(s, ev, coef)
    return ev


def log_coordinates(g: JointGroup, HJ: np.ndarray) -> np.ndarray:
    """Log coordinates of joints in the basis A: ``A^+ log(H_J0^-1 H_J)``, shape (nj, k).

    For abelian joints they equal the relative coordinates of Eq. (60) modulo 2 pi; for
    non-abelian joints (spherical, planar) they are *the* coordinates (|rotation| <= pi).
    """
    return np.einsum("jki,ji->jk", g.Apinv, lie.log_se3(lie.inverse(g.H0) @ HJ))


def fill_log_coordinates(s: System, HJ: np.ndarray, alpha: np.ndarray) -> None:
    """Write the log coordinates of all non-abelian joints into ``alpha`` (nq,), in place."""
    for g in s.groups:
        if g.k and not np.all(g.abelian):
            sel = ~g.abelian
            alpha[g.jdof[sel]] = log_coordinates(g, HJ[g.ids])[sel]


def matrix_values(s: System, ev: Evaluation, coef: tuple[float, float, float],
                  stab: dict | None = None) -> np.ndarray:
    """Values of the scaled iteration matrix (Eq. (46)) at an evaluated iterate, pattern order.

    Parameters
    ----------
    s : System
    ev : Evaluation
        From :func:`evaluate` at the same iterate (with ``velocity=True`` when ``stab``).
    coef : (cM, cC, cK)
        Coefficients of M, C_T and K_T T (see :func:`evaluate`).
    stab : dict or None
        For the stabilized index-2 matrix (pattern ``pattern(s, index2=True)``): ``cv`` =
        1/gamma' (float) and ``Adn`` = list over ``s.groups`` of ``Ad_{H_J,n^-1}`` (nj, 6, 6)
        at the start of the step (the correction direction ``B_n^T``, whose blocks are
        ``(Ad_n PA)^T`` on node A, ``-PB^T`` on node B and ``A^T`` on the joint coordinates).
        The extra blocks are ``-(cM M + cC C) B_n^T`` (dynamic rows, xi columns),
        ``B + cv d(B v)/dn`` with ``B = [Ad PA, -PB, A]`` and ``d(B v)/dn_J = ad(w) T_J A``,
        ``w = Ad PA v_A`` (velocity constraint rows, increment columns) and ``-B B_n^T``
        (velocity constraint rows, xi columns); see :mod:`se3dyn.integrator`.

    Notes
    -----
    Joint blocks (``Ad = Ad_{H_J^-1}``, Eq. (57); ``PA``, ``PB`` of :class:`JointGroup`):
    constraint rows ``D [Ad PA T_A, -Ad_{G^-1} PB T_B, T_J A]`` with ``D`` the derivative of
    ``vect`` at G (the exact linearisation of Eq. (55); Eq. (59) at ``G = I``); multiplier
    columns ``PA^T Ad^T`` (node A), ``-PB^T`` (node B), ``A^T`` (joint); geometric stiffness
    ``-cK PA^T Ad^T Lambda(lambda) T_J A`` (joint columns of the node-A rows).

    Returns
    -------
    ndarray (nvals,)
    """
    cM, cC, cK = coef
    Tn, RtF, mass, J, vU, vO, JO = ev.cache["nodes"]
    nf = len(s.node_free)
    blk = np.zeros((nf, 6, 6))
    blk[:, :3, :3] = mass[:, None, None] * np.eye(3)
    blk[:, 3:, 3:] = J
    blk *= cM
    if cC:
        # tangent damping, Eq. (53)
        CT = np.zeros((nf, 6, 6))
        CT[:, :3, :3] = mass[:, None, None] * lie.hat3(vO)
        CT[:, :3, 3:] = -mass[:, None, None] * lie.hat3(vU)
        CT[:, 3:, 3:] = lie.hat3(vO) @ J - lie.hat3(JO)
        blk += cC * CT
    blk_m = blk.copy() if stab is not None else None  # d r / d m (velocity-level part)
    if cK:
        # tangent stiffness of the external forces, Eq. (67), times T_SE(3)(n_I)
        KT = np.zeros((nf, 6, 6))
        KT[:, :3, 3:] = -lie.hat3(RtF)
        blk += cK * (KT @ Tn[s.node_free])
    vals = [blk.ravel()]
    for g, (G, AdP, AdT, TJ, lg, K, C, kp, kd, TA, TAinvT, _w) in zip(
            s.groups, ev.cache["groups"], strict=True):
        k, nj = g.k, len(g.ids)
        RG = G[:, :3, :3]
        Dv = np.zeros((nj, 6, 6))
        Dv[:, :3, :3] = RG
        Dv[:, 3:, 3:] = 0.5 * (np.trace(RG, axis1=1, axis2=2)[:, None, None] * np.eye(3)
                               - np.swapaxes(RG, 1, 2))
        # exact linearisation of vect(G), G = (H_B X_B)^-1 H_A X_A H_J; equals Eq. (59) (with
        # the offsets PA, PB) when Phi = 0. AdP = Ad_{H_J^-1} PA
        CA = Dv @ AdP @ Tn[g.a]
        if g.offset:
            CB = -Dv @ lie.adjoint_inv(G) @ g.PB @ Tn[g.b]
            FB = -np.swapaxes(g.PB, 1, 2)
        else:
            CB = -Dv @ lie.adjoint_inv(G) @ Tn[g.b]
            FB = np.broadcast_to(-np.eye(6), (nj, 6, 6))
        CJ = Dv @ TJ
        vals += [CA.ravel(), CB.ravel(), CJ.ravel(), AdT.ravel(), FB.ravel(),
                 np.swapaxes(g.A, 1, 2).ravel()]
        # geometric stiffness of Phi_q^T lambda w.r.t. the joint increment:
        # d/dn_J (PA^T Ad^T lambda) = -PA^T Ad^T Lambda(lambda) T_J A
        vals.append((-cK * (AdT @ _lam_matrix(lg) @ TJ)).ravel())
        if k:
            KJ = np.zeros((nj, k, k))
            idx = np.arange(k)
            KJ[:, idx, idx] = cK * (K + kp) + cC * (C + kd)
            if g.has_nonabelian_spring:
                # d alpha = T_A(alpha)^-1 T_A(n_j) d n_j for log coordinates
                TAn = g.Apinv @ TJ
                Knon = cK * (TAinvT @ (K[:, :, None] * np.linalg.inv(TA)) @ TAn)
                Knon[:, idx, idx] += cC * (C + kd)
                sel = ~g.abelian
                KJ[sel] = Knon[sel]
            vals.append(KJ.ravel())
    vals.append(np.zeros(s.nm))  # multiplier diagonal (used for dropped equations)
    if stab is not None:
        vals += _stab_values(s, ev, blk_m, coef, stab)
    return np.concatenate(vals)


def _stab_values(s: System, ev: Evaluation, blk_m: np.ndarray, coef, stab: dict) -> list:
    """Extra values of the stabilized index-2 matrix, in the order of :func:`_pattern`."""
    cC = coef[1]
    cv = stab["cv"]
    free_pos = np.maximum(s.node_dofadr, 0) // 6  # node -> index among free nodes
    vals = []
    Ad_all = np.zeros((s.m, 6, 6))
    Adn_all = np.zeros((s.m, 6, 6))
    PB_all = np.zeros((s.m, 6, 6))
    for g, cg, Adn in zip(s.groups, ev.cache["groups"], stab["Adn"], strict=True):
        G, AdP, AdT, TJ, lg, K, C, kp, kd, TA, TAinvT, w = cg
        k, nj = g.k, len(g.ids)
        if g.offset:
            Adn = Adn @ g.PA  # node-A block of B_n: Ad_{H_J,n^-1} PA
            PB = g.PB
        else:
            PB = np.broadcast_to(np.eye(6), (nj, 6, 6))
        Ad_all[g.ids] = AdP
        Adn_all[g.ids] = Adn
        PB_all[g.ids] = PB
        AdnT = np.swapaxes(Adn, 1, 2)
        # dynamic rows x xi columns: -(dr/dm) B_n^T (node B: -(dr/dm) (-PB)^T)
        vals.append((-blk_m[free_pos[g.a]] @ AdnT).ravel())
        vals.append((blk_m[free_pos[g.b]] @ np.swapaxes(PB, 1, 2) if g.offset
                     else blk_m[free_pos[g.b]]).ravel())
        if k:
            cj = (cC * (C + kd))[:, :, None] * np.swapaxes(g.A, 1, 2)
            vals.append((-cj).ravel())
        # velocity constraint rows x increment columns: B + cv d(B v)/dn, with
        # B = [Ad PA, -PB, A] and d(B v)/dn_J = ad(w) T_J A, w = Ad PA v_A
        vals += [AdP.ravel(), (-PB).ravel()]
        if k:
            vals.append((g.A + cv * (lie.ad6(w) @ TJ)).ravel())
    # velocity constraint rows x xi columns: -B B_n^T over joints sharing a free node
    pairs = pattern(s, True)["pairs"]
    Bi = np.where((pairs[:, 1] == 0)[:, None, None], Ad_all[pairs[:, 0]], -PB_all[pairs[:, 0]])
    Bj = np.where((pairs[:, 3] == 0)[:, None, None], Adn_all[pairs[:, 2]], -PB_all[pairs[:, 2]])
    vals.append((-Bi @ np.swapaxes(Bj, 1, 2)).ravel())
    AAt = np.zeros((s.m, 6, 6))
    for g in s.groups:
        if g.k:
            AAt[g.ids] = g.A @ np.swapaxes(g.A, 1, 2)
    vals.append((-AAt).ravel())
    vals.append(np.zeros(s.nm))
    return vals


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
        self.drop = np.unique(np.asarray(drop, dtype=np.int64))
        self._pat = None  # built on first use: the compiled engine may never need it

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
            rows, cols = self.pat["rows"], self.pat["cols"]
            self._mask = ~(dropped[rows] | dropped[cols])
            self._one = (dropped[rows] & (rows == cols)).astype(float)

    def matrix(self, values: np.ndarray):
        """The matrix (dense ndarray or scipy CSC) from the values in pattern order."""
        p = self.pat
        v = values[p["keep"]]
        if self._mask is not None:
            v = np.where(self._mask, v, 0.0) + self._one
        if self.dense:
            return np.bincount(p["dense_key"], weights=v, minlength=self.N * self.N).reshape(
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
