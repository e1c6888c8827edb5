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

from se3dyn import lie
from se3dyn._lazy import LazyModule
from se3dyn.engine.inputs import _Inputs
from se3dyn.errors import ModelError
from se3dyn.model.contact import contact_pairs
from se3dyn.model.sensors import parse_sensor
from se3dyn.model.specs import Model

sla = LazyModule("scipy.linalg")
sp = LazyModule("scipy.sparse")
spla = LazyModule("scipy.sparse.linalg")


_COMP6 = ("U_x", "U_y", "U_z", "Omega_x", "Omega_y", "Omega_z")


@dataclass(frozen=True)
class JointGroup:
    """All joints with the same number k of relative coordinates, as arrays.

    Attributes
    ----------
    k : int
    ids : ndarray (nj,)        joint indices
    A : ndarray (nj, 6, k)     subalgebra bases in the material frame of node B (Eq. (9))
    a, b : ndarray (nj,)       node indices of A and B
    dof_a, dof_b : ndarray (nj, 6)  unknown indices of nodes A and B (-1 when clamped)
    jdof : ndarray (nj, k)     unknown indices of the relative increments
    mult : ndarray (nj, 6)     multiplier indices (into the multiplier vector)
    abelian : ndarray (nj,) bool
    H0 : ndarray (nj, 4, 4)    initial joint transformations H_J0 = H_A0^-1 H_B0 (Sec. 5.2);
                               the identity for joints with an attachment point
    (The attachment frames of joints with ``at`` are ``System.joint_XA``/``joint_XB``; the
    joint element module turns them into its kernel's tables.)

    The constraint gradient at ``Phi = 0`` (Eq. (58) between the attachment frames) is
    ``[Ad_{H_J^-1} PA, -PB, A]`` (node A, node B, joint coordinates).
    """

    k: int
    ids: np.ndarray
    A: np.ndarray
    a: np.ndarray
    b: np.ndarray
    dof_a: np.ndarray
    dof_b: np.ndarray
    jdof: np.ndarray
    mult: np.ndarray
    abelian: np.ndarray
    H0: np.ndarray


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


