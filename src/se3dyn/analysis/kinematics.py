"""Assembly of initial configurations and kinematic analysis with inverse dynamics.

Both work directly on the unknowns of the dynamic formulation (Sec. 3.3, Eq. (14)): the
increments ``n`` of the free nodes (6 each) and of the joint relative coordinates (k each), with
the configuration updated on the group, ``H <- H exp(n)`` (Eq. (38)), and the frames re-based after
every correction so that the tangent operator is ``T(0) = I`` (Eqs. (25)-(27)). The constraints
are the vectorial map of Eq. (55), ``Phi_I = vect(H_B^-1 H_A H_J)`` (``vect((H_B X_B)^-1 H_A X_A
H_J)`` for joints with attachment offsets), and the constraint Jacobian
``B`` is its exact linearisation (Eq. (58) when ``Phi = 0``), obtained from
:func:`se3dyn.engine.evaluate.matrix_values` with coefficients ``(0, 0, 0)``.

* :func:`assemble` projects an inconsistent initial configuration onto ``Phi = 0`` by Gauss-Newton
  with minimum-norm corrections, then the velocities onto the velocity constraints ``B v = 0``.
* :func:`kinematics` prescribes the relative coordinates of abelian joints as functions of time
  (driving constraints ``alpha_D - f(t) = 0``, with alpha of Eq. (60)) on a mechanism left with
  no mobility, and solves positions, velocities, accelerations and, by inverse dynamics
  (Eq. (36)), the multipliers: joint reactions and driver efforts.

Scaling. Rank decisions and minimum-norm corrections use dimensionless unknowns and rows:
translations (node components ``U``, joint coordinates along translations, constraint rows 0-2)
are divided by the characteristic length ``L`` of the model (largest distance of a node from the
centroid of all nodes), rotations are left in radians.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.analysis.common import (
    _Accessors,
    _as_system,
    _Blocks,
    _joint_ids,
    _joint_item,
    _unknown_name,
    _zero_inputs,
)
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.scaling import (
    _RCOND,
    _char_length,
    _describe,
    _null_space,
    _row_scale,
    _svd,
    _unknown_scale,
)
from se3dyn.errors import ModelError, Se3dynWarning, SimulationError
from se3dyn.model.timefunc import (
    Callable,
    Component,
    TimeFunction,
    as_timefunc,
)
from se3dyn.results.results import node_accelerations

if TYPE_CHECKING:
    from se3dyn.engine.system import System
    from se3dyn.model.specs import Model

sla = LazyModule("scipy.linalg")


# =============================================================================================
# time functions: first and second derivatives
# =============================================================================================
def time_derivatives(f: TimeFunction, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Value, first and second time derivative of a time function at t.

    Exact for :class:`Constant`, :class:`Step` (away from the jump), :class:`Ramp` and
    :class:`Table` (piecewise linear: second derivative 0 away from the kinks) and :class:`Sine`.
    For a :class:`Callable` ``fn`` the derivatives are fourth-order central differences of ``fn``
    with steps ``h1 = 1e-3 max(1, |t|)`` for the rate (truncation ``h1^4 |f^(5)| / 30``,
    round-off ``~ 1.5 u |f| / h1``: ~1e-13 relative for functions varying on a time scale of 1)
    and ``h2 = 2e-3 max(1, |t|)`` for the second derivative (truncation ``h2^4 |f^(6)| / 90``,
    round-off ``~ 5 u |f| / h2^2``, ~1e-10 relative). Other TimeFunction subclasses: their
    ``rate`` and the same fourth-order difference of ``rate`` for the second derivative.

    Returns
    -------
    (value, rate, acceleration) : ndarrays, shape of ``f(t)`` (at least 1-D)
    """
    val = np.atleast_1d(np.asarray(f(t), dtype=float))
    if isinstance(f, Component):
        _, r, a = time_derivatives(f.base, t)
        i = f.index if r.size > 1 else 0
        return val, r[i:i + 1], a[i:i + 1]
    if isinstance(f, Callable):  # (Callable.rate is second order, for the time loop's inputs)
        h1 = 1e-3 * max(1.0, abs(t))
        p = [np.asarray(f.fn(t + c * h1), dtype=float) for c in (-2, -1, 1, 2)]
        rate = (p[0] - 8 * p[1] + 8 * p[2] - p[3]) / (12 * h1)
    else:
        rate = np.asarray(f.rate(t), dtype=float)
    acc = np.asarray(f.accel(t), dtype=float)
    return val, np.atleast_1d(rate) * np.ones_like(val), np.atleast_1d(acc) * np.ones_like(val)


