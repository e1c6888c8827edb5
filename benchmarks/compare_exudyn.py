"""se3dyn vs EXUDYN at EXUDYN's own default settings, paired in one run on this machine (issue 12).

What is compared
----------------
Both codes solve the same physical models, built independently in each, with their own
generalized-alpha schemes at rho_inf = 0.9 and a fixed step:

* **se3dyn at its defaults**: ``sd.simulate(model, t_end, step, rho_inf=0.9)``: Lie-group
  generalized-alpha on SE(3), stabilized index-2 form, modified Newton, tol_residual 1e-10,
  tol_constraint 1e-11, compiled engine (C++ extension ``se3dyn._core._engine``).
* **EXUDYN at its defaults**: ``exu.SimulationSettings()`` as it comes (the script reads the
  defaults at run time and prints them: modified Newton, relative tolerance 1e-8, index-3
  constraints, spectral radius 0.9, adaptive step on Newton failure, ...). Set are only what a
  user must set: ``endTime``, ``numberOfSteps`` (the step size), the sensors' ``writePeriod`` = h
  where sensors give the results, and for the chains the sparse solver
  (``linearSolver.solverType = EigenSparse``: EXUDYN's default is dense LU and EXUDYN itself warns
  to switch above 1000 coordinates). The spectral radius is not set: EXUDYN's default is 0.9
  already (checked at run time). The solution file (on by default, a text file written every
  0.01 s) is switched off: results come through sensors / ``GetObjectOutputBody`` in memory, as
  se3dyn's ``simulate`` returns them in memory (writing the file costs EXUDYN about 30 % of the
  slider-crank solve; leaving it on would only flatter se3dyn).
* **EXUDYN "full Newton" (for continuity only)**: the setting of the previous benchmark runs
  (``useModifiedNewton = False``, relative tolerance 1e-10, absolute 1e-12, no adaptive step),
  which EXUDYN's users do not run by default; clearly labelled, not used for the targets.

Models: (1) the spatial slider-crank of Sec. 11 of the paper, 5 s at h = 1e-2: se3dyn in the
paper's node form (``examples.slider_crank()``, the target) and the bodies form
(``examples.slider_crank_bodies()``); EXUDYN three rigid bodies (Euler-parameter nodes, its
default), four joints at their points, the 0.015 N m crank torque for t < 2 s as a load user
function. (2) The N-link spherical chain of ``chain_scaling.py`` (links 0.1 m, 1 kg, slender-rod
inertia, spherical joints attached with ``at=``, released horizontal, gravity -z), h = 1e-3:
N = 100 and 1000 for 1 s; N = 10^4 for 0.1 s of model time only (both codes), to keep the run
short.

Accuracy beside every time: each model gets a converged reference, se3dyn (node form for the
slider-crank) at a step 16x (slider-crank) or 8x (chains) smaller, checked against EXUDYN at the
same small step with tight tolerances (modified Newton, relative 1e-10, absolute 1e-12); the
agreement of the two small-step solutions is printed and must be far below the errors reported.
Errors: slider-crank rod centre of mass (node 6) at t = 1 s and crank angle at t = 2 s; chain:
tip position at the final time (and the largest error over all link ends).

Timings and the targets of issue 12 (PASS/MISS printed beside each):

1. Slider-crank, node form: a script's first ``simulate`` in a fresh process (subprocess:
   import, build, first simulate timed separately inside it; median over ``--processes``) <=
   1.0x EXUDYN's solve (``SolveDynamic``, median of ``--repeats`` in this process); warm
   (``simulate(model, ...)`` repeated in this process, compile included, median) <= 0.5x.
   The same for the bodies form (reported, same targets).
2. 1000-link chain, 1 s, h = 1e-3: se3dyn **as its users run it** <= 0.3x EXUDYN's
   ``SolveDynamic`` (issue 28): in a fresh process, ``sd.simulate(model, 1.0, 1e-3,
   rho_inf=0.9)`` on the model (``compile_model`` and the one-time set-up included) with every
   step stored (the default ``output_every=1``: 1001 rows), timed from the call; the same call
   again in that process (warm) beside it. The earlier figure stays as a second, labelled
   line: the solve alone with 10 stored rows, the model building, ``compile_model`` and the
   one-time set-up of the first ``simulate`` (a one-step run) timed apart.
3. The README's main job ``se3dyn run examples/slider_crank.yaml --out DIR --quiet`` as a whole
   process <= 10x EXUDYN's whole process on the same model (``python -c``: import exudyn, build
   the slider-crank, solve 5 s) with every cache empty, and <= 1.5x warm. There are no kernel
   caches any more (the C++ engine is compiled at install), so "cold" is a new process with no
   Python bytecode cache either (``PYTHONPYCACHEPREFIX`` = a new empty directory, for both codes
   alike: every module, the standard library included, is compiled from source); "warm" is a new
   process with the bytecode caches filled. The operating system's file cache cannot be emptied
   on this shared machine. Also ``python -c "import se3dyn"`` / ``"import exudyn"``, and, for
   reference, EXUDYN's process given the process settings the ``se3dyn`` command makes for
   itself (``se3dyn._command_startup``: idle BLAS threads asleep, the garbage collector paused
   while the modules load and the objects frozen at exit), which compares the work alone. Every
   subprocess of this script writes bytecode caches as Python does by default:
   ``PYTHONDONTWRITEBYTECODE`` is removed from their environment (set in some shells, it kept
   the caches of se3dyn's own modules, which an editable install runs from the source tree,
   from ever being written, so that every "warm" process and every "fresh process" of section 1
   compiled them from source; installed packages such as EXUDYN, numpy and a non-editable
   se3dyn have theirs written by pip at install).
4. Cost per step vs N = 100 ... 10^4 links (``chain_scaling.scaling_row``: set-up excluded,
   (wall(0.1 s) - wall(0.02 s)) / 80 steps, each the minimum of two runs, se3dyn defaults):
   fitted exponent <= 1.1; peak RSS
   of the N = 10^4 chain (0.1 s, every 10th step stored) in its own subprocess
   (``chain_scaling.py --memory``) <= 600 MB. The peak is VmHWM of /proc/self/status in that
   process: ``resource.getrusage`` maxrss of a child started by vfork (as ``subprocess`` does)
   inherits its parent's peak through execve, so after the big runs of this script it would
   report this script's own peak; it is printed beside, for the record.

The machine is shared (2 cores, other jobs running): the load average is recorded with every
section; se3dyn and EXUDYN runs are interleaved so that both see the same load.

Output: a table on stdout, copied to ``benchmarks/results/compare_exudyn.txt``; everything in
``benchmarks/results/compare_exudyn.json`` (versions, machine, git revision, load averages, date).

Run (about 15 min on this machine):
    .venv/bin/python benchmarks/compare_exudyn.py [--repeats 15] [--processes 9]
        [--cold-processes 5] [--chain-repeats 3] [--no-scaling] [--no-chain-reference]
        [--out PATH] [--only-slider-crank]
    (--only-slider-crank: section 1 only, a few seconds; write --out elsewhere to keep the full
    run's results)
(PASS/MISS is judged on medians; the minimum over the repeats and its ratio are printed beside,
since on a loaded machine the minimum is the better estimate of the unloaded cost.)
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

RHO = 0.9
G = (0.0, 0.0, -9.81)
SC_T_END, SC_H = 5.0, 1e-2          # slider-crank run (Sec. 11.2)
SC_REF_FACTOR = 16                   # reference step h / 16 (2 s of model time)
CHAIN_H = 1e-3
CHAIN_REF_FACTOR = 8                 # reference step h / 8
TARGETS = {"slider_crank_first": 1.0, "slider_crank_warm": 0.5, "chain1000": 0.3,
           "readme_cold": 10.0, "readme_warm": 1.5, "exponent": 1.1, "rss_MB": 600.0}


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


def load() -> list[float]:
    import os

    return [round(x, 2) for x in os.getloadavg()]


def load_str() -> str:
    return "load " + " ".join(f"{x:.2f}" for x in load())


def median(xs):
    import statistics

    return statistics.median(xs)


def dist(a, b) -> float:
    return float(np.linalg.norm(np.subtract(a, b)))


def verdict(value: float, target: float) -> str:
    return "PASS" if value <= target else "MISS"


# ------------------------------------------------------------------------------------------------
# se3dyn
def se3_sc_model(form: str):
    from se3dyn.model.examples import slider_crank, slider_crank_bodies

    return slider_crank() if form == "nodes" else slider_crank_bodies()


def se3_sc_outputs(res) -> dict:
    """Rod COM (node 6) at t = 1 s and crank angle (node 3) at t = 2 s of a se3dyn result."""
    return {"rod_com_t1": at_time(res.t, res.node_position("6"), 1.0).tolist(),
            "crank_angle_t2": float(at_time(res.t, crank_angle(res.node_rotation("3")), 2.0))}


def se3_slider_crank(form: str = "nodes", model=None, t_end: float = SC_T_END,
                     h: float = SC_H) -> dict:
    """``sd.simulate(model, t_end, h, rho_inf=0.9)`` at se3dyn's defaults, timed; ``model`` may be
    a Model (compiled inside simulate, as a user script does) or a compiled System."""
    import se3dyn as sd

    model = se3_sc_model(form) if model is None else model
    t0 = time.perf_counter()
    res = sd.simulate(model, t_end, h, rho_inf=RHO)
    solve = time.perf_counter() - t0
    st = res.stats
    return {"form": form, "solve_s": solve, **se3_sc_outputs(res),
            "steps": int(st["steps"]), "newton_iterations": int(st["newton_iterations"]),
            "factorizations": int(st.get("factorizations", 0)),
            "matrix_size": int(st["matrix_size"]), "formulation": st["formulation"],
            "engine": st["engine"]}


def se3_chain_model(n_links: int):
    """The se3dyn chain of benchmarks/chain_scaling.py (one model definition for both scripts)."""
    from chain_scaling import chain

    return chain(n_links)


def se3_link_ends(res, n_links: int) -> np.ndarray:
    """End points of all links at the last stored time, (N, 3)."""
    names = res.system.node_names
    idx = [names.index(f"b{i}") for i in range(n_links)]
    H = res.H[-1, idx]
    return H[:, :3, 3] + 0.05 * H[:, :3, 0]


def se3_chain(n_links: int, t_end: float, h: float = CHAIN_H, threads: int | None = None,
              **kw) -> dict:
    """Build, compile, set up (one-step run) and solve the chain (se3dyn defaults), timed;
    ``threads``: the element kernels' threads for this run (default: se3dyn's)."""
    import se3dyn as sd

    if threads is not None:
        sd.set_threads(threads)
        try:
            return {**se3_chain(n_links, t_end, h, **kw), "threads": threads}
        finally:
            sd.set_threads()

    t0 = time.perf_counter()
    model = se3_chain_model(n_links)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    system = sd.compile_model(model)
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    sd.simulate(system, h, h, rho_inf=RHO, **kw)   # one-time set-up of the first simulate
    setup = time.perf_counter() - t0
    nsteps = round(t_end / h)
    t0 = time.perf_counter()
    res = sd.simulate(system, t_end, h, rho_inf=RHO, output_every=max(1, nsteps // 10), **kw)
    solve = time.perf_counter() - t0
    ends = se3_link_ends(res, n_links)
    st = res.stats
    return {"N": n_links, "t_end": t_end, "h": h, "build_s": build, "compile_s": compile_s,
            "setup_s": setup, "solve_s": solve, "t_final": float(res.t[-1]),
            "tip_final": ends[-1].tolist(), "link_ends_final": ends,
            "steps": int(st["steps"]), "newton_iterations": int(st["newton_iterations"]),
            "factorizations": int(st.get("factorizations", 0)),
            "matrix_size": int(st["matrix_size"]), "formulation": st["formulation"],
            "newton": kw.get("newton", "modified"), "threads": sd.get_threads()}


# ------------------------------------------------------------------------------------------------
# EXUDYN
_USER_CHAIN = """
import json, sys, time
t0 = time.perf_counter()
import numpy as np
import se3dyn as sd
sys.path.insert(0, {here!r})
from chain_scaling import chain
t_import = time.perf_counter() - t0
model = chain({n})
t0 = time.perf_counter()
res = sd.simulate(model, {t_end!r}, {h!r}, rho_inf={rho!r})   # what a user writes: every row
first = time.perf_counter() - t0
t0 = time.perf_counter()
sd.simulate(model, {t_end!r}, {h!r}, rho_inf={rho!r})
warm = time.perf_counter() - t0
names = res.system.node_names
idx = [names.index(f"b{{i}}") for i in range({n})]
H = res.H[-1, idx]
ends = H[:, :3, 3] + 0.05 * H[:, :3, 0]
print(json.dumps({{"first_s": first, "warm_s": warm, "import_s": t_import, "rows": len(res.t),
                  "steps": res.stats["steps"], "newton_iterations": res.stats["newton_iterations"],
                  "threads": sd.get_threads(), "tip_final": ends[-1].tolist(),
                  "link_ends_final": ends.tolist()}}))
