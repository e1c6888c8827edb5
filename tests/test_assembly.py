"""Assembly of the equations of motion: iteration matrix, constraint gradient, constraint kernel.

What is asserted (paper equation numbers):

* The Newton matrix of Eq. (46) is the Jacobian of the discrete residual ``(r, Phi)`` of
  Eqs. (39)-(40) with respect to ``(n, lambda)``, where ``v = v0 + gamma' n`` and
  ``vd = vd0 + beta' n`` (Sec. 5.2). Compared with central finite differences at a
  mid-simulation state of the paper's slider-crank and of a model holding every joint type, with
  springs, dampers, actuators, a PD law, a nodal load (inertial force, material torque) and
  gravity. The only documented approximation is the tangent of a spring on a *non-abelian* joint
  (spherical, planar, non-abelian general), whose derivative of ``T_A(alpha)^-T`` is omitted;
  those joint-joint blocks are compared with a bound derived from the neglected term.
* At a consistent configuration the constraint rows equal Eq. (58)/(59):
  ``[Ad_{H_J^-1} T(n_A), -T(n_B), T(A n_j) A]``, i.e. ``[Ad_{H_J^-1}, -I, A]`` for ``n = 0``,
  with ``Ad`` computed here from Eq. (57) and ``A`` from Table 1 in the material frame of B.
* Eq. (55) vanishes along every allowed motion ``H_B = H_A H_J0 exp(A q)`` and only along those;
  the allowed motion is the physical one (rotation about / translation along the axis given in
  the inertial frame of the initial configuration, through node B), checked with
  ``scipy.linalg.expm``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import se3dyn as sd
from se3dyn import lie
from se3dyn.dynamics.integrator import GeneralizedAlpha
from se3dyn.engine.evaluate import evaluate
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.linsolve import LinearSolver
from se3dyn.engine.system import compile_model

# Central differences with step EPS: truncation ~ EPS^2 |F'''| and round-off ~ u |F| / EPS
# (u = 1.1e-16). With |F| <~ 1e4 and |F'''| <~ 1e6 on these models both are below ~1e-6; the
# tolerances below leave a margin of ~10-100 over that and are still orders of magnitude below
# any missing term (the smallest physical entries, e.g. the geometric stiffness |lambda|, the
# gyroscopic gamma' m |v| or the load tangent |f|, are >= 1e-2 here).
EPS = 1e-6

JOINT_K = {"rigid": 0, "hinge": 1, "prismatic": 1, "screw": 1, "cylindrical": 2,
           "spherical": 3, "planar": 3, "general": 3, "universal": 2}
NON_ABELIAN = ("spherical", "planar", "general")
# a non-abelian general joint: translations in the x-y plane and rotation about z (se(2))
A_SE2 = np.array([[1.0, 0, 0, 0, 0, 0], [0, 1.0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 1.0]]).T


def _rot(axis, angle):
    a = np.asarray(axis, dtype=float)
    return scipy.linalg.expm(angle * lie.hat3(a / np.linalg.norm(a)))


def all_joints_model(nonabelian_springs: bool = True) -> sd.Model:
    """A chain ground - b0 - b1 - ... with one joint of every type, bodies with non-identity
    initial orientations and principal axes, initial velocities, springs with references and
    dampers on every joint with coordinates, an actuator, a PD law, a load and gravity."""
    rng = np.random.default_rng(0)
    mb = sd.ModelBuilder(gravity=(0.3, -0.2, -9.81))
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    specs = [("hinge", dict(axis=(0.0, 0.0, 1.0), control=sd.PD(3.0, 0.2, 0.1))),
             ("prismatic", dict(axis=(1.0, 0.0, 0.0), force=0.4)),
             ("cylindrical", dict(axis=(0.0, 0.6, 0.8))),
             ("spherical", dict()),
             ("planar", dict(normal=(0.0, 0.0, 1.0))),
             ("screw", dict(axis=(1.0, 0.0, 0.0), pitch=0.05)),
             ("general", dict(A=A_SE2)),
             ("universal", dict(axes=[(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)])),
             ("rigid", dict())]
    prev = "ground"
    for i, (typ, kw) in enumerate(specs):
        name = f"b{i}"
        mb.node(name, position=(0.1 * (i + 1), 0.05 * i, -0.02 * i),
                orientation=_rot(rng.normal(size=3), rng.uniform(0.2, 1.0)),
                mass=1.0 + 0.1 * i, inertia=(0.01, 0.02, 0.025),
                principal_axes=_rot(rng.normal(size=3), 0.5),
                velocity=0.3 * rng.normal(size=3), angular_velocity=rng.normal(size=3))
        k = JOINT_K[typ]
        extra = {}
        if k:
            if nonabelian_springs or typ not in NON_ABELIAN:
                extra["stiffness"] = np.linspace(5.0, 9.0, k)
                extra["reference"] = np.linspace(0.01, 0.05, k)
            extra["damping"] = np.linspace(0.1, 0.3, k)
        mb.joint(f"j_{typ}", typ, prev, name, **kw, **extra)
        prev = name
    mb.load("push", "b3", force=(1.0, -2.0, 0.5), torque=(0.1, 0.2, -0.3))
    return mb.build()


def _mid_state(model, t_end, h, rho=0.9):
    res = sd.simulate(model, t_end, h, rho_inf=rho)
    return compile_model(model), res.stats["final_state"]


def _coefficients(h, rho=0.9):
    am, af, g, b = GeneralizedAlpha(rho_inf=rho).params
    bp = (1 - am) / (b * h * h * (1 - af))  # beta' of Sec. 5.2
    gp = g / (b * h)  # gamma'
    return bp, gp


def _jacobians(s, st, h, seed):
    """Analytic matrix (coef = (beta', gamma', 1): the unscaled Eq. (46)) and central differences
    of F(n, lambda) = (r, Phi) at a random iterate n ~ 1e-2, lambda ~ 1."""
    bp, gp = _coefficients(h)
    rng = np.random.default_rng(seed)
    n0 = 1e-2 * rng.normal(size=s.nq)
    lam0 = rng.normal(size=s.nm)
    inputs = step_inputs(s, st.t + h)

    def F(x):
        n, lam = x[:s.nq], x[s.nq:]
        ev = evaluate(s, st.H, st.HJ, st.alpha, n, st.v + gp * n, st.vd + bp * n, lam, inputs,
                      None)
        return np.concatenate([ev.r, ev.phi])

    x0 = np.concatenate([n0, lam0])
    ev = evaluate(s, st.H, st.HJ, st.alpha, n0, st.v + gp * n0, st.vd + bp * n0, lam0, inputs,
                  (bp, gp, 1.0))
    Ja = np.asarray(LinearSolver(s).matrix(ev.values))
    if hasattr(Ja, "toarray"):
        Ja = Ja.toarray()
    Jf = np.empty_like(Ja)
    for i in range(x0.size):
        e = np.zeros_like(x0)
        e[i] = EPS
        Jf[:, i] = (F(x0 + e) - F(x0 - e)) / (2 * EPS)
    F0 = F(x0)
    return Ja, Jf, F0, ev


def _fd_tolerance(Jf, F0):
    # round-off of the central difference ~ u |F_i| / EPS and truncation ~ EPS^2 |F'''|: bounded
    # by 1e-8 (1 + |F_i|) + 1e-9 max_j |J_ij| with a margin > 10 (see EPS above)
    return 1e-8 * (1.0 + np.abs(F0))[:, None] + 1e-9 * (1.0 + np.abs(Jf).max(axis=1))[:, None]


def _worst(s, D):
    i, j = np.unravel_index(np.argmax(D), D.shape)
    return f"{s.labels[i]} / {s.labels[j]}: {D[i, j]:.3e}"


def test_iteration_matrix_is_the_jacobian_of_the_slider_crank_residual():
    model = sd.examples.slider_crank()
    h = 1e-2
    s, st = _mid_state(model, 0.3, h)  # crank turning, actuator on, damper active
    Ja, Jf, F0, _ = _jacobians(s, st, h, seed=1)
    D = np.abs(Ja - Jf)
    tol = _fd_tolerance(Jf, F0)
    assert np.all(D <= tol), _worst(s, D / tol)
    # the comparison is not empty: the mass block is beta' m, the Phi_q^T blocks are O(1)
    assert np.abs(Jf).max() > 1e3


def test_iteration_matrix_is_the_jacobian_for_every_joint_type():
    model = all_joints_model(nonabelian_springs=True)
    h = 5e-3
    s, st = _mid_state(model, 0.05, h)
    assert set(s.joint_type) == set(JOINT_K) - {"universal"}  # universal = two hinges
    Ja, Jf, F0, ev = _jacobians(s, st, h, seed=2)
    D = np.abs(Ja - Jf)
    tol = _fd_tolerance(Jf, F0)

    # joint-joint blocks of the springs on non-abelian joints: documented approximate tangent
    approx = np.zeros_like(D, dtype=bool)
    bound = np.zeros_like(D)
    for jj, typ in enumerate(s.joint_type):
        if typ in NON_ABELIAN:
            d = s.joint_dofadr[jj] + np.arange(s.joint_k[jj])
            approx[np.ix_(d, d)] = True
            # the neglected term is d(T_A(alpha)^-T)/d alpha K (alpha - alpha0); with
            # |d T_A^-T / d alpha| <= 1/2 + O(|alpha|), |K (alpha - alpha0)| bounds it (factor
            # 2 margin); alpha is the iterate's log coordinate (ev.alpha)
            e = np.abs(ev.alpha[d] - s.dof_reference[d]).max()
            bound[np.ix_(d, d)] = s.dof_stiffness[d].max() * e + tol[d][:, [0]]
    exact = ~approx
    tolB = np.broadcast_to(tol, D.shape)
    assert np.all(D[exact] <= tolB[exact]), _worst(s, np.where(exact, D / tolB, 0.0))
    assert np.all(D[approx] <= bound[approx]), _worst(s, np.where(approx, D / bound, 0.0))


def test_iteration_matrix_is_exact_without_springs_on_non_abelian_joints():
    model = all_joints_model(nonabelian_springs=False)
    h = 5e-3
    s, st = _mid_state(model, 0.05, h)
    Ja, Jf, F0, _ = _jacobians(s, st, h, seed=3)
    D = np.abs(Ja - Jf)
    tol = _fd_tolerance(Jf, F0)
    assert np.all(D <= tol), _worst(s, D / tol)


# ---------------------------------------------------------------------------------------------
def _ad_inv(H):
    """Eq. (57), written out here: [[R^T, -R^T x~], [0, R^T]]."""
    R, x = H[:3, :3], H[:3, 3]
    out = np.zeros((6, 6))
    out[:3, :3] = R.T
    out[3:, 3:] = R.T
    out[:3, 3:] = -R.T @ lie.hat3(x)
    return out


def _frame(R, x):
    H = np.eye(4)
    H[:3, :3] = R
    H[:3, 3] = x
    return H


def _material_A(model, j):
    """Table 1 columns (inertial frame, initial configuration) in the material frame of B."""
    RB = model.node(j.node_b).orientation
    return np.vstack([RB.T @ j.A[:3], RB.T @ j.A[3:]])


def _constraint_block(Mat, s, jj, cols):
    rows = s.nq + s.joint_multadr[jj] + np.arange(6)
    return Mat[np.ix_(rows, cols)]


def _dof(s, node_index):
    d = s.node_dofadr[node_index]
    return None if d < 0 else d + np.arange(6)


@pytest.mark.parametrize("which", ["slider_crank", "all_joints"])
def test_constraint_gradient_at_the_initial_configuration_is_eq_58(which):
    model = sd.examples.slider_crank() if which == "slider_crank" else all_joints_model()
    s = compile_model(model)
    st = GeneralizedAlpha(rho_inf=0.9).init(s)
    z = np.zeros(s.nq)
    ev = evaluate(s, st.H, st.HJ, st.alpha, z, st.v, st.vd, st.lam, step_inputs(s, 0.0),
                  (1.0, 1.0, 1.0))
    Mat = np.asarray(LinearSolver(s).matrix(ev.values))
    assert np.abs(ev.phi).max() < 1e-14  # consistent initial configuration (Sec. 5.2)
    names = list(s.node_names)
    seen = np.zeros((s.nm, s.nq), dtype=bool)
    for jj, j in enumerate(model.joints):
        ia, ib = names.index(j.node_a), names.index(j.node_b)
        na, nb = model.node(j.node_a), model.node(j.node_b)
        HJ0 = np.linalg.inv(_frame(na.orientation, na.position)) @ _frame(nb.orientation,
                                                                           nb.position)
        da, db = _dof(s, ia), _dof(s, ib)
        if da is not None:
            np.testing.assert_allclose(_constraint_block(Mat, s, jj, da), _ad_inv(HJ0),
                                       atol=1e-14, err_msg=f"joint {j.name}: Ad_{{H_J^-1}}")
            seen[s.joint_multadr[jj]:s.joint_multadr[jj] + 6, da] = True
        if db is not None:
            np.testing.assert_allclose(_constraint_block(Mat, s, jj, db), -np.eye(6),
                                       atol=1e-14, err_msg=f"joint {j.name}: -I")
            seen[s.joint_multadr[jj]:s.joint_multadr[jj] + 6, db] = True
        if j.k:
            dj = s.joint_dofadr[jj] + np.arange(j.k)
            np.testing.assert_allclose(_constraint_block(Mat, s, jj, dj), _material_A(model, j),
                                       atol=1e-14, err_msg=f"joint {j.name}: A")
            seen[s.joint_multadr[jj]:s.joint_multadr[jj] + 6, dj] = True
    # every other entry of the constraint rows is zero
    assert np.all(Mat[s.nq:, :s.nq][~seen] == 0.0)


def test_constraint_gradient_after_a_converged_step_is_eq_59():
    # at Phi = 0 with non-zero increments: [Ad_{H_J^-1} T(n_A), -T(n_B), T(A n_j) A]
    model = all_joints_model()
    s = compile_model(model)
    integ = GeneralizedAlpha(rho_inf=0.9)
    h = 2e-2
    st0 = integ.init(s)
    st1, _ = integ.step(s, st0, h)
    n = np.zeros(s.nq)
    for i in s.node_free:
        d = s.node_dofadr[i] + np.arange(6)
        n[d] = lie.log_se3(np.linalg.inv(st0.H[i]) @ st1.H[i])
    for jj, j in enumerate(model.joints):
        if j.k:
            d = s.joint_dofadr[jj] + np.arange(j.k)
            nJ = lie.log_se3(np.linalg.inv(st0.HJ[jj]) @ st1.HJ[jj])
            n[d] = np.linalg.lstsq(_material_A(model, j), nJ, rcond=None)[0]
    assert np.abs(n).max() > 1e-3  # genuinely non-zero increments
    ev = evaluate(s, st0.H, st0.HJ, st0.alpha, n, st1.v, st1.vd, st1.lam,
                  step_inputs(s, h), (1.0, 1.0, 1.0))
    phi_max = np.abs(ev.phi).max()
    assert phi_max < 1e-10  # the converged step satisfies Eq. (40)
    Mat = np.asarray(LinearSolver(s).matrix(ev.values))
    names = list(s.node_names)
    # the exact gradient differs from Eq. (59) by O(|Phi|)
    tol = 1e-8
    for jj, j in enumerate(model.joints):
        ia, ib = names.index(j.node_a), names.index(j.node_b)
        AdJ = _ad_inv(ev.HJ[jj])
        da, db = _dof(s, ia), _dof(s, ib)
        if da is not None:
            np.testing.assert_allclose(_constraint_block(Mat, s, jj, da),
                                       AdJ @ lie.tangent_se3(n[da]), atol=tol)
        np.testing.assert_allclose(_constraint_block(Mat, s, jj, db),
                                   -lie.tangent_se3(n[db]), atol=tol)
        if j.k:
            dj = s.joint_dofadr[jj] + np.arange(j.k)
            A = _material_A(model, j)
            np.testing.assert_allclose(_constraint_block(Mat, s, jj, dj),
                                       lie.tangent_se3(A @ n[dj]) @ A, atol=tol)


# ---------------------------------------------------------------------------------------------
JOINT_CASES = {
    "rigid": dict(),
    "hinge": dict(axis=(0.0, 0.6, 0.8)),
    "prismatic": dict(axis=(0.48, 0.6, 0.64)),
    "cylindrical": dict(axis=(0.0, 0.6, 0.8)),
    "screw": dict(axis=(0.0, 0.6, 0.8), pitch=0.07),
    "spherical": dict(),
    "planar": dict(normal=(0.0, 0.6, 0.8)),
    "general": dict(A=A_SE2),
    "universal": dict(axes=[(1.0, 0.0, 0.0), (0.0, 0.6, 0.8)]),
}


def _two_body_model(typ):
    mb = sd.ModelBuilder()
    mb.node("A", position=(0.3, -0.1, 0.2), orientation=_rot((1.0, 2.0, 0.5), 0.7), mass=1.0,
            inertia=(1.0, 2.0, 2.5))
    mb.node("B", position=(0.5, 0.4, -0.3), orientation=_rot((-0.4, 1.0, 0.3), 1.1), mass=2.0,
            inertia=(1.0, 1.5, 2.0))
    mb.joint("j", typ, "A", "B", **JOINT_CASES[typ])
    return mb.build()


def _spatial_twist(col, xB):
    """Inertial-frame twist of the motion allowed by a column (e_U, e_Omega) of A (axes in the
    inertial frame, through node B's initial position): rotation about e_Omega through xB plus
    translation e_U, as a 4x4 se(3) matrix."""
    eU, eO = col[:3], col[3:]
    X = np.zeros((4, 4))
    X[:3, :3] = lie.hat3(eO)
    X[:3, 3] = eU - np.cross(eO, xB)
    return X


@pytest.mark.parametrize("typ", list(JOINT_CASES))
def test_constraints_vanish_exactly_along_the_allowed_motions(typ):
    model = _two_body_model(typ)
    s = compile_model(model)
    rng = np.random.default_rng(list(JOINT_CASES).index(typ))
    H0 = s.node_H0
    HJ0 = s.joint_H0
    for _ in range(5):
        # arbitrary rigid motion of node A, allowed relative motion q of the joint(s)
        HA = H0[0] @ lie.exp_se3(rng.normal(size=6))
        HJ = HJ0.copy()
        HB = HA.copy()
        q = {}
        for jj, j in enumerate(model.joints):  # a universal joint is a chain of two hinges
            qj = rng.uniform(-2.0, 2.0, size=j.k)
            q[j.name] = qj
            HJ[jj] = HJ0[jj] @ lie.exp_se3(_material_A(model, j) @ qj)
        Hn = H0.copy()
        Hn[0] = HA
        names = list(s.node_names)
        for jj, j in enumerate(model.joints):  # propagate H_B = H_A H_J along the chain
            Hn[names.index(j.node_b)] = Hn[names.index(j.node_a)] @ HJ[jj]
        HB = Hn[names.index("B")]
        ev = evaluate(s, Hn, HJ, np.zeros(s.nq), np.zeros(s.nq), np.zeros(s.nq), np.zeros(s.nq),
                      np.zeros(s.nm), step_inputs(s, 0.0), None)
        assert np.abs(ev.phi).max() < 1e-13  # Eq. (55)

        # the allowed motion is the physical one: with A at rest in its initial frame, B moves by
        # exp(sum_i q_i X_i) about axes given in the inertial frame (product over the chain)
        if typ != "universal":
            j = model.joints[0]
            X = sum(qi * _spatial_twist(j.A[:, i], model.node("B").position)
                    for i, qi in enumerate(q["j"]))
            X = np.zeros((4, 4)) if j.k == 0 else X
            # H_B(q) relative to H_A: H_A H_A0^-1 exp(X) H_B0
            expected = HA @ np.linalg.inv(H0[0]) @ scipy.linalg.expm(X) @ H0[1]
            np.testing.assert_allclose(HB, expected, atol=1e-12)
        else:
            a1, a2 = (np.array(a) for a in JOINT_CASES["universal"]["axes"])
            xB = model.node("B").position
            q1, q2 = q["j:1"][0], q["j:2"][0]
            M1 = scipy.linalg.expm(q1 * _spatial_twist(np.r_[0, 0, 0, a1], xB))
            # the second hinge axis is carried by the cross (rotated by the first hinge)
            M2 = scipy.linalg.expm(q2 * _spatial_twist(np.r_[0, 0, 0, a2], xB))
            expected = HA @ np.linalg.inv(H0[0]) @ M1 @ M2 @ H0[1]
            np.testing.assert_allclose(HB, expected, atol=1e-12)

    # and only along them: a motion of B outside span(A) violates Eq. (55) at first order, and no
    # joint motion can absorb it: Phi = -delta + O(|delta|^2), and since d Phi / d q = A at q = 0
    # (Eq. (58)) and A^T delta = 0, q = 0 already minimises |Phi| to first order
    if typ == "universal":
        return
    j = model.joints[0]
    A = _material_A(model, j)
    Q, _ = np.linalg.qr(np.hstack([A, rng.normal(size=(6, 6))]))
    perp = Q[:, j.k:]  # orthonormal complement of span(A)
    for _ in range(3):
        delta = 1e-6 * perp @ rng.normal(size=6 - j.k)
        Hn = H0.copy()
        Hn[1] = H0[1] @ lie.exp_se3(delta)
        ev = evaluate(s, Hn, HJ0, np.zeros(s.nq), np.zeros(s.nq), np.zeros(s.nq), np.zeros(s.nq),
                      np.zeros(s.nm), step_inputs(s, 0.0), None)
        np.testing.assert_allclose(ev.phi, -delta, atol=1e-11)
        assert np.linalg.norm(ev.phi) > 0.5 * np.linalg.norm(delta)
        assert np.abs(A.T @ ev.phi).max(initial=0.0) < 1e-11
