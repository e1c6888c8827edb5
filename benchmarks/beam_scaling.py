"""Cost per time step of a dynamic beam cantilever vs the number of elements N (issue 13).

Model (``cantilever``): a steel cantilever, 2 m long, solid circular section of diameter 20 mm
(``se3dyn.model.sections.circle(0.01, E=210e9, nu=0.3, density=7850)``), clamped at one end
(fixed node), released horizontal under gravity; N geometrically exact SE(3) beam elements
(``ModelBuilder.beam``, lumped mass). se3dyn's defaults: stabilized index-2 form, modified
Newton, tolerances 1e-10 / 1e-11, fixed step h = 1e-3 s, rho_inf = 0.9.

For each N it times the model building, ``compile_model`` and the one-time set-up of the first
``simulate`` (a one-step run) separately, then the cost per step without any set-up:
(wall(0.1 s run) - wall(0.02 s run)) / 80 steps on the same compiled system (the method of
``chain_scaling.py``); Newton iterations and factorisations per step; the exponent of a
least-squares fit of log(ms per step) vs log N over N >= 100 (below, fixed per-step overheads
dominate) and over all N. ``--memory N`` instead runs the N-element cantilever for ``--t-end``
in this process (every 10th step stored) and prints the peak resident set size (VmHWM of
/proc/self/status) as one JSON line; the scaling run calls it in a subprocess for the largest N.

Run:  python benchmarks/beam_scaling.py [N ...] [--out PATH]
      python benchmarks/beam_scaling.py --memory 10000 --t-end 0.1
Writes benchmarks/results/beam_scaling.json and .txt (the table as printed).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import se3dyn as sd
from se3dyn.model import sections

sys.path.insert(0, str(Path(__file__).resolve().parent))
from chain_scaling import _status_mb  # noqa: E402  (one reader of /proc/self/status)

LENGTH, RADIUS = 2.0, 0.01
STEEL = dict(E=210e9, nu=0.3, density=7850.0)
H = 1e-3


def cantilever(n: int, length: float = LENGTH, radius: float = RADIUS) -> sd.Model:
    """Steel cantilever along x from the fixed node ``root`` to ``tip``, ``n`` elements, gravity
    -z, at rest and straight at t = 0 (stress-free)."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name=f"cantilever{n}")
    mb.node("root", fixed=True)
    mb.node("tip", position=(length, 0.0, 0.0))
    mb.beam("b", "root", "tip", elements=n, **sections.circle(radius, **STEEL))
    return mb.build()


def hwm_mb() -> float:
    """Peak resident set size of this process (VmHWM, MB)."""
    return _status_mb("VmHWM")


def peak_memory(n: int, t_end: float = 0.1, output_every: int = 10) -> dict:
    """Build, compile and run the N-element cantilever in this process; peak RSS after each."""
    rss_import = hwm_mb()
    t0 = time.perf_counter()
    system = sd.compile_model(cantilever(n))
    build = time.perf_counter() - t0
    rss_compiled = hwm_mb()
    t0 = time.perf_counter()
    res = sd.simulate(system, t_end=t_end, step=H, rho_inf=0.9, output_every=output_every)
    wall = time.perf_counter() - t0
    return {"N": n, "t_end": t_end, "output_every": output_every, "stored_rows": len(res.t),
            "peak_rss_MB": hwm_mb(), "peak_rss_after_import_MB": rss_import,
            "peak_rss_after_build_compile_MB": rss_compiled, "build_compile_s": build,
            "simulate_s": wall, "unknowns": int(system.nq)}


def scaling_row(n: int, long: float = 0.1, short: float = 0.02) -> dict:
    """Build, compile, set up and time per step the N-element cantilever (one table row)."""
    t0 = time.perf_counter()
    model = cantilever(n)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    system = sd.compile_model(model)
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    sd.simulate(system, t_end=H, step=H, rho_inf=0.9)
    setup = time.perf_counter() - t0
    walls, stats = {}, {}
    for t_end in (short, long):
        t0 = time.perf_counter()
        res = sd.simulate(system, t_end=t_end, step=H, rho_inf=0.9,
                          output_every=round(t_end / H))
        walls[t_end] = time.perf_counter() - t0
        stats[t_end] = res.stats
    steps = round((long - short) / H)
    tip = res.H[-1, system.node_names.index("tip"), :3, 3]
    return {"N": n, "unknowns": int(system.nq), "matrix_size": int(res.stats["matrix_size"]),
            "build_s": build, "compile_s": compile_s, "setup_s": setup,
            "ms_per_step": 1e3 * (walls[long] - walls[short]) / steps,
            "newton_per_step": (stats[long]["newton_iterations"]
                                - stats[short]["newton_iterations"]) / steps,
            "factorizations_per_step": (stats[long].get("factorizations", 0)
                                        - stats[short].get("factorizations", 0)) / steps,
            "tip_z_t0.1": float(tip[2]), "linear_solver": res.stats["linear_solver"]}