"""


def se3_chain_user(n_links: int, t_end: float, h: float = CHAIN_H) -> dict:
    """The chain as a user runs it (issue 28): in a fresh process, ``sd.simulate(model, t_end,
    h, rho_inf=0.9)`` on the model (compile included) with every step stored (the default
    ``output_every=1``), timed from the call; then the same call again (warm)."""
    from pathlib import Path

    code = _USER_CHAIN.format(here=str(Path(__file__).resolve().parent), n=n_links,
                              t_end=t_end, h=h, rho=RHO)
    _, inner = run_process([sys.executable, "-c", code], Path.cwd(), cold=False)
    inner["link_ends_final"] = np.asarray(inner["link_ends_final"])
    return inner


def exu_default_settings() -> dict:
    """EXUDYN's defaults as read from ``exu.SimulationSettings()`` (and CreateRigidBody)."""
    import inspect

    import exudyn as exu

    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ga = ti.generalizedAlpha
    nw = ti.newton
    out = {
        "timeIntegration.solverType": str(ti.solverType),
        "generalizedAlpha.spectralRadius": ga.spectralRadius,
        "generalizedAlpha.useIndex2Constraints": bool(ga.useIndex2Constraints),
        "generalizedAlpha.useNewmark": bool(ga.useNewmark),
        "generalizedAlpha.computeInitialAccelerations": bool(ga.computeInitialAccelerations),
        "generalizedAlpha.lieGroupAddTangentOperator": bool(ga.lieGroupAddTangentOperator),
        "newton.useModifiedNewton": bool(nw.useModifiedNewton),
        "newton.relativeTolerance": nw.relativeTolerance,
        "newton.absoluteTolerance": nw.absoluteTolerance,
        "newton.maxIterations": nw.maxIterations,
        "newton.maxModifiedNewtonIterations": nw.maxModifiedNewtonIterations,
        "newton.modifiedNewtonContractivity": nw.modifiedNewtonContractivity,
        "newton.modifiedNewtonJacUpdatePerStep": bool(nw.modifiedNewtonJacUpdatePerStep),
        "newton.adaptInitialResidual": bool(nw.adaptInitialResidual),
        "newton.numericalDifferentiation.forODE2": bool(nw.numericalDifferentiation.forODE2),
        "newton.numericalDifferentiation.forAE": bool(nw.numericalDifferentiation.forAE),
        "timeIntegration.adaptiveStep": bool(ti.adaptiveStep),
        "timeIntegration.reuseConstantMassMatrix": bool(ti.reuseConstantMassMatrix),
        "linearSolver.solverType": str(ss.linearSolver.solverType),
        "parallel.numberOfThreads": ss.parallel.numberOfThreads,
        "solution.file.write": bool(ss.solution.file.write),
        "solution.file.writePeriod": ss.solution.file.writePeriod,
        "solution.sensors.writePeriod": ss.solution.sensors.writePeriod,
    }
    try:
        from exudyn.misc.mainSystemExtensions import MainSystemCreateRigidBody

        node = inspect.signature(MainSystemCreateRigidBody).parameters["nodeType"].default
        out["CreateRigidBody.nodeType"] = str(node)
    except Exception:  # noqa: BLE001 - informative only
        out["CreateRigidBody.nodeType"] = "?"
    return out


