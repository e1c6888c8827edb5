"""Threads of the element kernels (se3dyn.engine.threads, se3dyn/_core/pool.hpp).

The engine evaluates the elements of a type in chunks of 32, coloured so that no two chunks
of one colour add to the same frame, and sums every entry in the order of colours and chunks
whatever the number of threads (se3dyn/_core/engine.hpp). So a run must give the same numbers
to the last bit with 1, 2 or 3 threads: positions, velocities, accelerations, multipliers and
the energies and powers (summed per chunk), for every registered element type. The models
below have 70-160 elements of each type, i.e. several chunks and colours per type, so that the
parallel parts run (a model with fewer than 64 elements of a type never leaves one thread).
A wrong colouring or a kernel writing outside its own entries shows up as a race: different
numbers between runs.
"""

from __future__ import annotations

import multiprocessing
import os

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.elements import REGISTRY
from se3dyn.engine.workspace import engine_of

CHANNELS = ("H", "v", "vd", "lam", "kinetic", "potential", "spring", "dissipation",
            "work_actuators", "work_loads")


def _mixed(K=80):
    """A chain of K bodies (centres of mass off their nodes) on joints of four types with
    springs, dampers, actuators and PD laws; a load at a point of every body; spring-dampers
    between every body and the next but one; bushings between neighbours."""
    rng = np.random.default_rng(7)
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("g", fixed=True)
    prev = "g"
    for i in range(K):
        x = 0.1 * (i + 1)
        mb.node(f"b{i}", position=(x, 0.0, 0.0), mass=0.2, inertia=(1e-3, 1.2e-3, 1.4e-3),
                com=(x + 0.02, 0.01, 0.0))
        at = (x - 0.05, 0.0, 0.0)
        typ = ("spherical", "hinge", "cylindrical", "planar")[i % 4]
        kw = {"spherical": {}, "hinge": dict(axis=(0.0, 1.0, 0.0)),
              "cylindrical": dict(axis=(1.0, 0.0, 0.0)),
              "planar": dict(normal=(0.0, 0.0, 1.0))}[typ]
        k = {"spherical": 3, "hinge": 1, "cylindrical": 2, "planar": 3}[typ]
        if typ in ("hinge", "cylindrical"):
            kw.update(stiffness=(0.5,) * k, damping=(0.01,) * k, actuator=sd.Sine((0.01,) * k, 3.0),
                      control=sd.PD(kp=(0.2,) * k, kd=(0.02,) * k,
                                    target=sd.Ramp((0.1,) * k, 0.0, 0.05)))
        else:
            kw.update(stiffness=(0.3,) * k, damping=(0.01,) * k)
        mb.joint(f"j{i}", typ, prev, f"b{i}", at=at, **kw)
        mb.load(f"l{i}", f"b{i}", force=sd.Sine(tuple(0.05 * rng.normal(size=3)), 2.0),
                torque=(0.0, 0.001, 0.0), at=(x + 0.03, 0.02, 0.0), force_frame="body",
                torque_frame="inertial")
        prev = f"b{i}"
    for i in range(K - 2):
        mb.spring_damper(f"s{i}", f"b{i}", f"b{i + 2}", stiffness=5.0, damping=0.05)
    for i in range(K - 1):
        mb.bushing(f"u{i}", f"b{i}", f"b{i + 1}", at=(0.1 * (i + 1) + 0.05, 0.0, 0.0),
                   stiffness=(2.0, 2.0, 2.0, 0.01, 0.01, 0.01), damping=0.001)
    return mb.build()


def _beam(n=70):
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("a", fixed=True)
    mb.node("b", position=(1.0, 0.0, 0.0), mass=0.1, inertia=(1e-4, 1e-4, 1e-4))
    mb.beam("s", "a", "b", elements=n, EA=1e4, GA=(5e3, 5e3), GJ=20.0, EI=(30.0, 40.0),
            mass_per_length=0.5, rotary_inertia=(1e-4, 5e-5, 5e-5), damping=1e-4)
    return mb.build()


def _contacts(n=70):
    """A row of n balls on a floor, each touching the floor and its neighbours (exclusions
    keep the other pairs out): n + n - 1 contacts, sliding and spinning."""
    rng = np.random.default_rng(3)
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("g", fixed=True)
    mat = sd.ContactMaterial(stiffness=1e6, restitution=0.6, friction=0.4)
    mb.collision("floor", "g", "plane", material=mat)
    for i in range(n):
        mb.node(f"b{i}", position=(0.1999 * i, 0.0, 0.0999), mass=1.0, inertia=(4e-3,) * 3,
                velocity=tuple(0.01 * rng.normal(size=3)),
                angular_velocity=tuple(rng.normal(size=3)))
        far = tuple(f"b{j}" for j in range(n) if abs(j - i) > 1)
        mb.collision(f"s{i}", f"b{i}", "sphere", size=0.1, material=mat, exclude=far)
    return mb.build()


