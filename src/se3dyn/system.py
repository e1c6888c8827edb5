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

import weakref
from dataclasses import dataclass, field

import numpy as np

from se3dyn import lie
from se3dyn._lazy import LazyModule
from se3dyn.errors import ModelError, SimulationError
from se3dyn.model import Model

sla = LazyModule("scipy.linalg")
sp = LazyModule("scipy.sparse")
spla = LazyModule("scipy.sparse.linalg")

__all__ = ["System", "JointGroup", "compile_model", "system_of", "Evaluation", "evaluate",
           "matrix_values", "LinearSolver", "pattern", "step_inputs", "input_table"]

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
    :class:`se3dyn.assembly.Layout`, the CSC patterns, the redundant equations of the initial
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
    for jj, j in enumerate(joints):  # joints of a condensed model (se3dyn.condense)
        if j.frames is not None:
            joint_XA[jj], joint_XB[jj], joint_H0[jj] = j.frames[:3]
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
    abelian_of: dict = {}  # the bracket test once per distinct A (large models repeat a few)
    abelian = np.zeros(m, dtype=bool)
    for jj, j in enumerate(joints):
        A_ = np.asarray(j.A)
        key = (A_.shape, A_.dtype.str, A_.tobytes())
        ab = abelian_of.get(key)
        if ab is None:
            ab = abelian_of[key] = bool(j.abelian)
        abelian[jj] = ab

    dof_K = np.zeros(nq)
    dof_ref = np.zeros(nq)
    dof_C = np.zeros(nq)
    dof_kp = np.zeros(nq)
    dof_kd = np.zeros(nq)
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
        if j.control is not None:
            dof_kp[d] = j.control.kp
            dof_kd[d] = j.control.kd

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
        alpha0=alpha0,
        gravity=model.gravity.copy(), labels=tuple(labels), items=tuple(items),
        length_scale=max(L, 1.0), pattern={}, node_com=_node_com(nodes, H0),
        springs=_springs(model, nidx, H0), beams=_beams(model, nidx))
    _lump_beam_masses(sysd, model, nidx)
    sysd["inputs"] = _Inputs(sysd, model)
    return System(**sysd)


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


class _Inputs:
    """Slots of the time-dependent inputs ``u`` (nu,) handed to the element kernels.

    ``u[0:3]`` is gravity; then per load its force (3) and torque (3) components, per actuated
    joint its k actuator values, per controlled joint its k PD targets and k target rates.
    ``kind`` (nu,) tells each slot's kind (0 gravity, 1 load, 2 actuator, 3 PD target, 4 PD
    target rate), for load stepping in statics.
    """

    def __init__(self, d: dict, model: Model):
        nidx = {n: i for i, n in enumerate(d["node_names"])}
        self.sources = []  # (slot, k, time function, item, what, its rate is the input)
        kind = [0, 0, 0]
        self.load_slots = []
        for ld in model.loads:
            fs = ts = -1
            if ld.force is not None:
                fs = len(kind)
                self.sources.append((fs, 3, ld.force, f"load '{ld.name}'", "force", False))
                kind += [1] * 3
            if ld.torque is not None:
                ts = len(kind)
                self.sources.append((ts, 3, ld.torque, f"load '{ld.name}'", "torque", False))
                kind += [1] * 3
            i = nidx[ld.node]
            R0, x0 = d["node_H0"][i, :3, :3], d["node_H0"][i, :3, 3]
            c = np.zeros(3) if ld.at is None else R0.T @ (ld.at - x0)
            self.load_slots.append((i, c, fs, ts, int(ld.force_frame == "body"),
                                    int(ld.torque_frame == "body")))
        self.joint_slots = []  # (slot, k, kind, joint index)
        for j, js in enumerate(model.joints):
            k = js.k
            if js.actuator is not None:
                item = f"joint '{js.name}' actuator"
                self.joint_slots.append((len(kind), k, "tau", j))
                self.sources.append((len(kind), k, js.actuator, item, "value", False))
                kind += [2] * k
            if js.control is not None:
                item = f"joint '{js.name}' control target"
                tgt, rt = js.control.target, js.control.target_rate
                self.joint_slots.append((len(kind), k, "ref", j))
                self.sources.append((len(kind), k, tgt, item, "target", False))
                kind += [3] * k
                self.joint_slots.append((len(kind), k, "rate", j))
                if rt is None:
                    self.sources.append((len(kind), k, tgt, item, "target rate", True))
                else:
                    self.sources.append((len(kind), k, rt, item, "target_rate", False))
                kind += [4] * k
        self.kind = np.array(kind, np.int64)
        self.nu = len(kind)
        self.gravity = np.asarray(model.gravity, float)


