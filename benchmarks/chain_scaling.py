"""Cost per time step of an N-link spatial pendulum chain (the shape of issue 6's benchmark).

Links of 0.1 m and 1 kg (slender rod inertia), spherical joints attached at the link ends with
``at=``, the first to a fixed node, released horizontal under gravity; h = 1e-3, rho_inf = 0.9,
se3dyn's defaults (index-2 form, modified Newton; ``--formulations index2 index3`` adds the
index-3 form). For each N it times the model building, ``compile_model`` and the one-time set-up
of the first ``simulate`` (a one-step run) separately, then the cost per step without any
set-up: (wall(0.1 s run) - wall(0.02 s run)) / 80 steps on the same compiled system. It prints
ms per step, Newton iterations and factorisations per step and the exponent of a least-squares
fit of log(ms per step) vs log N (measured in this one run), at se3dyn's default thread count
for the element kernels and at one thread (``--threads``), and writes
benchmarks/results/chain_scaling.json. ``--memory N`` instead runs the N-link chain in this
process (``--t-end`` model time, every 10th step stored) and prints the peak resident set size
as one JSON line (VmHWM of /proc/self/status; ``ru_maxrss`` beside it, which a child started by
vfork inherits from a bigger parent); ``compare_exudyn.py`` runs it in its own subprocess.

Run:  python benchmarks/chain_scaling.py [N ...] [--formulations index2 [index3]]
      python benchmarks/chain_scaling.py --memory 10000 --t-end 0.1 [--phases]
"""

from __future__ import annotations

import os
import platform
import sys
import time

import numpy as np
import scipy

import se3dyn as sd


def chain(n_links: int, spin=None, name: str | None = None) -> sd.Model:
    """Chain model: one node per link at its centre, spherical joints attached to the bodies at
    the link ends (``at=``), the first to a fixed node: 6 N + 3 N unknowns, 6 N multipliers.
    ``spin(i)``: the initial angular velocity of link i (None: at rest; called link after link,
    tests/cpp/make_lu_matrices.py draws random ones)."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name=name or f"chain{n_links}")
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    J = 1.0 * 0.1**2 / 12.0
    prev = "ground"
    for i in range(n_links):
        x0 = 0.1 * i
        mb.node(f"b{i}", position=(x0 + 0.05, 0.0, 0.0), mass=1.0, inertia=(1e-4 * J, J, J),
                angular_velocity=spin(i) if spin else None)
        mb.joint(f"s{i}", "spherical", prev, f"b{i}", at=(x0, 0.0, 0.0))
        prev = f"b{i}"
    return mb.build()


def chain_nodes(n_links: int, spin=None, close: bool = False,
                name: str | None = None) -> sd.Model:
    """The same chain in the paper's rigid-constraint form (Sec. 5): per link a joint node, a
    body node at the centre and an end node, joined by rigid joints (massless joint and end
    nodes: zero 6x6 diagonal blocks). ``spin`` as in :func:`chain`; ``close`` clamps the far
    end by a spherical joint (a closed loop)."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name=name or f"chain{n_links}")
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    J = 1.0 * 0.1**2 / 12.0
    prev = "ground"
    for i in range(n_links):
        x0 = 0.1 * i
        mb.node(f"p{i}", position=(x0, 0.0, 0.0))
        mb.node(f"b{i}", position=(x0 + 0.05, 0.0, 0.0), mass=1.0, inertia=(1e-4 * J, J, J),
                angular_velocity=spin(i) if spin else None)
        mb.node(f"e{i}", position=(x0 + 0.1, 0.0, 0.0))
        mb.joint(f"s{i}", "spherical", prev, f"p{i}")
        mb.joint(f"r{i}", "rigid", f"p{i}", f"b{i}")
        mb.joint(f"t{i}", "rigid", f"b{i}", f"e{i}")
        prev = f"e{i}"
    if close:
        mb.node("end", position=(0.1 * n_links, 0.0, -0.1), fixed=True)
        mb.joint("close", "spherical", prev, "end")
    return mb.build()


