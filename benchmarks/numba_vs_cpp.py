"""Technology measurement behind docs/design.md: the numba engine se3dyn had (commit 57431aa,
``se3dyn.fast`` + ``se3dyn.blocklu``, cached machine code) against the C++ engine built at
install (``se3dyn._core._engine``), on the same models, in one run on this machine.

What a user pays, per engine, each in fresh subprocesses:

* ``cold``: the first ``simulate`` in a fresh process with every cache empty (numba: an empty
  ``NUMBA_CACHE_DIR``, so the kernels compile; C++: nothing to compile at run time);
* ``process``: the first ``simulate`` in a new process once the caches are warm (numba loads
  its cached kernels; C++ loads the extension);
* ``warm``: a repeated ``simulate`` in the same process (median of 5).

Models: the paper's slider-crank (node form, 5 s, h = 1e-2, defaults) and the 1000-link chain of
``chain_scaling.py`` (0.1 s, h = 1e-3, defaults). The build of the C++ extension at
``pip install`` is timed separately (``--build``: a wheel build in a temporary directory).

Run: python benchmarks/numba_vs_cpp.py [--build] [--out benchmarks/results/numba_vs_cpp.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OLD = "57431aa"  # the last commit with the numba engine

CODE = r"""
import sys, time, json
t0 = time.perf_counter()
{path}
import se3dyn as sd
t1 = time.perf_counter()
sys.path.insert(0, {bench!r})
from chain_scaling import chain
model = sd.examples.slider_crank() if {case!r} == "slider_crank" else chain(1000)
kw = dict(t_end=5.0, step=1e-2, rho_inf=0.9) if {case!r} == "slider_crank" else \
    dict(t_end=0.1, step=1e-3, rho_inf=0.9, output_every=10)
t2 = time.perf_counter()
sd.simulate(model, **kw)
t3 = time.perf_counter()
warm = []
for _ in range({repeats}):
    a = time.perf_counter(); sd.simulate(model, **kw); warm.append(time.perf_counter() - a)
print(json.dumps(dict(import_s=t1 - t0, first_simulate_s=t3 - t2, warm_s=warm,
                      file=sd.__file__)))
"""

OLD_PATH = """
sys.meta_path[:] = [f for f in sys.meta_path if 'scikit' not in type(f).__module__.lower()
                    and 'editable' not in type(f).__module__.lower()]
sys.path.insert(0, {src!r})
"""


def run(case: str, engine: str, src: str | None, env: dict, repeats: int) -> dict:
    path = OLD_PATH.format(src=src) if engine == "numba" else ""
    code = CODE.format(path=path, bench=str(HERE), case=case, repeats=repeats)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True)
    wall = time.perf_counter() - t0
    d = json.loads(out.stdout.strip().splitlines()[-1])
    d["process_wall_s"] = wall
    return d


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", action="store_true", help="also time a wheel build")
    ap.add_argument("--out", default=str(HERE / "results" / "numba_vs_cpp.json"))
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="se3dyn-old-"))
    subprocess.run(f"git -C {ROOT} archive {OLD} | tar -x -C {tmp}", shell=True, check=True)
    src = str(tmp / "src")
    res: dict = {"load_average": os.getloadavg(), "date": time.strftime("%Y-%m-%d %H:%M")}
    for case in ("slider_crank", "chain1000"):
        for engine in ("numba", "cpp"):
            env = dict(os.environ)
            cache = tempfile.mkdtemp(prefix="numba-cache-")
            env["NUMBA_CACHE_DIR"] = cache
            rows = {"cold": run(case, engine, src, env, 0)}
            rows["process"] = [run(case, engine, src, env, 5) for _ in range(3)]
            res[f"{case}/{engine}"] = rows
            p = rows["process"]
            print(f"{case:13s} {engine:6s} cold first simulate "
                  f"{rows['cold']['first_simulate_s']:8.3f} s (process "
                  f"{rows['cold']['process_wall_s']:7.2f} s) | new process first "
                  f"simulate {statistics.median(x['first_simulate_s'] for x in p):7.3f} s, import "
                  f"{statistics.median(x['import_s'] for x in p):6.3f} s | warm "
                  f"{statistics.median(w for x in p for w in x['warm_s']):7.3f} s", flush=True)
    if args.build:
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", d,
                            str(ROOT)], check=True, capture_output=True)
            res["wheel_build_s"] = time.perf_counter() - t0
            print(f"pip wheel build (C++ extension compiled): {res['wheel_build_s']:.1f} s")
    res["load_average_end"] = os.getloadavg()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(res, indent=1))
    print(f"load average {res['load_average']} -> {res['load_average_end']}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