def exu_settings(t_end: float, h: float, mode: str = "defaults", sparse: bool = False):
    """EXUDYN simulation settings. ``defaults``: only what a user must set; ``fullnewton``: the old
    setting (full Newton, 1e-10/1e-12, no adaptive step), for continuity; ``tight``: defaults with
    tolerances 1e-10/1e-12 (the small-step reference checks)."""
    import exudyn as exu

    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.endTime = t_end
    ti.numberOfSteps = int(round(t_end / h))
    if ti.generalizedAlpha.spectralRadius != RHO:      # EXUDYN 1.13.6: default 0.9 already
        ti.generalizedAlpha.spectralRadius = RHO
    ss.solution.file.write = False                     # results in memory (sensors)
    ss.solution.sensors.writePeriod = h
    if sparse:                                         # EXUDYN warns: > 1000 coordinates
        ss.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    if mode == "fullnewton":
        ti.newton.useModifiedNewton = False
        ti.newton.relativeTolerance = 1e-10
        ti.newton.absoluteTolerance = 1e-12
        ti.adaptiveStep = False
    elif mode == "tight":
        ti.newton.relativeTolerance = 1e-10
        ti.newton.absoluteTolerance = 1e-12
    elif mode != "defaults":
        raise ValueError(mode)
    return ss


def exu_counters(mbs) -> dict:
    try:
        it = mbs.sys["dynamicSolver"].it
        return {"newton_iterations": int(it.newtonStepsCount),
                "jacobians": int(it.newtonJacobiCount),
                "step_index": int(it.currentStepIndex),
                "modified_newton_restarts": int(it.rejectedModifiedNewtonSteps)}
    except Exception:  # noqa: BLE001 - statistics are optional
        return {}


def exu_size(mbs) -> int:
    sd_ = mbs.systemData
    return int(len(sd_.GetODE2Coordinates()) + len(sd_.GetAECoordinates()))


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
    s_rod = mbs.AddSensor(eu.SensorBody(bodyNumber=rod, storeInternal=True, writeToFile=False,
                                        outputVariableType=exu.OutputVariableType.Position))
    s_crank = mbs.AddSensor(eu.SensorBody(
        bodyNumber=crank, storeInternal=True, writeToFile=False,
        outputVariableType=exu.OutputVariableType.RotationMatrix))
    mbs.Assemble()
    return SC, mbs, s_rod, s_crank


def exu_slider_crank(mode: str = "defaults", t_end: float = SC_T_END, h: float = SC_H) -> dict:
    t0 = time.perf_counter()
    SC, mbs, s_rod, s_crank = exu_slider_crank_build()
    build = time.perf_counter() - t0
    ss = exu_settings(t_end, h, mode)
    t0 = time.perf_counter()
    ok = mbs.SolveDynamic(ss)
    solve = time.perf_counter() - t0
    if not ok:
        raise RuntimeError(f"EXUDYN slider-crank ({mode}) did not converge")
    rod = mbs.GetSensorStoredData(s_rod)
    rot = mbs.GetSensorStoredData(s_crank)
    ang = crank_angle(rot[:, 1:].reshape(-1, 3, 3))
    return {"mode": mode, "build_s": build, "solve_s": solve,
            "rod_com_t1": at_time(rod[:, 0], rod[:, 1:4], 1.0).tolist(),
            "crank_angle_t2": float(at_time(rot[:, 0], ang, 2.0)),
            "steps": ss.timeIntegration.numberOfSteps, **exu_counters(mbs),
            "equations": exu_size(mbs)}


def exu_chain(n_links: int, t_end: float, mode: str = "defaults", h: float = CHAIN_H) -> dict:
    import exudyn as exu
    import exudyn.utilities as eu

    t0 = time.perf_counter()
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.CreateGround(referencePosition=[0, 0, 0])
    J = 1.0 * 0.1**2 / 12.0
    inertia = eu.RigidBodyInertia(mass=1.0, inertiaTensor=np.diag([1e-4 * J, J, J]))
    prev = ground
    bodies = []
    for i in range(n_links):
        x0 = 0.1 * i
        body = mbs.CreateRigidBody(referencePosition=[x0 + 0.05, 0.0, 0.0], inertia=inertia,
                                   gravity=list(G))
        mbs.CreateSphericalJoint(itemNumbers=[prev, body], position=[x0, 0.0, 0.0],
                                 useGlobalFrame=True)
        bodies.append(body)
        prev = body
    mbs.Assemble()
    build = time.perf_counter() - t0
    ss = exu_settings(t_end, h, mode, sparse=True)
    t0 = time.perf_counter()
    ok = mbs.SolveDynamic(ss)
    solve = time.perf_counter() - t0
    if not ok:
        raise RuntimeError(f"EXUDYN chain N={n_links} ({mode}) did not converge")
    ends = np.array([mbs.GetObjectOutputBody(b, exu.OutputVariableType.Position,
                                             localPosition=[0.05, 0.0, 0.0],
                                             configuration=exu.ConfigurationType.Current)
                     for b in bodies])
    return {"N": n_links, "t_end": t_end, "h": h, "mode": mode, "build_s": build,
            "solve_s": solve, "tip_final": ends[-1].tolist(), "link_ends_final": ends,
            "t_final": float(mbs.systemData.GetTime()),
            "steps": ss.timeIntegration.numberOfSteps, **exu_counters(mbs),
            "equations": exu_size(mbs)}


def exu_process_job(same_settings: bool = False) -> None:
    """Body of EXUDYN's whole-process run (``python -c``): import, build the slider-crank, solve
    5 s at its defaults; prints the inner timings as one JSON line. ``same_settings``: the
    process settings the ``se3dyn`` command makes for itself (``se3dyn._command_startup``;
    the caller set the rest before numpy loaded): the collector resumes here, the modules'
    objects frozen."""
    t0 = time.perf_counter()
    import exudyn  # noqa: F401
    import exudyn.utilities  # noqa: F401
    if same_settings:
        import gc

        gc.freeze()
        gc.enable()
    t1 = time.perf_counter()
    SC, mbs, s_rod, s_crank = exu_slider_crank_build()
    t2 = time.perf_counter()
    ok = mbs.SolveDynamic(exu_settings(SC_T_END, SC_H))
    t3 = time.perf_counter()
    import json

    print(json.dumps({"import_s": t1 - t0, "build_s": t2 - t1, "first_solve_s": t3 - t2,
                      "ok": bool(ok)}))


# ------------------------------------------------------------------------------------------------
# subprocesses
SE3_FIRST_JOB = """
import json, time
t0 = time.perf_counter()
import se3dyn as sd
from se3dyn.model.examples import {fn}
sd.simulate  # the package face loads its modules on first use: loading them is the import's
t1 = time.perf_counter()
model = {fn}()
t2 = time.perf_counter()
sd.simulate(model, 5.0, 1e-2, rho_inf=0.9)
t3 = time.perf_counter()
sd.simulate(model, 5.0, 1e-2, rho_inf=0.9)
t4 = time.perf_counter()
print(json.dumps({{"import_s": t1 - t0, "build_s": t2 - t1, "first_simulate_s": t3 - t2,
                  "second_simulate_s": t4 - t3}}))
"""


def process_commands(here, repo) -> dict:
    """The whole-process commands (argv, cwd) of section 3 and the first-simulate jobs."""
    from pathlib import Path

    py = sys.executable
    cli = str(Path(py).parent / "se3dyn")
    exu_job = f"import sys; sys.path.insert(0, {str(here)!r}); import compare_exudyn as c; " \
              "c.exu_process_job()"
    # EXUDYN's process given the se3dyn command's process settings (idle BLAS threads asleep,
    # the collector paused while loading, the objects frozen at exit): the work compared alone
    same = ("import atexit, gc, os; os.environ.setdefault('OPENBLAS_THREAD_TIMEOUT', '4'); "
            "gc.disable(); atexit.register(gc.freeze); " + exu_job.replace("job()", "job(True)"))
    return {
        "python -c pass": [py, "-c", "pass"],
        "python -c 'import se3dyn'": [py, "-c", "import se3dyn"],
        "python -c 'import exudyn'": [py, "-c", "import exudyn"],
        "se3dyn run examples/slider_crank.yaml --out DIR --quiet":
            [cli, "run", str(repo / "examples" / "slider_crank.yaml"), "--out", "{tmp}",
             "--quiet"],
        "EXUDYN process: import, build slider-crank, solve 5 s": [py, "-c", exu_job],
        "  the same, with the se3dyn command's process settings": [py, "-c", same],
        "se3dyn first-simulate job (nodes)":
            [py, "-c", SE3_FIRST_JOB.format(fn="slider_crank")],
        "se3dyn first-simulate job (bodies)":
            [py, "-c", SE3_FIRST_JOB.format(fn="slider_crank_bodies")],
    }