def fit_exponent(rows: list[dict], n_min: int = 0) -> float:
    """Slope of a least-squares fit of log(ms per step) vs log N over N >= n_min."""
    sel = [r for r in rows if r["N"] >= n_min]
    n = np.array([r["N"] for r in sel], float)
    ms = np.array([r["ms_per_step"] for r in sel])
    return float(np.polyfit(np.log(n), np.log(ms), 1)[0])


def main(argv: list[str]) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sizes", nargs="*", type=int,
                    default=[10, 30, 100, 300, 1000, 3000, 10000])
    ap.add_argument("--memory", type=int, help="only: peak RSS of a run with N elements")
    ap.add_argument("--t-end", type=float, default=0.1, help="model time of --memory")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" /
                                          "beam_scaling.json"))
    a = ap.parse_args(argv)
    if a.memory:
        print(json.dumps(peak_memory(a.memory, a.t_end)))
        return 0
    lines = []

    def out(s: str = "") -> None:
        print(s, flush=True)
        lines.append(s)

    out(f"se3dyn {sd.__version__}, numpy {np.__version__}, Python "
        f"{platform.python_version()}, {platform.machine()}, {os.cpu_count()} CPUs, "
        f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    out(f"steel cantilever L = {LENGTH} m, d = {2 * RADIUS * 1e3:g} mm, released under gravity; "
        f"h = {H} s, rho_inf = 0.9, se3dyn defaults; per step = (wall(0.1 s) - wall(0.02 s)) / 80")
    out(f"{'N':>6} {'unknowns':>9} {'ms/step':>9} {'us/step/el':>11} {'Newton/step':>12} "
        f"{'fact/step':>10} {'build s':>8} {'compile s':>10} {'setup s':>8} {'tip z(0.1) m':>13}")
    rows = []
    for n in a.sizes:
        r = scaling_row(n)
        rows.append(r)
        out(f"{n:>6} {r['unknowns']:>9} {r['ms_per_step']:>9.3f} "
            f"{1e3 * r['ms_per_step'] / n:>11.2f} {r['newton_per_step']:>12.2f} "
            f"{r['factorizations_per_step']:>10.2f} {r['build_s']:>8.3f} {r['compile_s']:>10.3f} "
            f"{r['setup_s']:>8.3f} {r['tip_z_t0.1']:>13.6f}")
    e_all = fit_exponent(rows)
    e_100 = fit_exponent(rows, 100)
    out(f"fitted exponent of ms/step vs N: {e_100:.3f} (N >= 100), {e_all:.3f} (all N)")
    nmax = max(a.sizes)
    p = subprocess.run([sys.executable, __file__, "--memory", str(nmax), "--t-end", "0.1"],
                       capture_output=True, text=True)
    mem = json.loads(p.stdout.strip().splitlines()[-1]) if p.returncode == 0 else {
        "error": p.stderr[-2000:]}
    if "peak_rss_MB" in mem:
        out(f"peak RSS, N = {nmax}, 0.1 s (every 10th step stored), own process: "
            f"{mem['peak_rss_MB']:.0f} MB (after import {mem['peak_rss_after_import_MB']:.0f} MB,"
            f" after build + compile {mem['peak_rss_after_build_compile_MB']:.0f} MB)")
    out(f"load average at the end {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    report = {"machine": platform.platform(), "python": platform.python_version(),
              "numpy": np.__version__, "se3dyn": sd.__version__, "h": H,
              "model": {"length_m": LENGTH, "radius_m": RADIUS, **STEEL},
              "method": "(wall(0.1 s) - wall(0.02 s)) / 80 steps, set-up excluded",
              "rows": rows, "exponent_N_ge_100": e_100, "exponent_all": e_all, "memory": mem,
              "command": "python benchmarks/beam_scaling.py " + " ".join(argv)}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(report, indent=1))
    Path(a.out).with_suffix(".txt").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