# ---------------------------------------------------------------------------------------------
_CORE = None


def _sample(f, t: float, shape: tuple[int, ...], item: str, what: str) -> np.ndarray:
    """Evaluate a time function, checking shape and finiteness, naming the item on failure."""
    try:
        val = np.asarray(f(t), dtype=float)
        val = np.broadcast_to(val, shape)
    except Exception as exc:  # user callables may raise anything
        raise SimulationError(f"t={t:.9g}: {item}: {what} could not be evaluated to "
                              f"{shape[0]} component(s): {type(exc).__name__}: {exc}") from None
    if not np.all(np.isfinite(val)):
        raise SimulationError(f"t={t:.9g}: {item}: {what} returned a non-finite value {val}")
    return val


def step_inputs(s: System, t: float) -> dict:
    """Time-dependent inputs at time t.

    Returns
    -------
    dict
        ``u`` (nu,): gravity, load forces and torques, actuator values, PD targets and target
        rates in the slots of :class:`se3dyn.system._Inputs` (what the element kernels read).

    Raises
    ------
    SimulationError
        When a time function fails, changes size or returns a non-finite value (naming it).
    """
    ins = s.inputs
    u = np.zeros(ins.nu)
    u[:3] = ins.gravity
    for slot, k, tf, item, what, rate in ins.sources:
        u[slot:slot + k] = _sample(tf.rate if rate else tf, t, (k,), item, what)
    return dict(u=u)


def input_table(s: System, times: np.ndarray) -> tuple[np.ndarray, int]:
    """The inputs ``u`` of :func:`step_inputs` at many times, (nt, nu), one vectorised
    evaluation per time function (:meth:`se3dyn.timefunc.TimeFunction.sample`); where that is
    not possible, time by time. Returns the table and the number of leading rows filled: less
    than nt when a time function fails at ``times[n_ok]`` (the step to that time then
    reports the error, naming the function)."""
    ins = s.inputs
    nt = len(times)
    U = np.zeros((nt, ins.nu))
    U[:, :3] = ins.gravity
    slow = []
    for src in ins.sources:
        slot, k, tf, _item, _what, rate = src
        fn = getattr(tf, "sample_rate" if rate else "sample", None)
        try:
            val = np.asarray(fn(times), dtype=float).reshape(nt, -1)
            val = np.broadcast_to(val, (nt, k))
            ok = bool(np.all(np.isfinite(val)))
        except Exception:  # user code: anything; the per-time path names the failure
            ok = False
        if ok:
            U[:, slot:slot + k] = val
        else:
            slow.append(src)
    if not slow:
        return U, nt
    for row, t in enumerate(times):
        try:
            for slot, k, tf, item, what, rate in slow:
                U[row, slot:slot + k] = _sample(tf.rate if rate else tf, t, (k,), item, what)
        except SimulationError:
            return U, row
    return U, nt


def _core():
    """The compiled module, with the Taylor series of :mod:`se3dyn.lie` handed over once."""
    global _CORE
    if _CORE is None:
        from se3dyn import _engine
        from se3dyn.threads import initial_threads

        _engine.set_series(lie._C2, lie._C3, lie._C4, lie._C5, float(lie.SERIES_CUTOFF))
        _engine.set_threads(initial_threads())
        _CORE = _engine
    return _CORE