def run_process(argv: list[str], cwd, cold: bool, full: bool = False):
    """Wall time of one process; ``cold``: a new empty bytecode cache (PYTHONPYCACHEPREFIX)."""
    import json
    import os
    import shutil
    import subprocess
    import tempfile

    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # caches are written, as by default (docstring)
    tmp = tempfile.mkdtemp(prefix="cmpexu_")
    argv = [a.replace("{tmp}", os.path.join(tmp, "out")) for a in argv]
    if cold:
        env["PYTHONPYCACHEPREFIX"] = os.path.join(tmp, "pycache")
    try:
        t0 = time.perf_counter()
        proc = subprocess.run(argv, cwd=str(cwd), env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if proc.returncode:
        raise RuntimeError(f"{argv[:3]} failed: {proc.stderr.strip()[-500:]}")
    inner = None
    lines = proc.stdout.strip().splitlines()
    if lines and lines[-1].startswith("{"):
        inner = json.loads(lines[-1])
    if full:
        return wall, inner, proc.stdout, proc.stderr
    return wall, inner


# ------------------------------------------------------------------------------------------------
# reporting
class Tee:
    """Copy of stdout into a string (written to the .txt file at the end)."""

    def __init__(self, stream):
        self.stream, self.parts = stream, []

    def write(self, s):
        self.stream.write(s)
        self.parts.append(s)
        return len(s)

    def flush(self):
        self.stream.flush()

    def text(self) -> str:
        return "".join(self.parts)


def jsonable(obj):
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj


def strip_arrays(d: dict) -> dict:
    return {k: v for k, v in d.items() if k != "link_ends_final"}


def environment(repo) -> dict:
    import datetime
    import hashlib
    import os
    import platform
    import subprocess
    from pathlib import Path

    import exudyn
    import scipy

    import se3dyn
    from se3dyn._core import _engine as eng

    def git(*args):
        try:
            return subprocess.run(["git", *args], cwd=str(repo), capture_output=True,
                                  text=True).stdout.strip()
        except OSError:
            return "?"

    so = eng.__file__
    code = hashlib.sha256(open(so, "rb").read())
    for f in sorted(Path(se3dyn.__file__).parent.rglob("*.py")):
        code.update(f.read_bytes())
    cpu = "?"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"platform": platform.platform(), "machine": platform.machine(),
                    "cpu": cpu, "cpu_count": os.cpu_count()},
        "versions": {"python": platform.python_version(), "numpy": np.__version__,
                     "scipy": scipy.__version__, "se3dyn": se3dyn.__version__,
                     "exudyn": exudyn.__version__},
        "git": {"head": git("rev-parse", "HEAD"),
                "dirty": git("status", "--porcelain", "--untracked-files=no").splitlines()},
        "se3dyn_engine": {"file": so, "mtime": os.path.getmtime(so),
                          "built_native": bool(getattr(eng, "built_native", False)),
                          "sha256": hashlib.sha256(open(so, "rb").read()).hexdigest()[:16],
                          "code_sha256": code.hexdigest()[:16],
                          "threads": se3dyn.get_threads()},
    }


# ------------------------------------------------------------------------------------------------
def section_slider_crank(a, report) -> None:
    import se3dyn as sd

    print(f"\n== 1. slider-crank (Sec. 11): {SC_T_END:g} s, h = {SC_H:g}, rho_inf = {RHO} "
          f"[{load_str()}] ==")
    models = {"nodes": se3_sc_model("nodes"), "bodies": se3_sc_model("bodies")}
    systems = {k: sd.compile_model(m) for k, m in models.items()}
    runs = {k: [] for k in ("se3_nodes", "se3_bodies", "se3_nodes_system", "se3_bodies_system",
                            "exu_defaults", "exu_fullnewton")}
    # one untimed round first (first calls in this process), then interleaved repeats
    for rep in range(a.repeats + 1):
        r = {"se3_nodes": se3_slider_crank("nodes", models["nodes"]),
             "se3_bodies": se3_slider_crank("bodies", models["bodies"]),
             "se3_nodes_system": se3_slider_crank("nodes", systems["nodes"]),
             "se3_bodies_system": se3_slider_crank("bodies", systems["bodies"]),
             "exu_defaults": exu_slider_crank("defaults"),
             "exu_fullnewton": exu_slider_crank("fullnewton")}
        if rep:
            for k, v in r.items():
                runs[k].append(v)
    warm = {}
    for k, rs in runs.items():
        w = dict(rs[-1])
        w["solve_s_all"] = [x["solve_s"] for x in rs]
        w["solve_s"] = median(w["solve_s_all"])
        warm[k] = w
    load_warm = load()

    # fresh processes: the se3dyn first-simulate jobs and EXUDYN's process, interleaved
    here, repo = a.here, a.repo
    cmds = process_commands(here, repo)
    fresh = {"nodes": [], "bodies": [], "exu": []}
    jobs = (("nodes", "se3dyn first-simulate job (nodes)"),
            ("bodies", "se3dyn first-simulate job (bodies)"),
            ("exu", "EXUDYN process: import, build slider-crank, solve 5 s"))
    for _, name in jobs:  # fill the bytecode caches (not timed)
        run_process(cmds[name], repo, cold=False)
    for _ in range(a.processes):
        for key, name in jobs:
            wall, inner = run_process(cmds[name], repo, cold=False)
            inner["process_wall_s"] = wall
            fresh[key].append(inner)
    load_fresh = load()

    # converged reference: se3dyn node form at h/16 (2 s), checked against EXUDYN (tight) there
    h_ref = SC_H / SC_REF_FACTOR
    ref = se3_slider_crank("nodes", models["nodes"], t_end=2.0, h=h_ref)
    ref_half = se3_slider_crank("nodes", models["nodes"], t_end=2.0, h=2 * h_ref)
    ref_exu = exu_slider_crank("tight", t_end=2.0, h=h_ref)
    check = {"exudyn_tight_same_step": {"rod_com_t1_m": dist(ref["rod_com_t1"],
                                                              ref_exu["rod_com_t1"]),
                                        "crank_angle_t2_rad": abs(ref["crank_angle_t2"]
                                                                  - ref_exu["crank_angle_t2"])},
             "se3dyn_2h_ref": {"rod_com_t1_m": dist(ref["rod_com_t1"], ref_half["rod_com_t1"]),
                               "crank_angle_t2_rad": abs(ref["crank_angle_t2"]
                                                         - ref_half["crank_angle_t2"])}}

    def err(v):
        return {"rod_com_t1_m": dist(v["rod_com_t1"], ref["rod_com_t1"]),
                "crank_angle_t2_rad": abs(v["crank_angle_t2"] - ref["crank_angle_t2"])}

    exu_solve = warm["exu_defaults"]["solve_s"]
    rows = []
    exu_min = min(warm["exu_defaults"]["solve_s_all"])
    print(f"{'code / case (median; min of the repeats beside)':56s} {'time s':>9s} {'x EXU':>7s} "
          f"{'target':>10s} {'min s':>8s} {'x EXU':>6s} {'rod COM err m':>13s} "
          f"{'angle err rad':>13s} {'its':>5s} {'fac/jac':>7s}")

    def line(label, ts, key_err, target=None, its="", fac=""):
        t, t_min = median(ts), min(ts)
        ratio, ratio_min = t / exu_solve, t_min / exu_min
        tgt = f"<={target:g} {verdict(ratio, target)}" if target is not None else ""
        e = err(key_err)
        print(f"{label:56s} {t:9.4f} {ratio:7.2f} {tgt:>10s} {t_min:8.4f} {ratio_min:6.2f} "
              f"{e['rod_com_t1_m']:13.2e} {e['crank_angle_t2_rad']:13.2e} {its!s:>5s} "
              f"{fac!s:>7s}")
        rows.append({"case": label, "time_s": t, "ratio_to_exudyn_defaults_solve": ratio,
                     "time_min_s": t_min, "ratio_of_minima": ratio_min, "times_s": list(ts),
                     "target": target, "verdict": verdict(ratio, target) if target else None,
                     "error": e})

    ed, ef = warm["exu_defaults"], warm["exu_fullnewton"]
    line("EXUDYN defaults: SolveDynamic (warm)", ed["solve_s_all"], ed,
         its=ed.get("newton_iterations", ""), fac=ed.get("jacobians", ""))
    line("EXUDYN full Newton 1e-10 (continuity): SolveDynamic", ef["solve_s_all"], ef,
         its=ef.get("newton_iterations", ""), fac=ef.get("jacobians", ""))
    line("EXUDYN first solve in a fresh process",
         [x["first_solve_s"] for x in fresh["exu"]], ed)
    for form in ("nodes", "bodies"):
        w, ws = warm[f"se3_{form}"], warm[f"se3_{form}_system"]
        line(f"se3dyn {form}: first simulate, fresh process",
             [x["first_simulate_s"] for x in fresh[form]], w,
             target=TARGETS["slider_crank_first"], its=w["newton_iterations"],
             fac=w["factorizations"])
        line(f"se3dyn {form}: simulate(model) warm", w["solve_s_all"], w,
             target=TARGETS["slider_crank_warm"], its=w["newton_iterations"],
             fac=w["factorizations"])
        line(f"se3dyn {form}: simulate(compiled System) warm", ws["solve_s_all"], ws)
    for form in ("nodes", "bodies"):
        fr = fresh[form]
        print(f"  se3dyn {form} fresh process (median of {len(fr)}): import "
              f"{median([x['import_s'] for x in fr]):.3f} s, build "
              f"{median([x['build_s'] for x in fr]):.4f} s, first simulate "
              f"{median([x['first_simulate_s'] for x in fr]):.4f} s, second simulate "
              f"{median([x['second_simulate_s'] for x in fr]):.4f} s, process "
              f"{median([x['process_wall_s'] for x in fr]):.3f} s")
    fe = fresh["exu"]
    print(f"  EXUDYN fresh process (median of {len(fe)}): import "
          f"{median([x['import_s'] for x in fe]):.3f} s, build "
          f"{median([x['build_s'] for x in fe]):.4f} s, first solve "
          f"{median([x['first_solve_s'] for x in fe]):.4f} s, process "
          f"{median([x['process_wall_s'] for x in fe]):.3f} s")
    same, half = check["exudyn_tight_same_step"], check["se3dyn_2h_ref"]
    print(f"  reference: se3dyn node form at h = {h_ref:g} (2 s): rod COM t=1 "
          f"{np.round(ref['rod_com_t1'], 9)}, crank angle t=2 {ref['crank_angle_t2']:.9f} rad; "
          f"vs EXUDYN (tight) at the same step: {same['rod_com_t1_m']:.1e}"
          f" m, {same['crank_angle_t2_rad']:.1e} rad; vs se3dyn at "
          f"h = {2 * h_ref:g}: {half['rod_com_t1_m']:.1e} m, "
          f"{half['crank_angle_t2_rad']:.1e} rad")
    print(f"  [{load_str()}; during warm runs {load_warm}, during fresh processes {load_fresh}]")
    report["slider_crank"] = {
        "t_end": SC_T_END, "h": SC_H, "rows": rows,
        "warm": warm, "fresh_processes": fresh, "reference": {
            "se3dyn_nodes_h": h_ref, "se3dyn": ref, "se3dyn_2h": ref_half, "exudyn_tight": ref_exu,
            "agreement": check},
        "load_average": {"warm": load_warm, "fresh": load_fresh, "end": load()}}


