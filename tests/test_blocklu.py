"""Block LU solver (se3dyn.blocklu): random block-structured matrices against numpy, the
iteration matrices of se3dyn models against LinearSolver (SuperLU), zero fill on trees, failing
pivots reported by a return code."""

from __future__ import annotations

import numba
import numpy as np
import pytest

import se3dyn as sd
from se3dyn import blocklu, lie
from se3dyn.integrator import GeneralizedAlpha, step_inputs
from se3dyn.system import LinearSolver, evaluate, matrix_values

# ---------------------------------------------------------------------------------------------
# random block-structured matrices


def _random_problem(rng, nsn, extra_edges=0, dup=True):
    """Random supernode graph (a random tree plus ``extra_edges`` loop edges), random block
    sizes and kinds, random sparse blocks on the edges, diagonally dominant diagonal blocks, a
    random numbering of the unknowns, duplicated and ignored (negative) pattern entries.

    Returns N, rows, cols, values, sn, kind, the dense matrix, the edges."""
    size = rng.integers(1, 9, nsn)
    N = int(size.sum())
    perm = rng.permutation(N)  # unknowns of a supernode are scattered over the numbering
    sn = np.empty(N, np.int64)
    sn[perm] = np.repeat(np.arange(nsn), size)
    unk = [np.flatnonzero(sn == i) for i in range(nsn)]
    kind = rng.integers(0, 3, nsn)
    edges = [(int(rng.integers(0, i)), i) for i in range(1, nsn)]
    while extra_edges:
        i, j = rng.integers(0, nsn, 2)
        if i != j and (i, j) not in edges and (j, i) not in edges:
            edges.append((int(i), int(j)))
            extra_edges -= 1
    rows, cols, vals = [], [], []

    def add(ri, ci, dense, scale):
        R, C = np.meshgrid(ri, ci, indexing="ij")
        mask = np.ones(R.shape, bool) if dense else rng.random(R.shape) < 0.6
        v = scale * rng.standard_normal(R.shape)
        rows.append(R[mask])
        cols.append(C[mask])
        vals.append(v[mask])

    for i, j in edges:
        add(unk[i], unk[j], False, 1.0)
        if rng.random() < 0.8:  # sometimes structurally non-symmetric
            add(unk[j], unk[i], False, 1.0)
    rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    cols = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    vals = np.concatenate(vals) if vals else np.zeros(0)
    # diagonally dominant by rows and by columns, the diagonal blocks dense
    rsum = np.bincount(rows, np.abs(vals), N) + np.bincount(cols, np.abs(vals), N)
    dr, dc, dv = [], [], []
    for i in range(nsn):
        R, C = np.meshgrid(unk[i], unk[i], indexing="ij")
        v = 0.3 * rng.standard_normal(R.shape)
        v[np.arange(size[i]), np.arange(size[i])] = 0.0
        rsum[unk[i]] += np.abs(v).sum(axis=1) + np.abs(v).sum(axis=0)
        dr.append(R.ravel())
        dc.append(C.ravel())
        dv.append(v.ravel())
    diag = np.arange(N)
    rows = np.concatenate([rows, *dr, diag])
    cols = np.concatenate([cols, *dc, diag])
    vals = np.concatenate([vals, *dv, (1.0 + rsum) * rng.choice([-1.0, 1.0], N)])
    if dup:  # split some values into two duplicates, add ignored entries
        k = rng.choice(len(vals), len(vals) // 5, replace=False)
        part = rng.random(len(k))
        rows = np.concatenate([rows, rows[k], [-1, 0]])
        cols = np.concatenate([cols, cols[k], [0, -1]])
        vals = np.concatenate([vals, vals[k] * (1 - part), [1e300, 1e300]])
        vals[k] *= part
    keep = (rows >= 0) & (cols >= 0)
    A = np.zeros((N, N))
    np.add.at(A, (rows[keep], cols[keep]), vals[keep])
    return N, rows, cols, vals, sn, kind, A, edges


@pytest.mark.parametrize("extra", [0, 5, 40])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_block_matrices(seed, extra):
    rng = np.random.default_rng(100 * seed + extra)
    nsn = 60
    N, rows, cols, vals, sn, kind, A, _ = _random_problem(rng, nsn, extra)
    bl = blocklu.symbolic(N, rows, cols, sn, kind)
    assert sorted(bl.order.tolist()) == list(range(nsn))
    assert bl.factor(vals), bl.info
    for _ in range(3):
        b = rng.standard_normal(N)
        x = bl.solve(b)
        xr = np.linalg.solve(A, b)
        assert np.linalg.norm(x - xr) <= 1e-10 * np.linalg.norm(xr)
        assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(A, 1) * np.linalg.norm(x)


def test_random_tree_of_nodes_and_joints_no_fill():
    """Bipartite tree of bodies (kind 0) and joints (kind 2) with leaves bodies: no fill, and
    every joint is eliminated after a body next to it."""
    rng = np.random.default_rng(7)
    nb = 40
    # bodies 0..nb-1, joint nb + i between body parent[i] and body i + 1
    parent = [int(rng.integers(0, i + 1)) for i in range(nb - 1)]
    nsn = 2 * nb - 1
    size = np.where(np.arange(nsn) < nb, 6, 6 + rng.integers(0, 4, nsn))
    sn = np.repeat(np.arange(nsn), size)
    N = len(sn)
    unk = [np.flatnonzero(sn == i) for i in range(nsn)]
    kind = np.where(np.arange(nsn) < nb, 0, 2)
    rows, cols = [], []
    for i, p in enumerate(parent):
        j = nb + i
        for a, b in ((j, p), (p, j), (j, i + 1), (i + 1, j), (j, j)):
            R, C = np.meshgrid(unk[a], unk[b], indexing="ij")
            rows.append(R.ravel())
            cols.append(C.ravel())
    for i in range(nb):
        R, C = np.meshgrid(unk[i], unk[i], indexing="ij")
        rows.append(R.ravel())
        cols.append(C.ravel())
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    bl = blocklu.symbolic(N, rows, cols, sn, kind)
    assert bl.nfill == 0
    assert bl.nblocks == bl.nblocks_struct
    step = bl.step
    for i, p in enumerate(parent):
        assert step[nb + i] > min(step[p], step[i + 1])
    vals = rng.standard_normal(len(rows))
    vals[rows == cols] += 50.0
    A = np.zeros((N, N))
    np.add.at(A, (rows, cols), vals)
    assert bl.factor(vals)
    b = rng.standard_normal(N)
    assert np.allclose(bl.solve(b), np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)


def test_singular_pivot_returns_code():
    rng = np.random.default_rng(3)
    N, rows, cols, vals, sn, kind, A, _ = _random_problem(rng, 20, 3, dup=False)
    bl = blocklu.symbolic(N, rows, cols, sn, kind)
    # an all-zero unknown (row and column): structurally singular
    dead = int(np.flatnonzero(sn == bl.order[5])[0])  # a supernode of step 5
    v = np.where((rows == dead) | (cols == dead), 0.0, vals)
    assert not bl.factor(v)
    assert 1 <= bl.info <= bl.nsn
    with pytest.raises(RuntimeError):
        bl.solve(np.ones(N))
    # non-finite values
    v = vals.copy()
    v[len(v) // 2] = np.nan
    assert not bl.factor(v)
    v[len(v) // 2] = np.inf
    assert not bl.factor(v)
    # the njit kernel itself returns the code
    code = blocklu.factor(bl.sym, bl.vmask, bl.vone, np.zeros(len(vals)), bl.store, bl.piv)
    assert code == 1
    assert bl.factor(vals)


@numba.njit(cache=True)
def _newton_like(sym, vmask, vone, values, store, piv, b, x, work):
    """The kernels called from user njit code (as a Newton loop would)."""
    code = blocklu.factor(sym, vmask, vone, values, store, piv)
    if code != 0:
        return code
    blocklu.solve(sym, store, piv, b, x, work)
    blocklu.solve(sym, store, piv, x, x, work)  # x may alias b
    return 0


def test_kernels_callable_from_njit():
    rng = np.random.default_rng(11)
    N, rows, cols, vals, sn, kind, A, _ = _random_problem(rng, 15, 2)
    bl = blocklu.symbolic(N, rows, cols, sn, kind)
    b = rng.standard_normal(N)
    x = np.empty(N)
    assert _newton_like(bl.sym, bl.vmask, bl.vone, vals, bl.store, bl.piv, b, x, bl.work) == 0
    xr = np.linalg.solve(A, np.linalg.solve(A, b))
    assert np.linalg.norm(x - xr) <= 1e-10 * np.linalg.norm(xr)


# ---------------------------------------------------------------------------------------------
# iteration matrices of se3dyn models


def _chain(n_links: int, close: bool = False) -> sd.Model:
    """The spherical pendulum chain of benchmarks/chain_scaling.py (massless joint and end
    nodes rigidly attached to each body); ``close`` attaches the end to a second clamped node by
    a spherical joint (a closed loop)."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name=f"chain{n_links}")
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    J = 1.0 * 0.1**2 / 12.0
    prev = "ground"
    for i in range(n_links):
        x0 = 0.1 * i
        mb.node(f"p{i}", position=(x0, 0.0, 0.0))
        mb.node(f"b{i}", position=(x0 + 0.05, 0.0, 0.0), mass=1.0, inertia=(1e-4 * J, J, J))
        mb.node(f"e{i}", position=(x0 + 0.1, 0.0, 0.0))
        mb.joint(f"s{i}", "spherical", prev, f"p{i}")
        mb.joint(f"r{i}", "rigid", f"p{i}", f"b{i}")
        mb.joint(f"t{i}", "rigid", f"b{i}", f"e{i}")
        prev = f"e{i}"
    if close:
        # off the line of the chain: a straight chain between two clamped points is singular
        mb.node("end", position=(0.1 * n_links, 0.0, -0.1), fixed=True)
        mb.joint("close", "spherical", prev, "end")
    return mb.build()


def _body_chain(n: int, branch: bool = False) -> sd.Model:
    """Bodies connected directly by joints (no massless nodes), hanging from a clamped node;
    with ``branch`` a tree: every third body carries a side branch of two bodies."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name="bodies")
    mb.node("ground", fixed=True)
    types = ("spherical", "hinge", "cylindrical", "rigid", "prismatic")
    cnt = 0

    def body(name, x, y):
        mb.node(name, position=(x, y, 0.0), mass=1.0, inertia=(1e-3, 2e-3, 3e-3))

    def joint(a, b):
        nonlocal cnt
        t = types[cnt % len(types)]
        cnt += 1
        kw = {} if t in ("spherical", "rigid") else {"axis": (0.0, 0.6, 0.8)}
        mb.joint(f"j{cnt}", t, a, b, **kw)

    prev = "ground"
    for i in range(n):
        body(f"b{i}", 0.1 * (i + 1), 0.0)
        joint(prev, f"b{i}")
        if branch and i % 3 == 1:
            body(f"c{i}", 0.1 * (i + 1), 0.1)
            joint(f"b{i}", f"c{i}")
            body(f"d{i}", 0.1 * (i + 1), 0.2)
            joint(f"c{i}", f"d{i}")
        prev = f"b{i}"
    return mb.build()


def _four_bar() -> sd.Model:
    """Planar four-bar with parallel hinges: 3 redundant constraint equations (dropped)."""
    mb = sd.ModelBuilder(gravity=(0.0, -9.81, 0.0), name="fourbar")
    z = (0.0, 0.0, 1.0)
    mb.node("g1", position=(0.0, 0.0, 0.0), fixed=True)
    mb.node("g2", position=(1.0, 0.0, 0.0), fixed=True)
    pts = {"p1": (0.0, 0.0), "p2": (0.0, 0.5), "q2": (0.0, 0.5), "p3": (1.0, 0.6),
           "q3": (1.0, 0.6), "p4": (1.0, 0.0)}
    for k, (x, y) in pts.items():
        mb.node(k, position=(x, y, 0.0))
    for k, (x, y) in {"crank": (0.0, 0.25), "coupler": (0.5, 0.55),
                      "rocker": (1.0, 0.3)}.items():
        mb.node(k, position=(x, y, 0.0), mass=1.0, inertia=(1e-2, 1e-2, 1e-2))
    mb.joint("h1", "hinge", "g1", "p1", axis=z, torque=sd.Constant(0.5))
    mb.joint("r1", "rigid", "p1", "crank")
    mb.joint("r2", "rigid", "crank", "p2")
    mb.joint("h2", "hinge", "p2", "q2", axis=z)
    mb.joint("r3", "rigid", "q2", "coupler")
    mb.joint("r4", "rigid", "coupler", "p3")
    mb.joint("h3", "hinge", "p3", "q3", axis=z)
    mb.joint("r5", "rigid", "q3", "rocker")
    mb.joint("r6", "rigid", "rocker", "p4")
    mb.joint("h4", "hinge", "p4", "g2", axis=z)
    return mb.build()


def _iteration_values(s, integ, st, h, index2):
    """The scaled iteration matrix at the predictor of a step, as GeneralizedAlpha.step."""
    am, af, g, b = integ.params
    inputs = step_inputs(s, st.t + h)
    vd = np.zeros(s.nq)
    a = (af * st.vd - am * st.a) / (1 - am)
    v = st.v + h * (1 - g) * st.a + h * g * a
    n = h * st.v + h * h * (0.5 - b) * st.a + h * h * b * a
    bp = (1 - am) / (b * h * h * (1 - af))
    gp = g / (b * h)
    stab = (dict(cv=1.0 / gp, Adn=[lie.adjoint_inv(st.HJ[gr.ids]) for gr in s.groups])
            if index2 else None)
    ev = evaluate(s, st.H, st.HJ, st.alpha, n, v, vd, st.lam, inputs, full_alpha=False,
                  velocity=index2)
    return matrix_values(s, ev, (1.0, gp / bp, 1.0 / bp), stab)


def _integrator():
    try:  # the numpy engine: the state does not depend on the compiled kernels
        return GeneralizedAlpha(rho_inf=0.8, engine="numpy")
    except TypeError:  # an integrator without engines
        return GeneralizedAlpha(rho_inf=0.8)


def _state(model, steps=3, h=1e-3):
    s = sd.compile_model(model)
    integ = _integrator()
    st = integ.init(s)
    for _ in range(steps):
        st, _ = integ.step(s, st, h)
    return s, integ, st


def _a01() -> sd.Model:
    """IFToMM A01 as in examples/a01_simple_pendulum.yaml: a massless link between a hinge to
    the ground and a point mass on a spherical joint. No single supernode after the point mass
    and its joint is a nonsingular pivot: needs compound pivots."""
    mb = sd.ModelBuilder(gravity=(0.0, -9.81, 0.0), name="a01")
    mb.node("ground", fixed=True)
    mb.node("pivot")
    mb.node("tip", position=(1.0, 0.0, 0.0))
    mb.node("P1", position=(1.0, 0.0, 0.0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("O", "hinge", "ground", "pivot", axis=(0.0, 0.0, 1.0))
    mb.joint("link", "rigid", "pivot", "tip")
    mb.joint("ball", "spherical", "tip", "P1")
    return mb.build()


def _a05() -> sd.Model:
    """IFToMM A05 flyball governor (universal joints: massless cross nodes, massless struts)."""
    from pathlib import Path

    from se3dyn.modelfile import load_model

    path = Path(__file__).resolve().parents[1] / "examples" / "a05_flyball_governor.yaml"
    if not path.exists():
        pytest.skip("examples/a05_flyball_governor.yaml not found")
    return load_model(path)[0]


MODELS = {
    "a01": _a01,
    "a05_flyball": _a05,
    "slider_crank": lambda: sd.examples.slider_crank(),
    "chain": lambda: _chain(6),
    "closed_chain": lambda: _chain(5, close=True),
    "body_tree": lambda: _body_chain(7, branch=True),
    "four_bar": _four_bar,
}


@pytest.fixture(scope="module", params=list(MODELS))
def model_state(request):
    return request.param, *_state(MODELS[request.param](), h=2e-3)


def _backward_error(A, x, b):
    """Normwise backward error ``|A x - b| / (|A| |x| + |b|)`` (inf norms)."""
    r = np.abs(A @ x - b).max()
    return r / (abs(A).sum(axis=1).max() * np.abs(x).max() + np.abs(b).max())


@pytest.mark.parametrize("index2", [False, True])
def test_iteration_matrices_match_linear_solver(model_state, index2):
    """Against LinearSolver with dense LU (LAPACK) and with SuperLU. The matrices have
    condition numbers up to ~1e9 (the chain), so SuperLU and LAPACK themselves differ by up to
    ~1e-9 relative; the block LU agrees with LAPACK to ~1e-14 and is backward stable."""
    name, s, integ, st = model_state
    if name == "four_bar":
        assert st.dropped.size == 3
    h = 2e-3
    vals = _iteration_values(s, integ, st, h, index2)
    bl = blocklu.from_system(s, index2, drop=st.dropped)
    dense = LinearSolver(s, dense_max=10**6, index2=index2, drop=st.dropped)
    sparse = LinearSolver(s, dense_max=0, index2=index2, drop=st.dropped)
    assert bl.factor(vals), (name, bl.info, bl.failed())
    rng = np.random.default_rng(5)
    for scale in (1.0, 2.0):  # refactorisation with other values reuses the storage
        assert bl.factor(scale * vals)
        dense.factor(scale * vals, "test")
        sparse.factor(scale * vals, "test")
        A = dense.matrix(scale * vals)
        for _ in range(2):
            b = rng.standard_normal(bl.N)
            x = bl.solve(b)
            xd = dense.solve(b)
            xs = sparse.solve(b)
            assert np.linalg.norm(x - xd) <= 1e-9 * np.linalg.norm(xd), name
            assert np.linalg.norm(x - xs) <= 1e-9 * np.linalg.norm(xs) + 2 * np.linalg.norm(
                xs - xd), name
            # no pivoting across supernodes: element growth ~ |C|^2 / smallest inertia (A05:
            # rods of axial inertia 5e-6) costs a few digits of backward error ...
            assert _backward_error(A, x, b) <= 1e-10, name
            # ... which one step of iterative refinement restores (as LAPACK's pivoted LU)
            x1 = bl.solve(b, refine=1)
            assert _backward_error(A, x1, b) <= 4 * max(_backward_error(A, xd, b), 1e-16)
            y = np.empty(bl.N)
            blocklu.matvec(bl.rows, bl.cols, bl.vmask, bl.vone, scale * vals, x1, y)
            assert np.abs(y - A @ x1).max() <= 1e-13 * (abs(A) @ np.abs(x1)).max()


def test_initial_acceleration_matrix(model_state):
    """The matrix of GeneralizedAlpha.init (coef (1, 0, 0), index 3, dropped equations)."""
    name, s, integ, st = model_state
    inputs = step_inputs(s, st.t)
    zero = np.zeros(s.nq)
    ev = evaluate(s, st.H, st.HJ, st.alpha, zero, st.v, zero, st.lam, inputs, (1.0, 0.0, 0.0))
    bl = blocklu.from_system(s, False, drop=st.dropped)
    ref = LinearSolver(s, dense_max=10**6, drop=st.dropped)
    ref.factor(ev.values, "test")
    assert bl.factor(ev.values), name
    b = np.random.default_rng(2).standard_normal(bl.N)
    xr = ref.solve(b)
    x = bl.solve(b)
    assert np.linalg.norm(x - xr) <= 1e-9 * np.linalg.norm(xr)
    A = ref.matrix(ev.values)
    assert _backward_error(A, x, b) <= 1e-10
    assert _backward_error(A, bl.solve(b, refine=1), b) <= 4 * max(
        _backward_error(A, xr, b), 1e-16)


@pytest.mark.parametrize("branch", [False, True])
@pytest.mark.parametrize("index2", [False, True])
def test_body_trees_have_no_fill(branch, index2):
    s = sd.compile_model(_body_chain(12, branch=branch))
    bl = blocklu.from_system(s, index2)
    assert bl.nfill == 0
    assert bl.nblocks == bl.nblocks_struct


def test_chain_fill_is_linear():
    """The pendulum chain (massless nodes rigidly attached to each body) cannot be factored
    without fill (a massless end node is singular until its body is eliminated), but the fill
    per link is bounded: O(N) storage."""
    per = []
    for n in (10, 40):
        s = sd.compile_model(_chain(n))
        for index2 in (False, True):
            bl = blocklu.from_system(s, index2)
            per.append(bl.nblocks / n)
            assert bl.nfill <= 12 * n
    assert abs(per[0] - per[2]) < 0.5 and abs(per[1] - per[3]) < 0.5


def test_undetermined_massless_node_fails_gracefully():
    """A massless node on a hinge alone: its rotation is undetermined, the matrix singular."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("g", fixed=True)
    mb.node("b", position=(0.1, 0.0, 0.0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.node("e", position=(0.2, 0.0, 0.0))
    mb.joint("s", "spherical", "g", "b")
    mb.joint("h", "hinge", "b", "e", axis=(1.0, 0.0, 0.0))
    s = sd.compile_model(mb.build())
    inputs = step_inputs(s, 0.0)
    zero = np.zeros(s.nq)
    ev = evaluate(s, s.node_H0, s.joint_H0, zero, zero, zero, zero, np.zeros(s.nm), inputs,
                  (1.0, 0.0, 0.0))
    bl = blocklu.from_system(s, False)
    assert not bl.factor(ev.values)
    assert bl.info > 0