# =============================================================================================
# kinematic analysis and inverse dynamics
# =============================================================================================
@dataclass(eq=False)
class KinematicsResult(_Accessors):
    """Outcome of :func:`kinematics` (one row per time).

    Attributes
    ----------
    system : System
    t : ndarray (n,)
    H : ndarray (n, M, 4, 4)       node frames
    HJ : ndarray (n, m, 4, 4)      joint transformations
    alpha : ndarray (n, nq)        joint coordinates (Eq. (60)), 0 on node unknowns
    v, vd : ndarray (n, nq)        velocities and accelerations (material frame, Eq. (4))
    lam : ndarray (n, nm)          joint multipliers from inverse dynamics (reaction wrenches)
    efforts : dict                 driver name -> ndarray (n, k): the force/torque an actuator in
                                   that joint must exert (actuator sign of Eq. (66): power
                                   ``effort . alpha_dot``)
    kinetic, potential, spring : ndarray (n,)   energies (Eq. (47), gravity, elastic: Eq. (62)
                                   and the elastic elements, e.g. spring-dampers, bushings)
    iterations : ndarray (n,) int  Newton iterations for the positions
    """

    system: System
    t: np.ndarray
    H: np.ndarray
    HJ: np.ndarray
    alpha: np.ndarray
    v: np.ndarray
    vd: np.ndarray
    lam: np.ndarray
    efforts: dict
    kinetic: np.ndarray
    potential: np.ndarray
    spring: np.ndarray
    iterations: np.ndarray

    @property
    def _H(self):
        return self.H

    @property
    def _alpha(self):
        return self.alpha

    @property
    def _lam(self):
        return self.lam

    def node_velocity(self, name: str, frame: str = "material") -> np.ndarray:
        """Velocity ``(U, Omega)`` of a node, shape (n, 6); ``frame="inertial"`` gives
        ``(R v_U, R v_Omega)`` (the time derivative of the position, the spatial angular
        velocity)."""
        return self._node_dof(name, self.v, frame)

    def node_acceleration(self, name: str, frame: str = "material") -> np.ndarray:
        """Acceleration of a node, shape (n, 6): material ``(dU/dt, dOmega/dt)``, or
        ``frame="inertial"`` the acceleration of its origin and its angular acceleration in the
        inertial frame (:func:`se3dyn.results.results.node_accelerations`)."""
        return self._out(node_accelerations(self.system, self._H, self.v, self.vd,
                                            self._node(name), frame))

    def joint_velocities(self, name: str) -> np.ndarray:
        """Relative velocities of a joint (Eq. (61)), shape (n, k)."""
        return self._joint_cols(name, self.v)

    def joint_accelerations(self, name: str) -> np.ndarray:
        """Relative accelerations of a joint, shape (n, k)."""
        return self._joint_cols(name, self.vd)

    def driver_effort(self, name: str) -> np.ndarray:
        """Force/torque of a driver, shape (n, k)."""
        if name not in self.efforts:
            raise KeyError(_unknown_name("driver", name, list(self.efforts)))
        return self.efforts[name]

    @property
    def driver_power(self) -> np.ndarray:
        """Total power of the drivers ``sum effort . alpha_dot``, shape (n,)."""
        p = np.zeros(len(self.t))
        for name, e in self.efforts.items():
            p += np.sum(e * self.joint_velocities(name), axis=1)
        return p

    @property
    def total_energy(self) -> np.ndarray:
        """Kinetic + gravity potential + spring energy, shape (n,)."""
        return self.kinetic + self.potential + self.spring

    def __len__(self) -> int:
        return len(self.t)


