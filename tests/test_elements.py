"""Contract test over the element registry (se3dyn.elements.REGISTRY): registering an element
type runs these checks on the example models of its module, through the compiled engine.

* tangent blocks against central finite differences of the residual, constraints and velocity
  constraints at random states (configuration, velocity and acceleration columns, multiplier
  columns, the index-2 velocity-constraint rows);
* invariance of residual, constraints and matrix under a superposed rigid motion of the whole
  system (with the inertial-frame inputs, gravity and inertial loads, moved along);
* constraint elements: zero violation to second order and zero power along allowed motions;
* conservative elements: the generalised force is the gradient of the energy (power of the
  internal forces = -dE/dt).
"""

from __future__ import annotations

import numpy as np
import pytest

from se3dyn import lie
from se3dyn.elements import REGISTRY
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.linsolve import LinearSolver
from se3dyn.engine.system import compile_model

CASES = [(key, i) for key, mod in REGISTRY.items()
         for i in range(len(mod.examples(np.random.default_rng(0))))]


def _model(key, i, seed=0):
    return REGISTRY[key].examples(np.random.default_rng(seed))[i]


def _state(s, rng, scale=0.3):
    """A random state: frames at the start of the step, coordinates, increments, velocities,
    accelerations and multipliers."""
    Hn = s.node_H0 @ lie.exp_se3(scale * rng.normal(size=(s.M, 6)))
    HJn = s.joint_H0.copy()
    for g in s.groups:
        if g.k:
            HJn[g.ids] = s.joint_H0[g.ids] @ lie.exp_se3(
                np.einsum("jik,jk->ji", g.A, scale * rng.normal(size=(len(g.ids), g.k))))
    return dict(Hn=Hn, HJn=HJn, alpha=rng.normal(size=s.nq), n=scale * rng.normal(size=s.nq),
                v=rng.normal(size=s.nq), vd=rng.normal(size=s.nq), lam=rng.normal(size=s.nm))


def _with_pid_states(s, inputs, rng):
    """The inputs with PID states (z_n, e_n, h/2) in their slots (joint_force.hpp), as the
    time loop writes them: a step's integral and its tangent ki h/2 exercised."""
    for slot in s.inputs.pid_slots:
        inputs["u"][slot:slot + 3] = (rng.normal(), rng.normal(), 0.01)
    for i, slot in enumerate(s.inputs.contact_slots):  # contacts (contact.hpp): bristle, slip
        # velocity, penetration, its rate, impact speed (0: touching down in the step), h/2
        inputs["u"][slot:slot + 20] = (*rng.normal(size=6), -0.1, 1.0, 1.5 * ((i + 1) % 2),
                                       *np.zeros(10), 0.01)
    return inputs


def _eval(s, st, inputs, coef=None, **kw):
    return evaluate(s, st["Hn"], st["HJn"], st["alpha"], st["n"], st["v"], st["vd"], st["lam"],
                    inputs, coef, velocity=True, **kw)


def _dense(s, values, index2=False):
    A = LinearSolver(s, dense_max=10 ** 9, index2=index2).matrix(values)
    return np.asarray(A)


def _fd(f, x0, eps=1e-6):
    """Central finite-difference Jacobian of f at x0."""
    cols = []
    for i in range(len(x0)):
        d = np.zeros_like(x0)
        d[i] = eps
        cols.append((f(x0 + d) - f(x0 - d)) / (2 * eps))
    return np.array(cols).T


def _close(A, B, what):
    scale = max(np.abs(A).max(initial=0.0), np.abs(B).max(initial=0.0), 1.0)
    err = np.abs(A - B).max(initial=0.0)
    assert err <= 2e-7 * scale, f"{what}: max |analytic - FD| = {err:.3e} (scale {scale:.3e})"


@pytest.mark.parametrize("key, i", CASES)
def test_tangent_blocks_are_the_derivatives_of_the_residual(key, i):
    s = compile_model(_model(key, i))
    rng = np.random.default_rng(10 + i)
    st = _state(s, rng)
    inputs = _with_pid_states(s, step_inputs(s, 0.37), rng)
    nq, nm = s.nq, s.nm

    def f_of(name, what):
        def f(x):
            st2 = dict(st, **{name: x})
            ev = _eval(s, st2, inputs)
            return {"r": ev.r, "phi": ev.phi, "psi": ev.psi}[what]
        return f

    for coef, name in (((0.0, 0.0, 1.0), "n"), ((0.0, 1.0, 0.0), "v"), ((1.0, 0.0, 0.0), "vd")):
        A = _dense(s, _eval(s, st, inputs, coef).values)
        _close(A[:nq, :nq], _fd(f_of(name, "r"), st[name]), f"{key}: dr/d{name}")
        if nm:
            _close(A[:nq, nq:], _fd(f_of("lam", "r"), st["lam"]), f"{key}: dr/dlambda")
            if name == "n":
                _close(A[nq:, :nq], _fd(f_of("n", "phi"), st["n"]), f"{key}: dPhi/dn")
    if nm:
        # index 2: velocity-constraint rows x increments = dpsi/dv + cv dpsi/dn
        cv = 0.37
        A2 = _dense(s, _eval(s, st, inputs, (1.0, 0.5, 0.25), stab=dict(cv=cv)).values, True)
        ref = _fd(f_of("v", "psi"), st["v"]) + cv * _fd(f_of("n", "psi"), st["n"])
        _close(A2[nq + nm:, :nq], ref, f"{key}: index-2 velocity-constraint rows")


