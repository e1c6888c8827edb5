"""Scaling of ``se3dyn sweep``: 32 slider-crank runs on 2 dask workers against 1, and the cost
per run against calling ``simulate`` directly in one process.

    python benchmarks/sweep_scaling.py [--runs 32] [--repeat 3] [--out benchmarks/results]

The 32 runs vary the damping of the cylindrical joint (8) of ``examples/slider_crank.yaml``
(0.5 .. 4 N s/m; 5 s, h = 1e-2, the file's settings) with one metric. Measured (best of
``--repeat`` interleaved rounds, wall time;
every measure sees the same load of a shared machine):

* ``direct``: one process, for each variant: its model from the model-file data
  (``loads_model(format_model_data(data))``) and ``simulate`` (the fully compiled loop);
  ``direct_files`` also writes each run's HDF5 file as the sweep does; ``simulate_only``
  simulates prebuilt models (no model building);
* ``sweep_1`` / ``sweep_2``: ``se3dyn.sweep`` on a LocalCluster of 1 / 2 worker processes (one
  thread each), started beforehand (start-up reported separately, not counted), kernels
  already loaded by the worker plugin; with results files (``--h5 shared``, the default) and
  without (``--h5 none``).

Speed-up = sweep_1 / sweep_2; overhead per run = sweep_1 / direct - 1 (same files). Prints the
numbers and writes ``sweep_scaling.json`` into ``--out``. Not a test: timings on a shared
machine are noisy.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "examples" / "slider_crank.yaml"
PATH = "joints.8.damping.0"
METRIC = "peak=max(abs(joint/1/multiplier/3))"


def _direct(values, files: bool, folder: Path) -> float:
    import se3dyn as sd
    from se3dyn.io.modelfile import format_model_data, loads_model, parse_model_data
    from se3dyn.sweep.execute import _write_h5
    from se3dyn.sweep.metrics import parse_metric
    from se3dyn.sweep.spec import apply_values

    base = parse_model_data(MODEL.read_bytes(), filename=str(MODEL))
    metric = parse_metric(METRIC)
    t0 = time.perf_counter()
    for i, v in enumerate(values):
        data = apply_values(base, {PATH: v})
        text = format_model_data(data)
        model, cfg = loads_model(text)
        s = sd.compile_model(model)
        res = sd.simulate(s, **cfg)
        metric.evaluate(res)
        if files:
            stats = {k: x for k, x in res.stats.items() if k != "final_state"}
            _write_h5(folder / f"{i:04d}.h5", s, res, text, cfg, stats)
    return time.perf_counter() - t0


def _simulate_only(values) -> float:
    import se3dyn as sd
    from se3dyn.io.modelfile import format_model_data, loads_model, parse_model_data
    from se3dyn.sweep.spec import apply_values

    base = parse_model_data(MODEL.read_bytes(), filename=str(MODEL))
    systems = []
    for v in values:
        model, cfg = loads_model(format_model_data(apply_values(base, {PATH: v})))
        systems.append(sd.compile_model(model))
    t0 = time.perf_counter()
    for s in systems:
        sd.simulate(s, **cfg)
    return time.perf_counter() - t0


def _sweep(client, runs: int, h5: str, folder: Path) -> tuple[float, list]:
    import se3dyn

    shutil.rmtree(folder, ignore_errors=True)
    t0 = time.perf_counter()
    rows = se3dyn.sweep(MODEL, {PATH: f"0.5:4:{runs}"}, metrics=[METRIC], out=folder, h5=h5,
                        client=client, as_frame=False, progress=False)
    wall = time.perf_counter() - t0
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"sweep failed: {bad[0]['message']}")
    return wall, rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=32)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = ap.parse_args(argv)
    import numpy as np
    from distributed import Client, LocalCluster

    import se3dyn as sd
    from se3dyn.io.modelfile import load_model
    from se3dyn.sweep.execute import warm_up

    logging.getLogger("distributed").setLevel(logging.ERROR)
    warm_up()
    model, cfg = load_model(MODEL)
    sd.simulate(model, **cfg)  # kernels loaded in this process too
    values = [float(v) for v in np.linspace(0.5, 4.0, args.runs)]
    tmp = Path(tempfile.mkdtemp(prefix="se3dyn-sweep-bench-"))
    (tmp / "direct").mkdir()
    r: dict = {}
    clients = {}
    for n in (1, 2):
        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=":0",
                               silence_logs=logging.ERROR)
        client = Client(cluster)
        client.run(warm_up)
        r[f"cluster_{n}_start"] = time.perf_counter() - t0
        clients[n] = (client, cluster)
        for h5 in ("shared", "none"):
            _sweep(client, args.runs, h5, tmp / "warm")  # a first sweep warms every cache
    # interleaved rounds (the machine is shared: every measure sees the same load), best of
    best: dict = {}
    inside: dict = {}

    def keep(key, wall, rows=None):
        if wall < best.get(key, float("inf")):
            best[key] = wall
            if rows is not None:
                inside[key] = sum(row["wall_time"] for row in rows)

    for _ in range(args.repeat):
        keep("simulate_only", _simulate_only(values))
        keep("direct", _direct(values, False, tmp))
        keep("direct_files", _direct(values, True, tmp / "direct"))
        for n in (1, 2):
            for h5 in ("shared", "none"):
                keep(f"sweep_{n}_{h5}", *_sweep(clients[n][0], args.runs, h5,
                                                tmp / f"s{n}{h5}"))
    for client, cluster in clients.values():
        client.close()
        cluster.close()
    shutil.rmtree(tmp, ignore_errors=True)
    r.update(best)
    n = args.runs
    out = {
        "runs": n, "model": "examples/slider_crank.yaml (5 s, h = 1e-2)", "vary": PATH,
        "repeat": args.repeat, "cores": len(os.sched_getaffinity(0)),
        "load_average_1min": os.getloadavg()[0], "python": platform.python_version(),
        "se3dyn": sd.__version__, "distributed": __import__("distributed").__version__,
        "seconds": r,
        "per_run_ms": {k: 1e3 * v / n for k, v in r.items() if not k.endswith("_start")},
        "speedup_2_vs_1": r["sweep_1_shared"] / r["sweep_2_shared"],
        "speedup_2_vs_1_no_files": r["sweep_1_none"] / r["sweep_2_none"],
        "overhead_1_worker_vs_direct_files": r["sweep_1_shared"] / r["direct_files"] - 1,
        "overhead_1_worker_vs_direct_no_files": r["sweep_1_none"] / r["direct"] - 1,
        "overhead_2_workers_per_core_vs_direct_files":
            2 * r["sweep_2_shared"] / r["direct_files"] - 1,
        # the time in the workers' runs (sum of the rows' wall_time) of the 1-worker sweeps,
        # and what dask and the client's bookkeeping add to it (less sensitive to the load)
        "in_worker_seconds": inside,
        "dask_and_bookkeeping_1_worker": {
            h5: r[f"sweep_1_{h5}"] / inside[f"sweep_1_{h5}"] - 1 for h5 in ("shared", "none")},
        # time in runs / wall time of the 2-worker sweeps: how many runs dask kept going at once
        # (2 = both workers always busy; a speed-up below it is CPU taken by other processes)
        "concurrency_2_workers": {
            h5: inside[f"sweep_2_{h5}"] / r[f"sweep_2_{h5}"] for h5 in ("shared", "none")},
        "created": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    pr = out["per_run_ms"]
    print(f"{n} slider-crank runs (5 s, h = 1e-2), best of {args.repeat} interleaved rounds; "
          f"{out['cores']} cores, load average {out['load_average_1min']:.2f}")
    print(f"  simulate only (prebuilt models)   {pr['simulate_only']:7.1f} ms/run")
    print(f"  direct, one process: model+run    {pr['direct']:7.1f} ms/run   "
          f"(+ HDF5 file: {pr['direct_files']:.1f} ms/run)")
    for h5, label in (("shared", "with files"), ("none", "no files  ")):
        print(f"  sweep {label}: 1 worker {pr[f'sweep_1_{h5}']:7.1f} ms/run, 2 workers "
              f"{pr[f'sweep_2_{h5}']:7.1f} ms/run")
    print(f"  speed-up 2 vs 1 worker: {out['speedup_2_vs_1']:.2f} (files), "
          f"{out['speedup_2_vs_1_no_files']:.2f} (no files)")
    print(f"  overhead per run, 1 worker vs direct: "
          f"{100 * out['overhead_1_worker_vs_direct_files']:+.1f} % (files), "
          f"{100 * out['overhead_1_worker_vs_direct_no_files']:+.1f} % (no files)")
    print(f"  1 worker: dask + bookkeeping over the time spent in the runs: "
          f"{100 * out['dask_and_bookkeeping_1_worker']['shared']:+.1f} % (files), "
          f"{100 * out['dask_and_bookkeeping_1_worker']['none']:+.1f} % (no files)")
    print(f"  2 workers: runs in progress at once (time in runs / wall time): "
          f"{out['concurrency_2_workers']['shared']:.2f} (files), "
          f"{out['concurrency_2_workers']['none']:.2f} (no files)")
    print(f"  cluster start-up (not counted): 1 worker {r['cluster_1_start']:.1f} s, "
          f"2 workers {r['cluster_2_start']:.1f} s")
    folder = Path(args.out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "sweep_scaling.json").write_text(json.dumps(out, indent=1) + "\n")
    print(f"  wrote {folder / 'sweep_scaling.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
