"""Steady spin: relative equilibria of rotating machines, and Campbell diagrams (issue 32,
items 1 and 3).

A **relative equilibrium** is a motion in which every body turns rigidly, at a constant rate,
about one fixed axis: a rotor on its bearings, a rotating blade, a spinning top. The spin comes
from a joint whose body A is fixed (``joint``: a hinge, or any one-coordinate joint), turning at
``speed``: its inertial twist ``V = Ad(G) A speed`` (``G = H_A X_A H_J`` the joint's frame,
Eqs. (3)-(7)); every node then moves with the material velocity ``v_i = Ad(H_i^-1) V``
(Eq. (4)), constant in time, so ``vd = 0``, and the relative coordinates of the other joints
have the rates that the velocity constraints give (zero between bodies turning together). The
configuration is the unknown: ``r(q, v(q), 0) + B^T lambda = 0`` and ``Phi(q) = 0`` (Eqs. (36),
(55)), the spin coordinate held where it is (its row is the torque that keeps the speed: zero
without friction). Newton's matrix is ``K_T + C_T dv/dq`` with ``dv_i/dn_i = ad(v_i)`` (a
frame ``H exp(n)`` under the same twist has ``Ad(exp(-n)) v = v + ad(v) n``; Eq. (5)): the
centrifugal and gyroscopic stiffness of the spin. In material velocities the state is
time-invariant, so the linearisation about it (:func:`~se3dyn.analysis.linearize.linearize`)
holds for all times: its modes at a sequence of speeds are the **Campbell diagram**, tracked
from speed to speed by the modal assurance criterion (MAC), with the largest real part of the
eigenvalues as the stability margin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla

from se3dyn import lie
from se3dyn.analysis.common import _as_system, _Blocks, _joint_ids
from se3dyn.analysis.linearize import linearize
from se3dyn.analysis.statics import _equilibrate
from se3dyn.dynamics.state import State
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.system import System
from se3dyn.errors import ModelError, SimulationError
from se3dyn.model.specs import Model


def relative_equilibrium(model_or_system: Model | System, joint: str, speed: float, *,
                         t: float = 0.0, tol: float = 1e-10, max_iter: int = 50,
                         start: State | None = None) -> State:
    """The steady spin of a model about ``joint`` at ``speed`` (rad/s, or m/s for a
    translating joint), solved for (see the module docstring).

    Parameters
    ----------
    model_or_system : Model or System
    joint : str
        A joint of one coordinate whose node A is fixed: the spin axis.
    speed : float
        Its rate.
    t : float
        Time of the model's loads.
    tol : float
        Tolerance on the relative residual and the scaled constraints.
    max_iter : int
        Newton iterations.
    start : State, optional
        The state to start from (a relative equilibrium at a nearby speed); default: the
        model's initial configuration.

    Returns
    -------
    State
        At time ``t``: frames, velocities ``v`` (rigid spin), ``vd = a = 0``, multipliers;
        :func:`~se3dyn.linearize` takes it as ``at``.

    Raises
    ------
    ModelError
        Bad arguments.
    SimulationError
        Newton does not converge (the message gives the residuals reached).
    """
    s = _as_system(model_or_system, "relative_equilibrium")
    j, d = _spin_joint(s, joint)
    if isinstance(speed, bool) or not isinstance(speed, int | float) or not math.isfinite(speed):
        raise ModelError("relative_equilibrium", "speed", "a finite rate", speed)
    sp = _Spin(s, j, d, float(speed), dict(step_inputs(s, float(t))))
    H, HJ, alpha, lam = ((s.node_H0, s.joint_H0, s.alpha0, np.zeros(s.nm)) if start is None
                         else (start.H, start.HJ, start.alpha, start.lam))
    ev, v, lam = sp.solve(H, HJ, alpha, lam, tol, max_iter)
    z = np.zeros(s.nq)
    return State(t=float(t), H=ev.H, HJ=ev.HJ, v=v, vd=z, a=z.copy(), lam=lam, alpha=ev.alpha)


def _spin_joint(s: System, joint: Any) -> tuple[int, int]:
    ids = _joint_ids(s, joint, "relative_equilibrium", "joint")
    if len(ids) != 1 or int(s.joint_k[ids[0]]) != 1:
        raise ModelError("relative_equilibrium", "joint", "a joint of one coordinate (a hinge)",
                         joint)
    j = ids[0]
    if not s.node_fixed[s.joint_a[j]]:
        raise ModelError("relative_equilibrium", "joint", "a joint whose node A is fixed (the "
                         "spin axis must not move)", joint)
    return j, int(s.joint_dofadr[j])


@dataclass
class _Spin:
    """Newton on the configuration of a relative equilibrium (the module docstring)."""

    s: System
    j: int
    d: int
    speed: float
    inputs: dict
    blocks: Any = field(init=False)
    axis: np.ndarray = field(init=False)

    def __post_init__(self):
        self.blocks = _Blocks(self.s)
        # the spin joint's twist per unit rate in its frame: the column of its A (Eq. (9))
        g = next(g for g in self.s.groups if self.j in g.ids)
        self.axis = g.A[list(g.ids).index(self.j)][:, 0]

    def velocities(self, ev) -> np.ndarray:
        """Material velocities of the rigid spin at the iterate ``ev`` (nq,): nodes from the
        joint's twist, joint coordinates from the velocity constraints."""
        s, j = self.s, self.j
        a = int(s.joint_a[j])
        G = s.node_H0[a] @ s.joint_XA[j] @ ev.HJ[j]
        V = lie.adjoint(G) @ self.axis * self.speed
        v = np.zeros(s.nq)
        free = np.flatnonzero(~s.node_fixed)
        v[s.node_dofadr[free][:, None] + np.arange(6)] = lie.adjoint_inv(ev.H[free]) @ V
        joint = np.flatnonzero(s.dof_is_joint)
        v[self.d] = self.speed
        rest = np.setdiff1d(joint, [self.d])
        if rest.size:
            _, _, B = self.blocks(ev, (0.0, 0.0, 1.0))
            known = np.setdiff1d(np.arange(s.nq), rest)
            v[rest] = -sla.lstsq(B[:, rest], B[:, known] @ v[known])[0]
        return v

    def jacobian(self, ev, v):
        """``[[K_T + C_T D, B^T], [B, 0]]`` with ``D`` the ``ad(v_i)`` blocks of the nodes."""
        s = self.s
        K, PT, B = self.blocks(ev, (0.0, 0.0, 1.0))
        C = self.blocks(ev, (0.0, 1.0, 0.0))[0]
        D = np.zeros((s.nq, s.nq))
        for i in np.flatnonzero(~s.node_fixed):
            k = s.node_dofadr[i]
            D[k:k + 6, k:k + 6] = lie.ad6(v[k:k + 6])
        return np.block([[K + C @ D, PT], [B, np.zeros((s.nm, s.nm))]])

    def solve(self, H, HJ, alpha, lam, tol, max_iter):
        s, d = self.s, self.d
        n, z = np.zeros(s.nq), np.zeros(s.nq)
        for it in range(max_iter + 1):
            ev = evaluate(s, H, HJ, alpha, n, z, z, lam, self.inputs, None)
            v = self.velocities(ev)
            ev = evaluate(s, H, HJ, alpha, n, v, z, lam, self.inputs, None)
            r = ev.r.copy()
            r[d] = 0.0  # (the spin coordinate is held: its row is the driving torque)
            er = float(np.abs(r).max(initial=0.0)) / max(ev.f_scale, 1e-300)
            ep = float(np.abs(ev.phi).max(initial=0.0)) / max(s.length_scale, 1.0)
            if er <= tol and ep <= tol * 1e-2:
                return ev, v, lam
            if it == max_iter:
                break
            S = self.jacobian(ev, v)
            S[d] = 0.0
            S[d, d] = 1.0
            rhs = -np.concatenate([r, ev.phi])
            dr, dc = _equilibrate(S)
            x = dc * sla.lstsq(dr[:, None] * S * dc, dr * rhs, lapack_driver="gelsd")[0]
            n = n + x[:s.nq]
            lam = lam + x[s.nq:]
        raise SimulationError(f"relative_equilibrium: no convergence within max_iter="
                              f"{max_iter} at speed {self.speed:g}: relative residual "
                              f"{er:.3e}, constraint violation {ep:.3e} (tol {tol:.1e})")