def section_processes(a, report) -> None:
    print(f"\n== 3. whole processes: README main job vs EXUDYN's process [{load_str()}] ==")
    cmds = process_commands(a.here, a.repo)
    names = ["python -c pass", "python -c 'import se3dyn'", "python -c 'import exudyn'",
             "se3dyn run examples/slider_crank.yaml --out DIR --quiet",
             "EXUDYN process: import, build slider-crank, solve 5 s",
             "  the same, with the se3dyn command's process settings"]
    res = {}
    for cold, n in ((True, a.cold_processes), (False, a.processes)):
        tag = "cold" if cold else "warm"
        if not cold:
            for name in names:                    # fill the bytecode caches
                run_process(cmds[name], a.repo, cold=False)
        walls = {name: [] for name in names}
        for _ in range(n):
            for name in names:
                walls[name].append(run_process(cmds[name], a.repo, cold=cold)[0])
        res[tag] = {name: {"all_s": w, "median_s": median(w)} for name, w in walls.items()}
        res[tag]["load_average"] = load()
    se3, exu = names[3], names[4]
    print(f"{'process (wall time)':58s} {'cold s':>8s} {'min':>7s} {'warm s':>8s} {'min':>7s}")
    for name in names:
        c, w = res["cold"][name], res["warm"][name]
        print(f"{name:58s} {c['median_s']:8.3f} {min(c['all_s']):7.3f} {w['median_s']:8.3f} "
              f"{min(w['all_s']):7.3f}")
    rc = res["cold"][se3]["median_s"] / res["cold"][exu]["median_s"]
    rw = res["warm"][se3]["median_s"] / res["warm"][exu]["median_s"]
    res["ratio_cold_of_minima"] = min(res["cold"][se3]["all_s"]) / min(res["cold"][exu]["all_s"])
    res["ratio_warm_of_minima"] = min(res["warm"][se3]["all_s"]) / min(res["warm"][exu]["all_s"])
    print(f"README job / EXUDYN process: cold {rc:.2f} (target <= {TARGETS['readme_cold']:g}: "
          f"{verdict(rc, TARGETS['readme_cold'])}), warm {rw:.2f} (target <= "
          f"{TARGETS['readme_warm']:g}: {verdict(rw, TARGETS['readme_warm'])}) (medians; ratios "
          f"of minima {res['ratio_cold_of_minima']:.2f} / {res['ratio_warm_of_minima']:.2f})")
    print(f"  cold = new process with an empty bytecode cache (PYTHONPYCACHEPREFIX), "
          f"median of {a.cold_processes}; warm = new process, caches filled, median of "
          f"{a.processes} [{load_str()}; cold {res['cold']['load_average']}, warm "
          f"{res['warm']['load_average']}]")
    same = names[5]
    rs = res["warm"][se3]["median_s"] / res["warm"][same]["median_s"]
    rs_min = min(res["warm"][se3]["all_s"]) / min(res["warm"][same]["all_s"])
    print(f"  warm, against EXUDYN's process given the se3dyn command's process settings "
          f"(OPENBLAS_THREAD_TIMEOUT=4, collector paused while loading, objects frozen at "
          f"exit): {rs:.2f} (medians; minima {rs_min:.2f}), the work of the two alone")
    res["ratio_cold"], res["ratio_warm"] = rc, rw
    res["ratio_warm_same_settings"], res["ratio_warm_same_settings_of_minima"] = rs, rs_min
    res["readme_job_breakdown"] = readme_job_breakdown(a)
    report["processes"] = res


def readme_job_breakdown(a) -> dict:
    """Where the README job's process time goes (one warm run under ``-X importtime``): the
    top-level imports and the CLI's own 'wall time' (model compile + simulate + HDF5 writing)."""
    import re
    from pathlib import Path

    # the console script itself (its process settings are made for the `se3dyn` command only)
    argv = [sys.executable, "-X", "importtime", str(Path(sys.executable).parent / "se3dyn"),
            "run", str(a.repo / "examples" / "slider_crank.yaml"), "--out", "{tmp}", "--quiet"]
    wall, _, out, err = run_process(argv, a.repo, cold=False, full=True)
    top = {}     # self import time summed per top-level package, s
    for line in err.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        parts = line.split("|")
        self_us, name = parts[0].split(":", 1)[1], parts[2]
        pkg = name.strip().split(".")[0]
        top[pkg] = top.get(pkg, 0.0) + int(self_us) / 1e6
    m = re.search(r"wall time ([0-9.]+) s", out)
    cli_wall = float(m.group(1)) if m else float("nan")
    imports = sum(top.values())
    big = sorted(top.items(), key=lambda kv: -kv[1])[:6]
    print(f"  README job, one warm process under -X importtime: {wall:.3f} s; imports "
          f"{imports:.3f} s (self time by package: "
          + ", ".join(f"{k} {v:.3f}" for k, v in big) + f"); the CLI's "
          f"'wall time' (simulate + HDF5 streaming) {cli_wall:.2f} s; the rest (interpreter, "
          f"model file, exit) {wall - imports - cli_wall:.3f} s")
    return {"process_s": wall, "imports_s": imports, "top_level_imports_s": top,
            "cli_wall_time_s": cli_wall}


