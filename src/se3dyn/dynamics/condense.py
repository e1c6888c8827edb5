"""Condensation of rigid joints for the time loop: nodes joined by rigid joints move as one body.

A rigid joint (Table 1, k = 0) keeps the relative transformation of its nodes constant:
``H_B = H_A C`` with a constant ``C``. The paper's models use them to build a body from several
nodes (the slider-crank of Sec. 11 joins its auxiliary massless nodes 2, 4, 5, 7 to the bodies
3 and 6 by the rigid joints (2), (3), (5), (6)); robot descriptions join sensor and tool frames
by fixed joints. Each rigid joint costs 6 unknowns and 6 multipliers (12 more with the
stabilized index-2 form) in every step, for a motion that is known in closed form.

**What is condensed.** The nodes joined by rigid joints form groups (a spanning forest of the
rigid joints). Every group becomes one node of a *reduced* model: its root node's frame, the
group's whole mass with its centre of mass (``com``) and its inertia about it (parallel-axis
rule, Sec. 6); every other element attached to a member of the group (joints, point
spring-dampers, bushings, loads) is attached to the root at the same material place (joints
through their attachment frames, ``X -> C X``; the others through their points, which are
given in the inertial frame of the initial configuration). The time loop runs on the reduced
model; every stored row is expanded back to the model's own nodes and joints:

* frames ``H_i = H_root C_i``, velocities, accelerations and the generalized-alpha variable
  ``v_i = Ad(C_i^-1) v_root`` (Eqs. (3)-(6) for a constant ``C``);
* the multipliers of a condensed rigid joint from the equations of motion (Eq. (36)) of the
  nodes it carries, member by member from the leaves of its group: the rows of the members
  in ``r(q, v, vd) + B^T lambda = 0`` are a square system in the rigid joints' multipliers,
  with the constant gradient of Eq. (58) (``H_J`` of a rigid joint is constant). They are
  computed when first asked for (:attr:`Results.lam`), by the compiled element kernels of the
  full model.

**Same discrete motion.** The Lie-group update keeps ``H_B = H_A C``: ``H_A exp(n_A) C =
H_A C exp(Ad(C^-1) n_A)`` (Eq. (38)), so with the index-3 form the reduced run computes the
paper's discrete solution (up to the Newton tolerances). The stabilized index-2 form corrects
the increments by ``B_n^T xi``, a projection in the space of the unknowns: with the auxiliary
nodes counted, it depends on how a body was split into nodes (a difference of O(h^2), see
``tests/test_offsets.py``); condensed, it does not: a body built from several rigidly joined
nodes then moves exactly as the same body built as one node with ``com=`` and ``at=``.

**Not condensed** (kept as joints): a rigid joint that would join two groups that each hold a
fixed node, a beam node or a node loaded in its body frame with another orientation than the
root's (these cannot be moved to another node), and every group in which another element
(or a further rigid joint, closing a loop) connects two of its nodes. ``simulate(...,
condense=False)`` keeps every rigid joint.

**When a step fails.** Near a singular configuration the reduced system's Newton iterations can
stall where the model's own converge (measured once: A02, the N-four-bar, at h = 5/23872 s,
t = 3.21 s, the residual stuck at 2.6 times the tolerance). :func:`se3dyn.simulate` then goes
on with the rigid joints kept from the failing step (``stats["condensed_until"]``), so a
condensed run never fails where the model itself goes on.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from se3dyn import lie
from se3dyn.engine.system import joint_frames
from se3dyn.model.specs import Model

__all__ = ["Condensation", "condensation"]


def _groups(model: Model, cand: list[int], pinned: set, nidx: dict) -> tuple[np.ndarray, list]:
    """Union-find over the candidate rigid joints: (root of every node (M,), joints used)."""
    parent = list(range(len(model.nodes)))
    pin = [n.name in pinned for n in model.nodes]

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    used = []
    for j in cand:
        js = model.joints[j]
        a, b = find(nidx[js.node_a]), find(nidx[js.node_b])
        if a == b or (pin[a] and pin[b]):
            continue  # closes a loop (the group is dropped below) / two nodes that stay
        if pin[b] or (not pin[a] and model.nodes[b].mass > model.nodes[a].mass):
            a, b = b, a
        parent[b] = a  # a: the pinned node, else the heavier one
        used.append(j)
    return np.array([find(i) for i in range(len(parent))], np.int64), used


def _pinned(model: Model) -> set:
    """Nodes that must stay the root of their group: fixed and beam nodes."""
    out = {n.name for n in model.nodes if n.fixed}
    for b in model.beams:
        out.update(b.nodes)
    return out


def _ends(model: Model) -> list[tuple[str, str, str]]:
    """(kind and name, node a, node b) of every element that connects two nodes."""
    out = [(f"joint '{j.name}'", j.node_a, j.node_b) for j in model.joints]
    out += [(f"spring '{s.name}'", s.node_a, s.node_b) for s in model.springs]
    out += [(f"bushing '{b.name}'", b.node_a, b.node_b) for b in model.bushings]
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class Condensation:
    """A compiled system, the system of its condensed model and the maps between their
    states (see the module docstring).

    Attributes
    ----------
    full, reduced : System
    rigid : ndarray (nr,) int            the condensed rigid joints (indices in ``full``)
    node_root : ndarray (M,) int         the reduced node of every node
    node_C : ndarray (M, 4, 4)           ``H_i = H_root C_i``
    node_Ad : ndarray (M, 6, 6)          ``Ad(C_i^-1)``: ``v_i = Ad(C_i^-1) v_root``
    root_full : ndarray (Mr,) int        the node of every reduced node
    joint_full : ndarray (mr,) int       the joint of every reduced joint
    dof_full : ndarray (nq_r,) int       the unknown of every reduced unknown
    mult_full : ndarray (nm_r,) int      the multiplier of every reduced multiplier
    order : ndarray (nr,) int            the condensed joints from the leaves to the roots
                                         (indices into ``rigid``)
    child_dofs, parent_dofs : ndarray (nr, 6) int
                                         the unknowns of the node each rigid joint carries
                                         (the one further from the root) and of the other one
                                         (-1 where that is the root or fixed)
    child_inv, parent_block : ndarray (nr, 6, 6)
                                         the inverse of the joint's (constant) contribution
                                         ``d r / d lambda`` to the rows of its child, and its
                                         contribution to the rows of its parent
    """

    full: object
    reduced: object
    rigid: np.ndarray
    node_root: np.ndarray
    node_C: np.ndarray
    node_Ad: np.ndarray
    root_full: np.ndarray
    joint_full: np.ndarray
    dof_full: np.ndarray
    mult_full: np.ndarray
    order: np.ndarray
    child_dofs: np.ndarray
    parent_dofs: np.ndarray
    child_inv: np.ndarray
    parent_block: np.ndarray

    # -- states ---------------------------------------------------------------------------------
    @property
    def members(self) -> np.ndarray:
        """The nodes that are not the root of their group (indices in ``full``)."""
        return np.flatnonzero(self.root_full[self.node_root] != np.arange(len(self.node_root)))

    def restrict(self, st):
        """The reduced state of a state of the full system (exact copies of the roots'
        values), or None when a dropped (redundant) equation belongs to a condensed joint or
        the state's solver memory is that of a run that kept the rigid joints."""
        from se3dyn.dynamics.state import State
        from se3dyn.engine.workspace import layout_of

        if st.solver is not None:  # a state of a run that kept its rigid joints: continued so
            lay = layout_of(self.reduced)
            if len(st.solver.ref) not in (lay.nvals, lay.nvals2 + 1):  # (+1: the mode)
                return None
        inv = np.full(self.full.nm, -1, np.int64)
        inv[self.mult_full] = np.arange(len(self.mult_full))
        dropped = inv[np.asarray(st.dropped, np.int64)]
        if np.any(dropped < 0):
            return None
        d = self.dof_full
        return State(t=st.t, H=st.H[self.root_full], HJ=st.HJ[self.joint_full], v=st.v[d],
                     vd=st.vd[d], a=st.a[d], lam=st.lam[self.mult_full], alpha=st.alpha[d],
                     work_act=st.work_act, work_ext=st.work_ext, dissipated=st.dissipated,
                     power=st.power, dropped=dropped, h_last=st.h_last, solver=st.solver,
                     ctrl=st.ctrl)  # (PID laws are on joints kept: the same order)

    def expand_rows(self, H, v, vd, alpha, lam, a=None) -> tuple:
        """Rows of the reduced system (leading axis n) as rows of the full system: frames
        (n, M, 4, 4), v, vd (, a), alpha (n, nq) and the multipliers (n, nm), the condensed
        rigid joints' multipliers zero (see :meth:`rigid_multipliers`)."""
        f, r = self.full, self.reduced
        n = len(H)
        Hf = H[:, self.node_root]  # the roots' frames exactly, the members' from them
        mem = self.members
        Hf[:, mem] = np.matmul(Hf[:, mem], self.node_C[mem])
        outs = []
        for x in (v, vd, alpha) + ((a,) if a is not None else ()):
            y = np.zeros((n, f.nq))
            y[:, self.dof_full] = x
            outs.append(y)
        # members' velocities and accelerations: Ad(C^-1) of their root's (alpha: 0 on nodes)
        free = f.node_free
        roots = self.node_root[free]
        moving = r.node_dofadr[roots] >= 0
        members = free[moving & (self.root_full[roots] != free)]
        if len(members):
            src = r.node_dofadr[self.node_root[members]][:, None] + np.arange(6)
            dst = f.node_dofadr[members][:, None] + np.arange(6)
            for x, y in zip((v, vd) + ((a,) if a is not None else ()), outs[:2] + outs[3:],
                            strict=True):
                y[:, dst] = np.matmul(self.node_Ad[members], x[:, src][..., None])[..., 0]
        L = np.zeros((n, f.nm))
        L[:, self.mult_full] = lam
        return (Hf, *outs[:3], L) + ((outs[3],) if a is not None else ())

    def expand(self, st, ws=None, inputs=None):
        """The full system's state of a reduced state, the rigid joints' multipliers included
        (evaluated by the workspace ``ws`` of the full system, a new one if None; ``inputs``:
        :func:`se3dyn.engine.inputs.step_inputs` of the full system at ``st.t``)."""
        from se3dyn.dynamics.state import State
        from se3dyn.engine.inputs import step_inputs

        f = self.full
        H, v, vd, alpha, lam, a = (x[0] for x in self.expand_rows(
            st.H[None], st.v[None], st.vd[None], st.alpha[None], st.lam[None], st.a[None]))
        if len(st.HJ) == self.reduced.m:
            HJ = f.joint_H0.copy()
            HJ[self.joint_full] = st.HJ
        else:  # (the rows the compiled loop passes on carry no joint frames)
            HJ = self.joint_frames(H[None])[0]
        u = (inputs or step_inputs(f, st.t))["u"]
        self.rigid_multipliers(H[None], HJ[None], alpha[None], v[None], vd[None], lam[None],
                               u[None], ws)
        return State(t=st.t, H=H, HJ=HJ, v=v, vd=vd, a=a, lam=lam, alpha=alpha,
                     work_act=st.work_act, work_ext=st.work_ext, dissipated=st.dissipated,
                     power=st.power, dropped=self.mult_full[np.asarray(st.dropped, np.int64)],
                     h_last=st.h_last, solver=st.solver, ctrl=st.ctrl)

    # -- reactions ------------------------------------------------------------------------------
    def joint_frames(self, H: np.ndarray) -> np.ndarray:
        """(n, m, 4, 4) joint transformations of rows of full frames (n, M, 4, 4): the
        condensed ones constant, the others ``H_J = (H_A X_A)^-1 H_B X_B`` (Eq. (7))."""
        HJ = joint_frames(self.full, H)
        HJ[:, self.rigid] = self.full.joint_H0[self.rigid]
        return HJ

    def fill_multipliers(self, res) -> None:
        """Complete the multipliers of results of the full system (the deferred columns of
        :attr:`se3dyn.results.results.Results.lam`), in blocks of rows."""
        self.fill_rows(res.t, res.H, res.alpha, res.v, res.vd, res.__dict__["_lam"])

    def fill_rows(self, t, H, alpha, v, vd, lam, ws=None, U=None) -> None:
        """The same for rows of the full system given as arrays (``lam`` (n, nm) in place);
        ``U`` (n, nu): the rows' inputs (default: the model's time functions at ``t``)."""
        from se3dyn.engine.inputs import input_table
        from se3dyn.engine.workspace import Workspace

        ws = ws or Workspace(self.full)
        for lo in range(0, len(t), 4096):
            sl = slice(lo, lo + 4096)
            U_sl = (input_table(self.full, np.asarray(t[sl], float))[0] if U is None
                    else np.ascontiguousarray(U[sl], float))
            self.rigid_multipliers(H[sl], self.joint_frames(H[sl]), alpha[sl], v[sl], vd[sl],
                                   lam[sl], U_sl, ws)

    def rigid_multipliers(self, H, HJ, alpha, v, vd, lam, U, ws=None) -> None:
        """Fill in the multipliers of the condensed rigid joints of rows (n, ...) of the full
        system (``lam`` (n, nm), in place) from the rows of the equations of motion of the
        nodes they carry (Eq. (36)); ``U`` (n, nu) the inputs of the rows; evaluated by the
        workspace ``ws`` of the full system (a new one if None: never the system's shared
        default one, so that runs and results in several threads do not share work arrays)."""
        if not len(self.rigid) or not len(H):
            return
        from se3dyn.engine.workspace import Workspace, engine_of

        f = self.full
        eng, _ = engine_of(f, ws or Workspace(f))
        n = len(H)
        F = np.ascontiguousarray(np.concatenate([H, HJ], axis=1), float)
        mult = f.joint_multadr[self.rigid][:, None] + np.arange(6)
        lam[:, mult] = 0.0
        r = np.empty((n, f.nq))
        c = lambda x: np.ascontiguousarray(x, float)  # noqa: E731
        eng.residual_rows(F, c(alpha), c(v), c(vd), c(lam), c(U), r, n)

        def times(x, D):  # x (n, 6) -> x D^T, term by term: the same sums whatever the
            out = np.zeros((len(x), 6))  # number of rows (BLAS and einsum round a single
            for k in range(6):  # row and a block of rows differently)
                out += x[:, k:k + 1] * D[:, k]
            return out

        # member by member from the leaves: r_child + D_child lambda + (the child's own
        # children's contributions, added to r before) = 0
        for q in self.order:
            lq = -times(r[:, self.child_dofs[q]], self.child_inv[q])
            lam[:, mult[q]] = lq
            if self.parent_dofs[q, 0] >= 0:
                r[:, self.parent_dofs[q]] += times(lq, self.parent_block[q])


