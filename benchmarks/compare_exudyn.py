"""se3dyn vs EXUDYN on the same physical models, in one run on this machine.

Models (built independently in both codes):

1. The spatial slider-crank of Sec. 11 of the paper (Tables 2-4): 5 s at h = 1e-2 s,
   rho_inf = 0.9. EXUDYN: three rigid bodies and four joints at their points; se3dyn: the same
   three bodies with joints attached at the points (``examples.slider_crank_bodies``, the
   headline numbers) and, for reference, the paper's node/rigid-joint form
   (``examples.slider_crank``), each in the stabilized index-2 (se3dyn's default) and the
   index-3 form. Agreement: position of node 6 (rod COM) at t = 1 s and crank angle at t = 2 s.
2. The N-link spatial pendulum chain of ``chain_scaling.py`` (links 0.1 m, 1 kg, slender-rod
   inertia, spherical joints at the link ends, released horizontal, gravity -z): 1 s at
   h = 1e-3, rho_inf = 0.9 for N = 10, 100, 1000; N = 10000 (``--n10000``) with 0.1 s of model
   time in both codes. Agreement: tip position at the final time.
3. ``--memory``: peak resident memory of the N = 10000 chain in its own process (0.2 s in the
   index-3 form, 0.1 s in the index-2 form, every 10th step stored; set-up dominates).

Timed: the solve (se3dyn ``simulate`` on a compiled system whose kernels and block-LU set-up
are warm; EXUDYN ``SolveDynamic`` on an assembled system), median over repeats;
building/compiling is timed separately. For the slider-crank also the whole process from a cold
start (``python -c`` import + build + simulate, median of 3 subprocesses; se3dyn's numba cache
warm).

EXUDYN settings: implicit generalized-alpha (index 3 constraints, ``useIndex2Constraints =
False``), rigid bodies with Euler-parameter nodes (7 coordinates + 1 algebraic normalisation
constraint each), full Newton (``useModifiedNewton = False``), relative tolerance 1e-10,
absolute 1e-12, fixed step (``adaptiveStep = False``), no solution file, sensors stored in
memory every step. se3dyn: Lie-group generalized-alpha on SE(3), ``tol_residual = 1e-10``,
``tol_constraint = 1e-11`` (its defaults), compiled engine, modified Newton (its default).

Run:  python benchmarks/compare_exudyn.py [--repeats 3] [--no-1000] [--n10000] [--memory]
      [--out PATH]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RHO = 0.9
G = (0.0, 0.0, -9.81)


# ------------------------------------------------------------------------------------------------
# helpers
def crank_angle(R: np.ndarray) -> np.ndarray:
    """Unwrapped rotation angle about x of a stack of rotation matrices (n, 3, 3)."""
    return np.unwrap(np.arctan2(R[:, 2, 1], R[:, 1, 1]))


def at_time(t: np.ndarray, values: np.ndarray, t_query: float) -> np.ndarray:
    i = int(np.argmin(np.abs(t - t_query)))
    if abs(t[i] - t_query) > 1e-8:
        raise RuntimeError(f"no output at t = {t_query} (closest {t[i]})")
    return values[i]


# ------------------------------------------------------------------------------------------------
# se3dyn
def se3_slider_crank(model: str = "bodies", formulation: str = "index2"):
    """se3dyn slider-crank: ``bodies`` = three rigid bodies with joints attached at their
    points (``examples.slider_crank_bodies``, the same model EXUDYN builds), ``paper`` = the
    node/rigid-joint form of Sec. 11 (``examples.slider_crank``)."""
    import se3dyn as sd
    from se3dyn.examples import slider_crank, slider_crank_bodies

    t0 = time.perf_counter()
    system = sd.compile_model(slider_crank_bodies() if model == "bodies" else slider_crank())
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = sd.simulate(system, t_end=5.0, step=1e-2, rho_inf=RHO, formulation=formulation)
    solve = time.perf_counter() - t0
    t = res.t
    out = {
        "model": model, "formulation": formulation,
        "build_s": build, "solve_s": solve,
        "rod_com_t1": at_time(t, res.node_position("6"), 1.0).tolist(),
        "crank_angle_t2": float(at_time(t, crank_angle(res.node_rotation("3")), 2.0)),
        "crank_joint_coordinate_t2": float(at_time(t, res.joint_coordinates("1")[:, 0], 2.0)),
        "rod_com_t5": res.node_position("6")[-1].tolist(),
        "steps": int(res.stats["steps"]),
        "newton_iterations": int(res.stats["newton_iterations"]),
        "factorizations": int(res.stats.get("factorizations", 0)),
        "equations": int(res.stats["matrix_size"]),
        "engine": res.stats["engine"],
    }
    return out


def se3_chain_model(n_links: int):
    """The se3dyn chain of benchmarks/chain_scaling.py (one model definition for both scripts):
    one node per link, spherical joints attached at the link ends."""
    sys.path.insert(0, str(HERE))
    from chain_scaling import chain

    return chain(n_links)


def se3_chain(n_links: int, t_end: float, formulation: str = "index3"):
    import se3dyn as sd

    sys.path.insert(0, str(HERE))
    from chain_scaling import tip

    t0 = time.perf_counter()
    system = sd.compile_model(se3_chain_model(n_links))
    sd.simulate(system, t_end=1e-3, step=1e-3, formulation=formulation)  # block-LU set-up
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = sd.simulate(system, t_end=t_end, step=1e-3, rho_inf=RHO, formulation=formulation,
                      output_every=10)
    solve = time.perf_counter() - t0
    return {"build_s": build, "solve_s": solve, "formulation": formulation,
            "tip_final": tip(res, n_links)[-1].tolist(),
            "t_final": float(res.t[-1]), "steps": int(res.stats["steps"]),
            "newton_iterations": int(res.stats["newton_iterations"]),
            "factorizations": int(res.stats.get("factorizations", 0)),
            "equations": int(res.stats["matrix_size"])}


# ------------------------------------------------------------------------------------------------
# EXUDYN
def exu_settings(t_end: float, h: float, sparse: bool):
    import exudyn as exu

    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.numberOfSteps = int(round(t_end / h))
    ti.endTime = t_end
    ti.verboseMode = 0
    ti.adaptiveStep = False
    ti.generalizedAlpha.spectralRadius = RHO
    ti.generalizedAlpha.useIndex2Constraints = False   # index-3
    ti.generalizedAlpha.useNewmark = False
    ti.generalizedAlpha.computeInitialAccelerations = True
    ti.newton.useModifiedNewton = False                # full Newton, as se3dyn
    ti.newton.relativeTolerance = 1e-10
    ti.newton.absoluteTolerance = 1e-12
    ti.newton.maxIterations = 25
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = h
    ss.show.statistics = False
    ss.show.computationTime = False
    ss.parallel.numberOfThreads = 1
    ss.linearSolver.solverType = (exu.LinearSolverType.EigenSparse if sparse
                                  else exu.LinearSolverType.EXUdense)
    return ss


def exu_newton_count(mbs):
    try:
        return int(mbs.sys["dynamicSolver"].it.newtonStepsCount)
    except Exception:  # noqa: BLE001 - statistics are optional
        return None


def exu_size(mbs):
    sd_ = mbs.systemData
    return int(len(sd_.GetODE2Coordinates()) + len(sd_.GetAECoordinates()))


def slider_crank_refined(h: float, h_ref: float):
    """Same slider-crank over 2 s at a smaller step in both codes, plus an EXUDYN reference at
    h_ref: shows whether the h = 1e-2 differences are discretisation error (O(h^2))."""
    import se3dyn as sd
    from se3dyn.examples import slider_crank

    out = {}
    for tag, hh in (("exudyn", h), ("exudyn_ref", h_ref)):
        _, mbs, s_rod, s_crank = exu_slider_crank_build()
        if not mbs.SolveDynamic(exu_settings(2.0, hh, sparse=False)):
            raise RuntimeError("EXUDYN refined slider-crank did not converge")
        rod = mbs.GetSensorStoredData(s_rod)
        rot = mbs.GetSensorStoredData(s_crank)
        out[tag] = {"h": hh, "rod_com_t1": at_time(rod[:, 0], rod[:, 1:4], 1.0).tolist(),
                    "crank_angle_t2": float(at_time(rot[:, 0],
                                                    crank_angle(rot[:, 1:].reshape(-1, 3, 3)),
                                                    2.0))}
    res = sd.simulate(slider_crank(), 2.0, h, rho_inf=RHO)
    out["se3dyn"] = {"h": h, "rod_com_t1": at_time(res.t, res.node_position("6"), 1.0).tolist(),
                     "crank_angle_t2": float(at_time(res.t, crank_angle(res.node_rotation("3")),
                                                     2.0))}
    return out


def exu_slider_crank_build():
    import exudyn as exu
    import exudyn.utilities as eu

    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.CreateGround(referencePosition=[0, 0, 0])
    crank = mbs.CreateRigidBody(
        referencePosition=[0.0, 0.1, 0.16],
        inertia=eu.RigidBodyInertia(mass=0.12, inertiaTensor=np.diag([1e-4, 1e-4, 1e-5])),
        gravity=list(G))
    rod = mbs.CreateRigidBody(
        referencePosition=[0.1, 0.05, 0.1],
        inertia=eu.RigidBodyInertia(mass=0.5, inertiaTensor=np.diag([4e-3, 4e-4, 4e-3])),
        gravity=list(G))
    slider = mbs.CreateRigidBody(
        referencePosition=[0.2, 0.0, 0.0],
        inertia=eu.RigidBodyInertia(mass=2.0, inertiaTensor=1e-4 * np.eye(3)),
        gravity=list(G))
    s = math.sqrt(0.05)
    mbs.CreateRevoluteJoint(itemNumbers=[ground, crank], position=[0.0, 0.1, 0.12],
                            axis=[1.0, 0.0, 0.0], useGlobalFrame=True)
    mbs.CreateSphericalJoint(itemNumbers=[crank, rod], position=[0.0, 0.1, 0.2],
                             useGlobalFrame=True)
    mbs.CreateRevoluteJoint(itemNumbers=[rod, slider], position=[0.2, 0.0, 0.0],
                            axis=[0.0, 0.2 / s, -0.1 / s], useGlobalFrame=True)
    # cylindrical joint along global x: free translation x and rotation about x
    mbs.CreateGenericJoint(itemNumbers=[ground, slider], position=[0.2, 0.0, 0.0],
                           constrainedAxes=[0, 1, 1, 0, 1, 1], useGlobalFrame=True)
    # 1 N s/m on the translation of the cylindrical joint (slider moves along x only)
    mbs.CreateCartesianSpringDamper(itemNumbers=[ground, slider],
                                    localPosition0=[0.2, 0.0, 0.0],
                                    localPosition1=[0.0, 0.0, 0.0],
                                    stiffness=[0, 0, 0], damping=[1.0, 0.0, 0.0])

    def torque(mbs_, t, load):
        return [0.015 if 0.0 <= t < 2.0 else 0.0, 0.0, 0.0]

    mbs.CreateTorque(itemNumber=crank, loadVector=[0.015, 0.0, 0.0], bodyFixed=False,
                     loadVectorUserFunction=torque)
    s_rod = mbs.AddSensor(eu.SensorBody(bodyNumber=rod, storeInternal=True,
                                        outputVariableType=exu.OutputVariableType.Position))
    s_crank = mbs.AddSensor(eu.SensorBody(
        bodyNumber=crank, storeInternal=True,
        outputVariableType=exu.OutputVariableType.RotationMatrix))
    mbs.Assemble()
    return SC, mbs, s_rod, s_crank


def exu_slider_crank():
    t0 = time.perf_counter()
    SC, mbs, s_rod, s_crank = exu_slider_crank_build()
    ss = exu_settings(5.0, 1e-2, sparse=False)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    ok = mbs.SolveDynamic(ss)
    solve = time.perf_counter() - t0
    if not ok:
        raise RuntimeError("EXUDYN slider-crank did not converge")
    rod = mbs.GetSensorStoredData(s_rod)
    rot = mbs.GetSensorStoredData(s_crank)
    ang = crank_angle(rot[:, 1:].reshape(-1, 3, 3))
    return {"build_s": build, "solve_s": solve,
            "rod_com_t1": at_time(rod[:, 0], rod[:, 1:4], 1.0).tolist(),
            "crank_angle_t2": float(at_time(rot[:, 0], ang, 2.0)),
            "rod_com_t5": rod[-1, 1:4].tolist(),
            "steps": ss.timeIntegration.numberOfSteps,
            "newton_iterations": exu_newton_count(mbs),
            "equations": exu_size(mbs)}


def exu_chain(n_links: int, t_end: float):
    import exudyn as exu
    import exudyn.utilities as eu

    t0 = time.perf_counter()
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.CreateGround(referencePosition=[0, 0, 0])
    J = 1.0 * 0.1**2 / 12.0
    inertia = eu.RigidBodyInertia(mass=1.0, inertiaTensor=np.diag([1e-4 * J, J, J]))
    prev = ground
    body = None
    for i in range(n_links):
        x0 = 0.1 * i
        body = mbs.CreateRigidBody(referencePosition=[x0 + 0.05, 0.0, 0.0], inertia=inertia,
                                   gravity=list(G))
        mbs.CreateSphericalJoint(itemNumbers=[prev, body], position=[x0, 0.0, 0.0],
                                 useGlobalFrame=True)
        prev = body
    mbs.Assemble()
    ss = exu_settings(t_end, 1e-3, sparse=True)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    ok = mbs.SolveDynamic(ss)
    solve = time.perf_counter() - t0
    if not ok:
        raise RuntimeError(f"EXUDYN chain N={n_links} did not converge")
    tip = mbs.GetObjectOutputBody(body, exu.OutputVariableType.Position,
                                  localPosition=[0.05, 0.0, 0.0],
                                  configuration=exu.ConfigurationType.Current)
    return {"build_s": build, "solve_s": solve, "tip_final": list(map(float, tip)),
            "t_final": float(mbs.systemData.GetTime()), "steps": ss.timeIntegration.numberOfSteps,
            "newton_iterations": exu_newton_count(mbs)}


# ------------------------------------------------------------------------------------------------
def repeat(fn, n, *args):
    runs = [fn(*args) for _ in range(n)]
    out = dict(runs[-1])
    out["solve_s_all"] = [r["solve_s"] for r in runs]
    out["build_s_all"] = [r["build_s"] for r in runs]
    out["solve_s"] = statistics.median(out["solve_s_all"])
    out["build_s"] = statistics.median(out["build_s_all"])
    return out


COLD = {
    "se3dyn": ("import se3dyn as sd; from se3dyn.examples import slider_crank_bodies; "
               "sd.simulate(slider_crank_bodies(), 5.0, 1e-2, rho_inf=0.9)"),
    # the README demo's job: the paper's model file, results streamed to HDF5
    "se3dyn_demo_run": ("import tempfile, se3dyn.cli as c; d = tempfile.mkdtemp(); "
                        "c.main(['run', 'examples/slider_crank.yaml', '--out', d])"),
    "exudyn": (f"import sys; sys.path.insert(0, {str(HERE)!r}); import compare_exudyn as c; "
               "c.exu_slider_crank()"),
}


def cold_start(code: str, n: int) -> list[float]:
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True, cwd=str(HERE.parent),
                       capture_output=True)
        times.append(time.perf_counter() - t0)
    return times


def versions():
    import exudyn
    import numba
    import scipy

    import se3dyn
    return {"python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "se3dyn": se3dyn.__version__,
            "exudyn": exudyn.__version__, "numba": numba.__version__}


def memory_runs() -> list:
    """Peak RSS of the N = 10000 chain, each formulation in its own process; a tiny run of the
    same code path first, so that the measured process loads the compiled kernels from the
    cache instead of compiling them (compilation alone takes about 0.5 GB)."""
    res = []
    for form, t_end in (("index3", 0.2), ("index2", 0.1)):
        script = str(HERE / "chain_scaling.py")
        subprocess.run([sys.executable, script, "--memory", "10", "--t-end", "0.002",
                        "--formulation", form], capture_output=True, text=True)
        proc = subprocess.run([sys.executable, script, "--memory", "10000", "--t-end",
                               str(t_end), "--formulation", form],
                              capture_output=True, text=True)
        if proc.returncode:
            err = proc.stderr.strip().splitlines()[-1:] or ["?"]
            res.append({"formulation": form, "t_end": t_end, "failed": err[0]})
            print(f"memory run {form} {t_end} s failed: {err[0]}")
            continue
        mem = json.loads(proc.stdout.strip().splitlines()[-1])
        res.append(mem)
        print(f"\npeak RSS, N = 10000 chain, {form}, {t_end:g} s, every 10th step stored "
              f"({mem['stored_rows']} rows): {mem['peak_rss_MB']:.0f} MB "
              f"({mem['wall_s']:.1f} s)", flush=True)
    return res


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-1000", action="store_true", help="skip N = 1000")
    ap.add_argument("--repeats-1000", type=int, default=1)
    ap.add_argument("--n10000", action="store_true", help="also N = 10000 (both codes)")
    ap.add_argument("--t-10000", type=float, default=0.1, help="model time for N = 10000")
    ap.add_argument("--memory", action="store_true", help="peak RSS of the N = 10000 chain")
    ap.add_argument("--memory-only", action="store_true",
                    help="only the memory runs, updating the existing --out JSON")
    ap.add_argument("--out", default=str(HERE / "results" / "compare_exudyn.json"))
    a = ap.parse_args(argv)
    if a.memory_only:
        report = json.loads(Path(a.out).read_text())
        report["memory_N10000"] = memory_runs()
        Path(a.out).write_text(json.dumps(report, indent=2) + "\n")
        print(f"\nwrote {a.out}")
        return 0

    machine = {"platform": platform.platform(), "machine": platform.machine(),
               "processor": platform.processor(), "cpu_count": os.cpu_count()}
    ver = versions()
    print(f"machine: {machine['platform']} ({machine['machine']}), {machine['cpu_count']} CPUs")
    print("versions: " + ", ".join(f"{k} {v}" for k, v in ver.items()))
    print("EXUDYN: implicit generalized-alpha, index-3 constraints, Euler-parameter rigid-body "
          "nodes, full Newton (useModifiedNewton=False), relTol 1e-10 / absTol 1e-12, fixed step, "
          "dense LU (slider-crank) / EigenSparse LU (chains), 1 thread")
    print("se3dyn: Lie-group generalized-alpha on SE(3), compiled engine, modified Newton "
          "(Jacobian reuse), tol_residual 1e-10, tol_constraint 1e-11")
    report = {"machine": machine, "versions": ver, "repeats": a.repeats,
              "exudyn_settings": {
                  "integrator": "generalized-alpha (implicit), index-3 constraints",
                  "rotation_parameters": "Euler parameters (NodeType.RotationEulerParameters)",
                  "newton": "full Newton (useModifiedNewton=False)",
                  "relativeTolerance": 1e-10, "absoluteTolerance": 1e-12,
                  "adaptiveStep": False,
                  "linear_solver": {"slider_crank": "EXUdense", "chain": "EigenSparse"},
                  "threads": 1},
              "se3dyn_settings": {"integrator": "Lie-group generalized-alpha on SE(3)",
                                  "engine": "compiled (numba), block LU",
                                  "newton": "modified (Jacobian reuse)",
                                  "tol_residual": 1e-10, "tol_constraint": 1e-11}}

    # 1. slider-crank ---------------------------------------------------------------------------
    print("\n== slider-crank (Sec. 11): 5 s, h = 1e-2, rho_inf = 0.9 ==")
    se = repeat(se3_slider_crank, a.repeats)
    ex = repeat(exu_slider_crank, a.repeats)
    d_rod = float(np.linalg.norm(np.subtract(se["rod_com_t1"], ex["rod_com_t1"])))
    d_ang = abs(se["crank_angle_t2"] - ex["crank_angle_t2"])
    d_rod5 = float(np.linalg.norm(np.subtract(se["rod_com_t5"], ex["rod_com_t5"])))
    cold_se = cold_start(COLD["se3dyn"], 3)
    cold_ex = cold_start(COLD["exudyn"], 3)
    cold_demo = cold_start(COLD["se3dyn_demo_run"], 3)
    sc = {"se3dyn": se, "exudyn": ex,
          "solve_ratio_se3dyn_over_exudyn": se["solve_s"] / ex["solve_s"],
          "cold_process_s": {"se3dyn": cold_se, "exudyn": cold_ex,
                             "se3dyn_median": statistics.median(cold_se),
                             "exudyn_median": statistics.median(cold_ex),
                             "se3dyn_demo_run": cold_demo,
                             "se3dyn_demo_run_median": statistics.median(cold_demo)},
          "cold_ratio_se3dyn_over_exudyn": statistics.median(cold_se) / statistics.median(cold_ex),
          "agreement": {"rod_com_t1_diff_m": d_rod, "crank_angle_t2_diff_rad": d_ang,
                        "rod_com_t5_diff_m": d_rod5}}
    report["slider_crank"] = sc
    print(f"solve  se3dyn {se['solve_s']*1e3:9.1f} ms   EXUDYN {ex['solve_s']*1e3:9.1f} ms   "
          f"ratio se3dyn/EXUDYN {sc['solve_ratio_se3dyn_over_exudyn']:.2f}")
    print(f"build  se3dyn {se['build_s']*1e3:9.1f} ms   EXUDYN {ex['build_s']*1e3:9.1f} ms")
    print(f"cold process (import+build+simulate, median of 3)  se3dyn "
          f"{sc['cold_process_s']['se3dyn_median']:.2f} s   EXUDYN "
          f"{sc['cold_process_s']['exudyn_median']:.2f} s   ratio "
          f"{sc['cold_ratio_se3dyn_over_exudyn']:.2f}")
    print(f"cold process of the README demo job (se3dyn run examples/slider_crank.yaml, "
          f"median of 3): {statistics.median(cold_demo):.2f} s")
    print(f"Newton iterations  se3dyn {se['newton_iterations']}   EXUDYN {ex['newton_iterations']}")
    print(f"rod COM at t=1: se3dyn {np.round(se['rod_com_t1'], 6)}  EXUDYN "
          f"{np.round(ex['rod_com_t1'], 6)}  |diff| {d_rod:.2e} m")
    print(f"crank angle at t=2: se3dyn {se['crank_angle_t2']:.6f}  EXUDYN "
          f"{ex['crank_angle_t2']:.6f} rad  |diff| {d_ang:.2e} rad "
          f"(se3dyn hinge coordinate {se['crank_joint_coordinate_t2']:.6f})")
    print(f"rod COM at t=5: |diff| {d_rod5:.2e} m")
    sc["se3dyn_variants"] = {}
    print("se3dyn variants (model/formulation): solve, ratio to EXUDYN, Newton its, "
          "factorisations, matrix size, rod COM t=1 vs EXUDYN")
    for model, form in (("bodies", "index2"), ("bodies", "index3"), ("paper", "index2"),
                        ("paper", "index3")):
        v = se if (model, form) == ("bodies", "index2") else repeat(
            se3_slider_crank, a.repeats, model, form)
        dv = float(np.linalg.norm(np.subtract(v["rod_com_t1"], ex["rod_com_t1"])))
        sc["se3dyn_variants"][f"{model}/{form}"] = {
            "solve_s": v["solve_s"], "ratio": v["solve_s"] / ex["solve_s"],
            "newton_iterations": v["newton_iterations"],
            "factorizations": v["factorizations"], "equations": v["equations"],
            "rod_com_t1_diff_m": dv}
        print(f"  {model + '/' + form:15s} {v['solve_s']*1e3:8.1f} ms  ratio "
              f"{v['solve_s'] / ex['solve_s']:5.2f}  its {v['newton_iterations']:5d}  "
              f"fact {v['factorizations']:5d}  N {v['equations']:3d}  diff {dv:.2e} m")
    ref = slider_crank_refined(1e-3, 2e-4)
    sc["refined_check"] = ref
    r = ref["exudyn_ref"]
    for tag, v in (("se3dyn h=1e-2", se), ("EXUDYN h=1e-2", ex),
                   ("se3dyn h=1e-3", ref["se3dyn"]), ("EXUDYN h=1e-3", ref["exudyn"])):
        e_rod = float(np.linalg.norm(np.subtract(v["rod_com_t1"], r["rod_com_t1"])))
        e_ang = abs(v["crank_angle_t2"] - r["crank_angle_t2"])
        sc["refined_check"].setdefault("error_vs_exudyn_h2e-4", {})[tag] = {
            "rod_com_t1_m": e_rod, "crank_angle_t2_rad": e_ang}
        print(f"  vs EXUDYN h=2e-4 reference: {tag}: rod COM t=1 {e_rod:.2e} m, "
              f"crank angle t=2 {e_ang:.2e} rad")
    d_ref = abs(ref["se3dyn"]["crank_angle_t2"] - ref["exudyn"]["crank_angle_t2"])
    d_ref_rod = float(np.linalg.norm(np.subtract(ref["se3dyn"]["rod_com_t1"],
                                                 ref["exudyn"]["rod_com_t1"])))
    sc["agreement"]["h1e-3_rod_com_t1_diff_m"] = d_ref_rod
    sc["agreement"]["h1e-3_crank_angle_t2_diff_rad"] = d_ref
    print(f"  se3dyn vs EXUDYN at h=1e-3: rod COM t=1 {d_ref_rod:.2e} m, crank angle t=2 "
          f"{d_ref:.2e} rad (h=1e-2: {d_rod:.2e} m, {d_ang:.2e} rad; ratio ~ h^2 => "
          "same model, different O(h^2) discretisation error)")

    # 2. chains ---------------------------------------------------------------------------------
    cases = [(10, 1.0, a.repeats), (100, 1.0, a.repeats)]
    if not a.no_1000:
        cases.append((1000, 1.0, a.repeats_1000))
    if a.n10000:
        cases.append((10000, a.t_10000, 1))
    report["chain"] = []
    print("\n== N-link spherical chain: h = 1e-3, rho_inf = 0.9 ==")
    print(f"{'N':>5} {'t_end':>5} {'form':>6} {'se3dyn s':>10} {'EXUDYN s':>10} {'ratio':>7} "
          f"{'se3 ms/step':>11} {'exu ms/step':>11} {'tip |diff| m':>12}")
    for n, t_end, rep in cases:
        ex = repeat(exu_chain, rep, n, t_end)
        for form in ("index3", "index2"):
            se = repeat(se3_chain, rep, n, t_end, form)
            d_tip = float(np.linalg.norm(np.subtract(se["tip_final"], ex["tip_final"])))
            row = {"N": n, "t_end": t_end, "h": 1e-3, "repeats": rep, "formulation": form,
                   "se3dyn": se, "exudyn": ex,
                   "solve_ratio_se3dyn_over_exudyn": se["solve_s"] / ex["solve_s"],
                   "tip_final_diff_m": d_tip}
            report["chain"].append(row)
            print(f"{n:5d} {t_end:5.2f} {form:>6} {se['solve_s']:10.3f} {ex['solve_s']:10.3f} "
                  f"{row['solve_ratio_se3dyn_over_exudyn']:7.3f} "
                  f"{1e3*se['solve_s']/se['steps']:11.3f} "
                  f"{1e3*ex['solve_s']/ex['steps']:11.3f} {d_tip:12.2e}", flush=True)
        print(f"      tip se3dyn {np.round(se['tip_final'], 6)}  EXUDYN "
              f"{np.round(ex['tip_final'], 6)}; Newton its se3dyn {se['newton_iterations']} "
              f"(factorisations {se['factorizations']}) EXUDYN {ex['newton_iterations']}")

    # 3. memory of the N = 10000 chain (own process) --------------------------------------------
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    if a.memory:
        report["memory_N10000"] = memory_runs()

    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