@pytest.mark.parametrize("key, i", CASES)
def test_residual_is_invariant_under_a_superposed_rigid_motion(key, i):
    s = compile_model(_model(key, i))
    rng = np.random.default_rng(20 + i)
    st = _state(s, rng)
    inputs = _with_pid_states(s, step_inputs(s, 0.81), rng)
    G = lie.exp_se3(rng.normal(size=6))
    moved = dict(st, Hn=G @ st["Hn"])
    u = inputs["u"].copy()
    R = G[:3, :3]
    u[:3] = R @ u[:3]  # gravity is an inertial-frame input
    for _node, _c, fs, ts, fbody, tbody in s.inputs.load_slots:
        if fs >= 0 and not fbody:
            u[fs:fs + 3] = R @ u[fs:fs + 3]
        if ts >= 0 and not tbody:
            u[ts:ts + 3] = R @ u[ts:ts + 3]
    coef = (1.0, 0.3, 0.05)
    a = _eval(s, st, inputs, coef)
    b = _eval(s, moved, dict(u=u), coef)
    for what in ("r", "phi", "psi", "values"):
        x, y = getattr(a, what), getattr(b, what)
        np.testing.assert_allclose(y, x, rtol=0,
                                   atol=1e-11 * max(1.0, np.abs(x).max(initial=0.0)),
                                   err_msg=f"{key}: {what}")


@pytest.mark.parametrize("key, i", [c for c in CASES if REGISTRY[c[0]].TRAITS["constraint"]])
def test_constraints_hold_and_do_no_work_along_allowed_motions(key, i):
    s = compile_model(_model(key, i))
    rng = np.random.default_rng(30 + i)
    z = np.zeros(s.nq)
    inputs = step_inputs(s, 0.0)
    st = dict(Hn=s.node_H0, HJn=s.joint_H0, alpha=z, n=z, v=z, vd=z, lam=np.zeros(s.nm))
    A = _dense(s, _eval(s, st, inputs, (0.0, 0.0, 1.0)).values)
    B = A[s.nq:, :s.nq]
    _, sv, Vt = np.linalg.svd(B)
    null = Vt[int(np.sum(sv > 1e-10 * sv[0])):]
    assert null.shape[0] >= 1
    d = null.T @ rng.normal(size=null.shape[0])
    d /= np.abs(d).max()
    viol = []
    for eps in (1e-2, 5e-3):
        ev = _eval(s, dict(st, n=eps * d), inputs)
        viol.append(np.abs(ev.phi).max())
    # second order: halving the motion divides the violation by 4 (or it is at round-off:
    # the allowed motions of abelian joints are exact group motions)
    assert viol[0] < 1e-12 or (viol[0] < 1e-3 and 3.5 < viol[0] / viol[1] < 4.5), viol
    # the constraint forces B^T lambda do no work on velocities B v = 0
    lam = rng.normal(size=s.nm)
    forces = A[:s.nq, s.nq:] @ lam
    ev = _eval(s, dict(st, v=d), inputs)
    assert np.abs(ev.psi).max() < 1e-12
    assert abs(forces @ d) < 1e-12 * np.abs(forces).max() * np.abs(d).max() * len(d)


@pytest.mark.parametrize("key, i", [c for c in CASES if REGISTRY[c[0]].TRAITS["conservative"]])
def test_generalised_force_is_the_gradient_of_the_energy(key, i):
    """At rest (v = vd = 0, lambda = 0) the residual is the gradient of the potential and
    elastic energy along the increments: the power of the internal forces is -dE/dt."""
    s = compile_model(_model(key, i))
    rng = np.random.default_rng(40 + i)
    st = _state(s, rng)
    z = np.zeros(s.nq)
    st.update(n=z, v=z, vd=z, lam=np.zeros(s.nm))
    inputs = step_inputs(s, 0.0)
    r = _eval(s, st, inputs).r
    for _ in range(3):
        d = rng.normal(size=s.nq)
        eps = 1e-6
        e = [(lambda ev: ev.energy[1] + ev.energy[2])(_eval(s, dict(st, n=sgn * eps * d), inputs))
             for sgn in (1, -1)]
        dE = (e[0] - e[1]) / (2 * eps)
        assert abs(r @ d - dE) <= 1e-7 * max(1.0, abs(dE), np.abs(r).max() * np.abs(d).sum()), (
            key, r @ d, dE)