def _model_drivers(s: System) -> list[tuple[str, np.ndarray, TimeFunction]]:
    """The model's own drives (``ModelBuilder.drive``) as drivers, one per driven coordinate
    (named by the drive, ``name[i]`` for the coordinates of a drive of several): position
    drives only, kinematics prescribes positions."""
    out = []
    for k, (dof, kind, d) in enumerate(zip(s.drive_dof, s.drive_kind, s.drive_of,
                                           strict=True)):
        dr = s.model.drives[d]
        i = [t for t in range(len(s.drive_of)) if s.drive_of[t] == d].index(k)
        if kind != 0:
            raise ModelError(f"drive '{dr.name}'", "velocity", "position drives (kinematics "
                             "prescribes positions)", "a velocity drive",
                             "pass drivers= to kinematics, or drive the position")
        name = dr.name if len(dr.targets) == 1 else f"{dr.name}[{i}]"
        out.append((name, np.array([dof]), dr.functions[i]))
    if not out:
        raise ModelError("kinematics", "drivers", "a non-empty mapping joint name -> time "
                         "function of its relative coordinate(s), or a model with drives",
                         None)
    return out


def _drivers(s: System, drivers) -> list[tuple[str, np.ndarray, list[TimeFunction]]]:
    """Validate drivers: [(name, dof indices (k,), [TimeFunction per joint part])]; None: the
    model's drives (:func:`_model_drivers`)."""
    if drivers is None:
        return _model_drivers(s)
    if s.model.drives:
        warnings.warn(Se3dynWarning(
            "kinematics: the model's drives (" + ", ".join(repr(d.name) for d in s.model.drives)
            + ") are not used: the drivers given replace them (drivers=None uses them)"),
            stacklevel=3)
    if not isinstance(drivers, Mapping) or not drivers:
        raise ModelError("kinematics", "drivers", "a non-empty mapping joint name -> time "
                         "function of its relative coordinate(s)", drivers)
    out = []
    used = np.zeros(s.nq, dtype=bool)
    for name, spec in drivers.items():
        ids = _joint_ids(s, name, "driver", "joint")
        item = _joint_item(s, name)
        k = int(sum(s.joint_k[j] for j in ids))
        if k == 0:
            raise ModelError(item, "drivers", "a joint with relative coordinates to drive", name,
                             "a rigid joint has none")
        for j in ids:
            if not s.joint_abelian[j]:
                raise ModelError(item, "drivers", "an abelian joint (hinge, prismatic, "
                                 "cylindrical, screw, universal) whose relative coordinates "
                                 "exist (Eq. (60))", s.joint_type[j],
                                 "the coordinates of a non-abelian joint (spherical, planar) "
                                 "are not additive; drive its motion by other joints")
        tf = as_timefunc(spec, item, "drivers", k)
        dofs = np.concatenate([s.joint_dofadr[j] + np.arange(s.joint_k[j]) for j in ids])
        if used[dofs].any():
            raise ModelError(item, "drivers", "each joint driven once", name)
        used[dofs] = True
        out.append((name, dofs, tf))
    return out


def _driver_values(drv, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    vals, rates, accs = [], [], []
    for name, dofs, tf in drv:
        k = len(dofs)
        try:
            f, r, a = time_derivatives(tf, t)
            f, r, a = (np.broadcast_to(x, (k,)) for x in (f, r, a))
        except Exception as exc:  # user callables may raise anything
            raise SimulationError(f"t={t:.9g}: driver {name!r} could not be evaluated to {k} "
                                  f"component(s): {type(exc).__name__}: {exc}") from None
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(r)) and np.all(np.isfinite(a))):
            raise SimulationError(f"t={t:.9g}: driver {name!r} returned a non-finite value")
        vals.append(f)
        rates.append(r)
        accs.append(a)
    return np.concatenate(vals), np.concatenate(rates), np.concatenate(accs)