def layout_of(s: System):
    """The :class:`se3dyn.assembly.Layout` of a system (built once, then only read)."""
    lay = s.pattern.get("layout")
    if lay is None:
        from se3dyn.assembly import layout

        lay = s.pattern["layout"] = layout(s)
    return lay


#: Stabilized index-2 steps under modified Newton iterate with a block-triangular part of their
#: Newton matrix (one index-3-sized factorisation and a small one instead of a matrix with
#: twice the separators; a step that contracts too slowly goes on with the full matrix:
#: ``_core/newton.hpp``). The converged steps are the same to the Newton tolerances; False
#: iterates with the full matrix (tests compare the two).
SPLIT_INDEX2 = True


class Workspace:
    """The scratch of a run: the compiled engine of a system (its element batches with their
    work arrays) and the Newton steppers (sparse LU factors) by formulation and set of dropped
    equations. One per run (:func:`se3dyn.simulate` makes its own), so runs of one system never
    share work arrays; :func:`workspace` gives a default one for one-off evaluations.

    Parameters
    ----------
    s : System
    """

    def __init__(self, s: System) -> None:
        self.s = s
        self.layout = layout_of(s)
        self.engine = _core().Engine(self.layout.tables)
        self._steppers: dict = {}
        self._memo: dict = {}  # id(stepper) -> (stepper, its serials, SolverMemory it holds)

    def full_matrix_steps(self) -> int:
        """Steps of this workspace's split index-2 steppers done with the full matrix, once the
        split iteration contracted too slowly (``_core/newton.hpp``), over the workspace's
        life."""
        return sum(int(stp.full_steps()) for stp in self._steppers.values())

    def memory(self, stp):
        """The solver memory a stepper holds now (:class:`se3dyn.integrator.SolverMemory`, or
        None): a new object only when it changed since last asked."""
        from se3dyn.integrator import SolverMemory

        ser = stp.serials()
        c = self._memo.get(id(stp))
        if c is not None and c[0] is stp and c[1] == ser:
            return c[2]
        ref = stp.memory()
        mem = None if ref is None else SolverMemory(ref=ref)
        self._memo[id(stp)] = (stp, ser, mem)
        return mem

    def adopt(self, stp, mem) -> None:
        """Make a stepper hold the solver memory ``mem`` of a State (None: none), refactorising
        when it holds another one (a restart, a step repeated from an earlier state), so that
        the steps from that State give the numbers of the run that produced it, bit for bit."""
        ser = stp.serials()
        c = self._memo.get(id(stp))
        if c is not None and c[0] is stp and c[1] == ser and c[2] is mem:
            return
        ref = None if mem is None else mem.ref
        if ref is not None and len(ref) == stp.memory_size() - 1:
            # an index-2 memory without its mode (results files of se3dyn before the split
            # iteration, 2026-11-23): the full matrix's values, so the full matrix's mode
            ref = np.append(ref, 1.0)
        if not stp.holds(ref):
            code = stp.restore(ref)
            # (ref None: the factorisation of the model's generic matrix may fail, e.g. by
            # overflow along a chain of thousands of links with random frames; the stepper then
            # holds no reference and factorises the first matrix of the run anew, as a new
            # stepper whose generic matrix failed does: the same numbers)
            if code != 0 and ref is not None:
                raise SimulationError("restoring the linear solver's factors of the state failed "
                                      f"(LU status {code}): the state does not belong to this "
                                      "model or was altered")
        self._memo[id(stp)] = (stp, stp.serials(), mem)

    def stepper(self, index2: bool, dropped: np.ndarray, keep: bool = True,
                split: bool = True):
        """The compiled Newton stepper for one formulation and one set of dropped (redundant)
        equations, its sparse LU analysed on first use; ``keep=False``: not kept for later
        calls (a one-off solve, e.g. the initial accelerations of an index-2 run);
        ``split``: index 2 iterates with the split matrix (modified Newton; see
        :data:`SPLIT_INDEX2`)."""
        split = bool(split and index2 and SPLIT_INDEX2)
        key = (bool(index2), np.asarray(dropped, np.int64).tobytes(), split)
        stp = self._steppers.get(key)
        if stp is None:
            s = self.s
            drop = np.zeros(s.nm, np.int64)
            drop[np.asarray(dropped, np.int64)] = 1
            lay = self.layout
            groups = lay.groups2 if index2 else lay.groups3
            N = s.nq + (2 * s.nm if index2 else s.nm)
            # the compiled stepper builds its pattern from the layout's blocks
            # (a one-off stepper solves one matrix: no factorisation of the generic matrix
            # as the reference of refactorisations; its one solve factorises afresh)
            stp = _core().Stepper(self.engine, bool(index2), int(N), lay.block_table(index2),
                                  np.ascontiguousarray(groups, np.int64), drop,
                                  split=split, reference=keep)
            if keep:
                self._steppers[key] = stp
        return stp


