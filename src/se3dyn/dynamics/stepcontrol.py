"""Step-size control of adaptive runs (``simulate(..., tol=...)``): the norm of a step's local
error estimate and the choice of the next step; and the estimate of a run's global error
(:class:`GlobalEstimate`, ``global_error=True``), which never steers the steps.

The estimate itself comes from the integrator (:meth:`GeneralizedAlpha.step`): the part of the
increment's Taylor expansion the generalized-alpha update does not reproduce,
``(1/6 - beta - (alpha_m - alpha_f) / 2) h^2 (a_{n+1} - a_n)`` (Eqs. (38), (43), (44); ``a_n``
approximates the acceleration at ``t_n + (alpha_m - alpha_f) h``), an increment in the Lie
algebra of every node and joint.

**Norm.** A body's error is the root mean square, over its mass, of the position errors of its
material points: for an increment error ``(e_U, e_Omega)`` in the material frame of a node of
mass ``m``, centre of mass ``c`` and inertia ``J`` about it (Eqs. (47)-(53)),
``sqrt(|e_U + e_Omega x c|^2 + e_Omega . J e_Omega / m)`` (metres); the norm is the largest
over the nodes. Errors of a rotation weigh by the body's radius of gyration about that axis:
a slender rod's spin about its own axis, which moves no material point far, counts little,
and massless nodes (joint frames that the constraints determine) not at all. A node with
rotary inertia and no mass counts its rotation error times the model's length scale.

**Controller.** A step of size ``h`` is accepted when its error is at most its share
``tol * (h_bar / span) * (h_bar / h)^3``, with ``span = t_end - t_start`` and ``h_bar`` the
mean step from ``t_start`` so far (the initial step before the first one); with the error
``c h^3`` of a second-order scheme this places the steps as ``h ~ c^(-1/6)``. The next step is
``h (share / error)^(1/6)`` (the error-to-share ratio goes as ``h^6``; safety 0.9, at most
doubled, at least a fifth), kept unchanged when the proposal would grow it by less than 30 %
(no step-size jitter on motions of even difficulty).

**Tracking.** That rule makes the steps depend on the run's history: through ``h_bar`` (which
falls in a violent phase and rises in a quiet one) and through the dead band (steps shrink
step by step towards an acceleration peak, stay there after it and grow in 30 % jumps later).
On a mechanism passing singular positions (A02, the N-four-bar) that costs most of the
accuracy: a change of the step from ``h0`` to ``h1`` leaves an error of first order in
``h1^2 - h0^2`` that the passage amplifies (on A02, the error at t = 2 s over
``|h1^2 - h0^2|``: 0.2 m/s^2 for a change in the quiet phase, 80 m/s^2 at the acceleration
peak), and a step sequence that shrinks
before each peak and grows after it adds these errors up at every passage (7 to 8 times the
error of as many even steps), while one that is a function of the current state lets them
cancel (0.6 to 0.8 times). So while a step's error stays within ``[KEEP_BELOW^-6, 1]`` of its
share, the next step keeps ``h c^(1/6)``: ``h (c_n / c_{n+1})^(1/6)``, with ``c_n`` the
coefficient of the local error ``c h^3`` that the states at the step's ends give through
``a - vd = (alpha_m - alpha_f) h q^(3)`` (:func:`coefficient`); the rule above only rescales
it (an error outside the band, a coefficient changing by more than ``KEEP_BELOW`` in one
step, the first step, and rho_inf = 1, where ``a = vd`` gives nothing).

**Phases.** Under tracking the error-to-share ratio is ``k^6 span / (tol h_bar^4)`` with
``k = h c^(1/6)`` constant: it climbs as ``h_bar`` falls through a violent phase (on A02 at
tol = 1e-5 from 0.2 to 1 through the first swing from rest) and a rejection there, a 10 % step
change at the acceleration peak, cost most of the run's accuracy (10 tol). So a step shorter
than ``QUIET`` times ``h_bar`` (a violent phase) is accepted up to ``ALLOWANCE`` times its
share and keeps tracking down to ``KEEP_BELOW^-12`` of it (a spurious jump of ``a - vd`` near
a singular position then does not freeze the step for hundreds of steps); the first step of
the following quiet phase (``h >= QUIET h_bar``, where a step change costs little) is held to
its share and rescales ``k`` there (:func:`allowance`). On A02 at 1e-5: one rescale at
t = 1.59 s instead of two rejections at the peak, global error 1.2 tol instead of 10.

Why ``c^(-1/6)``. On a motion of even difficulty the steps are even and the shares add up to
``tol``: the local errors sum to ``tol``. Where the difficulty varies, the classical rule (equal
error per step, ``h ~ c^(-1/3)``, the fewest steps for a given *sum of local errors*) spends its
steps in short violent phases (a slider-crank's rod whipping round, a squeezer's links
swinging through) whose large local errors largely cancel in the global error, and takes long
steps in the quiet phases before them, whose errors the motion then amplifies. Measured on
eight problems at three tolerances (``benchmarks/adaptive_steps.py``, ``docs/accuracy.md``):
``c^(-1/6)`` with tracking and phases needs 0.45-1.04 times the steps of the best fixed
step of the same global error in all 24 runs (tracking alone: 0.44-1.05 in 22, the N-four-bar
at the tightest tolerance 2.7, the squeezer 1.2), against 0.45-1.07 and 1.3-4.2 (the
squeezer, the N-four-bar) without tracking and 0.39-2.8 (and 3.7-3.9) for ``c^(-1/3)``.
The price: where steps vary, the sum of the local errors is no longer ``tol``.
Everything depends on the time, the step count, the step and the states at the step's ends
only, so a run continued from a checkpoint chooses the same steps.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from se3dyn.engine.inputs import CONTACT_STATE
from se3dyn.errors import NewtonError

#: Safety factor on the proposed step, its bounds per step and the dead band of growth.
SAFETY, GROW_MAX, SHRINK_MIN, KEEP_BELOW = 0.9, 2.0, 0.2, 1.3
#: A step is in a quiet phase when it is at least QUIET times the mean step so far; elsewhere
#: (a violent phase) an error up to ALLOWANCE times its share is accepted, and a tracked step
#: keeps tracking down to KEEP_BELOW^-12 of it (KEEP_BELOW^-6 in a quiet phase).
QUIET, ALLOWANCE = 1.2, 4.0


#: Largest ``h`` times the contact rate of a pair (:func:`contact_ratio`): 0.25 resolves the
#: half period of a Hertz contact in about 12 steps (docs/contact.md: the measurements)
CONTACT_ETA = 0.15


def contact_ratio(s, st0, st1, h: float) -> float:
    """How far a step of size ``h`` from ``st0`` to ``st1`` is beyond what the contacts allow
    (<= 1: accepted; the step is to shrink by about this factor otherwise).

    Per contact pair (``s.contacts``, states in ``State.ctrl``: se3dyn.elements.contact) the
    rate ``sqrt(k_lin / m) (1 + c min(1, |delta'| / v_in))`` of the law at the larger of the
    step's two penetrations (``k_lin = 3/2 k sqrt(delta)``, the tangent of Hertz's force,
    raised by the damping's share of the force as it is during an impact; ``m`` the pair's
    reduced mass of its nodes) times ``h``, over
    :data:`CONTACT_ETA`: the step resolves the contact's own motion. A step that jumps from
    apart to deep penetration is refused the same way, which localises the touch-down. The
    rate counts in full while the penetration changes at the material's ``min_impact_speed``
    or faster and in proportion below: a resting or rolling contact, whose normal motion
    carries no energy to speak of, is left to the implicit scheme (which damps its
    unresolved normal vibration) instead of holding the step to its period."""
    if not s.contacts:
        return 0.0
    tab = _contact_table(s)
    off = s.inputs.contact_ctrl
    c0 = np.asarray(st0.ctrl[off:], float).reshape(-1, CONTACT_STATE)
    c1 = np.asarray(st1.ctrl[off:], float).reshape(-1, CONTACT_STATE)
    d = np.maximum(np.maximum(c0[:, 6], c1[:, 6]), 0.0)
    vin = np.maximum(np.maximum(c1[:, 8], c0[:, 8]), tab["vmin"])
    speed = np.maximum(np.abs(c0[:, 7]), np.abs(c1[:, 7]))
    damp = tab["c"] * np.minimum(speed / vin, 1.0)
    rate = np.sqrt(1.5 * tab["k"] * np.sqrt(d) / tab["m"]) * (1.0 + damp)
    return float(np.max(h * rate * np.minimum(1.0, speed / tab["vmin"]), initial=0.0)) / \
        CONTACT_ETA


def contact_restart(s, st0, st1):
    """``st1``, or when a contact pair touched down or separated in the step from ``st0``,
    ``st1`` with the generalized-alpha variable ``a`` set to the accelerations ``vd``: the run
    goes on as one started there. Without it the lag ``a - vd`` of the contact's fast force
    carries into the free motion and the next steps' growth amplifies it (``a_n = vd +
    (h / h_last)(a - vd)``): a ball leaving the floor gained 20 % of its energy at h = 5 ms."""
    if not s.contacts:
        return st1
    off = s.inputs.contact_ctrl
    on0 = np.asarray(st0.ctrl[off:], float).reshape(-1, CONTACT_STATE)[:, 8] > 0
    on1 = np.asarray(st1.ctrl[off:], float).reshape(-1, CONTACT_STATE)[:, 8] > 0
    if np.array_equal(on0, on1):
        return st1
    return dataclasses.replace(st1, a=np.array(st1.vd, float))


def _contact_table(s) -> dict:
    """The pairs' Hertz constants, damping constants, speed floors and reduced masses."""
    if "contact_table" not in s.pattern:
        mass = {n.name: (np.inf if n.fixed else n.mass) for n in s.model.nodes}
        col = lambda f: np.array([f(p) for p in s.contacts], float)  # noqa: E731
        s.pattern["contact_table"] = dict(
            k=col(lambda p: p.k), c=col(lambda p: p.c), vmin=col(lambda p: p.vmin),
            m=col(lambda p: 1.0 / (1.0 / mass[p.a.node] + 1.0 / mass[p.b.node])))
    return s.pattern["contact_table"]