def _run(model, threads, t_end=0.02, step=2e-3):
    sd.set_threads(threads)
    try:
        return sd.simulate(model, t_end=t_end, step=step)
    finally:
        sd.set_threads()


@pytest.fixture(scope="module")
def mixed():
    return sd.compile_model(_mixed())


def _colours(s):
    """{element type: (elements, chunks, colours)} of the system's engine"""
    eng, lay = engine_of(s)
    keys = [key for key, _ in lay.tables["elements"]]
    # (the engine may add an empty joint batch after the tables' types)
    return dict(zip(keys, [tuple(c) for c in eng.colours()], strict=False))


def test_the_models_cover_every_element_type_in_several_chunks(mixed):
    """(So that the comparisons below run every kernel in parallel parts.) A chain's chunks
    take two colours: neighbouring chunks share a node."""
    seen = {}
    for s in (mixed, sd.compile_model(_beam()), sd.compile_model(_contacts())):
        for key, (n, chunks, colours) in _colours(s).items():
            assert chunks == -(-n // 32) and (colours >= 1 or n == 0), (key, n, chunks, colours)
            if n >= seen.get(key, (0,))[0]:
                seen[key] = (n, chunks, colours)
    assert set(REGISTRY) == set(seen)
    assert all(n >= 64 and chunks >= 2 for n, chunks, _ in seen.values()), seen
    assert seen["joint"][2] == 2 and seen["beam"][2] == 2, seen


@pytest.mark.parametrize("which", ["mixed", "beam", "contacts"])
def test_results_do_not_depend_on_the_thread_count(mixed, which):
    model = {"mixed": lambda: mixed, "beam": lambda: sd.compile_model(_beam()),
             "contacts": lambda: sd.compile_model(_contacts())}[which]()
    runs = [_run(model, th) for th in (1, 2, 3, 2)]
    for ch in CHANNELS:
        ref = np.asarray(getattr(runs[0], ch))
        assert np.isfinite(ref).all(), ch
        for th, r in zip((2, 3, 2), runs[1:], strict=True):
            assert np.array_equal(np.asarray(getattr(r, ch)), ref), (which, ch, th)
    assert runs[0].stats["newton_iterations"] == runs[1].stats["newton_iterations"]


def test_energy_balance_holds_with_threads(mixed):
    """The chunked energy sums are the energies: their balance (Eq. (64)) closes to the
    accuracy of the step, as with one thread."""
    r = _run(mixed, 2, t_end=0.05, step=1e-3)
    bal = np.asarray(r.energy_balance)
    scale = np.abs(np.asarray(r.kinetic)).max() + np.abs(np.asarray(r.potential)).max()
    assert np.abs(bal - bal[0]).max() < 1e-3 * scale


def _child(q):
    r = sd.simulate(_beam(), t_end=0.01, step=2e-3)
    q.put(float(np.asarray(r.H)[-1, -1, 0, 3]))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_a_forked_child_runs_with_threads():
    """The pool's workers do not survive a fork; the child starts its own (no hang)."""
    sd.set_threads(2)
    parent = _run(_beam(), 2, t_end=0.01)
    sd.set_threads(2)
    ctx = multiprocessing.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_child, args=(q,))
    p.start()
    p.join(120)
    alive = p.is_alive()
    if alive:
        p.kill()
    sd.set_threads()
    assert not alive, "the forked child hung"
    assert q.get(timeout=10) == float(np.asarray(parent.H)[-1, -1, 0, 3])


@pytest.mark.parametrize("bad", [0, -1, 1.5, "two", True, None.__class__])
def test_bad_thread_counts_are_refused_with_the_value(bad):
    with pytest.raises(sd.Se3dynError, match="whole number of threads"):
        sd.set_threads(bad)


def test_environment_variable(monkeypatch):
    from se3dyn.engine import threads

    monkeypatch.setenv("SE3DYN_THREADS", "3")
    assert threads.from_environment() == 3
    monkeypatch.setenv("SE3DYN_THREADS", "")
    assert threads.from_environment() == threads.default_threads()
    monkeypatch.setenv("SE3DYN_THREADS", "zwei")
    with pytest.raises(sd.Se3dynError, match="SE3DYN_THREADS.*'zwei'"):
        threads.from_environment()
    assert sd.set_threads(1) == 1 and sd.get_threads() == 1
    monkeypatch.delenv("SE3DYN_THREADS")
    assert sd.set_threads() == threads.default_threads() == sd.get_threads()