@dataclass(frozen=True, eq=False)
class System(LayoutCounts):
    """Frozen arrays describing a compiled model (see the module docstring for the numbering).

    Shapes: M nodes, m joints, nq unknowns, nm = 6 m multipliers, N = nq + nm.

    ``pattern`` caches data derived from the system once and never changed after (the
    :class:`se3dyn.engine.layout.Layout`, the CSC patterns, the redundant equations of the initial
    configuration); scratch of a run lives in a :class:`Workspace`, apart. Systems compare and
    hash by identity.
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
    dof_ki: np.ndarray  # PID integral gains
    dof_limit: np.ndarray  # PID output limits (inf: none)
    dof_armature: np.ndarray  # inertia on joint coordinates (reflected rotor inertia)
    dof_ts: np.ndarray  # sample times of sampled PID laws (0: continuous)
    dof_is_joint: np.ndarray  # (nq,) bool
    #: (nq,) relative coordinates in the initial configuration: the joints' ``initial`` values
    #: (absolute coordinates), zero elsewhere
    alpha0: np.ndarray
    gravity: np.ndarray  # (3,)
    labels: tuple[str, ...]  # (N,) item and component of each unknown / constraint row
    items: tuple[str, ...]  # (N,) item name of each row
    length_scale: float
    pattern: dict = field(repr=False)
    node_com: np.ndarray = None  # (M, 3) centre of mass in the node's material frame
    springs: tuple = ()  # point spring-dampers (node a, node b, c_a, c_b, k, d, L0)
    beams: tuple = ()  # beam elements, see _beams
    inputs: object = None  # _Inputs: slots of the time-dependent inputs u
    #: contact pairs (se3dyn.model.contact.Pair), by the pair rule of se3dyn.model.contact
    contacts: tuple = ()
    #: driven coordinates (ModelBuilder.drive), one entry each: the unknown, 0 for a position
    #: driver or 1 for a velocity one, and the index of its drive in ``model.drives``
    drive_dof: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    drive_kind: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    drive_of: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: couplings (ModelBuilder.coupling), one entry each: the leader's and the follower's
    #: unknowns, ``alpha_follower = ratio alpha_leader + offset``
    cpl_lead: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    cpl_follow: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    cpl_ratio: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cpl_offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: sensors read by sampled PID laws (_sensor_tables), one entry per controlled coordinate
    sensor_dof: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    sensor_kind: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    sensor_node: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    sensor_point: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    sensor_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def N(self) -> int:
        return self.nq + self.nm

    @property
    def composites(self) -> dict:
        """Composite joints (e.g. universal): name -> names of their parts."""
        return self.model.composites



def joint_frames(s: System, H: np.ndarray) -> np.ndarray:
    """The joint transformations ``H_J = (H_A X_A)^-1 H_B X_B`` (Eq. (7) between the attachment
    frames), shape (n, m, 4, 4), of rows of node frames ``H`` (n, M, 4, 4)."""
    HA = H[:, s.joint_a] @ s.joint_XA
    HB = H[:, s.joint_b] @ s.joint_XB
    return lie.inverse(HA) @ HB


def residual_rows(s: System, t: np.ndarray, H: np.ndarray, HJ: np.ndarray, alpha: np.ndarray,
                  v: np.ndarray, vd: np.ndarray, lam: np.ndarray, ws=None) -> np.ndarray:
    """The residual ``r`` (n, nq) of the equations of motion (Eq. (36)) at stored rows (no
    increment): times (n,), node frames (n, M, 4, 4), joint frames (n, m, 4, 4), coordinates,
    velocities, accelerations (n, nq) and multipliers (n, nm), with the inputs at the rows'
    times; by the compiled element kernels, in blocks of 4096 rows. ``ws``: the workspace
    to evaluate in (a new one by default: never the system's shared one)."""
    from se3dyn.engine.inputs import input_table
    from se3dyn.engine.workspace import Workspace, engine_of

    eng, _ = engine_of(s, ws or Workspace(s))
    c = lambda x: np.ascontiguousarray(x, float)  # noqa: E731
    r = np.empty((len(t), s.nq))
    for lo in range(0, len(t), 4096):
        sl = slice(lo, lo + 4096)
        U, _ = input_table(s, np.asarray(t[sl], float))
        F = np.concatenate([H[sl], HJ[sl]], axis=1)
        n = len(U)
        eng.residual_rows(c(F), c(alpha[sl]), c(v[sl]), c(vd[sl]), c(lam[sl]), c(U), r[sl], n)
    return r


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
    nodes, joints = model.nodes, model.joints
    M = len(nodes)
    nidx = {n.name: i for i, n in enumerate(nodes)}
    labels: list[str] = []
    items: list[str] = []
    node = _number_nodes(nodes, labels, items)
    R0, node_tables = _node_tables(nodes)
    H0 = node_tables["node_H0"]
    joint, nq = _number_joints(joints, node["nq"], labels, items)
    ja, jb, has_at, frames = _joint_frames(joints, nidx, H0)
    abelian = _abelian(joints)
    groups = _joint_groups(joint["joint_k"], _joint_bases(joints, R0, jb, has_at), ja, jb,
                           node["node_fixed"], node["node_dofadr"], joint["joint_dofadr"],
                           joint["joint_multadr"], abelian, frames["joint_H0"])
    pos = H0[:, :3, 3]
    L = float(np.max(np.linalg.norm(pos - pos.mean(axis=0), axis=1))) if M else 1.0
    sysd = dict(
        model=model, nq=nq, nm=6 * len(joints), node_names=tuple(n.name for n in nodes),
        node_fixed=node["node_fixed"], node_dofadr=node["node_dofadr"],
        node_free=node["node_free"], node_dofidx=node["node_dofidx"], **node_tables,
        joint_names=tuple(j.name for j in joints), joint_type=tuple(j.type for j in joints),
        **joint, joint_a=ja, joint_b=jb, **frames, joint_abelian=abelian, groups=groups,
        **_dof_tables(joints, joint["joint_dofadr"], nq),
        gravity=model.gravity.copy(), labels=tuple(labels), items=tuple(items),
        length_scale=max(L, 1.0), pattern={}, node_com=_node_com(nodes, H0),
        springs=_springs(model, nidx, H0), beams=_beams(model, nidx),
        contacts=tuple(contact_pairs(model)))
    _lump_beam_masses(sysd, model, nidx)
    sysd.update(_drive_tables(model, joint["joint_dofadr"]))
    sysd.update(_sensor_tables(model, nidx, joint["joint_dofadr"]))
    sysd["inputs"] = _Inputs(sysd, model)
    return System(**sysd)


#: sensor kinds of the compiled kernel (joint_force.hpp): a marker's position component, the
#: distance of two markers, a joint coordinate
SENSOR_KINDS = {"position": 1, "distance": 2, "coordinate": 3}


def _sensor_tables(model: Model, nidx: dict, joint_dofadr: np.ndarray) -> dict:
    """The sensors read by sampled PID laws (``PID(sensor=...)``), one entry per controlled
    coordinate that reads one: ``sensor_dof`` (the coordinate's unknown), ``sensor_kind``
    (:data:`SENSOR_KINDS`), ``sensor_node`` (ns, 2) the markers' nodes, ``sensor_point``
    (ns, 2, 3) their origins in the nodes' material frames, ``sensor_index`` the axis of a
    position or the unknown of a joint coordinate."""
    jidx = {j.name: i for i, j in enumerate(model.joints)}
    out = dict(dof=[], kind=[], node=[], point=[], index=[])
    for jj, j in enumerate(model.joints):
        for c, name in enumerate(getattr(j.control, "sensor", None) or ()):
            ref = parse_sensor(name, f"joint {j.name!r}", "control.sensor")
            mks = [model.marker(m) for m in ref.names] if ref.kind != "coordinate" else []
            mks += [None] * (2 - len(mks))
            out["dof"].append(int(joint_dofadr[jj]) + c)
            out["kind"].append(SENSOR_KINDS[ref.kind])
            out["node"].append([-1 if m is None else nidx[m.node] for m in mks])
            out["point"].append([np.zeros(3) if m is None else m.X[:3, 3] for m in mks])
            out["index"].append(int(joint_dofadr[jidx[ref.names[0]]]) + ref.index
                                if ref.kind == "coordinate" else ref.index)
    n = len(out["dof"])
    return dict(sensor_dof=np.array(out["dof"], np.int64),
                sensor_kind=np.array(out["kind"], np.int64),
                sensor_node=np.array(out["node"], np.int64).reshape(n, 2),
                sensor_point=np.array(out["point"], float).reshape(n, 2, 3),
                sensor_index=np.array(out["index"], np.int64))


def _drive_tables(model: Model, joint_dofadr: np.ndarray) -> dict:
    """``drive_dof``, ``drive_kind`` and ``drive_of`` of the driven coordinates, drive by drive
    (:class:`~se3dyn.model.specs.DriveSpec`), and the couplings' tables (``cpl_*``)."""
    jidx = {j.name: i for i, j in enumerate(model.joints)}
    dof, kind, of = [], [], []
    for d, dr in enumerate(model.drives):
        for jname, i, k in dr.targets:
            dof.append(int(joint_dofadr[jidx[jname]]) + i)
            kind.append(0 if k == "position" else 1)
            of.append(d)
    ends = [[int(joint_dofadr[jidx[c.leader[2]]]) + c.leader[3],
             int(joint_dofadr[jidx[c.follower[2]]]) + c.follower[3]] for c in model.couplings]
    ends = np.array(ends, np.int64).reshape(-1, 2)
    return dict(drive_dof=np.array(dof, np.int64), drive_kind=np.array(kind, np.int64),
                drive_of=np.array(of, np.int64), cpl_lead=ends[:, 0].copy(),
                cpl_follow=ends[:, 1].copy(),
                cpl_ratio=np.array([c.ratio for c in model.couplings], float),
                cpl_offset=np.array([c.offset for c in model.couplings], float))


def _number_nodes(nodes, labels: list, items: list) -> dict:
    """Number the 6 unknowns of every free node (Eq. (14)), appending their row labels.

    Returns ``node_fixed``, ``node_dofadr``, ``node_free``, ``node_dofidx`` and the count ``nq``.
    """
    node_fixed = np.array([n.fixed for n in nodes], dtype=bool)
    node_dofadr = -np.ones(len(nodes), dtype=np.int64)
    nq = 0
    for i, n in enumerate(nodes):
        if not n.fixed:
            node_dofadr[i] = nq
            nq += 6
            labels += [f"node '{n.name}' {c}" for c in _COMP6]
            items += [f"node '{n.name}'"] * 6
    node_free = np.flatnonzero(~node_fixed)
    node_dofidx = node_dofadr[node_free][:, None] + np.arange(6)
    return dict(node_fixed=node_fixed, node_dofadr=node_dofadr, node_free=node_free,
                node_dofidx=node_dofidx, nq=nq)


def _node_tables(nodes) -> tuple[np.ndarray, dict]:
    """Initial orientations R0 and the node tables ``node_H0``, ``node_mass``, ``node_J``
    (material frame) and ``node_v0`` (material velocities)."""
    M = len(nodes)
    R0 = np.array([n.orientation for n in nodes])
    H0 = lie.make_frame(R0, np.array([n.position for n in nodes]))
    node_mass = np.array([n.mass for n in nodes])
    # inertia to the material frame of the initial configuration: J_mat = R0^T J_in R0 (Sec. 6)
    node_J = np.einsum("nji,njk,nkl->nil", R0, np.array([n.inertia for n in nodes]), R0)
    vin = np.array([n.velocity for n in nodes]).reshape(M, 6)
    node_v0 = np.concatenate([np.einsum("nji,nj->ni", R0, vin[:, :3]),
                              np.einsum("nji,nj->ni", R0, vin[:, 3:])], axis=1)
    return R0, dict(node_H0=H0, node_mass=node_mass, node_J=node_J, node_v0=node_v0)


def _number_joints(joints, nq: int, labels: list, items: list) -> tuple[dict, int]:
    """Number the k relative increments of every joint after the node unknowns and its 6
    multipliers (Eq. (55)), appending their row labels; returns the joint tables and ``nq``."""
    m = len(joints)
    joint_k = np.array([j.k for j in joints], dtype=np.int64)
    joint_dofadr = -np.ones(m, dtype=np.int64)
    for jj, j in enumerate(joints):
        if j.k:
            joint_dofadr[jj] = nq
            nq += j.k
            labels += [f"joint '{j.name}' alpha_{c}" for c in range(j.k)]
            items += [f"joint '{j.name}'"] * j.k
    for j in joints:
        labels += [f"joint '{j.name}' constraint {c}" for c in range(6)]
        items += [f"joint '{j.name}'"] * 6
    joint_multadr = 6 * np.arange(m, dtype=np.int64)
    return dict(joint_k=joint_k, joint_dofadr=joint_dofadr, joint_multadr=joint_multadr), nq


def _joint_frames(joints, nidx: dict, H0: np.ndarray) -> tuple:
    """Node indices of the joints, which have an attachment point, and the frames
    ``joint_H0``, ``joint_XA``, ``joint_XB`` (Sec. 5.2)."""
    m = len(joints)
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
    for jj, j in enumerate(joints):  # joints of a condensed model (se3dyn.dynamics.condense)
        if j.frames is not None:
            joint_XA[jj], joint_XB[jj], joint_H0[jj] = j.frames[:3]
    return ja, jb, has_at, dict(joint_H0=joint_H0, joint_XA=joint_XA, joint_XB=joint_XB)


def _joint_bases(joints, R0: np.ndarray, jb: np.ndarray, has_at: np.ndarray) -> list:
    """The subalgebra bases A of the joints in the material frame of node B (Eq. (9))."""
    # A in the material frame of node B: e -> (R_B0^T e_U, R_B0^T e_Omega); with ``at`` the
    # attachment frame of B has the inertial orientation at t0, so A is already material
    A_mat = []
    for jj, j in enumerate(joints):
        if j.frames is not None:
            A_mat.append(np.array(j.frames[3], dtype=float))
            continue
        if has_at[jj]:
            A_mat.append(np.array(j.A, dtype=float))
            continue
        Rb = R0[jb[jj]]
        A_mat.append(np.concatenate([Rb.T @ j.A[:3], Rb.T @ j.A[3:]], axis=0))
    return A_mat


def _abelian(joints) -> np.ndarray:
    """(m,) bool: whether each joint's subalgebra is abelian."""
    abelian_of: dict = {}  # the bracket test once per distinct A (large models repeat a few)
    abelian = np.zeros(len(joints), dtype=bool)
    for jj, j in enumerate(joints):
        A_ = np.asarray(j.A)
        key = (A_.shape, A_.dtype.str, A_.tobytes())
        ab = abelian_of.get(key)
        if ab is None:
            ab = abelian_of[key] = bool(j.abelian)
        abelian[jj] = ab
    return abelian


def _dof_tables(joints, joint_dofadr: np.ndarray, nq: int) -> dict:
    """The (nq,) tables of the force elements on joint unknowns and the initial coordinates
    ``alpha0``, zero on node unknowns."""
    dof_K = np.zeros(nq)
    dof_ref = np.zeros(nq)
    dof_C = np.zeros(nq)
    dof_kp = np.zeros(nq)
    dof_kd = np.zeros(nq)
    dof_ki = np.zeros(nq)
    dof_armature = np.zeros(nq)
    dof_ts = np.zeros(nq)
    dof_limit = np.full(nq, np.inf)
    dof_is_joint = np.zeros(nq, dtype=bool)
    alpha0 = np.zeros(nq)
    for jj, j in enumerate(joints):
        if not j.k:
            continue
        d = joint_dofadr[jj] + np.arange(j.k)
        dof_is_joint[d] = True
        if j.initial is not None:
            alpha0[d] = j.initial
        dof_K[d] = j.stiffness
        dof_ref[d] = j.reference
        dof_C[d] = j.damping
        if j.armature is not None:
            dof_armature[d] = j.armature
        # a PID law behind a gear: the joint receives gear times the motor's torque (gains and
        # limit on the joint side), and the reflected rotor inertia gear^2 J_rotor
        if j.control is not None:
            dof_kp[d] = j.control.kp
            dof_kd[d] = j.control.kd
            if hasattr(j.control, "ki"):  # PID
                N = j.control.gear
                dof_kp[d] = N * j.control.kp
                dof_kd[d] = N * j.control.kd
                dof_ki[d] = N * j.control.ki
                dof_limit[d] = abs(N) * j.control.limit
                dof_armature[d] += N * N * j.control.rotor_inertia
                dof_ts[d] = j.control.sample_time or 0.0
    return dict(dof_stiffness=dof_K, dof_reference=dof_ref, dof_damping=dof_C, dof_kp=dof_kp,
                dof_kd=dof_kd, dof_ki=dof_ki, dof_limit=dof_limit, dof_ts=dof_ts,
                dof_armature=dof_armature,
                dof_is_joint=dof_is_joint,
                alpha0=alpha0)


def _joint_groups(joint_k, A_mat, ja, jb, node_fixed, node_dofadr, joint_dofadr,
                  joint_multadr, abelian, joint_H0) -> tuple[JointGroup, ...]:
    """Batch the joints by their number k of relative coordinates (:class:`JointGroup`)."""
    groups = []
    for k in sorted(set(joint_k.tolist())):
        ids = np.flatnonzero(joint_k == k)
        A = np.array([A_mat[i] for i in ids]).reshape(len(ids), 6, k)
        dof_a = np.where(node_fixed[ja[ids]][:, None], -1,
                         node_dofadr[ja[ids]][:, None] + np.arange(6))
        dof_b = np.where(node_fixed[jb[ids]][:, None], -1,
                         node_dofadr[jb[ids]][:, None] + np.arange(6))
        jdof = joint_dofadr[ids][:, None] + np.arange(k)
        groups.append(JointGroup(
            k=k, ids=ids, A=A, a=ja[ids], b=jb[ids], dof_a=dof_a, dof_b=dof_b,
            jdof=jdof.reshape(len(ids), k), mult=joint_multadr[ids][:, None] + np.arange(6),
            abelian=abelian[ids], H0=joint_H0[ids]))
    return tuple(groups)


def system_of(model: Model | System) -> System:
    """The compiled system of a model, compiled on first use and kept with the (immutable)
    model, so that simulating one model again costs no compilation; a System is returned as
    it is."""
    if isinstance(model, System):
        return model
    s = model.__dict__.get("_system") if isinstance(model, Model) else None
    if s is None:
        s = compile_model(model)
        object.__setattr__(model, "_system", s)
    return s


def _node_com(nodes, H0: np.ndarray) -> np.ndarray:
    """(M, 3) centres of mass in the material frames of the nodes, ``R0^T (com - x0)``."""
    out = np.zeros((len(nodes), 3))
    for i, n in enumerate(nodes):
        if n.com is not None:
            out[i] = H0[i, :3, :3].T @ (n.com - H0[i, :3, 3])
    return out


def _springs(model: Model, nidx: dict, H0: np.ndarray) -> tuple:
    """Point spring-dampers as (node a, node b, c_a, c_b, k, d, L0), the points as material
    offsets ``R0^T (p - x0)`` of their nodes."""
    out = []
    for spec in model.springs:
        a, b = nidx[spec.node_a], nidx[spec.node_b]
        ca = H0[a, :3, :3].T @ (spec.at_a - H0[a, :3, 3])
        cb = H0[b, :3, :3].T @ (spec.at_b - H0[b, :3, 3])
        out.append((a, b, ca, cb, spec.stiffness, spec.damping, spec.length))
    return tuple(out)


def _beams(model: Model, nidx: dict) -> tuple:
    """Beam elements as dicts: node frames ``a, b``, section offsets ``XA, XB`` (4, 4), the
    reference relative motion ``d0 = log(F_a^-1 F_b)`` (6,), the reference length
    ``L = |d0_U|`` (the arc length of the reference screw motion), the section stiffness
    ``K`` and damping ``D`` (6, 6), the beam's name and the element's index in it."""
    out = []
    for spec in model.beams:
        F, X = spec.reference, spec.offsets
        for e in range(spec.elements):
            d0 = lie.log_se3(lie.inverse(F[e]) @ F[e + 1])
            out.append(dict(a=nidx[spec.nodes[e]], b=nidx[spec.nodes[e + 1]], XA=X[e],
                            XB=X[e + 1], d0=d0, L=float(np.linalg.norm(d0[:3])),
                            K=spec.stiffness, D=spec.damping, beam=spec.name, index=e))
    return tuple(out)


def _lump_beam_masses(d: dict, model: Model, nidx: dict) -> None:
    """Lumped beam mass: each element puts half its mass ``mu L`` and half its rotary inertia
    ``L diag(rho I1, rho I2, rho I3)`` (section frame) on each of its two nodes, combined with the
    node's own mass as one rigid body (centre of mass and inertia about it, parallel-axis rule)."""
    if not any(b.mass_per_length > 0 for b in model.beams):
        return
    mass, J, com = d["node_mass"].copy(), d["node_J"].copy(), d["node_com"].copy()
    for el in d["beams"]:
        spec = next(b for b in model.beams if b.name == el["beam"])
        if spec.mass_per_length == 0:
            continue
        m2 = 0.5 * spec.mass_per_length * el["L"]
        Js = 0.5 * el["L"] * np.diag(spec.rotary_inertia)
        for i, X in ((el["a"], el["XA"]), (el["b"], el["XB"])):
            if d["node_fixed"][i]:
                continue
            R = X[:3, :3]
            mass[i], J[i], com[i] = combine_inertia(
                np.array([mass[i], m2]), np.array([com[i], np.zeros(3)]),
                np.array([J[i], R @ Js @ R.T]))
    d["node_mass"], d["node_J"], d["node_com"] = mass, J, com


def combine_inertia(m: np.ndarray, c: np.ndarray, J: np.ndarray
                    ) -> tuple[float, np.ndarray, np.ndarray | None]:
    """Rigid bodies joined into one (Sec. 6): mass, inertia about the joint centre of mass
    (parallel-axis rule) and that centre.

    Parameters
    ----------
    m : ndarray (n,)
        Masses.
    c : ndarray (n, 3)
        Centres of mass (any one frame).
    J : ndarray (n, 3, 3)
        Inertias about them (the same frame).

    Returns
    -------
    M : float
    J : ndarray (3, 3)
    c : ndarray (3,) or None
        None when the bodies have no mass (J is then the sum of the inertias).
    """
    m, c = np.asarray(m, float), np.asarray(c, float)
    M = float(m.sum())
    Js = np.sum(J, axis=0)
    if M <= 0.0:
        return 0.0, Js, None
    com = (m[:, None] * c).sum(axis=0) / M
    d = c - com
    Js = Js + np.einsum("n,nij->ij", m, np.einsum("nk,nk->n", d, d)[:, None, None] * np.eye(3)
                        - np.einsum("ni,nj->nij", d, d))
    return M, 0.5 * (Js + Js.T), com

