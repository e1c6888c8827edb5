"""The split iteration of the stabilized index-2 form (``se3dyn/_core/newton.hpp``): Newton
iterates with a block-triangular part of the iteration matrix (the increments m = n - B_n^T xi
and the multipliers from an index-3-sized matrix, then xi from B B_n^T), or with the full
matrix once the split contracts too slowly. Only the iteration matrix differs, never the
residual: both iterations converge to the same discrete steps, to the Newton tolerances."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.dynamics.integrator import GeneralizedAlpha
from se3dyn.engine import workspace as system  # (SPLIT_INDEX2)
from se3dyn.engine.memory import SolverMemory
from se3dyn.io.modelfile import load_model

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import chain_scaling  # noqa: E402  (the benchmarks' chain model)


def _spinning_chain(n: int) -> sd.Model:
    """The benchmarks' chain with spinning links (3D motion, no entry zero by symmetry)."""
    rng = np.random.default_rng(n)
    return chain_scaling.chain(n, spin=lambda i: tuple(rng.uniform(-2.0, 2.0, 3)))


def _example(name: str) -> sd.Model:
    return load_model(ROOT / "examples" / f"{name}.yaml")[0]


def _both(monkeypatch, model, t_end, h, **kw):
    """The run with the split iteration (the default) and with the full matrix throughout."""
    split = sd.simulate(model, t_end, h, **kw)
    monkeypatch.setattr(system, "SPLIT_INDEX2", False)
    full = sd.simulate(model, t_end, h, **kw)
    monkeypatch.setattr(system, "SPLIT_INDEX2", True)
    return split, full


def _agree(a, b, pos=1e-8, rel=1e-6):
    """The same discrete motion to the Newton tolerances: frames, velocities, multipliers."""
    assert a.t.shape == b.t.shape
    L = max(1.0, float(np.abs(b.H[:, :, :3, 3]).max()))
    assert np.abs(a.H - b.H).max() <= pos * L
    for x, y in ((a.v, b.v), (a.lam, b.lam)):
        assert np.abs(x - y).max() <= rel * max(float(np.abs(y).max()), 1e-12)


@pytest.mark.parametrize("case", ["chain", "four_bar", "bricard", "squeezer"])
def test_split_and_full_matrix_reach_the_same_steps(monkeypatch, case):
    # a chain, a closed loop with 120 redundant equations (A02: dropped equations are identity
    # rows in both factorisations), a loop whose mobility needs every equation (A04) and a
    # stiff planar mechanism at small steps (A03); the split holds on all of them
    model, t_end, h = {
        "chain": (_spinning_chain(20), 0.2, 1e-3),
        "four_bar": (_example("a02_n_four_bar"), 0.3, 1e-3),
        "bricard": (_example("a04_bricard"), 0.5, 1e-3),
        "squeezer": (_example("a03_andrews_squeezer"), 0.01, 1e-5),
    }[case]
    split, full = _both(monkeypatch, model, t_end, h)
    _agree(split, full)
    assert split.stats["full_matrix_steps"] == 0
    assert full.stats["full_matrix_steps"] == 0  # (never split: nothing to fall back from)
    # linear, not quadratic, convergence: a little more than one iteration per step more at most
    assert split.stats["newton_iterations"] <= 2.5 * full.stats["newton_iterations"]
    assert split.iterations.max() <= 6


def test_stiff_elements_take_the_full_matrix_and_keep_the_steps(monkeypatch):
    # beams: the split leaves out h^2 K B_n^T, which a stiff element makes large, so the split
    # contracts slowly; the stepper goes over to the full matrix and stays with it
    model = _example("slider_crank_flexible")
    split, full = _both(monkeypatch, model, 0.01, 1e-4)
    _agree(split, full, rel=1e-5)
    steps = split.stats["steps"]
    assert steps - 5 <= split.stats["full_matrix_steps"] <= steps
    assert split.stats["newton_iterations"] <= full.stats["newton_iterations"] + 10


def test_full_newton_never_splits(monkeypatch):
    # a factorisation at every iteration asks for Newton's own matrix: the same numbers as the
    # full matrix throughout, bit for bit
    model = sd.examples.slider_crank()
    split, full = _both(monkeypatch, model, 0.5, 1e-2, newton="full")
    assert np.array_equal(split.H, full.H) and np.array_equal(split.lam, full.lam)
    assert split.stats["full_matrix_steps"] == 0


def _steps(s, integ, st, h, n, ws):
    out = [st]
    for _ in range(n):
        st, _info = integ.step(s, st, h, ws=ws)
        out.append(st)
    return out