@dataclass(frozen=True)
class Campbell:
    """Modes of a rotating machine against its speed (:func:`campbell`).

    Attributes
    ----------
    speeds : ndarray (ns,)
    omega : ndarray (ns, k)       natural angular frequencies of the tracked modes (rad/s)
    damping : ndarray (ns, k)     their damping ratios
    growth : ndarray (ns,)        the largest real part of the eigenvalues of all flexible
                                  modes (1/s): the stability margin (> 0: unstable)
    mac : ndarray (ns,)           the smallest MAC of the tracking from the previous speed
    """

    speeds: np.ndarray
    omega: np.ndarray
    damping: np.ndarray
    growth: np.ndarray
    mac: np.ndarray
    states: tuple = field(default=(), repr=False)

    def plot(self, path=None, *, hz: bool = True):
        """The Campbell diagram (matplotlib): frequencies against speed, with the lines of
        1x and 2x the speed; saved to ``path`` if given. Returns the figure."""
        import matplotlib.pyplot as plt

        f = self.omega / (2 * math.pi) if hz else self.omega
        x = self.speeds / (2 * math.pi) if hz else self.speeds
        fig, ax = plt.subplots(figsize=(6, 4))
        for m in range(f.shape[1]):
            ax.plot(x, f[:, m], "o-", ms=3, label=f"mode {m + 1}")
        for order in (1, 2):
            ax.plot(x, order * x, "k--", lw=0.8)
        ax.set_xlabel("speed (Hz)" if hz else "speed (rad/s)")
        ax.set_ylabel("frequency (Hz)" if hz else "frequency (rad/s)")
        ax.legend(fontsize=7)
        if path is not None:
            fig.savefig(path, dpi=120, bbox_inches="tight")
        return fig