def _check_rows(s: System, n: int) -> None:
    """Refuse, before anything is computed, more output times than a run may store
    (``simulate.MAX_STEPS``) or rows that would not fit in the available memory."""
    from se3dyn.dynamics.settings import MAX_STEPS, _available_memory

    if n > MAX_STEPS:
        raise ModelError("kinematics", "times", f"at most {MAX_STEPS:.0e} output times",
                         f"{n} times")
    per_row = 8 * (16 * (s.M + s.m) + 5 * s.nq + s.nm + 5)  # (H, HJ, alpha, v, vd, lam, ...)
    avail = _available_memory()
    if avail is not None and n * per_row > avail:
        raise ModelError("kinematics", "times", "results that fit in memory",
                         f"{n} times of {per_row} bytes = {n * per_row / 2**30:.1f} GiB",
                         f"{avail / 2**30:.1f} GiB available; ask for fewer output times")


def kinematics(model_or_system: Model | System, drivers: Mapping | None, times, *,
               tol: float = 1e-12,
               max_iter: int = 30) -> KinematicsResult:
    """Kinematic analysis of a driven mechanism and inverse dynamics.

    The relative coordinates of the driven (abelian) joints are prescribed,
    ``alpha_D(t) = f(t)`` (alpha of Eq. (60), measured from the model's initial configuration,
    or absolute for joints given ``initial`` values).
    With the joint constraints ``Phi = 0`` (Eq. (55)) they must leave no mobility: the Jacobian
    ``J = [B; D]`` (B: Eq. (58); D: selection of the driven coordinates) must have rank nq,
    redundant joint constraints being allowed. At every time:

    * positions: Newton on ``[Phi; alpha_D - f(t)] = 0`` from the previous solution advanced by
      ``exp(dt v + dt^2/2 vd)``, least-squares corrections ``J dn = -residual`` (SVD), to a
      scaled residual below ``tol``;
    * velocities: ``J v = [0; f'(t)]`` (``Phi_t = 0``: the joint constraints are scleronomic);
    * accelerations: ``J vd = [-(dB/dt) v; f''(t)]``. The quadratic velocity term
      ``c = (dB/dt) v = d/de [B(H exp(e v)) v]`` at ``e = 0`` (exactly, since ``T(e v) v = v``,
      Eq. (23)) is a Richardson-extrapolated central difference of the exact Jacobian:
      ``D(e) = (g(e) - g(-e)) / 2e``, ``c = (4 D(e/2) - D(e)) / 3``, truncation ``O(e^4)``, with
      ``e`` such that the scaled increment ``e |v|`` is 1e-3: relative error ~1e-12 truncation,
      ~1e-13 round-off;
    * inverse dynamics: with these accelerations the equations of motion (Eq. (36)) give
      ``Phi_q^T lambda + D^T mu = -(M vd - v^T M v + g_int - g_ext)`` (model actuators, PD laws,
      springs, dampers, loads and gravity included), solved by least squares (minimum norm in
      the scaled sense when constraints are redundant). The driver efforts are ``-mu`` (the
      actuator force of Eq. (66) that produces the motion), the joint reactions ``lambda``.

    Parameters
    ----------
    model_or_system : Model or System
    drivers : mapping joint name -> number, array (k,), TimeFunction or callable of t, or None
        Prescribed relative coordinates of abelian joints (hinge, prismatic, cylindrical, screw,
        universal). Derivatives: see :func:`time_derivatives`. None: the model's own position
        drives (``ModelBuilder.drive``), efforts named by drive; given drivers replace the
        model's drives (a warning says so).
    times : array_like (n,)
        Increasing output times.
    tol : float
        Newton tolerance on the scaled residual (translations / L, radians).
    max_iter : int
        Maximum Newton iterations per time.

    Returns
    -------
    KinematicsResult

    Raises
    ------
    ModelError
        Bad drivers (unknown joint, rigid or non-abelian joint, wrong number of components, a
        driver the constraints already fix) or a remaining mobility (naming the free unknowns).
    SimulationError
        Newton failure or a singular configuration (the mechanism loses its determinacy, e.g. a
        dead point), with the time and the worst item.
    """
    s = _as_system(model_or_system, "kinematics")
    if s.model.couplings:
        raise ModelError("kinematics", "model", "a model without couplings (kinematics does not "
                         "take them yet)", ", ".join(repr(c.name) for c in s.model.couplings),
                         hint="simulate drives the mechanism with them (ModelBuilder.drive)")
    drv = _drivers(s, drivers)
    if np.any(s.dof_ki > 0):
        warnings.warn(Se3dynWarning(
            "kinematics: the integral part of the PID laws is taken as zero in the inverse "
            "dynamics (its value is the history of a run); their P and D parts count"),
            stacklevel=2)
    tt = _check_settings(s, times, tol, max_iter)
    kp = _problem(s, drv)
    _check_structure(kp)
    nq, nm, nd, zq = s.nq, s.nm, len(kp.ddofs), kp.zq
    n_t = tt.size
    out_H = np.zeros((n_t, s.M, 4, 4))
    out_HJ = np.zeros((n_t, s.m, 4, 4))
    out_a = np.zeros((n_t, nq))
    out_v = np.zeros((n_t, nq))
    out_vd = np.zeros((n_t, nq))
    out_lam = np.zeros((n_t, nm))
    out_mu = np.zeros((n_t, nd))
    energy = np.zeros((n_t, 3))
    iters = np.zeros(n_t, dtype=int)
    H, HJ, alpha = s.node_H0.copy(), s.joint_H0.copy(), s.alpha0.copy()
    v = np.zeros(nq)
    vd = np.zeros(nq)
    for i, t in enumerate(tt):
        f, fr, fa = _driver_values(drv, float(t))
        # ----- positions: Newton from the predicted configuration
        pred = zq if i == 0 else (t - tt[i - 1]) * v + 0.5 * (t - tt[i - 1]) ** 2 * vd
        ev, iters[i] = _positions(kp, H, HJ, alpha, pred, f, t, tol, max_iter)
        H, HJ, alpha = ev.H, ev.HJ, ev.alpha
        # ----- velocities
        usv, PT = _velocity_solver(kp, ev, t)
        v = _lsq(kp, usv, np.concatenate([np.zeros(nm), fr]))
        # ----- accelerations: quadratic velocity term by Richardson extrapolation
        c = _quadratic_velocity_term(kp, H, HJ, alpha, v)
        vd = _lsq(kp, usv, np.concatenate([-c, fa]))
        # ----- inverse dynamics (Eq. (36)): Phi_q^T lam + D^T mu = -r0
        sol, energy[i] = _inverse_dynamics(kp, H, HJ, alpha, v, vd, PT, t)
        out_H[i], out_HJ[i], out_a[i] = H, HJ, alpha
        out_v[i], out_vd[i] = v, vd
        out_lam[i] = sol[:nm]
        out_mu[i] = sol[nm:]
    return KinematicsResult(system=s, t=tt, H=out_H, HJ=out_HJ, alpha=out_a, v=out_v,
                            vd=out_vd, lam=out_lam, efforts=_efforts(drv, out_mu),
                            kinetic=energy[:, 0], potential=energy[:, 1], spring=energy[:, 2],
                            iterations=iters)