def test_a_restart_continues_in_the_mode_of_its_run():
    """The slider-crank at 10 ms goes over to the full matrix after some steps. The mode is
    part of the solver memory, so restarts from states before and after the change, in fresh
    workspaces, give the uninterrupted run's numbers bit for bit."""
    from se3dyn.engine.workspace import Workspace

    s = sd.compile_model(sd.examples.slider_crank())
    integ = GeneralizedAlpha()
    ws = Workspace(s)
    states = [integ.init(s, ws=ws)]
    switched = None
    for k in range(150):
        states += _steps(s, integ, states[-1], 1e-2, 1, ws)[1:]
        if switched is None and ws.full_matrix_steps() > 0:
            switched = k
    assert switched is not None and 5 < switched < 140
    assert states[switched - 2].solver.ref[-1] == 0.0  # split
    assert states[switched + 2].solver.ref[-1] == 1.0  # the full matrix
    for start in (switched - 3, switched + 3):
        again = _steps(s, integ, states[start], 1e-2, 150 - start, Workspace(s))[-1]
        for f in ("H", "HJ", "v", "vd", "a", "lam", "alpha"):
            assert np.array_equal(getattr(again, f), getattr(states[-1], f)), (start, f)


def test_a_memory_without_its_mode_is_the_full_matrix(monkeypatch):
    """States written before the split iteration carry the full matrix's values without the
    mode entry: they continue with the full matrix, bit for bit as with the entry."""
    from se3dyn.engine.workspace import Workspace

    s = sd.compile_model(_spinning_chain(6))
    integ = GeneralizedAlpha()
    monkeypatch.setattr(system, "SPLIT_INDEX2", False)
    st = _steps(s, integ, integ.init(s, ws=Workspace(s)), 2e-3, 30, Workspace(s))[-1]
    monkeypatch.setattr(system, "SPLIT_INDEX2", True)
    assert st.solver is not None and st.solver.ref[-1] == 1.0
    old = dataclasses.replace(st, solver=SolverMemory(ref=st.solver.ref[:-1].copy()))
    a = _steps(s, integ, st, 2e-3, 20, Workspace(s))[-1]
    b = _steps(s, integ, old, 2e-3, 20, Workspace(s))[-1]
    for f in ("H", "v", "lam"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f


def test_a_split_memory_given_to_full_newton_is_set_aside(monkeypatch):
    """Continuing a default run in full Newton: the split factors' values lack the full
    matrix's blocks, so the stepper starts from the model's generic matrix (no error), and
    continues the motion the default run would, to the Newton tolerances."""
    s = sd.compile_model(_spinning_chain(6))
    first = sd.simulate(s, 0.05, 2e-3)
    st = first.stats["final_state"]
    assert st.solver is not None and st.solver.ref[-1] == 0.0
    a = sd.simulate(s, 0.1, 2e-3, t_start=0.05, initial_state=st, newton="full")
    b = sd.simulate(s, 0.1, 2e-3, t_start=0.05, initial_state=st)
    _agree(a, b)


def test_a_stepper_whose_generic_factorisation_overflows_holds_the_models_memory():
    """Along 6000 links the generic matrix's factorisation overflows (products of its random
    frames): the new stepper holds the model's own memory all the same (the first matrix of a
    run is then factorised anew, as by every new stepper of the model), so a run does not try
    that factorisation a second time; runs in a new workspace and in one that ran before give
    the same numbers. A stepper for the initial accelerations (one solve) keeps no memory."""
    from se3dyn.engine.workspace import Workspace

    s = sd.compile_model(chain_scaling.chain(6000))
    ws = Workspace(s)
    none = np.zeros(0, np.int64)
    assert ws.stepper(True, none).holds(None)
    assert ws.stepper(False, none).holds(None)
    assert not Workspace(s).stepper(False, none, keep=False).holds(None)  # (a one-off solve)
    integ = GeneralizedAlpha(rho_inf=0.9)
    a = _steps(s, integ, integ.init(s, ws=ws), 1e-3, 2, ws)[-1]
    fresh = Workspace(s)
    b = _steps(s, integ, integ.init(s, ws=fresh), 1e-3, 2, fresh)[-1]
    again = _steps(s, integ, integ.init(s, ws=ws), 1e-3, 2, ws)[-1]
    for f in ("H", "v", "vd", "lam"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
        assert np.array_equal(getattr(a, f), getattr(again, f)), f
    assert np.abs(a.H[-1, 2, 3]) > 0.0  # (the chain falls)
