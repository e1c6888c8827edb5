"""se3dyn's SE(3) beam vs EXUDYN's geometrically exact beam on the same dynamic cantilever, paired
in one run on this machine, EXUDYN at its default settings (issue 13).

What is compared
----------------
The cantilever of ``beam_scaling.py``: steel (E = 210 GPa, nu = 0.3, 7850 kg/m^3), 2 m long,
solid circular section of diameter 20 mm, clamped at one end, released horizontal under gravity
(-z) at rest and stress-free, simulated for 1 s (about 3.6 periods of its first bending mode,
tip deflection up to ~6 cm: a dynamic, mildly non-linear problem). Section values from
``se3dyn.model.sections.circle`` (Cowper's shear factor), the same numbers in both codes.

* **se3dyn at its defaults**: ``sd.simulate(model, t_end, step, rho_inf=0.9)`` with N two-node
  SE(3) beam elements (Sonneville, Cardona & Bruls, CMAME 268 (2014) 451-474), lumped mass and
  lumped gravity, stabilized index-2 form, modified Newton, tolerances 1e-10 / 1e-11.
* **EXUDYN at its defaults**: ``ObjectBeamGeometricallyExact`` (EXUDYN's two-node shear deformable
  3D beam, interpolated on SE(3)) on ``NodeRigidBodyEP`` nodes (Euler parameters: the node type
  of EXUDYN's own beam test ``geometricallyExactBeamTest.py`` and the default of its
  ``CreateRigidBody``; its Lie-group node ``NodeRigidBodyRotVecLG`` did not finish 0.3 s of a
  thinner variant of this cantilever in 200 s here), clamped by a ``GenericJoint`` to ground,
  gravity as ``LoadMassProportional`` on every element, ``exu.SimulationSettings()`` as it comes
  (printed below: modified Newton, relative tolerance 1e-8, index-3, spectral radius 0.9,
  adaptive step on Newton failure, dense LU). Set are only ``endTime``, ``numberOfSteps``, the
  sensors' write period (tip position every 0.01 s, in memory) and the solution file off (as in
  ``compare_exudyn.py``). A second EXUDYN variant, labelled, changes one setting more:
  ``newton.absoluteTolerance`` 1e-10 -> 1e-6. The default 1e-10 (N) lies near the round-off of
  the internal forces of this stiff beam (EA = 6.6e7 N), and EXUDYN then cuts its step
  (adaptive step) again and again. The converged EXUDYN reference (N = 128) needs
  ``absoluteTolerance`` 1e-4 to finish at all (with 1e-6 its solver fails) and the sparse solver
  (``EigenSparse``, which does not change the solution); its agreement with se3dyn's reference
  is printed.

Accuracy: every run's tip position every 0.01 s against the code's own converged reference
(N = ``--ref-n`` elements, step h / ``--ref-factor``): the largest distance over the run,
relative to the largest tip deflection. The two references are compared with each other (their
difference must be far below the errors reported; they differ by the mass discretisation:
lumped here, EXUDYN's own element mass there, both converging to the same continuum).

Timings: warm, in this process, median of ``--repeats`` (se3dyn: build + ``simulate``, compile
included; EXUDYN: build + ``Assemble`` + ``SolveDynamic``), the two codes interleaved. Fresh
process: ``python -c`` (import, build the N = 8 cantilever, first solve 1 s at h = 1e-3) in a
new process, median of ``--processes``, timed inside the process (import, build, first solve).
"Equal accuracy": for every se3dyn run, EXUDYN's time interpolated (log-log, between its runs
at neighbouring errors) at the same error, and the ratio.

Run (about 5 min on this machine):
    .venv/bin/python benchmarks/compare_exudyn_beam.py [--repeats 3] [--processes 3]
        [--sizes 4 8 16 32] [--step 1e-3] [--ref-n 128] [--ref-factor 8] [--defaults-max-n N]
Writes benchmarks/results/compare_exudyn_beam.txt (the table as printed) and .json.
"""

from __future__ import annotations

import json
import math
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import beam_scaling as bs  # noqa: E402
import compare_exudyn as ce  # noqa: E402

T_END, RHO, OUT_DT = 1.0, 0.9, 0.01
REF_ABS_TOL = 1e-4    # EXUDYN reference: with 1e-10 (default) or 1e-6 its N = 128 run fails
USER_ABS_TOL = 1e-6   # the one setting an EXUDYN user changes for this beam (labelled)
SLOW_S = 5.0          # a run slower than this is not repeated
G = (0.0, 0.0, -9.81)