def _check_settings(s: System, times, tol, max_iter) -> np.ndarray:
    """Refuse bad output times, tolerance or iteration limit; returns the times (n,)."""
    try:
        tt = np.asarray(times, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ModelError("kinematics", "times", "increasing finite times", times) from None
    if tt.size == 0 or not np.all(np.isfinite(tt)) or np.any(np.diff(tt) <= 0):
        raise ModelError("kinematics", "times", "a non-empty list of increasing finite times",
                         times)
    _check_rows(s, tt.size)
    if not (isinstance(tol, int | float) and 0 < tol < 1):
        raise ModelError("kinematics", "tol", "a positive tolerance below 1", tol)
    if not (isinstance(max_iter, int) and max_iter >= 1):
        raise ModelError("kinematics", "max_iter", "a positive integer", max_iter)
    return tt


@dataclass(frozen=True, eq=False)
class _Problem:
    """The constant data of a kinematic analysis: the system, the drivers, the selection ``D``
    of the driven unknowns, the row and unknown scales and the matrix blocks."""

    s: System
    drv: list
    ddofs: np.ndarray
    D: np.ndarray
    rs: np.ndarray
    cs: np.ndarray
    blocks: _Blocks
    zq: np.ndarray
    lam0: np.ndarray
    zin: object
    labels: list


def _problem(s: System, drv: list) -> _Problem:
    """The driven unknowns, their selection matrix, the scales and the block extractor."""
    nq = s.nq
    ddofs = np.concatenate([d for _, d, _ in drv])
    nd = len(ddofs)
    D = np.zeros((nd, nq))
    D[np.arange(nd), ddofs] = 1.0
    L = _char_length(s)
    cs = _unknown_scale(s, L)
    rs = np.concatenate([_row_scale(s, L), 1.0 / cs[ddofs]])
    return _Problem(s=s, drv=drv, ddofs=ddofs, D=D, rs=rs, cs=cs, blocks=_Blocks(s),
                    zq=np.zeros(nq), lam0=np.zeros(s.nm), zin=_zero_inputs(s),
                    labels=list(s.labels))


def _jac(kp: _Problem, ev) -> tuple[np.ndarray, np.ndarray]:
    """``J = [B; D]`` and ``Phi_q^T`` of an evaluation."""
    _, PT, B = kp.blocks(ev)
    return np.vstack([B, kp.D]), PT


def _check_structure(kp: _Problem) -> None:
    """Refuse, at the initial configuration, a remaining mobility or a redundant driver."""
    s, drv, ddofs, rs, cs, zq = kp.s, kp.drv, kp.ddofs, kp.rs, kp.cs, kp.zq
    nq, nm, nd = s.nq, s.nm, len(ddofs)
    H, HJ, alpha = s.node_H0.copy(), s.joint_H0.copy(), s.alpha0.copy()
    ev = evaluate(s, H, HJ, alpha, zq, zq, zq, kp.lam0, kp.zin, None, full_alpha=True)
    J, _ = _jac(kp, ev)
    Js = rs[:, None] * J * cs
    r, N = _null_space(Js)
    if r < nq:
        raise ModelError("kinematics", "drivers", "drivers that leave no mobility (remaining "
                         "degrees of freedom 0)", f"{nq - r} remaining degree(s) of freedom",
                         "free motion involves " + _describe(N[:, 0] * cs, kp.labels)
                         + "; drive one of these joints or fix the motion")
    rB = _null_space(Js[:nm])[0]
    if rB + nd > r:
        for name, dofs, _ in drv:
            keep_rows = np.ones(nm + nd, dtype=bool)
            keep_rows[nm + np.flatnonzero(np.isin(ddofs, dofs))] = False
            if _null_space(Js[keep_rows])[0] == r:
                raise ModelError(_joint_item(s, name), "drivers", "a driver on a coordinate the "
                                 "constraints leave free", name, "the joint constraints "
                                 "already determine this coordinate from the other drivers "
                                 "(redundant or conflicting driver)")


def _positions(kp: _Problem, H, HJ, alpha, pred, f, t, tol: float, max_iter: int):
    """Newton on ``[Phi; alpha_D - f(t)] = 0`` from the predicted configuration, least-squares
    corrections; returns the converged evaluation and the number of iterations."""
    s, ddofs, rs, cs, zq, lam0, zin = kp.s, kp.ddofs, kp.rs, kp.cs, kp.zq, kp.lam0, kp.zin
    nq, nm, labels = s.nq, s.nm, kp.labels
    ev = evaluate(s, H, HJ, alpha, pred, zq, zq, lam0, zin, None, full_alpha=True)
    it = 0
    while True:
        H, HJ, alpha = ev.H, ev.HJ, ev.alpha
        res = np.concatenate([ev.phi, alpha[ddofs] - f]) * rs
        err = float(np.abs(res).max(initial=0.0))
        if not np.isfinite(err):
            raise SimulationError(f"kinematics: t={t:.9g}: the configuration became "
                                  "non-finite")
        if err <= tol:
            return ev, it
        if it >= max_iter:
            w = int(np.argmax(np.abs(res)))
            where = labels[nq + w] if w < nm else f"driver on {labels[ddofs[w - nm]]}"
            raise SimulationError(
                f"kinematics: Newton failed at t={t:.9g} after {it} iterations: scaled "
                f"residual {err:.3e} (tol {tol:.1e}); worst: {where}. The prescribed "
                "motion may be out of reach of the mechanism, or the time step too large "
                "for the predictor")
        J, _ = _jac(kp, ev)
        Js = rs[:, None] * J * cs
        y = sla.lstsq(Js, -res, cond=_RCOND, lapack_driver="gelsd")[0]
        ev = evaluate(s, H, HJ, alpha, cs * y, zq, zq, lam0, zin, None, full_alpha=True)
        it += 1


def _velocity_solver(kp: _Problem, ev, t) -> tuple[tuple, np.ndarray]:
    """The truncated SVD ``(U_r, V_r, s_r)`` of the scaled ``J`` at the solved configuration,
    refusing a singular one, and ``Phi_q^T``."""
    nq, rs, cs = kp.s.nq, kp.rs, kp.cs
    J, PT = _jac(kp, ev)
    Js = rs[:, None] * J * cs
    U, sv, Vt = _svd(Js)
    rank = int(np.sum(sv > _RCOND * sv[0])) if sv.size and sv[0] > 0 else 0
    if rank < nq:
        Nv = _svd(Js, full=True)[2][rank:].T
        raise SimulationError(
            f"kinematics: singular configuration at t={t:.9g}: the drivers no longer "
            f"determine the motion (rank {rank} < {nq}; a dead point or a change of "
            "branch); free motion involves " + _describe(Nv[:, 0] * cs, kp.labels))
    return (U[:, :rank], Vt[:rank].T, sv[:rank]), PT


def _lsq(kp: _Problem, usv: tuple, rhs: np.ndarray) -> np.ndarray:
    """The solution of ``J x = rhs`` by the truncated SVD of :func:`_velocity_solver`."""
    Ur, Vr, sr = usv
    return kp.cs * (Vr @ ((Ur.T @ (kp.rs * rhs)) / sr))


def _quadratic_velocity_term(kp: _Problem, H, HJ, alpha, v: np.ndarray) -> np.ndarray:
    """``c = (dB/dt) v`` by a Richardson-extrapolated central difference of the exact
    Jacobian."""
    s, zq = kp.s, kp.zq
    vs = np.abs(v / kp.cs).max(initial=0.0)
    c = np.zeros(s.nm)
    if vs > 0:
        eps = 1e-3 / vs

        def g(e):
            evp = evaluate(s, H, HJ, alpha, e * v, zq, zq, kp.lam0, kp.zin, None,
                           full_alpha=False)
            return kp.blocks(evp)[2] @ v

        D1 = (g(eps) - g(-eps)) / (2 * eps)
        D2 = (g(eps / 2) - g(-eps / 2)) / eps
        c = (4 * D2 - D1) / 3
    return c


def _inverse_dynamics(kp: _Problem, H, HJ, alpha, v, vd, PT, t) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """Inverse dynamics (Eq. (36)): ``Phi_q^T lam + D^T mu = -r0`` by least squares; returns
    ``[lam; mu]`` and the kinetic, gravity and elastic energies."""
    s, rs, cs, zq = kp.s, kp.rs, kp.cs, kp.zq
    inputs = step_inputs(s, float(t))
    evd = evaluate(s, H, HJ, alpha, zq, v, vd, kp.lam0, inputs, None, full_alpha=True)
    # rows (equations) times cs and columns (multipliers) times rs: moment units
    G = cs[:, None] * np.hstack([PT, kp.D.T]) * rs
    sol = rs * sla.lstsq(G, -cs * evd.r, cond=_RCOND, lapack_driver="gelsd")[0]
    # kinetic (Eq. (47)), gravity potential, elastic energy of every element (joint
    # springs Eq. (62), spring-dampers, bushings), by the element kernels
    return sol, evd.energy[:3]


def _efforts(drv: list, out_mu: np.ndarray) -> dict:
    """The driver efforts ``-mu``, joint by joint."""
    efforts = {}
    off = 0
    for name, dofs, _ in drv:
        efforts[name] = -out_mu[:, off:off + len(dofs)]
        off += len(dofs)
    return efforts