def condensation(s, enabled: bool = True) -> Condensation | None:
    """The condensation of the rigid joints of a compiled system (built once, kept with the
    system), or None when there is nothing to condense."""
    if not enabled:
        return None
    if "condensation" not in s.pattern:
        s.pattern["condensation"] = _build(s)
    return s.pattern["condensation"]


def _build(s) -> Condensation | None:
    from se3dyn.engine.system import compile_model

    nidx = {name: i for i, name in enumerate(s.node_names)}
    root, used = _rigid_groups(s, nidx)
    if not used or s.contacts:  # (contact pairs are not carried to a reduced model yet)
        return None
    rigid = np.array(sorted(used), np.int64)
    roots = [i for i in range(s.M) if root[i] == i]
    rpos = {i: k for k, i in enumerate(roots)}
    node_root = np.array([rpos[int(root[i])] for i in range(s.M)], np.int64)
    H0 = s.node_H0
    C = lie.inverse(H0[root]) @ H0
    C[roots] = np.eye(4)
    r = compile_model(_reduced_model(s, nidx, root, roots, rigid, C))
    root_full, joint_full, dof_full, mult_full = _maps(s, r, roots)
    depth, child, child_dofs, parent_dofs, Dc, Dp = _multiplier_blocks(s, rigid, root)
    return Condensation(full=s, reduced=r, rigid=rigid, node_root=node_root, node_C=C,
                        node_Ad=lie.adjoint_inv(C), root_full=root_full, joint_full=joint_full,
                        dof_full=dof_full, mult_full=mult_full,
                        order=np.argsort(-depth[child], kind="stable"), child_dofs=child_dofs,
                        parent_dofs=parent_dofs, child_inv=np.linalg.inv(Dc), parent_block=Dp)