def section() -> dict:
    from se3dyn.model import sections

    return sections.circle(bs.RADIUS, **bs.STEEL)


# ------------------------------------------------------------------------------------------------
def se3_run(n: int, h: float) -> dict:
    """Build and simulate the se3dyn cantilever; tip position every OUT_DT."""
    import se3dyn as sd

    t0 = time.perf_counter()
    model = bs.cantilever(n)
    res = sd.simulate(model, t_end=T_END, step=h, rho_inf=RHO, output_every=round(OUT_DT / h))
    wall = time.perf_counter() - t0
    tip = res.H[:, res.system.node_names.index("tip"), :3, 3]
    return {"wall_s": wall, "t": np.asarray(res.t), "tip": tip,
            "newton_iterations": int(res.stats["newton_iterations"]),
            "steps": int(res.stats["steps"])}


def exu_build(n: int, sparse: bool = False):
    import exudyn as exu
    from exudyn.itemInterface import (
        GenericJoint,
        LoadMassProportional,
        MarkerBodyMass,
        MarkerBodyRigid,
        MarkerNodeRigid,
        NodeRigidBodyEP,
        ObjectBeamGeometricallyExact,
        ObjectGround,
        SensorNode,
    )

    p = section()
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    sec = exu.BeamSection()
    sec.stiffnessMatrix = np.diag([p["EA"], *p["GA"], p["GJ"], *p["EI"]])
    sec.massPerLength = p["mass_per_length"]
    sec.inertia = np.diag(p["rotary_inertia"])
    L = bs.LENGTH
    nodes = [mbs.AddNode(NodeRigidBodyEP(referenceCoordinates=[L * i / n, 0, 0, 1, 0, 0, 0]))
             for i in range(n + 1)]
    ground = mbs.AddObject(ObjectGround())
    mg = mbs.AddMarker(MarkerBodyRigid(bodyNumber=ground, localPosition=[0, 0, 0]))
    m0 = mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[0]))
    mbs.AddObject(GenericJoint(markerNumbers=[mg, m0], constrainedAxes=[1] * 6))
    for i in range(n):
        b = mbs.AddObject(ObjectBeamGeometricallyExact(nodeNumbers=nodes[i:i + 2], length=L / n,
                                                       sectionData=sec))
        mm = mbs.AddMarker(MarkerBodyMass(bodyNumber=b))
        mbs.AddLoad(LoadMassProportional(markerNumber=mm, loadVector=list(G)))
    sensor = mbs.AddSensor(SensorNode(nodeNumber=nodes[-1], storeInternal=True,
                                      outputVariableType=exu.OutputVariableType.Position))
    mbs.Assemble()
    return SC, mbs, sensor


def exu_settings(h: float, sparse: bool = False, abs_tol: float | None = None):
    import exudyn as exu

    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.endTime = T_END
    ti.numberOfSteps = int(round(T_END / h))
    if ti.generalizedAlpha.spectralRadius != RHO:  # EXUDYN 1.13.6: 0.9 already
        ti.generalizedAlpha.spectralRadius = RHO
    ti.verboseMode = 0
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = OUT_DT
    if sparse:
        ss.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    if abs_tol is not None:
        ss.timeIntegration.newton.absoluteTolerance = abs_tol
    return ss


def exu_run(n: int, h: float, sparse: bool = False, abs_tol: float | None = None) -> dict:
    t0 = time.perf_counter()
    SC, mbs, sensor = exu_build(n, sparse)
    ss = exu_settings(h, sparse, abs_tol)
    ok = mbs.SolveDynamic(ss)
    wall = time.perf_counter() - t0
    if not ok:
        raise RuntimeError(f"EXUDYN N={n} h={h} did not converge")
    data = np.asarray(mbs.GetSensorStoredData(sensor))
    return {"wall_s": wall, "t": data[:, 0], "tip": data[:, 1:4],
            "t_final": float(mbs.systemData.GetTime()), **ce.exu_counters(mbs)}


# ------------------------------------------------------------------------------------------------
def on_grid(run: dict) -> np.ndarray:
    """Tip positions at t = 0, OUT_DT, ..., T_END (rows matched by time)."""
    grid = np.round(np.arange(0.0, T_END + 0.5 * OUT_DT, OUT_DT), 9)
    t = np.round(run["t"], 9)
    idx = [int(np.argmin(np.abs(t - g))) for g in grid]
    if np.abs(t[idx] - grid).max() > 1e-7:
        raise RuntimeError("outputs not on the 0.01 s grid")
    return run["tip"][idx]