def tip(res, n_links: int) -> np.ndarray:
    """Tip of the chain (end of the last link) at every stored time, (nt, 3)."""
    H = res.H[:, res.system.node_names.index(f"b{n_links - 1}")]
    return H[:, :3, 3] + H[:, :3, 0] * 0.05


def per_step(system, formulation: str = "index2", h: float = 1e-3, long: float = 0.1,
             short: float = 0.02, newton: str = "modified", repeats: int = 2) -> dict:
    """Cost per step without the set-up: (wall(long run) - wall(short run)) / extra steps,
    each wall the minimum of ``repeats`` runs (short and long alternated: one disturbed short
    run would otherwise make the difference, and the cost, too small; 2026-11-27 it gave
    0.015 ms per step at N = 100 once).

    The one-time set-up of the system (first ``simulate``) is paid by a one-step run first and
    reported as ``setup_s``. Also returns the tip at the end of the long run."""
    t0 = time.perf_counter()
    sd.simulate(system, t_end=h, step=h, rho_inf=0.9, formulation=formulation, newton=newton)
    setup = time.perf_counter() - t0
    walls, res_long = {}, None
    for _ in range(max(1, repeats)):
        for t_end in (short, long):
            n_out = round(t_end / h)
            t0 = time.perf_counter()
            res = sd.simulate(system, t_end=t_end, step=h, rho_inf=0.9,
                              formulation=formulation, output_every=n_out, newton=newton)
            walls[t_end] = min(walls.get(t_end, np.inf), time.perf_counter() - t0)
            walls[f"its{t_end}"] = res.stats["newton_iterations"]
            walls[f"fac{t_end}"] = res.stats.get("factorizations", 0)
            res_long = res
    nsteps = round((long - short) / h)
    n_links = sum(1 for name in system.node_names if name.startswith("b"))
    return {"ms_per_step": 1e3 * (walls[long] - walls[short]) / nsteps,
            "newton_per_step": (walls[f"its{long}"] - walls[f"its{short}"]) / nsteps,
            "factorizations_per_step": (walls[f"fac{long}"] - walls[f"fac{short}"]) / nsteps,
            "setup_s": setup, "wall_long_s": walls[long], "wall_short_s": walls[short],
            "t_long": long, "t_short": short, "newton": newton,
            "newton_iterations_long": int(walls[f"its{long}"]),
            "factorizations_long": int(walls[f"fac{long}"]),
            "steps_long": int(res_long.stats["steps"]),
            "tip_long": tip(res_long, n_links)[-1].tolist(),
            "t_final_long": float(res_long.t[-1]),
            "engine": res_long.stats["engine"], "linear_solver": res_long.stats["linear_solver"],
            "matrix_size": res_long.stats["matrix_size"]}