def section_chains(a, report) -> None:
    print(f"\n== 2. N-link spherical chain (at=), h = {CHAIN_H:g}, rho_inf = {RHO} "
          f"[{load_str()}] ==")
    out = {}
    for n in a.chain_sizes:
        t_end = 1.0
        # se3dyn and EXUDYN alternated chain_repeats times; the run of median solve time of
        # each code is reported (its solve times all kept), the minima beside
        ses, eds, users = [], [], []
        for _ in range(a.chain_repeats):
            users.append(se3_chain_user(n, t_end))
            ses.append(se3_chain(n, t_end))
            ld_se = load()
            eds.append(exu_chain(n, t_end, "defaults"))
            ld_ed = load()
        se, ed = median_run(ses), median_run(eds)
        user = dict(sorted(users, key=lambda r: r["first_s"])[(len(users) - 1) // 2])
        user["first_s_all"] = [r["first_s"] for r in users]
        ef = exu_chain(n, t_end, "fullnewton") if not a.no_fullnewton_chain else None
        ld_ef = load()
        # se3dyn on one thread (EXUDYN's default is one), once, for continuity with the runs
        # before the threaded element kernels
        one = se3_chain(n, t_end, threads=1) if se["threads"] > 1 else None
        case = {"se3dyn": se, "se3dyn_user": user, "se3dyn_1_thread": one,
                "exudyn_defaults": ed,
                "exudyn_fullnewton": ef,
                "load_average": {"se3dyn": ld_se, "exudyn_defaults": ld_ed,
                                 "exudyn_fullnewton": ld_ef}}
        if not a.no_chain_reference:
            h_ref = CHAIN_H / CHAIN_REF_FACTOR
            ref = se3_chain(n, t_end, h=h_ref)
            ref_exu = exu_chain(n, t_end, "tight", h=h_ref)
            case["reference"] = {"h": h_ref, "se3dyn": ref, "exudyn_tight": ref_exu,
                                 "load_average": load()}
            case["reference"]["agreement_tip_m"] = dist(ref["tip_final"], ref_exu["tip_final"])
            case["reference"]["agreement_max_link_end_m"] = float(np.max(np.linalg.norm(
                ref["link_ends_final"] - ref_exu["link_ends_final"], axis=1)))
        out[n] = case
        print_chain_case(n, case)
        report.setdefault("chain", {})[str(n)] = strip_case(case)
        save(a, report)
    # where se3dyn's time goes on N = 1000: 0.1 s in variants
    diag = []
    n_diag = max(a.chain_sizes)
    for kw in ({}, {"threads": 1}, {"formulation": "index3"}, {"newton": "full"}):
        r = se3_chain(n_diag, 0.1, **kw)
        diag.append({"variant": kw or "defaults", **strip_arrays(r), "load_average": load()})
    print(f"  se3dyn N = {n_diag}, 0.1 s, variants (set-up excluded; defaults: "
          f"{diag[0]['threads']} threads):")
    for d in diag:
        print(f"    {str(d['variant']):28s} {1e3 * d['solve_s'] / d['steps']:8.2f} ms/step, "
              f"{d['newton_iterations'] / d['steps']:.2f} its/step, "
              f"{d['factorizations'] / d['steps']:.2f} factorisations/step, matrix "
              f"{d['matrix_size']} [{' '.join(map(str, d['load_average']))}]")
    report["chain_diagnostics"] = {"N": n_diag, "t_end": 0.1, "variants": diag}


def median_run(runs: list[dict]) -> dict:
    """The run of median solve time (the lower middle one of an even count), with every run's
    solve time as ``solve_s_all``."""
    order = sorted(runs, key=lambda r: r["solve_s"])
    out = dict(order[(len(order) - 1) // 2])
    out["solve_s_all"] = [r["solve_s"] for r in runs]
    return out


def strip_case(case: dict) -> dict:
    out = {}
    for k, v in case.items():
        if isinstance(v, dict):
            out[k] = strip_case(v)
        elif isinstance(v, np.ndarray):
            continue
        else:
            out[k] = v
    return out


def print_chain_case(n: int, case: dict) -> None:
    se, ed, ef = case["se3dyn"], case["exudyn_defaults"], case["exudyn_fullnewton"]
    ref = case.get("reference")

    def errs(v):
        if not ref:
            return float("nan"), float("nan")
        r = ref["se3dyn"]
        return (dist(v["tip_final"], r["tip_final"]),
                float(np.max(np.linalg.norm(v["link_ends_final"] - r["link_ends_final"], axis=1))))

    one = case.get("se3dyn_1_thread")
    user = case.get("se3dyn_user")
    for v in (se, ed) + ((ef,) if ef else ()) + ((one,) if one else ()) + ((user,) if user else ()):
        v["error_tip_m"], v["error_max_link_end_m"] = errs(v)
    exu_t = ed["solve_s"]
    ld = case["load_average"]
    print(f"N = {n}, t_end = {se['t_end']:g} s ({se['steps']} steps); se3dyn matrix "
          f"{se['matrix_size']}, EXUDYN {ed['equations']} equations")
    print(f"  {'code / case':46s} {'time s':>9s} {'x EXU':>7s} {'target':>10s} {'ms/step':>8s} "
          f"{'its/step':>8s} {'fac/step':>8s} {'tip err m':>10s} {'max err m':>10s}")

    def line(label, t, v, target=None, its=None, fac=None):
        ratio = t / exu_t
        tgt = f"<={target:g} {verdict(ratio, target)}" if target is not None else ""
        its_s = f"{its / v['steps']:8.2f}" if its is not None else f"{'':8s}"
        fac_s = f"{fac / v['steps']:8.2f}" if fac is not None else f"{'':8s}"
        print(f"  {label:46s} {t:9.3f} {ratio:7.3f} {tgt:>10s} {1e3 * t / v['steps']:8.2f} "
              f"{its_s} {fac_s} {v.get('error_tip_m', float('nan')):10.2e} "
              f"{v.get('error_max_link_end_m', float('nan')):10.2e}")

    tgt = TARGETS["chain1000"] if n == 1000 else None
    line(f"EXUDYN defaults: SolveDynamic [{ld['exudyn_defaults'][0]}]", exu_t, ed,
         its=ed.get("newton_iterations"), fac=ed.get("jacobians"))
    if ef:
        line(f"EXUDYN full Newton 1e-10 (continuity) [{ld['exudyn_fullnewton'][0]}]",
             ef["solve_s"], ef, its=ef.get("newton_iterations"), fac=ef.get("jacobians"))
    if user:
        line(f"se3dyn as a user runs it ({user['threads']} thr.): fresh process, every row",
             user["first_s"], user, target=tgt, its=user["newton_iterations"])
        line("  the same call again in that process (warm)", user["warm_s"], user)
        se["ratio_user_first"] = user["first_s"] / exu_t
        se["ratio_user_warm"] = user["warm_s"] / exu_t
    line(f"se3dyn solve, 10 rows, set-up excluded ({se['threads']} thr.) [{ld['se3dyn'][0]}]",
         se["solve_s"], se, its=se["newton_iterations"], fac=se["factorizations"])
    if one:
        line("se3dyn 1 thread (EXUDYN's default; continuity)", one["solve_s"], one,
             its=one["newton_iterations"], fac=one["factorizations"])
    su = se["setup_s"] + se["solve_s"]
    line("se3dyn: first simulate (set-up + solve), 10 rows", su, se)
    tot = se["build_s"] + se["compile_s"] + su
    line("se3dyn: build + compile + set-up + solve", tot, se)
    print(f"  se3dyn set-up: build {se['build_s']:.3f} s, compile_model {se['compile_s']:.3f} s, "
          f"one-time set-up of the first simulate {se['setup_s']:.3f} s; EXUDYN build + "
          f"Assemble {ed['build_s']:.3f} s (total with solve {ed['build_s'] + exu_t:.3f} s: "
          f"se3dyn total / EXUDYN total {tot / (ed['build_s'] + exu_t):.3f})")
    se["ratio_solve"] = se["solve_s"] / exu_t
    se["ratio_first_simulate"] = su / exu_t
    if len(se.get("solve_s_all", [])) > 1:
        se["ratio_solve_of_minima"] = min(se["solve_s_all"]) / min(ed["solve_s_all"])
        print(f"  {len(se['solve_s_all'])} alternated runs each: se3dyn solve "
              f"{' '.join(f'{t:.2f}' for t in se['solve_s_all'])} s, EXUDYN "
              f"{' '.join(f'{t:.2f}' for t in ed['solve_s_all'])} s; medians above, ratio of "
              f"minima {se['ratio_solve_of_minima']:.3f}")
    se["ratio_total"] = tot / (ed["build_s"] + exu_t)
    if ref:
        print(f"  reference: se3dyn at h = {ref['h']:g} ({ref['se3dyn']['solve_s']:.1f} s); "
              f"EXUDYN (tight) at the same step ({ref['exudyn_tight']['solve_s']:.1f} s) agrees "
              f"to {ref['agreement_tip_m']:.1e} m at the tip, {ref['agreement_max_link_end_m']:.1e}"
              f" m at worst over the link ends [{ref['load_average'][0]}]")


def section_scaling(a, report) -> None:
    import subprocess

    from chain_scaling import fit_exponent, scaling_row

    print(f"\n== 4. cost per step vs N (se3dyn defaults, set-up excluded: (wall(0.1 s) - "
          f"wall(0.02 s)) / 80 steps) and N = 10^4 vs EXUDYN (0.1 s) [{load_str()}] ==")
    rows = []
    print(f"  {'N':>6s} {'matrix':>7s} {'ms/step':>9s} {'its/step':>8s} {'fac/step':>8s} "
          f"{'build s':>8s} {'compile s':>9s} {'set-up s':>8s} {'load':>5s}")
    for n in a.sizes:
        r = scaling_row(n)
        r["load_average"] = load()
        rows.append(r)
        print(f"  {n:6d} {r['matrix_size']:7d} {r['ms_per_step']:9.3f} "
              f"{r['newton_per_step']:8.2f} {r['factorizations_per_step']:8.2f} "
              f"{r['build_s']:8.2f} {r['compile_s']:9.2f} {r['setup_s']:8.2f} "
              f"{r['load_average'][0]:5.2f}", flush=True)
    slope = fit_exponent(rows)
    work = fit_exponent([dict(N=r["N"], ms_per_step=r["multiply_adds_per_step"]) for r in rows])
    print(f"  fitted exponent of ms/step vs N ({min(a.sizes)}..{max(a.sizes)}): {slope:.3f} "
          f"(target <= {TARGETS['exponent']:g}: {verdict(slope, TARGETS['exponent'])}); of the "
          f"linear algebra's multiply-adds per step (refactorisation + iterations x factor "
          f"entries, chain_scaling.linear_algebra_work): {work:.3f}")
    res = {"rows": rows, "exponent": slope, "work_exponent": work, "threads": rows[0]["threads"]}
    if rows[0]["threads"] > 1:  # one thread (EXUDYN's default), for continuity
        ones = []
        for n in a.sizes:
            r = scaling_row(n, threads=1)
            r["load_average"] = load()
            ones.append(r)
        res["rows_1_thread"] = ones
        res["exponent_1_thread"] = fit_exponent(ones)
        print("  the same with 1 thread: " + ", ".join(f"{r['ms_per_step']:.3f}" for r in ones)
              + f" ms/step, exponent {res['exponent_1_thread']:.3f} (defaults: "
              f"{rows[0]['threads']} threads)")
    big = [r for r in rows if r["N"] == 10000]
    if big:
        b = big[0]
        ed = exu_chain(10000, b["t_long"], "defaults")
        ed_ld = load()
        t_se = b["wall_long_s"]
        print(f"  N = 10^4, {b['t_long']:g} s of model time (both codes): se3dyn solve "
              f"{t_se:.2f} s ({b['newton_iterations_long'] / b['steps_long']:.2f} its/step, set-up "
              f"{b['build_s'] + b['compile_s'] + b['setup_s']:.2f} s apart), EXUDYN defaults "
              f"{ed['solve_s']:.2f} s ({ed.get('newton_iterations', 0) / ed['steps']:.2f} its/step,"
              f" {ed.get('jacobians', 0) / ed['steps']:.2f} Jacobians/step, build "
              f"{ed['build_s']:.2f} s): ratio {t_se / ed['solve_s']:.3f}; tip difference "
              f"{dist(b['tip_long'], ed['tip_final']):.1e} m [{ed_ld[0]}]")
        res["N10000_vs_exudyn"] = {"t_end": b["t_long"], "se3dyn_solve_s": t_se,
                                   "exudyn": strip_arrays(ed), "ratio": t_se / ed["solve_s"],
                                   "tip_diff_m": dist(b["tip_long"], ed["tip_final"]),
                                   "load_average": ed_ld}
    # peak memory of the N = 10^4 chain in its own process
    proc = subprocess.run([sys.executable, str(a.here / "chain_scaling.py"), "--memory",
                           str(a.memory_n), "--t-end", str(a.t_memory)],
                          capture_output=True, text=True)
    if proc.returncode:
        res["memory"] = {"failed": proc.stderr.strip()[-300:]}
        print(f"  memory run failed: {res['memory']['failed']}")
    else:
        import json

        mem = json.loads(proc.stdout.strip().splitlines()[-1])
        mem["load_average"] = load()
        res["memory"] = mem
        print(f"  peak RSS, N = {a.memory_n} chain, {a.t_memory:g} s, every 10th step stored, own "
              f"process (VmHWM): {mem['peak_rss_MB']:.0f} MB (after import "
              f"{mem['peak_rss_after_import_MB']:.0f} MB, after build + compile "
              f"{mem['peak_rss_after_build_compile_MB']:.0f} MB, after the first simulate's "
              f"set-up {mem['peak_rss_after_setup_MB']:.0f} MB; ru_maxrss "
              f"{mem['ru_maxrss_MB']:.0f} MB, inherits the parent's peak); target <= "
              f"{TARGETS['rss_MB']:g} MB: {verdict(mem['peak_rss_MB'], TARGETS['rss_MB'])}) "
              f"[{mem['load_average'][0]}]")
    report["scaling"] = res


def save(a, report) -> None:
    import json

    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(jsonable(report), indent=1) + "\n")


def summary(report) -> list[dict]:
    sc, pr = report.get("slider_crank"), report.get("processes")
    rows = []

    def add(name, value, target, unit="x EXUDYN", note=""):
        rows.append({"target": name, "value": value, "limit": target, "unit": unit,
                     "verdict": verdict(value, target), "note": note})

    if sc:
        exu = sc["warm"]["exu_defaults"]["solve_s"]
        for form in ("nodes", "bodies"):
            exu_min = min(sc["warm"]["exu_defaults"]["solve_s_all"])
            fr = [x["first_simulate_s"] for x in sc["fresh_processes"][form]]
            first = median(fr)
            add(f"slider-crank ({form}): first simulate, fresh process", first / exu,
                TARGETS["slider_crank_first"], note=f"{first * 1e3:.1f} ms vs {exu * 1e3:.1f} ms"
                f" (medians); ratio of minima {min(fr) / exu_min:.2f}")
            ws = sc["warm"][f"se3_{form}"]["solve_s_all"]
            w = median(ws)
            add(f"slider-crank ({form}): warm simulate", w / exu, TARGETS["slider_crank_warm"],
                note=f"{w * 1e3:.1f} ms vs {exu * 1e3:.1f} ms (medians); ratio of minima "
                f"{min(ws) / exu_min:.2f}")
    ch = report.get("chain", {}).get("1000")
    if ch:
        se = ch["se3dyn"]
        mins = (f"; ratio of minima {se['ratio_solve_of_minima']:.3f}"
                if "ratio_solve_of_minima" in se else "")
        user = ch.get("se3dyn_user")
        if user:
            add("1000-link chain 1 s at se3dyn's defaults: fresh process, every row",
                se["ratio_user_first"], TARGETS["chain1000"],
                note=f"{user['first_s']:.2f} s vs {ch['exudyn_defaults']['solve_s']:.2f} s; "
                f"warm {se['ratio_user_warm']:.3f}")
        add("1000-link chain 1 s: solve, 10 rows, set-up excluded", se["ratio_solve"],
            TARGETS["chain1000"],
            note=f"{se['solve_s']:.2f} s vs {ch['exudyn_defaults']['solve_s']:.2f} s{mins}")
    if pr:
        se3 = "se3dyn run examples/slider_crank.yaml --out DIR --quiet"
        exu_p = "EXUDYN process: import, build slider-crank, solve 5 s"
        for tag in ("cold", "warm"):
            a_, b_ = pr[tag][se3]["median_s"], pr[tag][exu_p]["median_s"]
            add(f"README job process, {tag}", pr[f"ratio_{tag}"], TARGETS[f"readme_{tag}"],
                note=f"{a_:.2f} s vs {b_:.2f} s (medians); ratio of minima "
                f"{pr[f'ratio_{tag}_of_minima']:.2f}")
    scl = report.get("scaling")
    if scl:
        ns = [r["N"] for r in scl["rows"]]
        add(f"per-step exponent N = {min(ns)}..{max(ns)}", scl["exponent"], TARGETS["exponent"],
            unit="")
        mem = scl.get("memory", {})
        if "peak_rss_MB" in mem:
            add(f"peak RSS N = {mem['N']}, {mem['t_end']:g} s (VmHWM)", mem["peak_rss_MB"],
                TARGETS["rss_MB"], unit="MB")
    return rows


def main(argv) -> int:
    import argparse
    from pathlib import Path

    here = Path(__file__).resolve().parent
    sys.path.insert(0, str(here))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=15, help="in-process slider-crank repeats")
    ap.add_argument("--processes", type=int, default=9, help="fresh/warm processes per command")
    ap.add_argument("--cold-processes", type=int, default=5, help="cold processes per command")
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000, 3000, 10000],
                    help="chain sizes of the per-step scaling (section 4)")
    ap.add_argument("--chain-sizes", type=int, nargs="+", default=[100, 1000],
                    help="chains of section 2 (1 s, with reference)")
    ap.add_argument("--memory-n", type=int, default=10000, help="links of the RSS run")
    ap.add_argument("--t-memory", type=float, default=0.1, help="model time of the RSS run")
    ap.add_argument("--chain-repeats", type=int, default=3,
                    help="alternated se3dyn / EXUDYN runs of each chain (medians judged)")
    ap.add_argument("--no-scaling", action="store_true", help="skip section 4")
    ap.add_argument("--no-chains", action="store_true", help="skip section 2")
    ap.add_argument("--no-chain-reference", action="store_true")
    ap.add_argument("--no-fullnewton-chain", action="store_true")
    ap.add_argument("--only-slider-crank", action="store_true",
                    help="section 1 only (slider-crank warm and first simulate, references)")
    ap.add_argument("--out", default=str(here / "results" / "compare_exudyn.json"))
    a = ap.parse_args(argv)
    a.here, a.repo, a.out = here, here.parent, Path(a.out)
    tee = Tee(sys.stdout)
    sys.stdout = tee
    t_start = time.perf_counter()
    try:
        env = environment(a.repo)
        defaults = exu_default_settings()
        report = {**env, "load_average_start": load(), "exudyn_defaults_read": defaults,
                  "settings": {
                      "se3dyn": "sd.simulate(model, t_end, h, rho_inf=0.9): index2, modified "
                                "Newton, tol_residual 1e-10, tol_constraint 1e-11; engine on "
                                f"{env['se3dyn_engine']['threads']} threads (the default: the "
                                "cores; results identical for any count)",
                      "exudyn_defaults": "SimulationSettings() + endTime, numberOfSteps, "
                                         "sensors.writePeriod = h, solution.file.write = False; "
                                         "chains: linearSolver EigenSparse",
                      "exudyn_fullnewton": "defaults + useModifiedNewton False, relTol 1e-10, "
                                           "absTol 1e-12, adaptiveStep False (continuity)",
                      "exudyn_tight": "defaults + relTol 1e-10, absTol 1e-12 (reference "
                                      "checks at the small step)"},
                  "targets": TARGETS}
        print(f"se3dyn vs EXUDYN at EXUDYN's defaults; {env['date']}; {load_str()}")
        print(f"threads: se3dyn's engine {env['se3dyn_engine']['threads']} (its default, the "
              f"cores), EXUDYN parallel.numberOfThreads "
              f"{defaults.get('parallel.numberOfThreads')} (its default)")
        print(f"machine: {env['machine']['platform']}, {env['machine']['cpu']}, "
              f"{env['machine']['cpu_count']} CPUs (shared)")
        print("versions: " + ", ".join(f"{k} {v}" for k, v in env["versions"].items())
              + f"; git {env['git']['head'][:10]}"
              + (f" + {len(env['git']['dirty'])} modified files" if env["git"]["dirty"] else "")
              + f"; _engine sha256 {env['se3dyn_engine']['sha256']}, engine + sources "
              f"{env['se3dyn_engine']['code_sha256']}, built for this machine "
              f"(-march=native): {'yes' if env['se3dyn_engine']['built_native'] else 'NO'}")
        print("EXUDYN defaults as read from exu.SimulationSettings():")
        for k, v in defaults.items():
            print(f"  {k} = {v}")
        print("EXUDYN runs set only: endTime, numberOfSteps, sensors.writePeriod = h, "
              "solution.file.write = False, and EigenSparse for the chains (spectral radius: "
              f"default {defaults['generalizedAlpha.spectralRadius']} = {RHO}, not set)")
        print("EXUDYN 'full Newton' (continuity only): useModifiedNewton False, relTol 1e-10, "
              "absTol 1e-12, adaptiveStep False")
        print("se3dyn: sd.simulate(model, t_end, h, rho_inf=0.9) (index-2, modified Newton, "
              "tol_residual 1e-10, tol_constraint 1e-11)")
        save(a, report)
        section_slider_crank(a, report)
        save(a, report)
        if not (a.no_chains or a.only_slider_crank):
            section_chains(a, report)
            save(a, report)
        if not a.only_slider_crank:
            section_processes(a, report)
            save(a, report)
        if not (a.no_scaling or a.only_slider_crank):
            section_scaling(a, report)
            save(a, report)
        env_end = environment(a.repo)
        report["git_end"], report["se3dyn_engine_end"] = env_end["git"], env_end["se3dyn_engine"]
        changed = (env_end["se3dyn_engine"]["code_sha256"]
                   != env["se3dyn_engine"]["code_sha256"])
        report["tree_changed_during_run"] = changed
        rows = summary(report)
        report["summary"] = rows
        report["load_average_end"] = load()
        report["wall_s"] = time.perf_counter() - t_start
        print(f"\n== summary: targets of issue 12 [{load_str()}; whole run "
              f"{report['wall_s'] / 60:.1f} min] ==")
        for r in rows:
            print(f"  {r['target']:54s} {r['value']:9.3f} {r['unit']:9s} <= {r['limit']:<6g} "
                  f"{r['verdict']}  {r['note']}")
        if changed:
            print("  WARNING: se3dyn's code (engine + Python sources) changed during this run "
                  "(subprocesses started after the change used the new code): "
                  f"{env['se3dyn_engine']['code_sha256']} -> "
                  f"{env_end['se3dyn_engine']['code_sha256']}, git {env['git']['head'][:10]} -> "
                  f"{env_end['git']['head'][:10]}")
        save(a, report)
        print(f"\nwrote {a.out} and {a.out.with_suffix('.txt')}")
    finally:
        sys.stdout = tee.stream
        a.out.with_suffix(".txt").write_text(tee.text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