_DEFAULT_WS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def workspace(s: System) -> Workspace:
    """The default :class:`Workspace` of a system, for evaluations outside a run (statics,
    kinematics, analysis, tests); not for concurrent use (give each run its own)."""
    ws = _DEFAULT_WS.get(s)
    if ws is None:
        ws = _DEFAULT_WS[s] = Workspace(s)
    return ws


def _engine(s: System, ws: Workspace | None = None):
    """The compiled engine of a workspace (the system's default one) and the layout."""
    ws = ws or workspace(s)
    return ws.engine, ws.layout


def _pattern(s: System, index2: bool = False) -> dict:
    """Fixed sparsity pattern of the iteration matrix in CSC storage and the map ``inv`` of each
    value, in the order the engine writes them (:mod:`se3dyn.assembly`), to its slot there
    (blocks do not overlap: one slot per value)."""
    lay = layout_of(s)
    N = s.nq + (2 * s.nm if index2 else s.nm)
    indptr, indices, inv = lay.csc(index2)
    return dict(inv=inv, nnz=len(indices), indices=indices, indptr=indptr.astype(np.int32),
                nvals=len(inv), N=N)


def pattern_entries(s: System, index2: bool = False) -> tuple:
    """(N, rows, cols): the matrix size and the row and column (nvals,) of every value."""
    lay = layout_of(s)
    N = s.nq + (2 * s.nm if index2 else s.nm)
    return (N, *lay.entries(index2))


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
    energy : (6,) kinetic, potential, elastic energy and the actuator, load and dissipation
        powers of the iterate (see :func:`se3dyn.integrator.energies`)
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
    energy: np.ndarray | None = None
    arhs: np.ndarray | None = None