def _status_mb(key: str) -> float:
    """A size of /proc/self/status in MB (VmRSS, VmHWM), NaN when unknown."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) / 1024.0  # kB -> MB
    except OSError:
        pass
    return float("nan")


def _report_phases() -> None:
    """Print VmRSS and VmHWM to stderr after the phases of every ``simulate`` (workspace,
    steppers, initial state, first compiled chunk of steps), by wrapping those calls."""
    import se3dyn.dynamics.integrator as ig
    import se3dyn.engine.system as sy
    sim = sys.modules["se3dyn.dynamics.run"]

    def wrap(owner, name, label, once=False):
        orig = getattr(owner, name)

        def call(self, *a, **k):
            out = orig(self, *a, **k)
            if not (once and getattr(self, "_phase_reported", False)):
                lab = label(a) if callable(label) else label
                print(f"  {lab:34s} VmRSS {_status_mb('VmRSS'):6.0f} MB, VmHWM "
                      f"{_status_mb('VmHWM'):6.0f} MB", file=sys.stderr, flush=True)
                if once:
                    self._phase_reported = True
            return out
        setattr(owner, name, call)

    wrap(sy.Workspace, "__init__", "workspace (engine, layout)")
    wrap(sy.Workspace, "stepper", lambda a: f"stepper index {2 if a[0] else 3}")
    wrap(ig.GeneralizedAlpha, "init", "initial state")
    wrap(sim._Recorder, "added", "first compiled chunk of steps", once=True)


def peak_memory(n_links: int, t_end: float = 1.0, output_every: int = 10,
                formulation: str = "index2", phases: bool = False) -> dict:
    """Run the chain in this process (se3dyn defaults) and report the peak resident set size,
    also as it was after importing, after building + compiling the model and after the one-time
    set-up of the first ``simulate`` (a one-step run).

    The peak is read as VmHWM from /proc/self/status (the high-water mark of this process's own
    address space). ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` is reported too, but it is not
    trusted: a child started by vfork (Python's subprocess does) inherits its parent's peak
    through execve, so a big parent makes it report the parent's peak. ``phases``: VmRSS and
    VmHWM after every phase of both runs on stderr (:func:`_report_phases`)."""
    import resource

    def hwm_mb() -> float:
        return _status_mb("VmHWM")

    def maxrss_mb() -> float:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB -> MB (Linux)

    rss_import = hwm_mb()
    if phases:
        _report_phases()
    t0 = time.perf_counter()
    system = sd.compile_model(chain(n_links))
    build = time.perf_counter() - t0
    rss_compiled = hwm_mb()
    t0 = time.perf_counter()
    sd.simulate(system, t_end=1e-3, step=1e-3, rho_inf=0.9, formulation=formulation)
    setup = time.perf_counter() - t0
    rss_setup = hwm_mb()
    t0 = time.perf_counter()
    res = sd.simulate(system, t_end=t_end, step=1e-3, rho_inf=0.9, output_every=output_every,
                      formulation=formulation)
    wall = time.perf_counter() - t0
    return {"N": n_links, "t_end": t_end, "output_every": output_every,
            "formulation": formulation, "stored_rows": len(res.t),
            "peak_rss_MB": hwm_mb(), "peak_rss_after_import_MB": rss_import,
            "peak_rss_after_build_compile_MB": rss_compiled,
            "peak_rss_after_setup_MB": rss_setup, "ru_maxrss_MB": maxrss_mb(),
            "build_compile_s": build, "setup_s": setup, "simulate_s": wall,
            "tip_final": tip(res, n_links)[-1].tolist()}


def fit_exponent(rows: list[dict]) -> float:
    """Slope of a least-squares fit of log(ms per step) vs log N."""
    n = np.array([r["N"] for r in rows], float)
    ms = np.array([r["ms_per_step"] for r in rows])
    return float(np.polyfit(np.log(n), np.log(ms), 1)[0])


def scaling_row(n: int, formulation: str = "index2", newton: str = "modified",
                threads: int | None = None) -> dict:
    """Build, compile, set up and time per step the N-link chain (one row of the table);
    ``threads``: the element kernels' threads (default: se3dyn's, ``se3dyn.get_threads``)."""
    if threads is not None:
        sd.set_threads(threads)
        try:
            return scaling_row(n, formulation, newton)
        finally:
            sd.set_threads()
    t0 = time.perf_counter()
    model = chain(n)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    system = sd.compile_model(model)
    compile_s = time.perf_counter() - t0
    r = per_step(system, formulation, newton=newton)
    r.update(N=n, formulation=formulation, build_s=build, compile_s=compile_s,
             threads=sd.get_threads())
    r.update(linear_algebra_work(system, formulation, newton, r["newton_per_step"]))
    return r


def linear_algebra_work(system, formulation: str, newton: str, its: float) -> dict:
    """The work of a step's linear algebra, from the factors of the run's stepper (analysed as
    a run does, after one step): multiply-adds of a refactorisation (the LU and, split index 2,
    the xi block's LDL^T), entries of the factors (a solve does one multiply-add per entry),
    and per step ``refactorisation + its * entries`` with the measured iterations ``its``."""
    from se3dyn.dynamics.integrator import GeneralizedAlpha
    from se3dyn.engine.workspace import Workspace

    ws = Workspace(system)
    integ = GeneralizedAlpha(rho_inf=0.9, formulation=formulation, newton=newton)
    st = integ.init(system, ws=ws)
    st, _ = integ.step(system, st, 1e-3, ws=ws)
    stp = ws.stepper(integ.index2, st.dropped, split=newton == "modified")
    _n, nnz_l, nnz_u, refac, _sn = stp.lu_stats()
    return {"refactor_multiply_adds": int(refac), "factor_entries": int(nnz_l + nnz_u),
            "multiply_adds_per_step": float(refac + its * (nnz_l + nnz_u))}


def main(argv: list[str]) -> int:
    import argparse
    import json
    from pathlib import Path

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sizes", nargs="*", type=int, default=[100, 300, 1000, 3000, 10000])
    ap.add_argument("--formulations", nargs="+", default=["index2"],
                    choices=["index2", "index3"])
    ap.add_argument("--memory", type=int, help="only: peak RSS of a run with N links")
    ap.add_argument("--t-end", type=float, default=1.0, help="model time of --memory")
    ap.add_argument("--formulation", default="index2", help="formulation of --memory")
    ap.add_argument("--phases", action="store_true",
                    help="--memory: VmRSS and VmHWM after every phase of the runs on stderr")
    ap.add_argument("--threads", nargs="+", type=int,
                    help="thread counts of the element kernels (default: se3dyn's default, "
                    "and 1 beside it when that is more)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" /
                                          "chain_scaling.json"))
    a = ap.parse_args(argv)
    threads = a.threads or sorted({sd.get_threads(), 1}, reverse=True)
    if a.memory:
        print(json.dumps(peak_memory(a.memory, a.t_end, formulation=a.formulation,
                                     phases=a.phases)))
        return 0
    print(f"se3dyn {sd.__version__}, numpy {np.__version__}, scipy {scipy.__version__}, "
          f"Python {platform.python_version()}, {platform.machine()}, {os.cpu_count()} CPUs, "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    report = {"machine": platform.platform(), "python": platform.python_version(),
              "numpy": np.__version__, "scipy": scipy.__version__, "se3dyn": sd.__version__,
              "load_average_start": os.getloadavg(),
              "h": 1e-3, "method": "(wall(0.1 s) - wall(0.02 s)) / 80 steps, set-up excluded",
              "rows": []}
    for n in a.sizes:
        for form, th in [(f, t) for f in a.formulations for t in threads]:
            r = scaling_row(n, form, threads=th)
            report["rows"].append(r)
            print(f"N = {n:5d} {form} {th} thr: matrix {r['matrix_size']:7d}, "
                  f"{r['ms_per_step']:9.3f} "
                  f"ms/step, {r['newton_per_step']:.2f} Newton iterations and "
                  f"{r['factorizations_per_step']:.2f} factorisations per step; set-up: build "
                  f"{r['build_s']:.2f} s, compile {r['compile_s']:.2f} s, first simulate "
                  f"{r['setup_s']:.2f} s", flush=True)
    for form, th in [(f, t) for f in a.formulations for t in threads]:
        rows = [r for r in report["rows"] if r["formulation"] == form and r["threads"] == th]
        if len(rows) >= 2:
            slope = fit_exponent(rows)
            work = fit_exponent([dict(N=r["N"], ms_per_step=r["multiply_adds_per_step"])
                                 for r in rows])
            tag = form if th == threads[0] else f"{form}_{th}_thread"
            report[f"exponent_{tag}"] = slope
            report[f"work_exponent_{tag}"] = work
            print(f"{form}, {th} threads: fitted exponent of cost per step vs N "
                  f"({min(r['N'] for r in rows)}..{max(r['N'] for r in rows)}): {slope:.3f}; "
                  f"of the linear algebra's multiply-adds per step: {work:.3f} (per link and "
                  "step: " + ", ".join(f"{r['multiply_adds_per_step'] / r['N']:.0f}"
                                       for r in rows) + ")")
    report["load_average_end"] = os.getloadavg()
    Path(a.out).write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