def campbell(model_or_system: Model | System, joint: str, speeds, k: int = 6, *,
             tol: float = 1e-10) -> Campbell:
    """Campbell diagram: the ``k`` slowest flexible modes of the relative equilibria at
    ``speeds`` (:func:`relative_equilibrium`, each started from the previous), tracked from
    speed to speed by the modal assurance criterion of their shapes.

    Parameters
    ----------
    model_or_system : Model or System
    joint : str
        The spin joint (node A fixed).
    speeds : array_like (ns,)
        Increasing speeds (rad/s).
    k : int
        Number of modes tracked (rigid-body modes left out).

    Returns
    -------
    Campbell
    """
    s = _as_system(model_or_system, "campbell")
    sp = np.asarray(speeds, dtype=float)
    if sp.ndim != 1 or sp.size < 1 or not np.all(np.isfinite(sp)) or np.any(np.diff(sp) <= 0):
        raise ModelError("campbell", "speeds", "increasing finite speeds", speeds)
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
        raise ModelError("campbell", "k", "a positive integer", k)
    rows, states, prev, st = [], [], None, None
    for w in sp:
        st = relative_equilibrium(s, joint, float(w), tol=tol, start=st)
        md = linearize(s, at=st).modes()
        flex = np.flatnonzero(~md.rigid)[:k]
        if flex.size < k:
            raise ModelError("campbell", "k", f"at most {flex.size} (flexible modes)", k)
        shapes = md.full_shapes[:, flex]
        order, worst = (np.arange(k), 1.0) if prev is None else _track(prev, shapes)
        growth = float(np.max(md.eigenvalues.real[~md.rigid], initial=-np.inf))
        rows.append((md.omega[flex][order], md.damping[flex][order], growth, worst))
        prev = shapes[:, order]
        states.append(st)
    om, dm, gr, mac = (np.array(x) for x in zip(*rows, strict=True))
    return Campbell(speeds=sp, omega=om, damping=dm, growth=gr, mac=mac, states=tuple(states))


def _track(prev: np.ndarray, shapes: np.ndarray) -> tuple[np.ndarray, float]:
    """The order of ``shapes`` that best matches ``prev`` by MAC (Hungarian assignment), and
    the smallest MAC of the match."""
    from scipy.optimize import linear_sum_assignment

    num = np.abs(prev.conj().T @ shapes) ** 2
    den = np.outer(np.sum(np.abs(prev) ** 2, 0), np.sum(np.abs(shapes) ** 2, 0))
    mac = num / np.maximum(den, 1e-300)
    r, c = linear_sum_assignment(-mac)
    return c[np.argsort(r)], float(mac[r, c].min())