def _rigid_groups(s, nidx: dict) -> tuple[np.ndarray | None, list]:
    """The groups of the condensed rigid joints: (root of every node (M,), joints used),
    dropping the groups that cannot be condensed (see the module docstring)."""
    model = s.model
    cand = [j for j, js in enumerate(model.joints)
            if js.type == "rigid" and js.k == 0 and js.composite is None]
    if not cand:
        return None, []
    pinned = _pinned(model)
    ends = _ends(model)
    while True:
        root, used = _groups(model, cand, pinned, nidx)
        usedset = set(used)
        bad = set()
        for j, (_item, a, b) in enumerate(ends):
            if root[nidx[a]] == root[nidx[b]] and j not in usedset:
                bad.add(int(root[nidx[a]]))  # closes a loop inside a group
        R0 = s.node_H0[:, :3, :3]
        for ld in model.loads:  # body-frame loads on members turned against their root
            i = nidx[ld.node]
            body = ((ld.force is not None and ld.force_frame == "body")
                    or (ld.torque is not None and ld.torque_frame == "body"))
            if body and root[i] != i and not np.array_equal(R0[i], R0[root[i]]):
                bad.add(int(root[i]))
        if not bad:
            return root, used
        cand = [j for j in cand if root[nidx[model.joints[j].node_a]] not in bad]