def error(run: dict, ref: np.ndarray, scale: float) -> float:
    """|tip(t_end) - reference tip(t_end)| / scale (EXUDYN's adaptive step, when its Newton
    fails, moves its sensor times off the 0.01 s grid; the final time is always t_end)."""
    if abs(run["t"][-1] - T_END) > 1e-9:
        raise RuntimeError(f"run ended at {run['t'][-1]}")
    return float(np.linalg.norm(run["tip"][-1] - ref[-1]) / scale)


def error_max(run: dict, ref: np.ndarray, scale: float) -> float:
    """Largest |tip - reference tip| over the 0.01 s grid / scale (nan when off the grid)."""
    try:
        return float(np.linalg.norm(on_grid(run) - ref, axis=1).max() / scale)
    except RuntimeError:
        return float("nan")


FRESH = {
    "se3dyn": """
import json, sys, time
t0 = time.perf_counter()
import se3dyn as sd
sys.path.insert(0, {here!r})
import beam_scaling as bs
t1 = time.perf_counter()
model = bs.cantilever(8)
t2 = time.perf_counter()
sd.simulate(model, t_end=1.0, step=1e-3, rho_inf=0.9, output_every=10)
t3 = time.perf_counter()
print(json.dumps({{"import_s": t1 - t0, "build_s": t2 - t1, "first_solve_s": t3 - t2}}))
""",
    "exudyn": """
import json, sys, time
t0 = time.perf_counter()
import exudyn
sys.path.insert(0, {here!r})
import compare_exudyn_beam as cb
t1 = time.perf_counter()
SC, mbs, sensor = cb.exu_build(8)
ss = cb.exu_settings(1e-3)
t2 = time.perf_counter()
ok = mbs.SolveDynamic(ss)
t3 = time.perf_counter()
print(json.dumps({{"import_s": t1 - t0, "build_s": t2 - t1, "first_solve_s": t3 - t2,
                  "ok": bool(ok)}}))
""",
}


def fresh(code: str) -> dict:
    p = subprocess.run([sys.executable, "-c", FRESH[code].format(here=str(HERE))],
                       capture_output=True, text=True, timeout=600, cwd=str(HERE))
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-2000:])
    return json.loads(p.stdout.strip().splitlines()[-1])


def interp_time(err: float, errs: list[float], times: list[float]) -> float | None:
    """Time at error ``err`` by log-log interpolation between runs with neighbouring errors
    (None outside their range)."""
    pts = sorted(zip(errs, times, strict=False))
    for (e0, t0), (e1, t1) in zip(pts, pts[1:], strict=False):
        if e0 <= err <= e1 and e1 > e0:
            w = (math.log(err) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + w * (math.log(t1) - math.log(t0)))
    return None