def evaluate(s: System, Hn: np.ndarray, HJn: np.ndarray, alpha_n: np.ndarray, n: np.ndarray,
             v: np.ndarray, vd: np.ndarray, lam: np.ndarray, inputs: dict,
             coef: tuple[float, float, float] | None = None, *,
             full_alpha: bool = True, velocity: bool = False, stab: dict | None = None,
             accel: bool = False, ws: Workspace | None = None) -> Evaluation:
    """Evaluate the residual, the constraints and (if ``coef``) the scaled iteration matrix by
    the element kernels of the compiled engine (one implementation, :mod:`se3dyn.assembly`).

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
        ``u`` (nu,): the time-dependent inputs at the end of the step (:func:`se3dyn.
        integrator.step_inputs`).
    coef : (cM, cC, cK) or None
        Coefficients of M, C_T and K_T T in the iteration matrix (``(1, gamma'/beta', 1/beta')``
        for the scaled Newton matrix; ``(1, 0, 0)`` for the initial accelerations).
    full_alpha : bool
        Compute the log coordinates of non-abelian joints (outputs) too.
    velocity : bool
        Also evaluate the velocity constraints ``psi = Phi_q v`` (nm,) (index 2).
    stab : dict or None
        With ``coef``: the stabilized index-2 matrix, ``cv`` = 1/gamma' (its blocks ``B_n``
        come from the frames at the start of the step, ``Hn``/``HJn``).
    accel : bool
        Also evaluate the right-hand side ``arhs`` (nm,) of the acceleration-level constraints
        ``Phi_q vd = arhs`` (the time derivative of ``Phi_q v = 0``).
    ws : Workspace, optional
        The workspace whose engine evaluates (the system's default one otherwise).

    Returns
    -------
    Evaluation
    """
    eng, lay = _engine(s, ws)
    F = s.M + s.m
    Hall = np.ascontiguousarray(np.concatenate([Hn, HJn]).reshape(F, 4, 4), dtype=float)
    Hout = np.empty_like(Hall)
    r = np.empty(s.nq)
    phi = np.empty(s.nm)
    alpha = np.zeros(s.nq)
    idx2 = stab is not None
    psi = np.empty(s.nm) if (velocity or idx2) else None
    vals = None
    if coef is not None:
        vals = np.empty(lay.nvals2 if idx2 else lay.nvals)
    energy = np.empty(6)
    arhs = np.empty(s.nm)
    c = (0.0, 0.0, 0.0) if coef is None else coef
    u = np.ascontiguousarray(inputs["u"], dtype=float)
    f = lambda x: np.ascontiguousarray(x, dtype=float)  # noqa: E731
    fs = eng.evaluate(Hall, f(alpha_n), f(n), f(v), f(vd), f(lam), u, Hout, r, phi, alpha,
                      psi, vals, energy, float(c[0]), float(c[1]), float(c[2]), idx2,
                      float(stab["cv"]) if idx2 else 0.0, bool(full_alpha),
                      arhs if accel else None)
    ev = Evaluation(H=Hout[:s.M], HJ=Hout[s.M:], r=r, phi=phi, alpha=alpha, f_scale=fs,
                    values=vals, psi=psi if (velocity or idx2) else None, energy=energy,
                    arhs=arhs if accel else None)
    ev.cache = dict(args=(Hn, HJn, alpha_n, n, v, vd, lam, inputs), full_alpha=full_alpha)
    return ev


def increment_correction(s: System, Hn: np.ndarray, HJn: np.ndarray, xi: np.ndarray
                         ) -> np.ndarray:
    """``B_n^T xi`` (nq,): the increment correction of the stabilized index-2 formulation, with
    ``B_n`` the constraint gradient of Eq. (58) at the frames ``Hn`` (M, 4, 4), ``HJn`` (m, 4,
    4) of the start of the step."""
    eng, _ = _engine(s)
    F = s.M + s.m
    Hall = np.ascontiguousarray(np.concatenate([Hn, HJn]).reshape(F, 4, 4), dtype=float)
    out = np.empty(s.nq)
    eng.BnT(Hall, np.ascontiguousarray(xi, dtype=float), out)
    return out


def matrix_values(s: System, ev: Evaluation, coef: tuple[float, float, float],
                  stab: dict | None = None) -> np.ndarray:
    """Values of the scaled iteration matrix (Eq. (46)) at an evaluated iterate, pattern order
    (the element kernels evaluated again at the same iterate, see :func:`evaluate`)."""
    Hn, HJn, alpha_n, n, v, vd, lam, inputs = ev.cache["args"]
    return evaluate(s, Hn, HJn, alpha_n, n, v, vd, lam, inputs, coef,
                    full_alpha=ev.cache["full_alpha"], stab=stab).values


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
        self.drop = np.array(sorted(set(np.asarray(drop, dtype=np.int64).tolist())), np.int64)
        self._pat = None  # built on first use: the compiled engine may never need it
        self._dense_key = None

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
            _, rows, cols = pattern_entries(s, index2)
            self._mask = ~(dropped[rows] | dropped[cols])
            self._one = (dropped[rows] & (rows == cols)).astype(float)

    def matrix(self, values: np.ndarray):
        """The matrix (dense ndarray or scipy CSC) from the values in pattern order."""
        p = self.pat
        v = np.asarray(values)[:p["nvals"]]
        if self._mask is not None:
            v = np.where(self._mask, v, 0.0) + self._one
        if self.dense:
            if self._dense_key is None:
                _, rows, cols = pattern_entries(self.s, self.index2)
                self._dense_key = rows * self.N + cols
            return np.bincount(self._dense_key, weights=v, minlength=self.N * self.N).reshape(
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
