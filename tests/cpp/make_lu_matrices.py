"""Dump se3dyn iteration matrices for the standalone sparse LU test (tests/cpp/test_sparse_lu.cpp).

For every model: the scaled iteration matrix of GeneralizedAlpha.step at the predictor of a step
(index-3 and/or stabilized index-2 form, as LinearSolver.matrix builds it), a second value array
of the same pattern a few steps later (a realistic refactor), a group id per unknown (the 6
unknowns of a node, the k unknowns of a joint, the 6 multipliers of a joint, the 6 index-2
multipliers of a joint), a coarser grouping (each joint with its child node: see joint_groups)
and a right-hand side. The bodies get random initial angular velocities (3D motion: no entry
is zero by the symmetry of a planar motion, though about a third to a half of the pattern's
entries are zero in every configuration), except in "chainplanar" (the planar fall of
benchmarks/chain_scaling.py, where about two thirds are zero). Next to each matrix file a
``.splu`` text file holds what SciPy's SuperLU (COLAMD) does on the same matrix: nnz(L+U)
(SciPy counts only the numerically nonzero entries), factor and solve times (thread CPU time,
best of a few runs) and the backward error, which the C++ driver prints next to its own.

Run (from anywhere; writes into OUTDIR, default /work/scratch-lu/matrices):

    python tests/cpp/make_lu_matrices.py [OUTDIR] [--big]

``--big`` adds the 10000-link chains (n ~ 150,000; a few minutes).

File format (little endian): int64 n, int64 nnz, int32 colptr[n+1], int32 rowind[nnz],
int32 group[n], int32 group2[n], float64 values[nnz], float64 values2[nnz], float64 b[n].
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "src"))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import chain_scaling  # noqa: E402  (the chain models, defined once there)

import se3dyn as sd  # noqa: E402
from se3dyn import lie
from se3dyn.dynamics.integrator import GeneralizedAlpha
from se3dyn.engine.evaluate import evaluate, matrix_values  # noqa: E402
from se3dyn.engine.inputs import step_inputs  # noqa: E402
from se3dyn.engine.linsolve import LinearSolver
from se3dyn.model.examples import slider_crank  # noqa: E402


# ---------------------------------------------------------------------------------------------
# models
def spin(rng, planar):
    """A random initial angular velocity (3D motion: no entry of the pattern stays zero by
    symmetry), or none (the planar fall of benchmarks/chain_scaling.py)."""
    return None if planar else tuple(rng.uniform(-2.0, 2.0, 3))


def chain(n_links: int, planar: bool = False) -> sd.Model:
    """benchmarks/chain_scaling.py's chain: one node per link, spherical joints at the link
    ends, the bodies spinning (see spin) unless ``planar``."""
    rng = np.random.default_rng(n_links)
    return chain_scaling.chain(n_links, spin=lambda i: spin(rng, planar))


def chain_nodes(n_links: int, close: bool = False) -> sd.Model:
    """benchmarks/chain_scaling.py's chain in the paper's form: massless joint and end nodes
    rigidly attached to each body (zero 6x6 diagonal blocks); ``close`` clamps the far end by a
    spherical joint (a closed loop)."""
    rng = np.random.default_rng(n_links)
    return chain_scaling.chain_nodes(n_links, spin=lambda i: spin(rng, False), close=close,
                                     name=f"chainn{n_links}")


def binary_tree(depth: int) -> sd.Model:
    """A binary tree of 2^depth - 1 bodies, spherical and hinge joints at attachment points."""
    rng = np.random.default_rng(depth)
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name=f"tree{depth}")
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    pos = {}

    def add(i, parent, x, y, z):
        mb.node(f"b{i}", position=(x, y, z), mass=1.0, inertia=(1e-3, 2e-3, 3e-3),
                angular_velocity=spin(rng, False))
        px, py, pz = pos.get(parent, (0.0, 0.0, 0.0))
        at = (0.5 * (x + px), 0.5 * (y + py), 0.5 * (z + pz))
        if i % 2:
            mb.joint(f"j{i}", "spherical", parent, f"b{i}", at=at)
        else:
            mb.joint(f"j{i}", "hinge", parent, f"b{i}", at=at, axis=(0.0, 0.6, 0.8))
        pos[f"b{i}"] = (x, y, z)

    nb = 2**depth - 1
    for i in range(1, nb + 1):
        lev = int(np.log2(i))
        parent = "ground" if i == 1 else f"b{i // 2}"
        add(i, parent, 0.1 * (i - 2**lev + 0.5) / 2**lev, 0.1 * i % 0.7, -0.1 * (lev + 1))
    return mb.build()


# ---------------------------------------------------------------------------------------------
def iteration_values(s, integ, st, h, index2):
    """The scaled iteration matrix values at the predictor of a step (as GeneralizedAlpha.step
    and tests/test_blocklu.py)."""
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


def groups(s, index2):
    """One id per unknown: node unknowns by node, joint unknowns by joint, multipliers by joint
    (and the index-2 multipliers by joint, a separate group)."""
    ids = {}
    out = [ids.setdefault(("dof", it), len(ids)) for it in s.items[:s.nq]]
    out += [ids.setdefault(("mult", it), len(ids)) for it in s.items[s.nq:]]
    if index2:
        out += [ids.setdefault(("xi", it), len(ids)) for it in s.items[s.nq:]]
    return np.asarray(out, np.int32)


def joint_groups(s, index2):
    """Coarser groups: every joint with its multipliers, its relative unknowns and one free node
    not yet taken (its node B, else its node A): on a tree each joint with its child body, a
    block whose diagonal is nonsingular (the multipliers' zero diagonal is paired)."""
    g = groups(s, index2)
    nq = s.nq
    taken = np.zeros(s.M, bool)
    out = g.copy()
    for j in range(s.m):
        gid = int(g[nq + s.joint_multadr[j]])
        rows = [nq + s.joint_multadr[j] + np.arange(6),
                s.joint_dofadr[j] + np.arange(s.joint_k[j])]
        if index2:
            rows.append(nq + s.nm + s.joint_multadr[j] + np.arange(6))
        for node in (s.joint_b[j], s.joint_a[j]):
            if s.node_dofadr[node] >= 0 and not taken[node]:
                taken[node] = True
                rows.append(s.node_dofadr[node] + np.arange(6))
                break
        for r in rows:
            out[r] = gid
    return out


def best_of(fn, reps):
    """Best thread CPU time of `reps` calls (as the C++ driver measures: the machine may be
    shared) and the last result."""
    t = []
    for _ in range(reps):
        t0 = time.thread_time()
        r = fn()
        t.append(time.thread_time() - t0)
    return min(t), r


def dump(outdir: Path, name: str, A, group, group2, values2, b):
    A = A.tocsc()
    A.sort_indices()
    n, nnz = A.shape[0], A.nnz
    with open(outdir / f"{name}.bin", "wb") as f:
        np.array([n, nnz], "<i8").tofile(f)
        A.indptr.astype("<i4").tofile(f)
        A.indices.astype("<i4").tofile(f)
        group.astype("<i4").tofile(f)
        group2.astype("<i4").tofile(f)
        A.data.astype("<f8").tofile(f)
        values2.astype("<f8").tofile(f)
        b.astype("<f8").tofile(f)
    # SuperLU with COLAMD, as LinearSolver uses it
    reps = 5 if n < 20000 else 2
    tf, lu = best_of(lambda: spla.splu(A, permc_spec="COLAMD"), reps)
    ts, x = best_of(lambda: lu.solve(b), reps)
    r = np.abs(A @ x - b).max()
    berr = r / (abs(A).sum(axis=1).max() * np.abs(x).max() + np.abs(b).max())
    nnzlu = lu.L.nnz + lu.U.nnz - n
    with open(outdir / f"{name}.splu", "w") as f:
        f.write(f"{nnzlu} {tf:.6e} {ts:.6e} {berr:.3e}\n")
    print(f"{name:22s} n={n:7d} nnz={nnz:8d} splu nnz(L+U)={nnzlu:9d} factor {1e3 * tf:8.2f} ms "
          f"solve {1e3 * ts:7.3f} ms berr {berr:.1e}", flush=True)


def model_matrices(outdir: Path, name: str, model, forms=("i3", "i2"), steps=3, h=2e-3):
    s = sd.compile_model(model)
    integ = GeneralizedAlpha(rho_inf=0.8, engine="numpy")
    st = integ.init(s)
    for _ in range(steps):
        st, _ = integ.step(s, st, h)
    st_later = st
    for _ in range(3):
        st_later, _ = integ.step(s, st_later, h)
    rng = np.random.default_rng(len(name))
    for form in forms:
        index2 = form == "i2"
        ls = LinearSolver(s, dense_max=0, index2=index2, drop=st.dropped)
        A = ls.matrix(iteration_values(s, integ, st, h, index2))
        A2 = ls.matrix(iteration_values(s, integ, st_later, h, index2))
        A.sort_indices()
        A2.sort_indices()
        assert np.array_equal(A.indices, A2.indices) and np.array_equal(A.indptr, A2.indptr)
        b = rng.standard_normal(A.shape[0])
        dump(outdir, f"{name}_{form}", A, groups(s, index2), joint_groups(s, index2), A2.data,
             b)


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    big = "--big" in sys.argv
    outdir = Path(args[0]) if args else Path("/work/scratch-lu/matrices")
    outdir.mkdir(parents=True, exist_ok=True)
    model_matrices(outdir, "slider_crank", slider_crank())
    for n in (10, 100, 1000):
        model_matrices(outdir, f"chain{n}", chain(n))
    model_matrices(outdir, "chainplanar1000", chain(1000, planar=True))
    model_matrices(outdir, "chainnodes1000", chain_nodes(1000), forms=("i2",))
    model_matrices(outdir, "closedchain100", chain_nodes(100, close=True))
    model_matrices(outdir, "tree10", binary_tree(10))
    if big:
        model_matrices(outdir, "chain10000", chain(10000), steps=1)


if __name__ == "__main__":
    main()