def _chain(n):
    """N links of 0.1 m on spherical joints at their ends, the first on the ground."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("ground", fixed=True)
    prev = "ground"
    for i in range(n):
        mb.node(f"b{i}", position=(0.1 * i + 0.05, 0.0, 0.0), mass=1.0,
                inertia=(1e-4, 1e-3, 1e-3))
        mb.joint(f"j{i}", "spherical", prev, f"b{i}", at=(0.1 * i, 0.0, 0.0))
        prev = f"b{i}"
    return mb.build()


def test_a_long_chain_factorises_in_two_parts_alike_on_any_thread_count():
    """From 3000 unknowns on, the sparse LU orders a chain by a two-way dissection and its
    refactorisation and solves take the two halves at once (sparse_lu.hpp), as do the xi
    block's LDL^T factorisation and solves (sparse_ldlt.hpp); the numbers must not depend on
    the thread count either, and the parts must hold the chain's halves."""
    from se3dyn.dynamics.integrator import GeneralizedAlpha
    from se3dyn.engine.workspace import Workspace

    s = sd.compile_model(_chain(600))
    ws = Workspace(s)
    integ = GeneralizedAlpha(rho_inf=0.9)
    st = integ.init(s, ws=ws)
    st, _ = integ.step(s, st, 1e-3, ws=ws)
    stepper = ws.stepper(integ.index2, st.dropped, split=True)
    for part in ("lu", "xi"):  # the iteration block's LU, the xi block's LDL^T
        n, n1, n2 = stepper.lu_parts(part)
        assert 0.3 * n <= n1 and 0.3 * n <= n2 - n1 and n - n2 <= 0.02 * n, (part, n, n1, n2)
    runs = [_run(s, th, t_end=0.03, step=1e-3) for th in (1, 2, 1)]
    for ch in ("H", "v", "vd", "lam", "kinetic", "potential"):
        ref = np.asarray(getattr(runs[0], ch))
        for r in runs[1:]:
            assert np.array_equal(np.asarray(getattr(r, ch)), ref), ch
    # and they are a solution: the joints hold (Eq. (55) at every stored step)
    assert np.abs(np.asarray(runs[0].constraint)).max() < 1e-11


def test_the_command_line_takes_threads_and_gives_the_same_file(tmp_path):
    """``se3dyn run --threads N``: the same results file for 1 and 2 threads; a bad count is
    refused with the value, no traceback."""
    from se3dyn.io.h5 import read_results
    from test_cli import run

    model = tmp_path / "chain.yaml"
    lines = ["se3dyn: 1", "name: chain", "gravity: [0, 0, -9.81]", "nodes:",
             "  ground: {position: [0, 0, 0], fixed: true}"]
    lines += [f"  b{i}: {{position: [{0.1 * i + 0.05:.2f}, 0, 0], mass: 1, "
              f"inertia: [0.0001, 0.001, 0.001]}}" for i in range(70)]
    lines += ["joints:"]
    lines += [f"  j{i}: {{type: spherical, a: {'ground' if i == 0 else f'b{i - 1}'}, b: b{i}, "
              f"at: [{0.1 * i:.2f}, 0, 0]}}" for i in range(70)]
    lines += ["simulation: {t_end: 0.02, step: 0.002}"]
    model.write_text("\n".join(lines) + "\n")
    res = {}
    for th in (1, 2):
        p = run("run", model, "--out", tmp_path / f"t{th}", "--quiet", "--threads", th)
        assert p.returncode == 0, p.stderr
        res[th] = read_results(tmp_path / f"t{th}" / "chain.h5")
    for ch in ("H", "v", "lam"):
        assert np.array_equal(np.asarray(getattr(res[1], ch)), np.asarray(getattr(res[2], ch)))
    p = run("run", model, "--out", tmp_path / "bad", "--threads", "0")
    assert p.returncode != 0 and "--threads" in p.stderr and "'0'" in p.stderr


def test_sweep_workers_run_the_engine_on_one_thread():
    from se3dyn.sweep.execute import warm_up

    sd.set_threads(2)
    try:
        warm_up()
        assert sd.get_threads() == 1
    finally:
        sd.set_threads()