def _lumped_nodes(s, root: np.ndarray, roots: list) -> list:
    """One node per group: its root's, with the group's whole mass, centre of mass and
    inertia about it (parallel-axis rule, Sec. 6)."""
    from se3dyn.engine.system import combine_inertia

    model = s.model
    nodes = []
    for i in roots:
        grp = [model.nodes[k] for k in range(s.M) if root[k] == i]
        n0 = model.nodes[i]
        if len(grp) == 1:
            nodes.append(n0)
            continue
        M, J, com = combine_inertia(
            np.array([g.mass for g in grp]),
            np.array([g.position if g.com is None else g.com for g in grp], float),
            np.array([g.inertia for g in grp]))
        # (a fixed node is always its group's root: the group is fixed)
        nodes.append(dataclasses.replace(n0, mass=M, inertia=J, com=com))
    return nodes


def _moved_joints(s, root: np.ndarray, rigid: np.ndarray, C: np.ndarray) -> list:
    """The joints that are not condensed, attached to the roots through their attachment
    frames ``X -> C X``."""
    name_of = lambda k: s.node_names[int(root[k])]  # noqa: E731
    A_mat = {}
    for g in s.groups:
        for q, jid in enumerate(g.ids):
            A_mat[int(jid)] = g.A[q]
    rset = set(rigid.tolist())
    joints = []
    for j, js in enumerate(s.model.joints):
        if j in rset:
            continue
        a, b = s.joint_a[j], s.joint_b[j]
        if root[a] == a and root[b] == b:
            joints.append(js)
            continue
        joints.append(dataclasses.replace(
            js, node_a=name_of(a), node_b=name_of(b),
            frames=(C[a] @ s.joint_XA[j], C[b] @ s.joint_XB[j], s.joint_H0[j].copy(),
                    A_mat[j])))
    return joints


