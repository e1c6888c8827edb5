"""The ``se3dyn`` command, run through the installed console script (subprocess).

Facts checked: the paper's sizes and the mobility of the slider-crank (Sec. 11.1), the classic three
redundant equations of a planar four-bar modelled with spatial hinges, the results file against the
in-memory simulation, exit codes 0/1/2, results kept on failure, plots and CSV exports.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import se3dyn as sd

ROOT = Path(__file__).resolve().parents[1]
SLIDER = ROOT / "examples" / "slider_crank.yaml"

h5py = pytest.importorskip("h5py")


def _script() -> list[str]:
    exe = Path(sys.executable).parent / "se3dyn"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("se3dyn")
    if found:
        return [found]
    # not installed (running from a source tree): the same entry point through the module
    return [sys.executable, "-m", "se3dyn.cli"]


def run(*args, cwd=None, timeout=300):
    p = subprocess.run(_script() + [str(a) for a in args], capture_output=True, text=True,
                       cwd=cwd, timeout=timeout)
    assert "Traceback" not in p.stderr, p.stderr
    return p


FOUR_BAR = """\
se3dyn: 1
name: four_bar
gravity: [0, -9.81, 0]
nodes:
  A0: {position: [0, 0, 0], fixed: true}
  D0: {position: [2, 0, 0], fixed: true}
  crank: {position: [0, 0.5, 0], mass: 1, inertia: [0.1, 0.1, 0.1]}
  coupler: {position: [1, 1, 0], mass: 1, inertia: [0.1, 0.1, 0.1]}
  rocker: {position: [2, 0.5, 0], mass: 1, inertia: [0.1, 0.1, 0.1]}
  Aj: {position: [0, 0, 0]}
  Bj: {position: [0, 1, 0]}
  Bj2: {position: [0, 1, 0]}
  Cj: {position: [2, 1, 0]}
  Cj2: {position: [2, 1, 0]}
  Dj: {position: [2, 0, 0]}
joints:
  hA: {type: hinge, a: A0, b: Aj, axis: [0, 0, 1]}
  rA: {type: rigid, a: Aj, b: crank}
  rB: {type: rigid, a: crank, b: Bj}
  hB: {type: hinge, a: Bj, b: Bj2, axis: [0, 0, 1]}
  rB2: {type: rigid, a: Bj2, b: coupler}
  rC: {type: rigid, a: coupler, b: Cj}
  hC: {type: hinge, a: Cj, b: Cj2, axis: [0, 0, 1]}
  rC2: {type: rigid, a: Cj2, b: rocker}
  rD: {type: rigid, a: rocker, b: Dj}
  hD: {type: hinge, a: Dj, b: D0, axis: [0, 0, 1]}
"""


def test_check_reports_the_paper_sizes_and_one_degree_of_freedom():
    p = run("check", SLIDER)
    assert p.returncode == 0, p.stderr
    assert "unknowns 49" in p.stdout and "multipliers 48" in p.stdout
    assert "97 x 97" in p.stdout
    assert "degrees of freedom (mobility) 1" in p.stdout
    assert "no redundant constraints" in p.stdout


def test_check_counts_beams_and_their_elements(tmp_path):
    f = tmp_path / "cantilever.yaml"
    f.write_text("""se3dyn: 1
nodes:
  root: {fixed: true}
  tip: {position: [1, 0, 0]}
beams:
  rod: {a: root, b: tip, elements: 8, EA: 1.0e6, GA: 5.0e5, GJ: 50.0, EI: 80.0,
        mass_per_length: 1.0, rotary_inertia: [0.002, 0.001, 0.001]}