class ErrorNorm:
    """The mass-weighted norm of errors of the node frames of one system (see the module):
    of a step's local error estimate (an increment) and, exactly for finite errors, of the
    frames of one run against another (:meth:`frames`).

    Parameters
    ----------
    s : System
    """

    def __init__(self, s):
        free = np.asarray(s.node_free, dtype=np.int64)
        m = np.asarray(s.node_mass, dtype=float)[free]
        J = np.asarray(s.node_J, dtype=float)[free]
        massive = m > 0
        spinning = ~massive & (np.abs(J).max(axis=(1, 2), initial=0.0) > 0)
        self._nodes = free[massive]  # (nb,) node indices
        self._spin_nodes = free[spinning]  # (nr,)
        self._dof = np.asarray(s.node_dofidx)[massive]  # (nb, 6)
        self._com = np.asarray(s.node_com, dtype=float)[free][massive]  # (nb, 3)
        self._Jm = J[massive] / m[massive, None, None]  # (nb, 3, 3) J / m
        # second moment of the mass about the centre of mass per unit mass, S = tr(J)/2 - J
        tr = np.trace(self._Jm, axis1=1, axis2=2)
        self._Sm = 0.5 * tr[:, None, None] * np.eye(3) - self._Jm
        self._rot = np.asarray(s.node_dofidx)[spinning][:, 3:]  # (nr, 3)
        self._length = float(s.length_scale)

    def frames(self, H: np.ndarray, H_ref: np.ndarray) -> np.ndarray:
        """The norm of the error of the node frames ``H`` against ``H_ref``, exact for finite
        errors: per body the root mean square over its mass of ``|x + R X - x_ref - R_ref X|``
        over its material points X, ``|dx + dR c|^2 + tr(dR S dR^T) / m`` with S the second
        moment of the mass about the centre of mass, the largest over the bodies (m).

        Parameters
        ----------
        H, H_ref : ndarray (..., M, 4, 4)
            Frames of all nodes (e.g. ``Results.H`` of two runs on the same times).

        Returns
        -------
        ndarray (...)
        """
        H, H_ref = np.asarray(H, dtype=float), np.asarray(H_ref, dtype=float)
        A, B = H[..., self._nodes, :, :], H_ref[..., self._nodes, :, :]
        dR = A[..., :3, :3] - B[..., :3, :3]
        d = A[..., :3, 3] - B[..., :3, 3] + np.einsum("...ij,...j->...i", dR, self._com)
        sq = (np.einsum("...i,...i->...", d, d)
              + np.einsum("...ij,...jk,...ik->...", dR, self._Sm, dR))
        out = np.sqrt(np.maximum(sq, 0.0).max(axis=-1, initial=0.0))
        if len(self._spin_nodes):
            C = np.einsum("...ji,...jk->...ik", H_ref[..., self._spin_nodes, :3, :3],
                          H[..., self._spin_nodes, :3, :3])
            c = np.clip(0.5 * (np.trace(C, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
            out = np.maximum(out, self._length * np.arccos(c).max(axis=-1))
        return out

    def _squares(self, e: np.ndarray) -> np.ndarray:
        """(nb,) squared norms of the bodies for an error estimate ``e`` (nq,)."""
        E = e[self._dof]
        ew = E[:, 3:]
        d = E[:, :3] + np.cross(ew, self._com)
        return np.einsum("ni,ni->n", d, d) + np.einsum("ni,nij,nj->n", ew, self._Jm, ew)

    def __call__(self, e: np.ndarray) -> float:
        """Norm (m) of a local error estimate ``e`` of shape (nq,) (the node components, an
        increment ``(e_U, e_Omega)`` per node in its material frame)."""
        out = float(np.sqrt(self._squares(e).max(initial=0.0)))
        if len(self._rot):
            out = max(out, self._length * float(np.abs(e[self._rot]).max()))
        return out

    def worst(self, e: np.ndarray) -> int:
        """Index in ``e`` of the largest component of the node with the largest error."""
        if not len(self._dof):
            return int(np.argmax(np.abs(e)))
        k = int(np.argmax(self._squares(e)))
        return int(self._dof[k][np.argmax(np.abs(e[self._dof[k]]))])


def share(tol: float, span: float, t: float, t_start: float, steps: int, h: float) -> float:
    """A step's share of the tolerance, ``tol (h_bar / span) (h_bar / h)^3`` for a step of size
    ``h``, with ``h_bar`` the mean step of the ``steps`` steps from ``t_start`` to ``t`` (``h``
    before the first): ``tol / N`` for N even steps."""
    h_bar = (t - t_start) / steps if steps > 0 and t > t_start else h
    return max(tol * (h_bar / span) * (h_bar / h) ** 3, 1e-300)


def allowance(t: float, t_start: float, steps: int, h: float) -> float:
    """The error-to-share ratio up to which a step of size ``h`` from ``t`` is accepted, after
    ``steps`` steps from ``t_start``: 1 in a quiet phase (``h`` at least ``QUIET`` times the
    mean step so far), ``ALLOWANCE`` in a violent one (see the module: there the ratio of
    tracked steps climbs as the mean step falls, and a rejection, a step change, costs most;
    the first quiet step rescales)."""
    h_bar = (t - t_start) / steps if steps > 0 and t > t_start else h
    return 1.0 if h >= QUIET * h_bar else ALLOWANCE


def coefficient(norm: ErrorNorm, st, params: tuple[float, float, float, float]) -> float | None:
    """The local error coefficient ``c`` (a step's error ``c h^3``, m/s^3) at the state ``st``,
    from ``a - vd = (alpha_m - alpha_f) h_last q^(3)`` (Eq. (43): ``a`` approximates ``vd`` at
    ``t + (alpha_m - alpha_f) h``): ``|1/6 - beta - (alpha_m - alpha_f)/2| |q^(3)|`` in the
    norm ``norm``. None where ``a - vd`` carries no information: the initial state
    (``h_last = 0``) and ``alpha_m = alpha_f`` (rho_inf = 1).

    Parameters
    ----------
    norm : ErrorNorm
    st : State
    params : (alpha_m, alpha_f, gamma, beta) of the integrator
    """
    am, af, _, b = params
    d = am - af
    if not st.h_last > 0 or abs(d) < 1e-9:
        return None
    e = np.asarray(st.a, dtype=float) - np.asarray(st.vd, dtype=float)
    return abs(1.0 / 6.0 - b - 0.5 * d) * norm(e) / (abs(d) * st.h_last)


def next_step(h: float, ratio: float, accepted: bool,
              c: tuple[float | None, float | None] | None = None, limit: float = 1.0) -> float:
    """The step after one of size ``h`` whose error was ``ratio`` times its share (a ratio that
    goes as ``h^6``, see the module; unbounded by ``h_min``/``h_max``: the caller clips). A
    rejected step always shrinks.

    ``c``: the error coefficients (:func:`coefficient`) of the states at the start and the end
    of the accepted step. With both known, a ratio within ``[KEEP_BELOW^-6, 1]`` and a change
    of at most a factor ``KEEP_BELOW``, the step *tracks* the state: ``h (c_0 / c_1)^(1/6)``,
    so that ``h c^(1/6)`` stays what it was (steps as ``c^(-1/6)`` of the current state, not of
    the run's history); otherwise the rule below. ``limit``: the step's :func:`allowance`;
    above 1 (a violent phase) the band is ``[KEEP_BELOW^-12, limit]``."""
    f = SAFETY * max(ratio, 1e-10) ** (-1.0 / 6.0)
    if not accepted:
        return h * min(SAFETY, max(SHRINK_MIN, f))
    if c is not None and c[0] is not None and c[1] is not None and c[1] > 0:
        g = (c[0] / c[1]) ** (1.0 / 6.0)
        low = KEEP_BELOW ** (-12 if limit > 1.0 else -6)
        if low <= ratio <= limit and 1.0 / KEEP_BELOW <= g <= KEEP_BELOW:
            return h * g
    f = min(GROW_MAX, max(SHRINK_MIN, f))
    if 1.0 <= f < KEEP_BELOW:
        f = 1.0
    return h * f


class GlobalEstimate:
    """Richardson estimate of the global position error of an adaptive run (``simulate(...,
    tol=..., global_error=True)``), from a companion run on the run's own steps taken two at a
    time.

    The companion starts from the same state and takes one step across every two accepted
    steps of the run (``h_1 + h_2``); at the end of each such pair both runs stand at the same
    time. The scheme being second order in the positions (Eqs. (38)-(46)), on step sequences
    ``h(t)`` and ``2 h(t)`` the global errors are ``C(t) h^2`` and ``4 C(t) h^2`` to leading
    order, so the run's own error is ``(y_2h - y_h) / (2^2 - 1)`` (Richardson's global
    extrapolation: Hairer, Nørsett & Wanner, Solving Ordinary Differential Equations I, 2nd
    ed., Springer 1993, Sec. II.12):
    the :class:`ErrorNorm` of the frames of the two runs, over three. It costs about half the
    run's steps again (the companion's steps, each a Newton solve), and no step of the run
    depends on it. Where the companion's Newton iterations fail (a step twice as long may not
    converge near a singular position) the estimate stops there and says so. It holds where
    the errors are in their asymptotic range, ``C h^2``: where the steps do not resolve the
    fast modes of a model (a flexible beam released at t = 0) it can be off by a factor of
    a few (docs/accuracy.md).

    Parameters
    ----------
    norm : ErrorNorm
        The norm of the run's system.
    state : State
        The state both runs start from.
    step : callable ``step(state, t) -> State``
        One step of the companion from ``state`` to the time ``t`` (its own workspace),
        raising
        :class:`~se3dyn.errors.NewtonError` when Newton fails.
    """

    #: 2^p - 1 for a scheme of order p = 2
    RICHARDSON = 3.0

    def __init__(self, norm: ErrorNorm, state, step):
        self.norm, self.coarse, self._step = norm, state, step
        self.t_from = float(state.t)
        self.pending = 0  # accepted steps of the run since the companion's last step
        self.largest, self.t_largest, self.last = 0.0, float(state.t), 0.0
        self.steps = 0
        self.failed_at: float | None = None
        self.failure = ""
        self._t: list[float] = []
        self._e: list[float] = []

    def accepted(self, st, final: bool) -> None:
        """The run accepted a step ending in the state ``st``; ``final``: the run's last
        step (a single step left over is taken alone)."""
        if self.failed_at is not None:
            return
        self.pending += 1
        if self.pending < 2 and not final:
            return
        self.pending = 0
        try:
            c = self._step(self.coarse, float(st.t))
        except NewtonError as exc:
            self.failed_at, self.failure = float(self.coarse.t), str(exc).split(";")[0]
            return
        self.coarse = c
        self.steps += 1
        e = float(self.norm.frames(st.H, c.H)) / self.RICHARDSON
        self.last = e
        if e > self.largest:
            self.largest, self.t_largest = e, float(st.t)
        self._t.append(float(st.t))
        self._e.append(e)

    def replace(self, norm: ErrorNorm, coarse, step) -> None:
        """Continue on another system (the rigid joints of a condensed run kept from here):
        its norm, the companion's state expanded to it and its step."""
        self.norm, self.coarse, self._step = norm, coarse, step

    def history(self) -> np.ndarray:
        """(k, 2) the times at which both runs met and the estimate there (m)."""
        return np.column_stack([np.asarray(self._t, dtype=float),
                                np.asarray(self._e, dtype=float)]).reshape(-1, 2)

    def stats(self) -> dict:
        """The entries of ``Results.stats``: ``global_error`` (the largest estimate, m),
        ``global_error_at`` (its time), ``global_error_final`` (at the last meeting),
        ``global_error_from`` (where the companion started), ``global_error_steps`` (its
        steps), ``global_error_history`` ((k, 2) times and estimates) and, when its Newton
        iterations failed, ``global_error_until`` and ``global_error_failure``."""
        out = dict(global_error=self.largest if self._e else None,
                   global_error_at=self.t_largest, global_error_final=self.last,
                   global_error_from=self.t_from, global_error_steps=self.steps,
                   global_error_history=self.history())
        if self.failed_at is not None:
            out.update(global_error_until=self.failed_at, global_error_failure=self.failure)
        return out
