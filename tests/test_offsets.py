"""Joints attached to body frames at constant offsets (``ModelBuilder.joint(..., at=p)``).

A joint with an attachment point p connects the frames ``H_A X_A`` and ``H_B X_B`` with
``X_A = H_A0^-1 P``, ``X_B = H_B0^-1 P``, ``P = H(I, p)``: ``H_B X_B = H_A X_A H_J`` (Eq. (7)
between the attachment frames), constraints ``Phi = vect((H_B X_B)^-1 H_A X_A H_J)`` (Eq. (55)).

What is asserted:

* Equivalence with the paper's form: a body with several attachment points described by extra
  massless nodes and rigid joints (paper) or by one node and offsets is the same mechanism, the
  rigid joints being exact constraints. With the paper's index-3 scheme (Eqs. (38)-(46)) the
  massless nodes are eliminated exactly by the discrete equations too, so the two trajectories
  agree to round-off and Newton tolerance (1e-9 over 100-200 steps). The stabilized index-2 form
  corrects the increments by ``B_n^T xi``, a Euclidean projection in the space of *all* unknowns
  (massless nodes included), so with the rigid joints kept (``condense=False``) its discrete
  solution depends on the parametrisation: there the two models differ by O(h^2), a small part
  of the discretisation error, and agree as h -> 0. By default the rigid joints are condensed
  for the time loop (:mod:`se3dyn.dynamics.condense`) and both forms agree to Newton tolerance
  in both
  formulations.
  Checked on the slider-crank of Sec. 11 (``examples.slider_crank_bodies`` vs
  ``examples.slider_crank``), on an N-link spherical pendulum chain, on a universal joint.
* The constraints are Eq. (55) between the attachment frames, computed here independently from
  the definition; a hinge placed by ``at`` allows exactly the rotation about the axis through
  ``at`` (``scipy.linalg.expm``).
* The iteration matrix (index-3 and stabilized index-2 layouts) is the Jacobian of the scaled
  residual, against central finite differences at random states with random offsets, nonzero
  multipliers, velocities and index-2 multipliers xi.
* Invariance under a superposed rigid motion; statics (closed form) and assembly (the new model
  keeps the joints where the assembled bodies put them).
* Bad ``at`` values: ModelError naming the joint and the field, from Python and from files.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from scipy.optimize import brentq

import se3dyn as sd
from se3dyn import lie
from se3dyn.engine.evaluate import evaluate, increment_correction, matrix_values
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.linsolve import LinearSolver
from se3dyn.engine.system import compile_model
from se3dyn.io.modelfile import ModelFileError, load_model, loads_model, save_model
from test_assembly import A_SE2, _coefficients, _fd_tolerance

ROOT = Path(__file__).resolve().parents[1]
G = 9.81
EPS = 1e-6  # central differences, see tests/test_assembly.py for the error budget


def _rot(axis, angle):
    """Rotation by ``angle`` about ``axis`` (scipy's expm, independent of se3dyn.lie)."""
    a = np.asarray(axis, dtype=float)
    return scipy.linalg.expm(angle * lie.hat3(a / np.linalg.norm(a)))


def _frame(R, x):
    H = np.eye(4)
    H[:3, :3] = R
    H[:3, 3] = x
    return H


# ---------------------------------------------------------------------------------------------
# 1. slider-crank: three bodies and four joints with offsets vs the paper's nine nodes
# ---------------------------------------------------------------------------------------------
def _max_diff(a, b, nodes, joints=("1",)):
    dx = max(np.abs(a.node_position(n) - b.node_position(n)).max() for n in nodes)
    dR = max(np.abs(a.node_rotation(n) - b.node_rotation(n)).max() for n in nodes)
    da = max(np.abs(a.joint_coordinates(j) - b.joint_coordinates(j)).max() for j in joints)
    return dx, dR, da


def test_slider_crank_bodies_has_the_paper_sizes_minus_the_auxiliary_nodes():
    s = compile_model(sd.examples.slider_crank_bodies())
    # 3 free bodies (18) + hinge 1 + spherical 3 + hinge 1 + cylindrical 2 = 25 unknowns,
    # 4 joints x 6 = 24 multipliers (the paper's model: 49 and 48, Sec. 11.1)
    assert (s.nq, s.nm) == (25, 24)
    assert list(s.joint_names) == ["1", "4", "7", "8"]
    # the joints sit where the paper's auxiliary nodes were: X_A, X_B put the attachment frames
    # at the points of Table 2 with the inertial orientation
    paper = sd.examples.slider_crank()
    where = {"1": "2", "4": "4", "7": "7", "8": "9"}
    for j, jn in enumerate(s.joint_names):
        for X, node in ((s.joint_XA[j], s.joint_a[j]), (s.joint_XB[j], s.joint_b[j])):
            F = s.node_H0[node] @ X
            np.testing.assert_allclose(F[:3, 3], paper.node(where[jn]).position, atol=1e-15)
            np.testing.assert_allclose(F[:3, :3], np.eye(3), atol=1e-15)
        np.testing.assert_array_equal(s.joint_H0[j], np.eye(4))


@pytest.mark.parametrize("condense", [True, False])
@pytest.mark.parametrize("formulation", ["index3", "index2"])
def test_slider_crank_bodies_moves_like_the_paper_model(formulation, condense):
    h, T = 1e-2, 1.0
    run = lambda m, hh: sd.simulate(m, T, hh, rho_inf=0.9,  # noqa: E731
                                    formulation=formulation, condense=condense)
    paper = run(sd.examples.slider_crank(), h)
    bodies = run(sd.examples.slider_crank_bodies(), h)
    np.testing.assert_array_equal(paper.t, bodies.t)
    dx, dR, da = _max_diff(paper, bodies, "368")
    print(f"{formulation}: h={h}: positions {dx:.2e} m, rotations {dR:.2e}, hinge 1 {da:.2e} rad")
    assert paper.stats["condensed"] == (["2", "3", "5", "6"] if condense else [])
    if formulation == "index3" or condense:
        # identical discrete equations for the bodies: round-off and Newton tolerances
        # (1e-10 relative per step) accumulated over 100 steps
        assert max(dx, dR, da) <= 1e-9
        return
    # index-2: the projection B_n^T xi depends on the unknowns (see the module docstring). Both
    # are second-order approximations of the same motion: their difference is O(h^2), falls by
    # ~4 when h halves, and is a small part of the discretisation error itself (estimated by
    # the change between h and h/2)
    paper2 = run(sd.examples.slider_crank(), h / 2)
    bodies2 = run(sd.examples.slider_crank_bodies(), h / 2)
    dx2, dR2, da2 = _max_diff(paper2, bodies2, "368")
    print(f"index2: h={h / 2}: positions {dx2:.2e} m, rotations {dR2:.2e}, hinge 1 {da2:.2e}")
    err = max(np.abs(paper.node_position(n) - paper2.node_position(n)[::2]).max()
              for n in "368")
    assert dx2 <= dx / 3 and dR2 <= dR / 3 and da2 <= da / 3
    assert dx <= 0.25 * err


def test_slider_crank_bodies_file_equals_the_python_model():
    model, cfg = load_model(ROOT / "examples" / "slider_crank_bodies.yaml")
    ref = sd.examples.slider_crank_bodies()
    assert cfg == sd.examples.SLIDER_CRANK_SETTINGS
    assert [j.name for j in model.joints] == [j.name for j in ref.joints]
    for a, b in zip(model.joints, ref.joints, strict=True):
        np.testing.assert_array_equal(a.at, b.at)
        np.testing.assert_allclose(a.A, b.A, rtol=0, atol=1e-15)
    s, sr = compile_model(model), compile_model(ref)
    for f in ("joint_XA", "joint_XB", "node_H0", "node_J", "node_mass"):
        np.testing.assert_array_equal(getattr(s, f), getattr(sr, f))
    # a saved model round-trips with its attachment points
    again, _ = loads_model(save_model(model))
    for a, b in zip(model.joints, again.joints, strict=True):
        np.testing.assert_array_equal(a.at, b.at)


# ---------------------------------------------------------------------------------------------
# 2. N-link spherical pendulum chain: one node per link vs benchmarks/chain_scaling.py
# ---------------------------------------------------------------------------------------------
J_LINK = 1.0 * 0.1 ** 2 / 12.0


def _chain_rigid(n):
    """benchmarks/chain_scaling.py chain(): per link a joint node p_i, a body node b_i at the
    centre and an end node e_i, tied by rigid joints; spherical joints e_(i-1) - p_i."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    prev = "ground"
    for i in range(n):
        x0 = 0.1 * i
        mb.node(f"p{i}", position=(x0, 0.0, 0.0))
        mb.node(f"b{i}", position=(x0 + 0.05, 0.0, 0.0), mass=1.0,
                inertia=(1e-4 * J_LINK, J_LINK, J_LINK))
        mb.node(f"e{i}", position=(x0 + 0.1, 0.0, 0.0))
        mb.joint(f"s{i}", "spherical", prev, f"p{i}")
        mb.joint(f"r{i}", "rigid", f"p{i}", f"b{i}")
        mb.joint(f"t{i}", "rigid", f"b{i}", f"e{i}")
        prev = f"e{i}"
    return mb.build()


def _chain_offsets(n):
    """The same chain with one node per link (at its centre) and spherical joints at the link
    ends, placed with ``at``."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    prev = "ground"
    for i in range(n):
        mb.node(f"b{i}", position=(0.1 * i + 0.05, 0.0, 0.0), mass=1.0,
                inertia=(1e-4 * J_LINK, J_LINK, J_LINK))
        mb.joint(f"s{i}", "spherical", prev, f"b{i}", at=(0.1 * i, 0.0, 0.0))
        prev = f"b{i}"
    return mb.build()


def _tips(res_rigid, res_off, n):
    tip_r = res_rigid.node_position(f"e{n - 1}")
    H = res_off.node_frame(f"b{n - 1}")
    tip_o = H[:, :3, 3] + H[:, :3, :3] @ np.array([0.05, 0.0, 0.0])  # the link end
    return tip_r, tip_o


@pytest.mark.parametrize("condense", [True, False])
@pytest.mark.parametrize("formulation", ["index3", "index2"])
def test_spherical_chain_with_offsets_moves_like_the_chain_with_rigid_joints(formulation,
                                                                              condense):
    n, T, h = 5, 0.2, 1e-3
    run = lambda m, hh: sd.simulate(m, T, hh, rho_inf=0.9,  # noqa: E731
                                    formulation=formulation, condense=condense)
    rigid, off = run(_chain_rigid(n), h), run(_chain_offsets(n), h)
    tip_r, tip_o = _tips(rigid, off, n)
    d = np.abs(tip_r - tip_o).max()
    dH = max(np.abs(rigid.node_frame(f"b{i}") - off.node_frame(f"b{i}")).max()
             for i in range(n))
    print(f"{formulation}: tip {d:.2e} m, link frames {dH:.2e}")
    assert np.abs(tip_r[-1] - tip_r[0]).max() > 0.05  # the chain has fallen a good way
    if formulation == "index3" or condense:
        assert d <= 1e-9 and dH <= 1e-9
        return
    # index-2: O(h^2) difference (module docstring), well below the discretisation error
    rigid2, off2 = run(_chain_rigid(n), h / 2), run(_chain_offsets(n), h / 2)
    tip_r2, tip_o2 = _tips(rigid2, off2, n)
    d2 = np.abs(tip_r2 - tip_o2).max()
    err = np.abs(tip_r - tip_r2[::2]).max()
    print(f"index2: h/2: tip {d2:.2e} m; discretisation error ~{err:.2e} m")
    assert d2 <= d / 3
    assert d <= 0.1 * err


def test_universal_joint_with_offset_moves_like_an_extra_node_and_a_rigid_joint():
    axes = [(1.0, 0.0, 0.0), (0.0, 0.6, 0.8)]
    p = np.array([0.0, 0.0, 0.3])
    models = []
    for with_at in (False, True):
        mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
        mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
        mb.node("body", position=(0.2, 0.1, -0.1), mass=1.5, inertia=(0.02, 0.03, 0.04),
                angular_velocity=(0.5, 0.0, 1.0), velocity=(0.0, 0.0, 0.0))
        if with_at:
            mb.joint("u", "universal", "ground", "body", axes=axes, damping=(0.01, 0.02),
                     at=p)
        else:
            mb.node("knuckle", position=p)
            mb.joint("u", "universal", "ground", "knuckle", axes=axes, damping=(0.01, 0.02))
            mb.joint("fix", "rigid", "knuckle", "body")
        models.append(mb.build())
    # both crosses sit at p (the centre of the universal joint)
    for m in models:
        np.testing.assert_array_equal(m.node("u:cross").position, p)
    a, b = (sd.simulate(m, 0.5, 2e-3, rho_inf=0.9, formulation="index3") for m in models)
    assert np.abs(a.node_position("body") - b.node_position("body")).max() <= 1e-9
    assert np.abs(a.node_rotation("body") - b.node_rotation("body")).max() <= 1e-9
    assert np.abs(a.joint_coordinates("u") - b.joint_coordinates("u")).max() <= 1e-9
    assert np.abs(a.joint_coordinates("u")).max() > 0.1


# ---------------------------------------------------------------------------------------------
# 3. constraints and iteration matrix with random offsets
# ---------------------------------------------------------------------------------------------
def offsets_model(seed: int = 0) -> sd.Model:
    """A chain ground - b0 - b1 - ... with every joint type placed by a random attachment point
    away from both nodes, bodies with random initial orientations and principal axes, springs
    (abelian joints) and dampers, an actuator, a PD law, a load, gravity; plus joints without
    offsets in the same groups (mixed batches)."""
    rng = np.random.default_rng(seed)
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
        x = np.array([0.3 * (i + 1), 0.1 * i, -0.05 * i])
        mb.node(name, position=x, orientation=_rot(rng.normal(size=3), rng.uniform(0.3, 1.2)),
                mass=1.0 + 0.1 * i, inertia=(0.01, 0.02, 0.025),
                principal_axes=_rot(rng.normal(size=3), 0.5),
                velocity=0.3 * rng.normal(size=3), angular_velocity=rng.normal(size=3))
        extra = {}
        if typ not in ("rigid", "spherical", "planar", "general"):
            k = 2 if typ in ("cylindrical", "universal") else 1
            extra = dict(stiffness=np.linspace(5.0, 9.0, k), reference=np.linspace(0.01, 0.05, k))
        if typ != "rigid":
            extra["damping"] = 0.2
        at = x - np.array([0.15, 0.0, 0.0]) + 0.1 * rng.normal(size=3)  # between the nodes
        mb.joint(f"j_{typ}", typ, prev, name, at=at, **kw, **extra)
        prev = name
    # same-k joints without offsets: a hinge (k = 1) and a rigid joint (k = 0)
    mb.node("c0", position=(0.5, -0.4, 0.2), mass=0.7, inertia=(0.01, 0.01, 0.01),
            orientation=_rot((1.0, 1.0, 0.0), 0.4), angular_velocity=(0.2, -0.3, 0.5))
    mb.node("c1", position=(0.8, -0.4, 0.3), mass=0.5, inertia=(0.01, 0.02, 0.01))
    mb.joint("plain_hinge", "hinge", "b1", "c0", axis=(0.0, 1.0, 0.0), stiffness=3.0,
             damping=0.1)
    mb.joint("plain_rigid", "rigid", "c0", "c1")
    mb.load("push", "b3", force=(1.0, -2.0, 0.5), torque=(0.1, 0.2, -0.3))
    return mb.build()


def _random_state(s, rng):
    """Random frames near the initial ones, joint transformations in their subgroups,
    coordinates, increments, velocities, accelerations, multipliers and xi."""
    H = s.node_H0.copy()
    H[s.node_free] = H[s.node_free] @ lie.exp_se3(0.4 * rng.normal(size=(len(s.node_free), 6)))
    HJ = s.joint_H0.copy()
    for g in s.groups:
        if g.k:
            HJ[g.ids] = g.H0 @ lie.exp_se3(np.einsum("jik,jk->ji", g.A,
                                                     0.5 * rng.normal(size=(len(g.ids), g.k))))
    alpha = np.where(s.dof_is_joint, 0.3 * rng.normal(size=s.nq), 0.0)
    return dict(H=H, HJ=HJ, alpha=alpha, n=0.05 * rng.normal(size=s.nq),
                v=rng.normal(size=s.nq), vd=rng.normal(size=s.nq), lam=rng.normal(size=s.nm),
                xi=1e-2 * rng.normal(size=s.nm))


def test_constraints_are_eq_55_between_the_attachment_frames():
    model = offsets_model()
    s = compile_model(model)
    rng = np.random.default_rng(11)
    st = _random_state(s, rng)
    z = np.zeros(s.nq)
    ev = evaluate(s, st["H"], st["HJ"], st["alpha"], z, z, z, np.zeros(s.nm),
                  step_inputs(s, 0.0), None)
    names = list(s.node_names)
    for jj, j in enumerate(model.joints):
        assert j.at is not None or j.name.startswith("plain")
        na, nb = model.node(j.node_a), model.node(j.node_b)
        P = _frame(np.eye(3), j.at if j.at is not None else nb.position)
        if j.at is None:  # the paper's form: X = I
            XA = XB = np.eye(4)
        else:
            XA = np.linalg.inv(_frame(na.orientation, na.position)) @ P
            XB = np.linalg.inv(_frame(nb.orientation, nb.position)) @ P
        Ga = st["H"][names.index(j.node_a)] @ XA
        Gb = st["H"][names.index(j.node_b)] @ XB
        G = np.linalg.inv(Gb) @ Ga @ st["HJ"][jj]
        expected = np.concatenate([G[:3, 3], 0.5 * np.array([G[2, 1] - G[1, 2],
                                                             G[0, 2] - G[2, 0],
                                                             G[1, 0] - G[0, 1]])])  # Eq. (56)
        np.testing.assert_allclose(ev.phi[6 * jj:6 * jj + 6], expected, atol=1e-13,
                                   err_msg=j.name)
        assert np.abs(expected).max() > 1e-2  # a violated, informative state
    # at the initial configuration the constraints hold (H_J0 = I for joints with offsets)
    ev0 = evaluate(s, s.node_H0, s.joint_H0, z, z, z, z, np.zeros(s.nm), step_inputs(s, 0.0),
                   None)
    assert np.abs(ev0.phi).max() < 1e-14


def test_hinge_at_a_point_allows_exactly_the_rotation_about_the_axis_through_it():
    mb = sd.ModelBuilder()
    mb.node("ground", position=(0.1, 0.2, 0.3), fixed=True, orientation=_rot((1, 2, 0), 0.4))
    mb.node("body", position=(1.0, -0.5, 0.2), orientation=_rot((0, 1, 1), 1.1), mass=1.0,
            inertia=(1.0, 1.0, 1.0))
    p, axis = np.array([0.4, 0.0, 0.5]), np.array([0.0, 0.6, 0.8])
    mb.joint("h", "hinge", "ground", "body", axis=axis, at=p)
    s = compile_model(mb.build())
    z = np.zeros(s.nq)
    inputs = step_inputs(s, 0.0)
    for theta in (0.3, -2.0, 3.0):
        # rotation about the line through p along the axis, applied to the body (inertial)
        R = _rot(axis, theta)
        M = _frame(R, p - R @ p)
        H = s.node_H0.copy()
        H[1] = M @ H[1]
        HJ = lie.exp_se3(np.concatenate([np.zeros(3), theta * axis]))[None]
        ev = evaluate(s, H, HJ, z, z, z, z, np.zeros(6), inputs, None)
        assert np.abs(ev.phi).max() < 1e-14
        # any other motion violates the constraints
        H2 = H.copy()
        H2[1] = _frame(_rot((1, 0, 0), 1e-3), np.zeros(3)) @ H[1]
        assert np.abs(evaluate(s, H2, HJ, z, z, z, z, np.zeros(6), inputs, None).phi).max() \
            > 1e-4


def _dense(mat):
    return mat.toarray() if hasattr(mat, "toarray") else np.asarray(mat)


@pytest.mark.parametrize("index2", [False, True], ids=["index3", "index2"])
def test_iteration_matrix_with_offsets_is_the_jacobian(index2):
    """Scaled Newton system of GeneralizedAlpha.step: unknowns (n, lambda / beta', xi), rows
    (r / beta', Phi, psi / gamma') with ``m = n - B_n^T xi``, ``v = v0 + gamma' m``,
    ``vd = vd0 + beta' m`` (index-3: xi absent, m = n). Its matrix is
    ``matrix_values(coef=(1, gamma'/beta', 1/beta'))``."""
    model = offsets_model()
    s = compile_model(model)
    offsets = np.maximum(np.abs(s.joint_XA - np.eye(4)).max(axis=(1, 2)),
                         np.abs(s.joint_XB - np.eye(4)).max(axis=(1, 2)))
    assert np.sum(offsets > 0.1) == s.m - 2  # all but the two plain joints have offsets
    h = 5e-3
    bp, gp = _coefficients(h)
    coef = (1.0, gp / bp, 1.0 / bp)
    rng = np.random.default_rng(5 + index2)
    st = _random_state(s, rng)
    H, HJ, alpha = st["H"], st["HJ"], st["alpha"]
    v0, vd0 = st["v"], st["vd"]
    inputs = step_inputs(s, 0.7)
    nq, nm = s.nq, s.nm
    Adn = [lie.adjoint_inv(HJ[g.ids]) for g in s.groups]
    def BnT(s_, Adn_, xi):
        return increment_correction(s_, H, HJ, xi)

    def F(x):
        n, mu = x[:nq], x[nq:nq + nm]
        m = n - BnT(s, Adn, x[nq + nm:]) if index2 else n
        ev = evaluate(s, H, HJ, alpha, n, v0 + gp * m, vd0 + bp * m, bp * mu, inputs, None,
                      velocity=index2)
        return np.concatenate([ev.r / bp, ev.phi] + ([ev.psi / gp] if index2 else []))

    x0 = np.concatenate([st["n"], st["lam"] / bp] + ([st["xi"]] if index2 else []))
    n0 = x0[:nq]
    m0 = n0 - BnT(s, Adn, st["xi"]) if index2 else n0
    ev = evaluate(s, H, HJ, alpha, n0, v0 + gp * m0, vd0 + bp * m0, st["lam"], inputs, None,
                  velocity=index2)
    stab = dict(cv=1.0 / gp, Adn=Adn) if index2 else None
    Ja = _dense(LinearSolver(s, index2=index2).matrix(matrix_values(s, ev, coef, stab)))
    assert Ja.shape == (x0.size, x0.size)
    Jf = np.empty_like(Ja)
    for i in range(x0.size):
        e = np.zeros_like(x0)
        e[i] = EPS
        Jf[:, i] = (F(x0 + e) - F(x0 - e)) / (2 * EPS)
    F0 = F(x0)
    D = np.abs(Ja - Jf)
    tol = _fd_tolerance(Jf, F0)
    labels = list(s.labels) + ([f"xi of {c}" for c in s.labels[nq:]] if index2 else [])
    i, j = np.unravel_index(np.argmax(D / tol), D.shape)
    assert np.all(D <= tol), f"{labels[i]} / {labels[j]}: {D[i, j]:.3e} > tol {tol[i, 0]:.3e}"
    # the offset blocks are exercised: node-B constraint columns are -Ad(G^-1) PB T, not -I
    jj = s.joint_names.index("j_spherical")
    rows = nq + s.joint_multadr[jj] + np.arange(6)
    db = s.node_dofadr[s.joint_b[jj]] + np.arange(6)
    assert np.abs(Jf[np.ix_(rows, db)] + np.eye(6)).max() > 0.05


# ---------------------------------------------------------------------------------------------
# 4. invariance under a superposed rigid motion
# ---------------------------------------------------------------------------------------------
def moved_slider_crank_bodies(Q, d, frames: bool) -> sd.Model:
    """examples.slider_crank_bodies under x -> Q x + d (node frames at Q when ``frames``)."""
    Q = np.asarray(Q, dtype=float)
    d = np.asarray(d, dtype=float)
    mb = sd.ModelBuilder(gravity=Q @ np.array([0.0, 0.0, -9.81]))

    def node(name, pos, J=None, mass=0.0, fixed=False):
        kw = {"orientation": Q} if frames else {}
        if J is not None:
            kw.update(dict(inertia=J, principal_axes=Q) if frames
                      else dict(inertia=Q @ np.diag(J) @ Q.T))
        mb.node(name, position=Q @ np.asarray(pos) + d, mass=mass, fixed=fixed, **kw)

    at = lambda p: Q @ np.asarray(p) + d  # noqa: E731
    node("1", (0.0, 0.1, 0.12), fixed=True)
    node("3", (0.0, 0.1, 0.16), (1e-4, 1e-4, 1e-5), 0.12)
    node("6", (0.1, 0.05, 0.1), (4e-3, 4e-4, 4e-3), 0.5)
    node("8", (0.2, 0.0, 0.0), (1e-4, 1e-4, 1e-4), 2.0)
    node("9", (0.2, 0.0, 0.0), fixed=True)
    s5 = math.sqrt(0.05)
    mb.joint("1", "hinge", "1", "3", axis=Q @ np.array([1.0, 0.0, 0.0]),
             torque=sd.Step(0.015, 0.0, 2.0), at=at((0.0, 0.1, 0.12)))
    mb.joint("4", "spherical", "3", "6", axes=Q.T, at=at((0.0, 0.1, 0.2)))
    mb.joint("7", "hinge", "6", "8", axis=Q @ np.array([0.0, 0.2 / s5, -0.1 / s5]),
             at=at((0.2, 0.0, 0.0)))
    mb.joint("8", "cylindrical", "8", "9", axis=Q @ np.array([1.0, 0.0, 0.0]),
             damping=(1.0, 0.0), at=at((0.2, 0.0, 0.0)))
    return mb.build()


@pytest.mark.parametrize("frames", [False, True], ids=["identity_frames", "rotated_frames"])
def test_offsets_are_invariant_under_a_superposed_rigid_motion(frames):
    Q = _rot((0.3, -1.0, 0.5), 2.0)
    d = np.array([1.5, -0.7, 2.0])
    h, T = 1e-2, 1.0
    ref = sd.simulate(sd.examples.slider_crank_bodies(), T, h, rho_inf=0.9)
    mov = sd.simulate(moved_slider_crank_bodies(Q, d, frames), T, h, rho_inf=0.9)
    # x' = Q x + d; R' = Q R Q^T (identity initial frames) or Q R (frames at Q); relative
    # coordinates identical; round-off and Newton tolerances over 100 steps: 1e-9
    for k in "1368":
        np.testing.assert_allclose(mov.node_position(k), ref.node_position(k) @ Q.T + d,
                                   atol=1e-9, err_msg=f"node {k}")
        Rr = ref.node_rotation(k)
        np.testing.assert_allclose(mov.node_rotation(k), Q @ Rr if frames else Q @ Rr @ Q.T,
                                   atol=1e-9, err_msg=f"node {k}")
    for j in "1478":
        np.testing.assert_allclose(mov.joint_coordinates(j), ref.joint_coordinates(j),
                                   atol=1e-9, err_msg=f"joint {j}")
    np.testing.assert_allclose(mov.kinetic, ref.kinetic, atol=1e-10)
    assert np.abs(ref.joint_coordinates("1")).max() > 3.0  # the crank turned


# ---------------------------------------------------------------------------------------------
# statics and assembly with offsets
# ---------------------------------------------------------------------------------------------
def test_pendulum_on_an_offset_hinge_droops_to_the_analytic_angle():
    # body at its centre of mass (0, L, 0), hinge about x at the origin placed with ``at``:
    # k phi = m g L cos(phi) for the droop phi below the horizontal
    L, m = 0.5, 2.0
    k = m * G * L
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G))
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    mb.node("bob", position=(0.0, L, 0.0), mass=m, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("hinge", "hinge", "ground", "bob", axis=(1.0, 0.0, 0.0), stiffness=k,
             at=(0.0, 0.0, 0.0))
    phi = brentq(lambda p: k * p - m * G * L * math.cos(p), 0.0, math.pi / 2)
    res = sd.static_equilibrium(mb.build(), load_steps=5)
    assert res.joint_coordinates("hinge")[0] == pytest.approx(-phi, rel=1e-9)
    np.testing.assert_allclose(res.node_position("bob"),
                               [0.0, L * math.cos(phi), -L * math.sin(phi)], atol=1e-10)
    # multipliers: the wrench on the bob at the hinge, in the attachment frame (inertial axes
    # at t0 carried with the bob): the weight m g upwards, and about the axis the spring torque
    lam = res.joint_multipliers("hinge")
    R = res.node_rotation("bob")
    np.testing.assert_allclose(R @ lam[:3], [0.0, 0.0, m * G], rtol=1e-9, atol=1e-9)
    assert lam[3] == pytest.approx(m * G * L * math.cos(phi), rel=1e-9)
    np.testing.assert_allclose(lam[4:], 0.0, atol=1e-9)


def test_assembled_model_keeps_the_joints_where_the_bodies_put_them():
    model = sd.examples.slider_crank_bodies()
    theta = 0.7
    asm = sd.assemble(model, coordinates={"1": theta}, keep=["1"])
    assert asm.violation < 1e-12
    new = asm.model
    # the spherical joint moved with the crank: rotation by theta about x through the hinge
    c = np.array([0.0, 0.1, 0.12])
    R = _rot((1.0, 0.0, 0.0), theta)
    np.testing.assert_allclose(new.joint("4").at, c + R @ (np.array([0.0, 0.1, 0.2]) - c),
                               atol=1e-12)
    np.testing.assert_allclose(new.joint("1").at, c, atol=1e-15)
    # the new model starts consistent (Phi = 0 at its initial configuration, H_J0 = I)
    s = compile_model(new)
    z = np.zeros(s.nq)
    ev = evaluate(s, s.node_H0, s.joint_H0, z, z, z, z, np.zeros(s.nm), step_inputs(s, 0.0),
                  None)
    assert np.abs(ev.phi).max() < 1e-11
    # and describes the same mechanism: the assembled paper model lands on the same frames
    paper = sd.assemble(sd.examples.slider_crank(), coordinates={"1": theta}, keep=["1"])
    for k in "368":
        np.testing.assert_allclose(asm.node_frame(k), paper.node_frame(k), atol=1e-10)


def test_kinematics_of_the_bodies_model_matches_the_paper_model():
    times = np.linspace(0.0, 0.5, 6)
    drive = sd.Ramp(2.0, start=0.0, duration=0.5)
    a = sd.kinematics(sd.examples.slider_crank(), {"1": drive}, times)
    b = sd.kinematics(sd.examples.slider_crank_bodies(), {"1": drive}, times)
    for k in "368":
        np.testing.assert_allclose(b.node_frame(k), a.node_frame(k), atol=1e-10)
        np.testing.assert_allclose(b.node_velocity(k), a.node_velocity(k), atol=1e-9)
    np.testing.assert_allclose(b.driver_effort("1"), a.driver_effort("1"), atol=1e-9)


# ---------------------------------------------------------------------------------------------
# 5. errors
# ---------------------------------------------------------------------------------------------
def _builder():
    mb = sd.ModelBuilder()
    mb.node("ground", fixed=True)
    mb.node("body", position=(1.0, 0.0, 0.0), mass=1.0, inertia=(1.0, 1.0, 1.0))
    return mb


@pytest.mark.parametrize("typ,kw", [("hinge", dict(axis=(0, 0, 1))),
                                    ("universal", dict(axes=[(1, 0, 0), (0, 1, 0)]))])
@pytest.mark.parametrize("bad,what", [((0.0, 1.0), "3 numbers"),
                                      ((0.0, float("nan"), 1.0), "finite"),
                                      ("here", "3 numbers"),
                                      ([[0, 0, 0]], "3 numbers")])
def test_bad_attachment_point_names_the_joint_and_the_field(typ, kw, bad, what):
    mb = _builder()
    with pytest.raises(sd.ModelError) as exc:
        mb.joint("pin", typ, "ground", "body", at=bad, **kw)
    e = exc.value
    assert e.field == "at" and "joint 'pin'" in e.item and what in e.expected
    assert "joint 'pin'" in str(e) and "field 'at'" in str(e)
    # nothing was added (a universal joint adds no cross node either)
    mb.joint("pin", typ, "ground", "body", at=(0.5, 0.0, 0.0), **kw)


@pytest.mark.parametrize("value,what", [("[0.0, 1.0]", "3 numbers"),
                                        ("[0.0, .nan, 1.0]", "finite"),
                                        ("here", "3 numbers")])
def test_bad_attachment_point_in_a_model_file(value, what):
    text = ("se3dyn: 1\nnodes:\n  g: {fixed: true}\n"
            "  b: {position: [1, 0, 0], mass: 1, inertia: [1, 1, 1]}\n"
            "joints:\n"
            f"  pin: {{type: hinge, a: g, b: b, axis: [0, 0, 1], at: {value}}}\n")
    with pytest.raises(ModelFileError) as exc:
        loads_model(text, filename="bad.yaml")
    e = exc.value
    assert e.line == 6 and e.field.startswith("at") and "joint 'pin'" in e.item
    assert what in str(e) and "bad.yaml, line 6" in str(e)


def test_results_file_keeps_the_attachment_points(tmp_path):
    pytest.importorskip("h5py")
    from se3dyn.io.h5 import ResultsWriter, read_results

    model = sd.examples.slider_crank_bodies()
    path = tmp_path / "bodies.h5"
    with ResultsWriter(path, compile_model(model)) as w:
        res = sd.simulate(model, 0.1, 1e-2, on_output=w.append)
        w.close(res.stats)
    back = read_results(path)
    np.testing.assert_array_equal(back.node_position("6"), res.node_position("6"))
    stored, _ = loads_model(back.stats["model"])
    for a, b in zip(stored.joints, model.joints, strict=True):
        np.testing.assert_array_equal(a.at, b.at)
