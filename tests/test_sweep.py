"""Parameter sweeps on dask.distributed (se3dyn.sweep, ``se3dyn sweep``).

Facts checked on a two-worker LocalCluster on loopback, with a small pendulum (hinge, massless
link, point mass on a ball joint): a damper dampens (the final energy falls and the dissipated
energy grows with the damping, their sum is the initial energy); a pendulum's swing does not
depend on its mass while the joint force grows in proportion to it (LHS sampling); every run's
results file holds the run's own model file with the varied value; failing variants fail alone
with a one-line message; a worker killed mid-sweep leaves a complete summary without duplicate
rows; a resumed sweep runs only the missing runs. Bad input is one line and exit code 2.
"""

from __future__ import annotations

import json
import logging
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import se3dyn

distributed = pytest.importorskip("distributed")
h5py = pytest.importorskip("h5py")

from se3dyn.cli.commands import main as cli_main  # noqa: E402
from se3dyn.io.h5 import read_results  # noqa: E402
from se3dyn.io.modelfile import parse_model_data  # noqa: E402
from se3dyn.sweep import SweepSpecError, parse_metric, parse_spec, plan_runs  # noqa: E402
from se3dyn.sweep.spec import Variable, check_path, get_path, set_path  # noqa: E402
from se3dyn.sweep.table import read_summary_csv  # noqa: E402

PENDULUM = """\
se3dyn: 1
name: pendulum
gravity: [0.0, 0.0, -9.81]
nodes:
  ground: {position: [0.0, 0.0, 0.0], fixed: true}
  pivot: {position: [0.0, 0.0, 0.0]}
  tip: {position: [0.5, 0.0, 0.0]}
  bob: {position: [0.5, 0.0, 0.0], mass: 1.0, inertia: [1.0e-3, 1.0e-3, 1.0e-3]}
joints:
  hinge: {type: hinge, a: ground, b: pivot, axis: [0.0, 1.0, 0.0], damping: 0.0}
  link: {type: rigid, a: pivot, b: tip}
  ball: {type: spherical, a: tip, b: bob}   # point mass: its rotation never enters
simulation: {t_end: 2.0, step: 0.01, rho_inf: 0.9}
"""


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("model") / "pendulum.yaml"
    p.write_text(PENDULUM, encoding="utf-8")
    return p


@pytest.fixture(scope="module")
def client():
    """Two single-threaded worker processes on loopback, shared by the tests of this file."""
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       host="127.0.0.1", dashboard_address=":0",
                                       silence_logs=logging.ERROR)
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def _rows(out: Path) -> list[dict]:
    return read_summary_csv(out / "summary.csv")


def _journal_len(out: Path) -> int:
    j = out / "journal.jsonl"
    return len(j.read_text().splitlines()) if j.is_file() else 0


# ---------------------------------------------------------------------------------------------
# specs, paths, plans, metrics (no cluster)
def test_value_specs_parse_without_evaluation():
    assert parse_spec("0.1,0.2,5e-1").values == (0.1, 0.2, 0.5)
    assert parse_spec("index2,index3").values == ("index2", "index3")
    assert parse_spec("true,false").values == (True, False)
    assert parse_spec("0:1:5").values == (0.0, 0.25, 0.5, 0.75, 1.0)
    assert parse_spec("1:5:5").values == (1, 2, 3, 4, 5)  # integer ends, integer steps
    assert parse_spec("2:2:1").values == (2,)
    u = parse_spec("uniform(-1, 2.5)")
    assert (u.kind, u.params) == ("uniform", (-1.0, 2.5))
    assert parse_spec("normal(1e-3,2e-4)").params == (1e-3, 2e-4)
    for bad in ("", "1,,2", "1:2", "0:1:0", "uniform(2,1)", "normal(0,-1)", "loguniform(0,1)",
                "__import__('os').system('x')", "exp(1)", "1;2", "nan,1"):
        with pytest.raises(SweepSpecError) as e:
            parse_spec(bad, "--vary x")
        assert "\n" not in str(e.value) and "expected" in str(e.value)