def main(argv: list[str]) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", nargs="+", type=int, default=[4, 8, 16, 32])
    ap.add_argument("--step", type=float, default=1e-3)
    ap.add_argument("--ref-n", type=int, default=128)
    ap.add_argument("--ref-factor", type=int, default=8)
    ap.add_argument("--defaults-max-n", type=int, default=None,
                    help="run EXUDYN at its pure defaults only up to this N (they cut the step "
                         "again and again on the finer meshes: 40 s at N = 16, > 5 min at 32)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--processes", type=int, default=3)
    ap.add_argument("--out", default=str(HERE / "results" / "compare_exudyn_beam.json"))
    a = ap.parse_args(argv)
    tee = ce.Tee(sys.stdout)
    sys.stdout = tee
    report: dict = {"environment": ce.environment(HERE.parent), "args": vars(a),
                    "command": "python benchmarks/compare_exudyn_beam.py " + " ".join(argv)}
    env = report["environment"]
    print(f"se3dyn {env['versions']['se3dyn']} vs EXUDYN {env['versions']['exudyn']}, "
          f"Python {env['versions']['python']}, {env['machine']['cpu']}, "
          f"{env['machine']['cpu_count']} CPUs, git {env['git']['head'][:10]}, {ce.load_str()}")
    p = section()
    print(f"cantilever: steel, L = {bs.LENGTH} m, d = {2e3 * bs.RADIUS:g} mm, EA = {p['EA']:.4g} N,"
          f" EI = {p['EI'][0]:.4g} N m^2, {p['mass_per_length']:.4g} kg/m; released under "
          f"gravity, {T_END} s, rho_inf = {RHO}, h = {a.step}")
    defaults = ce.exu_default_settings()
    report["exudyn_defaults"] = defaults
    print("EXUDYN defaults as read from exu.SimulationSettings():")
    for k, v in defaults.items():
        print(f"    {k} = {v}")

    # references
    href = a.step / a.ref_factor
    print(f"\n== converged references: N = {a.ref_n}, h = {href:g} [{ce.load_str()}] ==")
    ref_se3 = se3_run(a.ref_n, href)
    ref_exu = exu_run(a.ref_n, href, sparse=True, abs_tol=REF_ABS_TOL)
    R_se3, R_exu = on_grid(ref_se3), on_grid(ref_exu)
    scale = float(np.linalg.norm(R_se3 - R_se3[0], axis=1).max())
    agree = float(np.linalg.norm(R_se3 - R_exu, axis=1).max() / scale)
    agree_end = float(np.linalg.norm(R_se3[-1] - R_exu[-1]) / scale)
    print(f"  largest tip deflection {scale:.5f} m (se3dyn reference); tip at t = 1 s: se3dyn "
          f"{np.array2string(R_se3[-1], precision=6)}, EXUDYN "
          f"{np.array2string(R_exu[-1], precision=6)}")
    print(f"  EXUDYN reference: its defaults with newton.absoluteTolerance = {REF_ABS_TOL:g} and "
          f"the sparse solver; {ref_exu.get('step_index')} steps, "
          f"{ref_exu.get('newton_iterations')} Newton iterations")
    print(f"  the two references differ by {agree_end:.2e} of the largest deflection at t = 1 s, "
          f"{agree:.2e} at most over the run; wall {ref_se3['wall_s']:.1f} s (se3dyn), "
          f"{ref_exu['wall_s']:.1f} s (EXUDYN)")
    report["reference"] = {"N": a.ref_n, "h": href, "scale_m": scale, "agreement_rel": agree,
                           "agreement_rel_t_end": agree_end,
                           "exudyn_abs_tol": REF_ABS_TOL,
                           "se3dyn_tip_final": R_se3[-1].tolist(),
                           "exudyn_tip_final": R_exu[-1].tolist(),
                           "se3dyn_wall_s": ref_se3["wall_s"], "exudyn_wall_s": ref_exu["wall_s"]}

    # paired runs
    variants = [("se3dyn", "se3dyn defaults", lambda n: se3_run(n, a.step), R_se3),
                ("exu", "EXUDYN defaults", lambda n: exu_run(n, a.step), R_exu),
                ("exu_abs", f"EXUDYN defaults + absoluteTolerance {USER_ABS_TOL:g}",
                 lambda n: exu_run(n, a.step, abs_tol=USER_ABS_TOL), R_exu)]
    print(f"\n== warm runs, h = {a.step}, median of {a.repeats} (1 run when the first takes "
          f"> {SLOW_S:g} s) [{ce.load_str()}] ==")
    print("  error: |tip(1 s) - reference tip(1 s)| / largest deflection, against the code's own "
          "reference (the other code's in brackets); max: largest over the run (0.01 s grid; "
          "'-' when adaptive steps moved the outputs off it)")
    print(f"{'variant':<44} {'N':>4} {'wall s':>8} {'error':>9} {'(other)':>9} {'max':>9} "
          f"{'steps':>6} {'Newton':>7} {'Jac':>6}")
    rows = []
    for n in a.sizes:
        for key, label, fn, R in variants:
            if key == "exu" and a.defaults_max_n is not None and n > a.defaults_max_n:
                print(f"{label:<44} {n:>4} skipped (--defaults-max-n {a.defaults_max_n})")
                continue
            walls, run = [], None
            try:
                for _ in range(a.repeats):
                    t0 = time.perf_counter()
                    run = fn(n)
                    walls.append(run["wall_s"])
                    if run["wall_s"] > SLOW_S:
                        break
            except Exception as exc:  # noqa: BLE001 - EXUDYN's solver failure is a result
                row = {"variant": key, "label": label, "N": n, "h": a.step, "failed": True,
                       "wall_s": time.perf_counter() - t0, "message": str(exc)[:200],
                       "load": ce.load()}
                rows.append(row)
                print(f"{label:<44} {n:>4} {row['wall_s']:>8.4f} FAILED: {row['message']}",
                      flush=True)
                continue
            other = R_exu if key == "se3dyn" else R_se3
            row = {"variant": key, "label": label, "N": n, "h": a.step,
                   "wall_s": statistics.median(walls), "wall_min_s": min(walls),
                   "runs": len(walls), "error": error(run, R, scale),
                   "error_vs_other_ref": error(run, other, scale),
                   "error_max": error_max(run, R, scale),
                   "steps": run.get("steps", run.get("step_index")),
                   "newton_iterations": run.get("newton_iterations"),
                   "jacobians": run.get("jacobians", "-"), "load": ce.load()}
            rows.append(row)
            em = "-" if math.isnan(row["error_max"]) else f"{row['error_max']:.2e}"
            print(f"{label:<44} {n:>4} {row['wall_s']:>8.4f} {row['error']:>9.2e} "
                  f"({row['error_vs_other_ref']:.2e}) {em:>9} {row['steps']!s:>6} "
                  f"{row['newton_iterations']!s:>7} {row['jacobians']!s:>6}", flush=True)
    report["rows"] = rows

    print("\n== ratios se3dyn / EXUDYN (wall time, medians) ==")
    by = {(r["variant"], r["N"]): r for r in rows if not r.get("failed")}

    def ratio(n, key):
        if ("se3dyn", n) in by and (key, n) in by:
            return f"{by[('se3dyn', n)]['wall_s'] / by[(key, n)]['wall_s']:.3f}"
        return "n/a (skipped or failed)"

    for n in a.sizes:
        print(f"  N = {n:>3}: same N and h: {ratio(n, 'exu')} (EXUDYN defaults), "
              f"{ratio(n, 'exu_abs')} (EXUDYN + absoluteTolerance {USER_ABS_TOL:g})")
    eq = []
    se3_rows = [r for r in rows if r["variant"] == "se3dyn" and not r.get("failed")]
    for measure, what in (("error", "tip error at t = 1 s"),
                          ("error_max", "largest tip error over the run")):
        print(f"\n== equal accuracy, {what} (EXUDYN's time interpolated, log-log, at se3dyn's "
              "error) ==")
        for key in ("exu", "exu_abs"):
            ex = [r for r in rows if r["variant"] == key and not r.get("failed")
                  and not math.isnan(r[measure])]
            if len(ex) < 2:
                print(f"  vs {key}: fewer than 2 EXUDYN runs with this measure")
                continue
            for r in se3_rows:
                t_exu = interp_time(r[measure], [x[measure] for x in ex],
                                    [x["wall_s"] for x in ex])
                if t_exu is None:
                    print(f"  vs {ex[0]['label']}: se3dyn N = {r['N']}: error {r[measure]:.2e} "
                          f"outside EXUDYN's range ({min(x[measure] for x in ex):.2e} ... "
                          f"{max(x[measure] for x in ex):.2e})")
                    continue
                eq.append({"measure": measure, "variant": key, "N": r["N"],
                           "error": r[measure], "se3dyn_s": r["wall_s"],
                           "exudyn_s_interp": t_exu, "ratio": r["wall_s"] / t_exu})
                print(f"  vs {ex[0]['label']}: error {r[measure]:.2e}: se3dyn "
                      f"{r['wall_s']:.4f} s (N = {r['N']}), EXUDYN {t_exu:.4f} s: ratio "
                      f"{r['wall_s'] / t_exu:.3f}")
    report["equal_accuracy"] = eq

    print(f"\n== fresh process, N = 8, 1 s at h = 1e-3, median of {a.processes} "
          f"[{ce.load_str()}] ==")
    fr = {"se3dyn": [], "exudyn": []}
    for _ in range(a.processes):
        for code in ("se3dyn", "exudyn"):
            fr[code].append(fresh(code))
    for code in ("se3dyn", "exudyn"):
        med = {k: statistics.median(x[k] for x in fr[code]) for k in
               ("import_s", "build_s", "first_solve_s")}
        print(f"  {code:>6}: import {med['import_s']:.3f} s, build {med['build_s']:.3f} s, "
              f"first solve {med['first_solve_s']:.3f} s")
        report[f"fresh_{code}"] = {"median": med, "all": fr[code]}
    r_first = (report["fresh_se3dyn"]["median"]["first_solve_s"]
               / report["fresh_exudyn"]["median"]["first_solve_s"])
    print(f"  first solve ratio se3dyn / EXUDYN: {r_first:.3f}")
    report["fresh_first_solve_ratio"] = r_first
    print(f"\n{ce.load_str()}")
    sys.stdout = tee.stream
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(ce.jsonable(report), indent=1))
    out.with_suffix(".txt").write_text(tee.text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
