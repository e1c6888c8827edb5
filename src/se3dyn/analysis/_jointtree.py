"""Compiled path of :class:`se3dyn.analysis.jointspace.JointSpace` on trees: the tables of the
C++ ``JointTree`` (``se3dyn/_core/joint_tree.hpp``: recursive Newton-Euler and the
composite-rigid-body algorithm), computed once from the System, and the reason when a model is
left to the general path.

A link per node that moves: every floating root (its pose from q, Pinocchio's free-flyer
convention), then every node a joint places, in the order of JointSpace's tree plan. A joint
places its child ``H_child = H_parent P exp(S0 (alpha - alpha0)) Q`` (Eq. (7)): forward
(child = node B) ``P = X_A H_J0, S0 = A, Q = X_B^-1``; backward (child = node A, from
``H_J^-1 = exp(-A da) H_J0^-1``) ``P = X_B, S0 = -A, Q = H_J0^-1 X_A^-1``; a fixed parent's pose
is folded into ``P``. The motion subspace in the child's material frame is ``S = Ad(Q^-1) S0``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from se3dyn import lie
from se3dyn.elements.body import mass_matrices
from se3dyn.elements.joint_force import law_table

if TYPE_CHECKING:
    from se3dyn.analysis.jointspace import JointSpace

__all__ = ["fallback_reason", "tree_tables"]


def fallback_reason(js: JointSpace) -> str:
    """Why the model needs the general path ('' when the compiled path covers it): closed
    loops, couplings, drives, or forces beyond inertia, gravity, armature and the joints'
    springs and dampers."""
    s, md = js.system, js.system.model
    dof = np.concatenate([s.dof_kp, s.dof_kd, s.dof_ki])
    checks = (
        (bool(js._plan.closures), "closed loops"),
        (len(s.cpl_follow) > 0, "couplings"),
        (len(md.drives) > 0, "drives"),
        (len(md.loads) > 0, "loads"),
        (len(s.springs) + len(s.beams) + len(md.bushings) > 0,
         "spring-dampers, beams or bushings"),
        (len(s.contacts) + len(md.contact_pairs) + len(md.collisions) > 0, "contacts"),
        (bool(np.any(dof != 0)), "joint control laws (PD, PID)"),
        (len(s.inputs.joint_slots) > 0 or len(law_table(s)[0]) > 0, "joint actuators"),
        (s.inputs.nu != 3, "time-dependent inputs beyond gravity"),
    )
    for bad, why in checks:
        if bad:
            return why
    placed = set(js._roots) | {int(b if fwd else a) for _, fwd, a, b, _, _ in js._plan.order}
    if placed != set(int(i) for i in s.node_free):
        return "free nodes that no joint places"
    return ""


def _joint_A(s) -> dict:
    """Joint index -> its subspace A (6, k)."""
    out = {}
    for g in s.groups:
        for n, j in enumerate(g.ids):
            out[int(j)] = np.asarray(g.A[n], float).reshape(6, int(g.k))
    return out


def tree_tables(js: JointSpace, gravity: np.ndarray) -> dict:
    """The tables of the compiled ``JointTree`` (module docstring) of a tree JointSpace."""
    s = js.system
    ind = js.partition.independent
    vpos = {int(d): n for n, d in enumerate(ind)}
    nodes = list(js._roots)
    link = {i: n for n, i in enumerate(nodes)}
    A = _joint_A(s)
    nl = len(js._roots) + len(js._plan.order)
    par, kind, k = np.full(nl, -1, np.int64), np.zeros(nl, np.int64), np.zeros(nl, np.int64)
    qadr, vadr = np.zeros(nl, np.int64), np.zeros(nl, np.int64)
    P, Q = np.tile(np.eye(4), (nl, 1, 1)), np.tile(np.eye(4), (nl, 1, 1))
    S0, S, alpha0 = np.zeros((nl, 6, 6)), np.zeros((nl, 6, 6)), np.zeros((nl, 6))
    for n, d in enumerate(js._rootdofs):
        kind[n], vadr[n] = 1, vpos[d]
        qadr[n] = js._qpos[vpos[d]]
    for n, (j, fwd, a, b, _, _) in enumerate(js._plan.order, start=len(js._roots)):
        p, c = (a, b) if fwd else (b, a)
        XA, XB, HJ0 = s.joint_XA[j], s.joint_XB[j], s.joint_H0[j]
        P[n] = XA @ HJ0 if fwd else XB
        Q[n] = lie.inverse(XB) if fwd else lie.inverse(HJ0) @ lie.inverse(XA)
        if s.node_fixed[p]:
            P[n] = s.node_H0[p] @ P[n]
        else:
            par[n] = link[p]
        kk = k[n] = int(s.joint_k[j])
        d = int(s.joint_dofadr[j])
        if kk:
            S0[n, :kk] = (A[j] if fwd else -A[j]).T  # rows: columns of S0
            S[n, :kk] = (lie.adjoint_inv(Q[n]) @ S0[n, :kk].T).T
            vadr[n], qadr[n] = vpos[d], js._qpos[vpos[d]]
            alpha0[n, :kk] = s.alpha0[d:d + kk]
        link[c] = n
        nodes.append(c)
    M, mc, m = mass_matrices(s, np.array(nodes, np.int64))
    qidx = np.where(np.asarray(s.dof_is_joint, bool)[ind], js._qpos, -1).astype(np.int64)
    per_v = {name: np.asarray(getattr(s, "dof_" + name), float)[ind].copy()
             for name in ("armature", "stiffness", "reference", "damping")}
    return dict(nq=js.nq, nv=js.nv, parent=par, kind=kind, k=k, qadr=qadr, vadr=vadr, P=P,
                Q=Q, S0=S0, S=S, alpha0=alpha0, M=M, mc=mc, m=m, qidx=qidx, **per_v,
                gravity=np.asarray(gravity, float).copy())