def test_paths_address_model_file_fields_by_names_and_indices():
    data = parse_model_data(PENDULUM)
    assert check_path(data, "joints.hinge.damping") == 0.0
    assert check_path(data, "nodes.bob.position.0") == 0.5
    assert check_path(data, "simulation.step") == 0.01
    assert check_path(data, "joints.hinge.stiffness") is None  # a format field left out
    set_path(data, "joints.hinge.stiffness", 3.0)
    set_path(data, "nodes.bob.position.2", -0.1)
    assert get_path(data, "joints.hinge.stiffness") == 3.0
    assert data["nodes"]["bob"]["position"] == [0.5, 0.0, -0.1]
    # an absent section is created; names with dots match as a whole
    d2 = {"se3dyn": 1, "nodes": {"a.b": {"mass": 1.0}}}
    set_path(d2, "simulation.step", 0.1)
    assert d2["simulation"] == {"step": 0.1}
    assert check_path(d2, "nodes.a.b.mass") == 1.0
    cases = {
        "joints.9.damping": "hinge, link, ball",
        "joints.hinge.dampng": "did you mean 'damping'?",
        "nodes.bob.position.3": "an index 0..2",
        "nodes.bob.mass.x": "no more keys after 'nodes.bob.mass'",
        "simulation.tl": "t_end, step, rho_inf",
        "joints.hinge.torque.value": "vary 'joints.hinge.torque' as a whole",
        "nodes.bob": "a value, not a mapping",
        "nodes..mass": "keys and indices joined by dots",
    }
    for path, text in cases.items():
        with pytest.raises(SweepSpecError) as e:
            check_path(data, path)
        assert text in str(e.value), (path, str(e.value))
        assert "\n" not in str(e.value)


def test_grid_random_and_lhs_plans():
    v = [Variable.parse("a=1,2,3"), Variable.parse("b=0:1:2")]
    grid = plan_runs(v)
    assert grid == [{"a": a, "b": b} for a in (1, 2, 3) for b in (0.0, 1.0)]  # first slowest
    r = [Variable.parse("m=uniform(0.5,2)"), Variable.parse("c=0.1,0.2"),
         Variable.parse("k=loguniform(1,100)"), Variable.parse("x=normal(3,0.1)")]
    a, b = plan_runs(r, "random", 200, seed=7), plan_runs(r, "random", 200, seed=7)
    assert a == b and a != plan_runs(r, "random", 200, seed=8)
    m = np.array([p["m"] for p in a])
    k = np.array([p["k"] for p in a])
    x = np.array([p["x"] for p in a])
    assert m.min() >= 0.5 and m.max() <= 2.0 and {p["c"] for p in a} == {0.1, 0.2}
    assert k.min() >= 1 and k.max() <= 100 and abs(np.median(np.log10(k)) - 1) < 0.2
    assert abs(x.mean() - 3) < 0.03 and abs(x.std() - 0.1) < 0.02
    # Latin hypercube: each of the N equal strata of every variable holds exactly one point
    n = 16
    lhs = plan_runs([Variable.parse("m=uniform(0.5,2)"), Variable.parse("q=uniform(0,1)")],
                    "lhs", n, seed=1)
    for key, lo, hi in (("m", 0.5, 2.0), ("q", 0.0, 1.0)):
        strata = sorted(int((p[key] - lo) / (hi - lo) * n) for p in lhs)
        assert strata == list(range(n))
    for args, text in (((v, "grid", 3), "no --samples with --method grid"),
                       ((r, "grid"), "distributions need --method random or lhs"),
                       ((r, "lhs", None), "a positive number of runs"),
                       ((r, "sobol", 3), "one of grid, random, lhs"),
                       ((v + v[:1], "grid"), "each path once")):
        with pytest.raises(SweepSpecError) as e:
            plan_runs(*args)
        assert text in str(e.value)


def test_metrics_parse_and_time_averages():
    m = parse_metric("peak=max(abs(joint/1/multiplier/3))")
    assert (m.name, m.func, m.channel, m.absolute) == ("peak", "max", "joint/1/multiplier/3",
                                                       True)
    assert parse_metric("final(energy/total)", name="e").text == "e=final(energy/total)"
    for bad, text in (("peak=max(abs(x)", "optionally inside abs(...)"),
                      ("peak max(x)", "NAME=FUNC(CHANNEL)"),
                      ("p=peak(time)", "one of max, min, final, mean, rms"),
                      ("p=max(__import__('os'))", "a channel name"),
                      ("p=max(time + 1)", "a channel name"),
                      ("status=max(time)", "not a summary column")):
        with pytest.raises(SweepSpecError) as e:
            parse_metric(bad)
        assert text in str(e.value), str(e.value)
    # time averages (trapezoidal in time) over an uneven grid: mean and rms of f(t) = t
    from se3dyn.sweep.metrics import _empty_results

    mb = se3dyn.ModelBuilder()
    mb.node("a", mass=1.0, inertia=(1, 1, 1))
    res = _empty_results(se3dyn.compile_model(mb.build()))
    res.t = np.sort(np.concatenate([[0.0, 2.0], np.random.default_rng(0).uniform(0, 2, 4000)]))
    assert parse_metric("a=mean(time)").evaluate(res) == pytest.approx(1.0, rel=1e-12)
    assert parse_metric("a=rms(time)").evaluate(res) == pytest.approx(2 / math.sqrt(3),
                                                                        rel=1e-5)
    assert parse_metric("a=final(time)").evaluate(res) == 2.0


