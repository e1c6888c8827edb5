"""Same inputs, same numbers: runs above every parallel threshold of the engine, repeated.

The engine's parallel paths switch on at sizes (se3dyn/_core/engine.hpp: 64 elements of a
type for the coloured element chunks, 256 frames for the frame updates, 2^16 matrix values
for the zeroing; sparse_lu.hpp / sparse_ldlt.hpp: 3000 unknowns for the two-way dissection
whose parts refactor, factor and solve at once). Issue 28 found a race at the largest of these
(the LDL^T solve's second part cleared the separator while the first still read it): two-thread
runs of the 1000-link chain differed from each other and from one thread, more often with the
machine busy, while tests/test_threads.py (600 links, each case once) passed. So here:

* the 1000-link spherical chain (9000 unknowns, 6000 multipliers: every threshold passed),
  a 1000-element beam and the 10^4-link chain (once, a few steps);
* each run several times on 2 threads and on 1 thread in one process, with another process
  keeping the second core busy (the race needs the two parts to overlap in time);
* and in separate fresh processes;
* compared to the last bit: positions, velocities, accelerations, multipliers, energies and
  the solver statistics (Newton iterations, the largest constraint residual).

The C++ side is checked by ThreadSanitizer builds of the drivers (tests/test_cpp_drivers.py).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import se3dyn as sd
from test_threads import _beam as beam  # a 1 m cantilever of n elements with a tip mass

CHANNELS = ("H", "v", "vd", "lam", "kinetic", "potential", "spring", "dissipation")
STATS = ("newton_iterations", "max_constraint", "steps")


def chain(n: int) -> sd.Model:
    """n links of 0.1 m (1 kg) on spherical joints at their ends (``at=``), the first on the
    ground, under gravity: benchmarks/chain_scaling.py's chain."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("ground", fixed=True)
    J = 1.0 * 0.1**2 / 12.0
    prev = "ground"
    for i in range(n):
        mb.node(f"b{i}", position=(0.1 * i + 0.05, 0.0, 0.0), mass=1.0, inertia=(1e-4 * J, J, J))
        mb.joint(f"s{i}", "spherical", prev, f"b{i}", at=(0.1 * i, 0.0, 0.0))
        prev = f"b{i}"
    return mb.build()


MODELS = {"chain1000": (lambda: chain(1000), 0.1, 1e-3),
          "beam1000": (lambda: beam(1000), 0.03, 1e-3),
          "chain10000": (lambda: chain(10000), 0.004, 1e-3)}


def digest(r) -> dict:
    """A fingerprint of a run: SHA-256 of each channel's bytes and the statistics."""
    out = {ch: hashlib.sha256(np.ascontiguousarray(getattr(r, ch)).tobytes()).hexdigest()
           for ch in CHANNELS}
    out.update({k: r.stats[k] for k in STATS})
    return out


def run(system, threads: int, t_end: float, step: float) -> dict:
    sd.set_threads(threads)
    try:
        return digest(sd.simulate(system, t_end=t_end, step=step))
    finally:
        sd.set_threads()


@pytest.fixture
def busy_core():
    """Another process spinning on a core for the duration of the test."""
    p = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        p.kill()
        p.wait()


def _repeat(name: str, sequence) -> list[dict]:
    make, t_end, step = MODELS[name]
    system = sd.compile_model(make())
    return [run(system, th, t_end, step) for th in sequence]


def _all_equal(runs, sequence, name):
    for th, d in zip(sequence, runs, strict=True):
        diff = {k: (d[k], runs[0][k]) for k in d if d[k] != runs[0][k]}
        assert not diff, f"{name}: a run on {th} thread(s) differs from the first: {diff}"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["chain1000", "beam1000"])
def test_repeated_runs_on_one_and_two_threads_agree_to_the_last_bit(name, busy_core):
    """6 runs on 2 threads and 6 on 1, alternated, with the other core busy."""
    sequence = (2, 1) * 6
    _all_equal(_repeat(name, sequence), sequence, name)


@pytest.mark.slow
def test_the_ten_thousand_link_chain_agrees_on_one_and_two_threads(busy_core):
    sequence = (2, 1, 2)
    _all_equal(_repeat("chain10000", sequence), sequence, "chain10000")


CHILD = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, {tests!r})
    import se3dyn as sd
    from test_determinism import MODELS, run
    make, t_end, step = MODELS[sys.argv[1]]
    print(json.dumps(run(sd.compile_model(make()), int(sys.argv[2]), t_end, step)))
""")


@pytest.mark.slow
def test_fresh_processes_agree_with_each_other_and_with_this_one(busy_core):
    """Two fresh processes on 2 threads and one on 1 give this process's numbers."""
    here = run(sd.compile_model(chain(1000)), 2, *MODELS["chain1000"][1:])
    code = CHILD.format(tests=str(Path(__file__).parent))
    env = {**os.environ, "SE3DYN_THREADS": ""}
    for th in (2, 2, 1):
        p = subprocess.run([sys.executable, "-c", code, "chain1000", str(th)], env=env,
                           capture_output=True, text=True, timeout=600, check=False)
        assert p.returncode == 0, p.stderr
        assert json.loads(p.stdout.strip().splitlines()[-1]) == here, th


GALLERY = sorted(p.name for p in (Path(__file__).parents[1] / "examples").glob("*.yaml"))


@pytest.mark.parametrize("name", GALLERY)
def test_the_gallery_models_agree_on_one_two_and_three_threads(name):
    """Every model file of examples/ at its own settings (stepping, tolerances), 50 steps,
    on 2, 1, 3 and 2 threads: the same numbers to the last bit."""
    from se3dyn.io.modelfile import load_model

    model, settings = load_model(Path(__file__).parents[1] / "examples" / name)
    settings = dict(settings)
    settings["t_end"] = 50 * settings["step"]
    system = sd.compile_model(model)
    runs = []
    for th in (2, 1, 3, 2):
        sd.set_threads(th)
        try:
            runs.append(digest(sd.simulate(system, **settings)))
        finally:
            sd.set_threads()
    _all_equal(runs, (2, 1, 3, 2), name)