def _reduced_model(s, nidx: dict, root: np.ndarray, roots: list, rigid: np.ndarray,
                   C: np.ndarray) -> Model:
    """The reduced model: one node per group, the elements moved to the roots."""
    model, H0 = s.model, s.node_H0
    nodes = _lumped_nodes(s, root, roots)
    name_of = lambda k: s.node_names[int(root[k])]  # noqa: E731
    joints = _moved_joints(s, root, rigid, C)
    loads = []
    for ld in model.loads:
        i = nidx[ld.node]
        if root[i] == i:
            loads.append(ld)
            continue
        loads.append(dataclasses.replace(
            ld, node=name_of(i), at=H0[i, :3, 3].copy() if ld.at is None else ld.at))
    springs = tuple(dataclasses.replace(sp, node_a=name_of(nidx[sp.node_a]),
                                        node_b=name_of(nidx[sp.node_b]))
                    for sp in model.springs)
    bushings = tuple(dataclasses.replace(b, node_a=name_of(nidx[b.node_a]),
                                         node_b=name_of(nidx[b.node_b]))
                     for b in model.bushings)
    # (markers: the sensors of sampled PID laws read them in the time loop)
    markers = tuple(dataclasses.replace(mk, node=name_of(nidx[mk.node]),
                                        X=C[nidx[mk.node]] @ mk.X) for mk in model.markers)
    return Model(nodes=tuple(nodes), joints=tuple(joints), loads=tuple(loads),
                 gravity=model.gravity, composites=model.composites, name=model.name,
                 springs=springs, visuals=(), beams=model.beams, bushings=bushings,
                 markers=markers, drives=model.drives, couplings=model.couplings)


