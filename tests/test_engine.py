"""The engine's contracts: an immutable State that restarts bit-exactly, runs of one system that
share no work arrays (each simulate has its own workspace), the compiled loop and the per-step
path giving the same numbers."""

from __future__ import annotations

import dataclasses
import threading

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.dynamics.integrator import GeneralizedAlpha


def test_state_is_immutable():
    s = sd.compile_model(sd.examples.slider_crank())
    st = GeneralizedAlpha().init(s)
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.t = 1.0
    with pytest.raises(ValueError):
        st.v[0] = 1.0


@pytest.mark.parametrize("formulation", ["index2", "index3"])
def test_restart_from_a_state_is_bit_exact(formulation):
    s = sd.compile_model(sd.examples.slider_crank())
    integ = GeneralizedAlpha(formulation=formulation)
    st = integ.init(s)
    states = [st]
    for _ in range(20):
        st, _info = integ.step(s, st, 1e-2)
        states.append(st)
    again = states[10]
    for _ in range(10):
        again, _info = integ.step(s, again, 1e-2)
    for f in dataclasses.fields(again):
        a, b = getattr(again, f.name), getattr(states[20], f.name)
        assert np.array_equal(np.asarray(a), np.asarray(b)), f.name


def test_concurrent_runs_of_one_system_agree_bit_for_bit():
    """Two threads simulate the same compiled system at once (the compiled loop releases the
    GIL): each run has its own workspace, so both equal the sequential run."""
    s = sd.compile_model(sd.examples.slider_crank())
    ref = sd.simulate(s, t_end=2.0, step=1e-2)
    out = [None, None]

    def run(k):
        out[k] = sd.simulate(s, t_end=2.0, step=1e-2)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for r in out:
        assert np.array_equal(r.H, ref.H) and np.array_equal(r.lam, ref.lam)


def test_compiled_loop_and_per_step_path_give_the_same_numbers():
    """The fixed-step loop in the engine and GeneralizedAlpha.step (adaptive and dense-output
    runs use it) are the same Newton iteration: identical states."""
    s = sd.compile_model(sd.examples.slider_crank())
    # (the rigid joints kept: both paths on the same system; condensed runs use both paths
    # on the reduced system alike, tests/test_condense.py)
    res = sd.simulate(s, t_end=1.0, step=1e-2, condense=False)
    integ = GeneralizedAlpha()
    st = integ.init(s)
    for k in range(100):
        st, _ = integ.step(s, st, res.t[k + 1] - st.t)
    assert np.array_equal(st.H, res.H[-1])
    assert np.array_equal(st.v, res.v[-1]) and np.array_equal(st.lam, res.lam[-1])


def _chain(n_links: int) -> sd.Model:
    """A chain of slender links on spherical joints, released horizontal from rest: the
    velocity-dependent entries of its iteration matrix are zero at the start only."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("ground", fixed=True)
    prev = "ground"
    for i in range(n_links):
        name = f"link{i}"
        mb.node(name, position=(0.1 * i + 0.05, 0.0, 0.0), mass=1.0,
                inertia=(1e-4, 1e-2 / 12, 1e-2 / 12))
        mb.joint(f"j{i}", "spherical", prev, name, at=(0.1 * i, 0.0, 0.0))
        prev = name
    return mb.build()


@pytest.mark.parametrize("formulation", ["index2", "index3"])
@pytest.mark.parametrize("model", ["slider_crank", "chain"])
def test_restart_in_a_new_workspace_is_bit_exact(formulation, model):
    """A State holds all that later steps depend on, the linear solver's memory included
    (State.solver: the matrix of the last full LU factorisation, whose pivot sequence later
    refactorisations reuse; the ordering comes from the model alone): stepping from it in a
    fresh workspace (as a new process would) gives the uninterrupted run's numbers bit for bit,
    and so does a workspace that meanwhile stepped from another state."""
    from se3dyn.engine.workspace import Workspace

    m = sd.examples.slider_crank() if model == "slider_crank" else _chain(6)
    h = 1e-2 if model == "slider_crank" else 2e-3
    s = sd.compile_model(m)
    integ = GeneralizedAlpha(formulation=formulation)
    ws = Workspace(s)
    st = integ.init(s, ws=ws)
    states = [st]
    for _ in range(30):
        st, _info = integ.step(s, st, h, ws=ws)
        states.append(st)
    for start, other in ((10, None), (5, states[25])):
        ws2 = Workspace(s)
        if other is not None:  # the workspace holds factors of a different state first
            integ.step(s, other, h, ws=ws2)
        again = states[start]
        for _ in range(30 - start):
            again, _info = integ.step(s, again, h, ws=ws2)
        for f in ("H", "HJ", "v", "vd", "a", "lam", "alpha"):
            assert np.array_equal(getattr(again, f), getattr(states[30], f)), (start, f)


def test_solver_memory_is_shared_not_copied():
    """The solver memory (the values of a whole iteration matrix) is one read-only array that
    the stepper and every State holding it share: no copy per State or per call."""
    from se3dyn.engine.workspace import Workspace

    s = sd.compile_model(_chain(6))
    integ = GeneralizedAlpha()
    ws = Workspace(s)
    st = integ.init(s, ws=ws)
    for _ in range(30):
        st, _info = integ.step(s, st, 2e-3, ws=ws)
    assert st.solver is not None  # (released from rest: refactorisations fail at the start)
    ref = ws.stepper(True, st.dropped).memory()
    assert np.shares_memory(ref, st.solver.ref)
    with pytest.raises(ValueError):
        ref.flags.writeable = True