def test_worker_model_cache_serves_simulation_only_variants():
    """Runs that differ only in simulation settings reuse the worker's compiled model; their
    settings are still validated by the model-file rules."""
    from collections import OrderedDict

    from se3dyn.sweep.execute import RunContext, execute_run
    from se3dyn.sweep.metrics import parse_metric

    ctx = RunContext(data=parse_model_data(PENDULUM), metrics=[parse_metric("e=final(time)")])
    cache: OrderedDict = OrderedDict()
    rows = [execute_run(ctx, i, {"joints.hinge.damping": 0.1, "simulation.step": h,
                                 "simulation.t_end": 0.2}, cache)
            for i, h in enumerate((0.01, 0.005, -0.01))]
    assert len(cache) == 1
    assert [r["status"] for r in rows] == ["ok", "ok", "failed"]
    assert [r["steps"] for r in rows[:2]] == [20, 40] and rows[1]["e"] == 0.2
    assert "simulation: field 'step': expected a finite number > 0, got -0.01" in \
        rows[2]["message"]
    other = execute_run(ctx, 3, {"joints.hinge.damping": -1.0, "simulation.step": 0.01}, cache)
    assert other["status"] == "failed" and "field 'damping'" in other["message"]


def test_core_never_imports_the_sweep_layer_and_se3dyn_sweep_is_callable():
    code = ("import sys, se3dyn, se3dyn.cli.commands, se3dyn.io.h5; "
            "print(any(m.startswith(('se3dyn.sweep', 'distributed', 'dask')) "
            "for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"
    code = ("import sys; from se3dyn.cli.commands import build_parser; build_parser(); "
            "print(sorted(m for m in sys.modules "
            "if m.startswith(('se3dyn.sweep', 'distributed'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "['se3dyn.sweep', 'se3dyn.sweep.cli']"  # options only, no machinery
    import se3dyn.sweep as mod  # the package import keeps the function callable

    assert callable(se3dyn.sweep) and se3dyn.sweep is mod
    assert mod.run_sweep.__doc__ and "summary table" in mod.run_sweep.__doc__


# ---------------------------------------------------------------------------------------------
# sweeps on the two-worker cluster
def test_grid_sweep_damper_dampens_and_files_hold_each_runs_model(client, pendulum, tmp_path):
    out = tmp_path / "grid"
    damping = (0.0, 0.05, 0.2)
    table = se3dyn.sweep(pendulum, {"joints.hinge.damping": "0,0.05,0.2",
                                    "simulation.step": "0.01,0.005"},
                         metrics=["e_end=final(energy/total)", "diss=final(energy/dissipation)",
                                  "w=rms(joint/hinge/velocity/0)"],
                         out=out, client=client, as_frame=False)
    assert [r["run"] for r in table] == list(range(6))
    assert all(r["status"] == "ok" and r["message"] == "" for r in table), \
        [r["message"] for r in table]
    for h in (0.01, 0.005):
        rows = [r for r in table if r["simulation.step"] == h]
        assert [r["joints.hinge.damping"] for r in rows] == list(damping)
        e = [r["e_end"] for r in rows]
        d = [r["diss"] for r in rows]
        w = [r["w"] for r in rows]
        assert e[0] > e[1] > e[2] and d[0] < d[1] < d[2] and w[0] > w[1] > w[2]
        assert d[0] == 0.0 and d[2] > 1.0
        # energy balance: E(T) + dissipated = E(0) = 0 up to the scheme's O(h^2) error
        assert all(abs(ei + di) < 0.02 for ei, di in zip(e, d, strict=True))
        assert all(r["steps"] == round(2.0 / h) for r in rows)
        assert all(r["newton_iterations"] >= r["steps"] for r in rows)
    # each results file is complete and holds its run's own model file and settings
    for r in table:
        res = read_results(out / r["results"])
        assert res.stats["complete"] and not res.stats.get("failed", False)
        data = parse_model_data(res.stats["model"])
        assert get_path(data, "joints.hinge.damping") == r["joints.hinge.damping"]
        assert res.stats["settings"]["step"] == r["simulation.step"]
        assert len(res.t) == r["steps"] + 1
        assert np.sqrt(np.mean(res.joint_velocities("hinge")[:, 0] ** 2)) == \
            pytest.approx(r["w"], rel=0.05)
    # the summary on disk is the returned table, one row per run
    disk = _rows(out)
    assert [r["run"] for r in disk] == list(range(6))
    assert [r["e_end"] for r in disk] == [r["e_end"] for r in table]
    assert json.loads((out / "sweep.json").read_text())["runs"] == 6
    assert not list((out / "runs").glob(".*"))
    try:
        import pyarrow.parquet as pq
    except ImportError:
        assert not (out / "summary.parquet").exists()
    else:
        assert pq.read_table(out / "summary.parquet").column("e_end").to_pylist() == \
            [r["e_end"] for r in table]


def test_lhs_sweep_swing_independent_of_mass_joint_force_proportional(client, pendulum,
                                                                      tmp_path):
    n = 6
    table = se3dyn.sweep(pendulum, ["nodes.bob.mass=uniform(0.5,2.0)"], method="lhs",
                         samples=n, seed=3,
                         metrics={"angle": "final(joint/hinge/alpha/0)",
                                  "highest": "max(joint/hinge/alpha/0)",
                                  "force": "max(abs(joint/ball/multiplier/0))"},
                         overrides={"t_end": 1.0, "rho_inf": 1.0}, out=tmp_path / "lhs",
                         h5="client", client=client, as_frame=False)
    assert all(r["status"] == "ok" for r in table), table
    m = np.array([r["nodes.bob.mass"] for r in table])
    assert sorted(int((mi - 0.5) / 1.5 * n) for mi in m) == list(range(n))  # stratified
    for key in ("angle", "highest"):  # Galileo: the swing does not depend on the mass
        x = np.array([r[key] for r in table])
        assert x.min() > 0.5 and np.ptp(x) < 1e-8 * x.max()
    f = np.array([r["force"] for r in table])
    assert f.min() > 1.0 and np.ptp(f / m) < 1e-8 * (f / m).max()  # force = m (...)
    # results files sent back to the client and written by it
    for r in table:
        res = read_results(tmp_path / "lhs" / r["results"])
        assert parse_model_data(res.stats["model"])["nodes"]["bob"]["mass"] == r["nodes.bob.mass"]
        assert res.stats["settings"]["t_end"] == 1.0


def test_random_sweep_without_files_returns_the_table(client, pendulum):
    table = se3dyn.sweep(pendulum, {"joints.hinge.damping": "uniform(0,0.3)",
                                    "simulation.formulation": "index2,index3"},
                         method="random", samples=5, seed=11, metrics=["e=final(energy/total)"],
                         overrides={"t_end": 0.5}, client=client, as_frame=False)
    assert len(table) == 5 and all(r["status"] == "ok" and r["results"] == "" for r in table)
    plan = plan_runs([Variable.parse("joints.hinge.damping=uniform(0,0.3)"),
                      Variable.parse("simulation.formulation=index2,index3")], "random", 5, 11)
    assert [{k: r[k] for k in plan[0]} for r in table] == plan


def test_failing_variants_fail_alone_cli_with_own_cluster(pendulum, tmp_path, capsys, client):
    out = tmp_path / "fail"
    rc = cli_main(["sweep", str(pendulum), "--vary", "joints.hinge.damping=0.1,-1",
                   "--vary", "simulation.step=0.01,0.5", "--metric", "e=final(energy/total)",
                   "--t-end", "1.5", "--workers", "2", "--quiet", "--out", str(out)])
    cap = capsys.readouterr()
    assert rc == 1, cap
    assert "Traceback" not in cap.err and "3 of 4 runs failed" in cap.err
    rows = {(r["joints.hinge.damping"], r["simulation.step"]): r for r in _rows(out)}
    assert len(rows) == 4
    good = rows[(0.1, 0.01)]
    assert good["status"] == "ok" and good["steps"] == 150 and good["e"] < 0
    diverged = rows[(0.1, 0.5)]
    assert diverged["status"] == "failed" and "Newton" in diverged["message"]
    assert math.isnan(diverged["e"])
    res = read_results(out / diverged["results"])  # the steps computed so far are kept
    assert res.stats["complete"] and res.stats["failed"]
    for h in (0.01, 0.5):
        bad = rows[(-1, h)]
        assert bad["status"] == "failed" and bad["results"] is None
        assert "joint 'hinge': field 'damping': expected a finite number >= 0, got -1" in \
            bad["message"]
    assert all("\n" not in (r["message"] or "") for r in rows.values())
    # failed runs count as finished for --resume; --retry-failed runs them (and only them) again
    lines: list[str] = []
    kw = dict(metrics=["e=final(energy/total)"], overrides={"t_end": 1.5}, out=out, resume=True,
              client=client, as_frame=False, log=lines.append)
    vary = ["joints.hinge.damping=0.1,-1", "simulation.step=0.01,0.5"]
    se3dyn.sweep(pendulum, vary, **kw)
    assert "  4 of 4 runs already done; 0 to run" in lines
    again = se3dyn.sweep(pendulum, vary, retry_failed=True, **kw)
    assert "  1 of 4 runs already done; 3 to run" in lines
    assert [r["status"] for r in again] == ["ok", "failed", "failed", "failed"]
    assert again[0]["wall_time"] == pytest.approx(good["wall_time"], rel=1e-12)


def test_worker_killed_mid_sweep_summary_complete_without_duplicates(client, pendulum,
                                                                     tmp_path):
    out = tmp_path / "kill"
    n = 10
    pids = client.run(os.getpid)
    result: dict = {}

    def go():
        try:
            result["table"] = se3dyn.sweep(
                pendulum, {"joints.hinge.damping": f"0:0.2:{n}"},
                metrics=["e=final(energy/total)"], overrides={"t_end": 4.0, "step": 1e-3},
                out=out, client=client, as_frame=False)
        except BaseException as exc:  # noqa: BLE001 - reported by the assertion below
            result["error"] = exc

    th = threading.Thread(target=go)
    th.start()
    deadline = time.monotonic() + 120
    while _journal_len(out) < 1 and th.is_alive() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert th.is_alive(), "the sweep ended before a worker could be killed"
    victim = sorted(pids.values())[0]
    os.kill(victim, signal.SIGKILL)  # mid-sweep: it is running a run right now
    th.join(timeout=300)
    assert "error" not in result, result.get("error")
    table = result["table"]
    assert [r["run"] for r in table] == list(range(n))
    assert all(r["status"] == "ok" for r in table), [r["message"] for r in table]
    disk = _rows(out)
    assert [r["run"] for r in disk] == list(range(n))  # no duplicate, none missing
    files = sorted(p.name for p in (out / "runs").iterdir())
    assert files == [f"{i:04d}.h5" for i in range(n)]  # no half-written file left
    for r in table:
        res = read_results(out / r["results"])
        assert res.stats["complete"] and len(res.t) == 4001
    client.wait_for_workers(2, timeout=120)  # the nanny restarted the killed worker


def test_resume_after_interrupted_sweep_runs_only_missing(client, pendulum, tmp_path):
    out = tmp_path / "resume"
    n = 8
    args = ["sweep", str(pendulum), "--vary", f"joints.hinge.damping=0:0.1:{n}",
            "--metric", "e=final(energy/total)", "--t-end", "4", "--step", "1e-3",
            "--scheduler", client.scheduler.address, "--quiet", "--out", str(out)]
    p = subprocess.Popen([sys.executable, "-m", "se3dyn.cli", *args], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while _journal_len(out) < 2 and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert p.poll() is None, p.communicate()
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, (stdout, stderr)
    assert "Traceback" not in stderr and "--resume" in stderr
    first = _rows(out)
    done = [r["run"] for r in first]
    assert 2 <= len(done) < n and len(set(done)) == len(done)
    stamp = {r["run"]: (out / r["results"]).stat().st_mtime_ns for r in first}
    lines: list[str] = []
    table = se3dyn.sweep(pendulum, [f"joints.hinge.damping=0:0.1:{n}"],
                         metrics=["e=final(energy/total)"],
                         overrides={"t_end": 4.0, "step": 1e-3}, out=out, resume=True,
                         client=client, as_frame=False, log=lines.append)
    assert f"  {len(done)} of {n} runs already done; {n - len(done)} to run" in lines
    assert [r["run"] for r in table] == list(range(n))
    assert all(r["status"] == "ok" for r in table)
    for r in first:  # finished runs were not run again: same row, same file
        assert table[r["run"]]["worker"] == r["worker"]
        assert table[r["run"]]["wall_time"] == pytest.approx(r["wall_time"], rel=1e-12)
        assert (out / r["results"]).stat().st_mtime_ns == stamp[r["run"]]
    assert [r["run"] for r in _rows(out)] == list(range(n))
    e = [r["e"] for r in table]
    assert all(a > b for a, b in zip(e, e[1:], strict=False))  # more damping, less energy
    # a finished sweep resumed again runs nothing; a different sweep in DIR is refused
    lines.clear()
    se3dyn.sweep(pendulum, [f"joints.hinge.damping=0:0.1:{n}"], metrics=["e=final(energy/total)"],
                 overrides={"t_end": 4.0, "step": 1e-3}, out=out, resume=True, client=client,
                 log=lines.append)
    assert f"  {n} of {n} runs already done; 0 to run" in lines
    with pytest.raises(SweepSpecError, match="the same vary as the stored sweep"):
        se3dyn.sweep(pendulum, ["joints.hinge.damping=0,1"], out=out, resume=True,
                     overrides={"t_end": 4.0, "step": 1e-3}, client=client)
    with pytest.raises(SweepSpecError, match="the model file and run-time overrides of the "):
        se3dyn.sweep(pendulum, [f"joints.hinge.damping=0:0.1:{n}"], out=out, resume=True,
                     metrics=["e=final(energy/total)"], client=client)


# ---------------------------------------------------------------------------------------------
# bad input: one line, exit code 2, before any run
@pytest.mark.parametrize("extra, text", [
    (["--vary", "joints.hinge.dampin=1,2"], "expected a key under 'joints.hinge': type, a, b"),
    (["--vary", "joints.9.damping=1,2"], "expected a key under 'joints': hinge, link, ball, "
                                         "got '9'"),
    (["--vary", "joints.hinge.damping=1:2"], "expected a list V1,V2,..., a range"),
    (["--vary", "joints.hinge.damping"], "a path and a value spec joined by '='"),
    (["--vary", "joints.hinge.damping=uniform(0,1)"], "distributions need --method random"),
    (["--vary", "joints.hinge.damping=1,2", "--metric", "p=peak(time)"], "one of max, min"),
    (["--vary", "joints.hinge.damping=1,2", "--metric", "p=max(joint/hinge/alpha/4)"],
     "did you mean 'joint/hinge/alpha/0'"),
    (["--vary", "joints.hinge.damping=1,2", "--metric", "p=max(eval(1))"], "a channel name"),
    (["--vary", "joints.hinge.damping=1,2", "--samples", "4"], "no --samples with --method"),
    (["--vary", "joints.hinge.damping=uniform(0,1)", "--method", "lhs"],
     "a positive number of runs for --method lhs"),
    (["--vary", "joints.hinge.damping=1,2", "--samples", "0"], "expected a positive integer"),
    (["--vary", "joints.hinge.damping=1,2", "--h5", "nfs"], "invalid choice"),
])
def test_bad_input_is_one_line_exit_2(pendulum, tmp_path, capsys, extra, text):
    rc = _cli(["sweep", str(pendulum), *extra, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2
    assert text in err, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("se3dyn: error:")]
    assert len(lines) == 1
    assert not (tmp_path / "o").exists()  # nothing started, nothing written


def test_bad_model_and_existing_sweep_folder(pendulum, tmp_path, capsys):
    assert _cli(["sweep", str(tmp_path / "none.yaml"), "--vary", "a=1", "--out",
                     str(tmp_path / "o")]) == 2
    assert "expected an existing model file" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text(PENDULUM.replace("damping: 0.0", "damping: -1"))
    assert _cli(["sweep", str(bad), "--vary", "joints.hinge.damping=1", "--out",
                     str(tmp_path / "o")]) == 2
    assert "line 10: joint 'hinge': field 'damping'" in capsys.readouterr().err
    nostep = tmp_path / "nostep.yaml"
    nostep.write_text(PENDULUM.replace("step: 0.01, ", ""))
    assert _cli(["sweep", str(nostep), "--vary", "joints.hinge.damping=1", "--out",
                     str(tmp_path / "o")]) == 2
    assert "simulation.step" in capsys.readouterr().err
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "sweep.json").write_text("{}")
    assert _cli(["sweep", str(pendulum), "--vary", "joints.hinge.damping=1", "--out",
                 str(tmp_path / "old")]) == 2
    assert "give --resume" in capsys.readouterr().err


def _cli(argv: list[str]) -> int:
    """Exit code of ``se3dyn ARGV`` in this process (argparse errors raise SystemExit)."""
    try:
        return cli_main(argv)
    except SystemExit as exc:
        return int(exc.code)