""")
    p = run("check", str(f))
    assert p.returncode == 0, p.stderr
    assert "beams: 1 with 8 elements in all (7 of the nodes created by them)" in p.stdout
    assert "9 nodes (8 free" in p.stdout


def test_check_names_the_three_redundant_equations_of_a_spatial_four_bar(tmp_path):
    # a planar four-bar with four spatial hinges: 3 bodies (18) - 4 x 5 hinge equations (20)
    # = -2 by Gruebler's count, yet it moves with mobility 1: 3 equations are redundant.
    f = tmp_path / "four_bar.yaml"
    f.write_text(FOUR_BAR)
    p = run("check", f)
    assert p.returncode == 0, p.stderr
    assert "degrees of freedom (mobility) 1" in p.stdout
    assert "redundant constraint equations (3)" in p.stdout
    assert p.stdout.count("rotation") >= 3  # out-of-plane rotations


@pytest.mark.parametrize("text, expect", [
    ("se3dyn: 1\nnodes:\n  a: {posiiton: [0, 0, 0]}\n", ["line 3", "posiiton", "position"]),
    ("se3dyn: 1\nnodes:\n  a: {position: [0, 0]}\n", ["line 3", "node 'a'", "position"]),
    ("nodes: {}\n", ["se3dyn"]),
    ("se3dyn: 1\nnodes:\n  a: {position: [0, 0, 0], fixed: true}\njoints:\n"
     "  j: {type: hinge, a: a, b: zz, axis: [1, 0, 0]}\n", ["joint 'j'", "zz"]),
    ("a: [1, 2\n", ["line"]),
])
def test_check_rejects_bad_files_with_exit_code_2_and_a_named_problem(tmp_path, text, expect):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    p = run("check", f)
    assert p.returncode == 2
    assert "bad.yaml" in p.stderr
    for e in expect:
        assert e in p.stderr, (e, p.stderr)


def test_usage_errors_exit_with_code_2(tmp_path):
    assert run("run").returncode == 2
    assert run("frobnicate").returncode == 2
    assert run("check", tmp_path / "missing.yaml").returncode == 2
    p = run("run", SLIDER, "--step", "-1", "--out", tmp_path)
    assert p.returncode == 2 and "step" in p.stderr
    assert run("--version").stdout.startswith("se3dyn ")


@pytest.fixture(scope="module")
def slider_results(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    p = run("run", SLIDER, "--t-end", "0.3", "--out", out)
    assert p.returncode == 0, p.stderr
    return out / "slider_crank.h5", p.stdout


def test_run_writes_the_results_of_the_simulation(slider_results):
    from se3dyn.io.h5 import read_results

    path, stdout = slider_results
    assert "results:" in stdout and "Newton iterations" in stdout
    stored = read_results(path)
    ref = sd.simulate(sd.examples.slider_crank(), t_end=0.3, step=1e-2, rho_inf=0.9)
    np.testing.assert_array_equal(stored.t, ref.t)
    for node in ("3", "6", "8"):
        np.testing.assert_allclose(stored.node_position(node), ref.node_position(node),
                                   rtol=0, atol=1e-13)
    np.testing.assert_allclose(stored.joint_coordinates("1"), ref.joint_coordinates("1"),
                               rtol=0, atol=1e-13)


def test_failed_run_exits_1_and_keeps_the_steps_computed(tmp_path):
    from se3dyn.io.h5 import read_results

    # rho_inf = 1 leaves the index-3 multipliers undamped: Newton diverges at t = 1.81 s
    # (the default stabilized index-2 formulation runs through, see test_accuracy.py)
    p = run("run", SLIDER, "--t-end", "2.5", "--rho-inf", "1", "--formulation", "index3",
            "--out", tmp_path)
    assert p.returncode == 1
    assert "Newton" in p.stderr and "t=" in p.stderr
    stored = read_results(tmp_path / "slider_crank.h5")
    assert 1.0 < stored.t[-1] < 2.5
    assert np.all(np.diff(stored.t) > 0)


def test_plot_writes_a_png_and_rejects_unknown_channels(slider_results, tmp_path):
    path, _ = slider_results
    png = tmp_path / "fig.png"
    p = run("plot", path, "node/6/position/x", "node/6/position/z", "-o", png)
    assert p.returncode == 0, p.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    p = run("plot", path, "node/6/positon/x", "-o", png)
    assert p.returncode == 2 and "node/6/position/x" in p.stderr


def test_export_writes_named_columns_equal_to_the_channels(slider_results, tmp_path):
    from se3dyn.io.h5 import read_results
    from se3dyn.results.channels import get_channel

    path, _ = slider_results
    csv = tmp_path / "out.csv"
    p = run("export", path, "--csv", csv, "node/6/position/x", "joint/1/alpha/0")
    assert p.returncode == 0, p.stderr
    header = csv.read_text().splitlines()[0]
    assert header == "time [s],node/6/position/x [m],joint/1/alpha/0 [rad]"
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    res = read_results(path)
    np.testing.assert_array_equal(data[:, 0], res.t)
    np.testing.assert_array_equal(data[:, 1], get_channel(res, "node/6/position/x"))
    np.testing.assert_array_equal(data[:, 2], res.joint_coordinates("1")[:, 0])


def test_channel_patterns_expand_to_the_matching_channels(slider_results, tmp_path):
    path, _ = slider_results
    csv = tmp_path / "xyz.csv"
    p = run("export", path, "--csv", csv, "node/6/displacement/[xyz]")
    assert p.returncode == 0, p.stderr
    header = csv.read_text().splitlines()[0].split(",")
    assert header == ["time [s]"] + [f"node/6/displacement/{c} [m]" for c in "xyz"]
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(data[0, 1:], 0.0)  # displacement from the initial position
    assert run("plot", path, "node/6/nothing*", "-o", tmp_path / "x.png").returncode == 2


def test_every_malformed_file_of_the_corpus_is_rejected_by_the_command(tmp_path):
    # the hand-written corpus of tests/test_modelfile.py, through the real command at once
    from test_modelfile import CASES

    files = []
    for cid, text, line, _ in CASES:
        f = tmp_path / f"{cid}.yaml"
        f.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
        files.append((f, line))
    p = run("check", *[f for f, _ in files], timeout=600)
    assert p.returncode == 2
    errors = [ln for ln in p.stderr.splitlines() if ln.startswith("se3dyn: error: ")]
    assert len(errors) == len(files), p.stderr
    for f, line in files:
        mine = [e for e in errors if f"{f}," in e or f"{f}:" in e]
        assert len(mine) == 1, (f.name, p.stderr)
        if line is not None:
            assert f"line {line}:" in mine[0], mine[0]
    assert f"{len(files)} of {len(files)} model files are invalid" in p.stderr


def test_a_run_imports_no_module_it_does_not_use(tmp_path):
    # the `run` path of the command (as the console script calls it): scipy, matplotlib and the
    # opt-in layers stay out, the package's lazy names still resolve afterwards, and the
    # garbage collector, paused while the command loads, runs again
    code = ("import gc, sys; sys.argv[0] = 'se3dyn'; from se3dyn.cli.commands import main; "
            "print(gc.isenabled()); "
            f"assert main(['run', {str(SLIDER)!r}, '--out', {str(tmp_path)!r}, '--quiet']) == 0; "
            "bad = ('scipy', 'matplotlib', 'dask', 'se3dyn.viewer', 'se3dyn.sweep', "
            "'se3dyn.analysis.statics'); "
            "print(sorted(m for m in sys.modules if m.startswith(bad))); "
            "import se3dyn; print(se3dyn.static_equilibrium.__name__, se3dyn.kinematics.__name__,"
            " gc.isenabled())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip().splitlines()
    assert out[0] == "False" and out[-2:] == ["[]", "static_equilibrium kinematics True"]


@pytest.mark.parametrize("argv, preset, expect", [
    (["se3dyn", "run"], None, "4 frozen"), (["se3dyn", "run"], "12", "12 frozen"),
    (["se3dyn", "sweep"], None, "4 not frozen"), (["python"], None, "None not frozen")])
def test_the_command_lets_idle_blas_threads_sleep_and_skips_the_exit_collections(argv, preset,
                                                                                 expect):
    # the se3dyn command only: OPENBLAS_THREAD_TIMEOUT=4 unless set, and every object frozen
    # at exit (gc.freeze in the last atexit handler), except for sweep
    import os

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_THREAD_TIMEOUT"}
    if preset is not None:
        env["OPENBLAS_THREAD_TIMEOUT"] = preset
    code = ("import atexit, gc, os, sys; atexit.register(lambda: print("
            "'frozen' if gc.get_freeze_count() else 'not frozen')); "
            f"sys.argv = {argv!r}; import se3dyn.cli; "
            "print(os.environ.get('OPENBLAS_THREAD_TIMEOUT'), end=' ')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=env).stdout.strip()
    assert out == expect


def test_a_reader_that_goes_away_stops_the_command_quietly():
    # `se3dyn types | head -0`: the command's stdout is a pipe whose reader has closed; it
    # stops with 141 (128 + SIGPIPE), as command-line tools do, with no traceback
    import os

    r, w = os.pipe()
    os.close(r)
    try:
        p = subprocess.run([sys.executable, "-m", "se3dyn.cli", "types"], stdout=w,
                           stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(w)
    assert p.returncode == 141, p.stderr
    assert "Traceback" not in p.stderr and p.stderr == "", p.stderr