def _maps(s, r, roots: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The node, joint, unknown and multiplier of ``s`` of every reduced one of ``r``."""
    root_full = np.array(roots, np.int64)
    jnames = list(s.joint_names)
    joint_full = np.array([jnames.index(n) for n in r.joint_names], np.int64)
    dof_full = np.empty(r.nq, np.int64)
    for k, i in enumerate(roots):
        if r.node_dofadr[k] >= 0:
            dof_full[r.node_dofadr[k] + np.arange(6)] = s.node_dofadr[i] + np.arange(6)
    for k, j in enumerate(joint_full):
        if r.joint_k[k]:
            dof_full[r.joint_dofadr[k] + np.arange(r.joint_k[k])] = (
                s.joint_dofadr[j] + np.arange(s.joint_k[j]))
    mult_full = (s.joint_multadr[joint_full][:, None] + np.arange(6)).reshape(-1)
    return root_full, joint_full, dof_full, mult_full


def _multiplier_blocks(s, rigid: np.ndarray, root: np.ndarray) -> tuple:
    """The constant blocks ``d r / d lambda`` of the rigid joints on the rows of their child
    and parent nodes: (depth, child, child_dofs, parent_dofs, Dc, Dp)."""
    from se3dyn.engine.evaluate import evaluate
    from se3dyn.engine.inputs import step_inputs
    from se3dyn.engine.workspace import Workspace

    # the rigid joints' multipliers: the rows of the node each carries (the end further from
    # the root) and of its other end, by the residual's linearity in lambda (constant blocks:
    # H_J of a rigid joint is constant, Eq. (58)); joints sharing no node perturbed together
    depth = _depths(rigid, s, root)
    a_, b_ = s.joint_a[rigid], s.joint_b[rigid]
    child = np.where(depth[b_] > depth[a_], b_, a_)
    parent = np.where(depth[b_] > depth[a_], a_, b_)
    dofs = lambda i: s.node_dofadr[i][:, None] + np.arange(6)  # noqa: E731
    child_dofs = dofs(child)
    parent_dofs = np.where((root[parent] != parent)[:, None], dofs(parent), -1)
    nr = len(rigid)
    Dc, Dp = np.zeros((nr, 6, 6)), np.zeros((nr, 6, 6))
    z, zl = np.zeros(s.nq), np.zeros(s.nm)
    inputs = step_inputs(s, 0.0)
    ws = Workspace(s)  # (its own: the build may run in several threads at once)
    ev = lambda lam: evaluate(s, s.node_H0, s.joint_H0, s.alpha0, z, z, z, lam,  # noqa: E731
                              inputs, ws=ws).r
    r0 = ev(zl)
    # unit multipliers scaled to the forces of r0 (a power of two: the division is exact): the
    # difference keeps their digits however large the forces (a centre of mass 1e15 m from
    # its node gives gravity moments of 1e16 N m, which swallowed a unit multiplier)
    big = float(np.max(np.abs(r0))) if r0.size else 0.0
    sc = 2.0 ** math.ceil(math.log2(big)) if math.isfinite(big) and big > 1.0 else 1.0
    todo = list(range(nr))
    while todo:
        batch, used_nodes, rest = [], set(), []
        for q in todo:
            ends = {int(child[q]), int(parent[q])}
            (rest if ends & used_nodes else batch).append(q)
            if q in batch:
                used_nodes |= ends
        todo = rest
        for k in range(6):
            lk = zl.copy()
            lk[s.joint_multadr[rigid[batch]] + k] = sc
            d = (ev(lk) - r0) / sc
            for q in batch:
                Dc[q, :, k] = d[child_dofs[q]]
                if parent_dofs[q, 0] >= 0:
                    Dp[q, :, k] = d[parent_dofs[q]]
    return depth, child, child_dofs, parent_dofs, Dc, Dp


def _depths(rigid: np.ndarray, s, root: np.ndarray) -> np.ndarray:
    """(M,) distance of every node from its group's root along the condensed rigid joints."""
    adj: dict = {}
    for j in rigid:
        a, b = int(s.joint_a[j]), int(s.joint_b[j])
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    depth = np.zeros(s.M, np.int64)
    for r0 in {int(root[i]) for i in adj}:
        seen, todo = {r0}, [r0]
        while todo:
            x = todo.pop()
            for y in adj.get(x, ()):
                if y not in seen:
                    seen.add(y)
                    depth[y] = depth[x] + 1
                    todo.append(y)
    return depth
