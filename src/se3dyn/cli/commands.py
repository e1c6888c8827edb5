"""The ``se3dyn`` command: check, run, plot and export multibody models and results.

Exit codes: 0 success, 1 simulation failure (results computed so far are kept in the results
file), 2 bad input or usage, 130 / 143 interrupted by Ctrl-C / SIGTERM (the results file is
closed; ``--resume`` continues it), 141 when the reader of the output went away
(``se3dyn check ... | head``). Errors are one clear line on stderr, never a Python
traceback.

    se3dyn check MODEL...
    se3dyn run MODEL [--t-end T] [--step H] [--rho-inf R] [--formulation F]
                  [--tol TOL [--global-error [bound]]] [--output-step DT] [--out DIR]
                  [--overwrite] [--quiet]
    se3dyn run MODEL --resume RESULTS [--t-end T] [--quiet]
    se3dyn sweep MODEL --vary PATH=SPEC... [--method M --samples N --seed S]
                  [--metric NAME=FUNC(EXPR)...] [--scheduler ADDR | --workers N] [--resume]
                  [run-time overrides as for run] --out DIR        (docs/sweep.md)
    se3dyn channels RESULTS
    se3dyn plot RESULTS CHANNEL... [-o PNG]
    se3dyn export RESULTS --csv FILE [CHANNEL...]
    se3dyn export RESULTS --gltf FILE.glb
    se3dyn view RESULTS [-o FILE.html] [--model MODEL] [--channel PATTERN] [--trace NODE]
    se3dyn export-fmu MODEL -o FILE.fmu [--step H] [--out-channel CHANNEL...]
    se3dyn import-urdf ROBOT.urdf -o MODEL.yaml [--floating-base] [--fixed keep|merge]
                  [--mimic enforce|ignore] [--package-dir DIR...]

A MODEL may be a URDF file (``*.urdf``) for check and run: imported with the defaults of
``se3dyn.load_urdf`` (docs/urdf.md).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["main"]


class _Usage(Exception):
    """Bad input or usage: exit code 2."""


def _err(msg: str) -> None:
    print(f"se3dyn: error: {msg}", file=sys.stderr)


# ---------------------------------------------------------------------------------------------
def _load(path: str, say=None):
    """``(model, settings)`` of a model file, or of a URDF file (``*.urdf``: imported with
    the defaults of ``se3dyn.load_urdf``, no settings; its import report said by ``say``)."""
    from se3dyn.errors import ModelError
    from se3dyn.io.modelfile import load_model

    if not Path(path).is_file():
        raise _Usage(f"{path}: no such model file")
    try:
        if _is_urdf(path):
            return _load_urdf(path, say, {})
        return load_model(Path(path))
    except ModelError as exc:
        raise _Usage(str(exc)) from None


def _is_urdf(path: str) -> bool:
    return Path(path).suffix.lower() == ".urdf"


def _load_urdf(path: str, say, options: dict):
    """A URDF file's model (no settings); the import report (what was not mapped) said line
    by line by ``say`` instead of a Python warning."""
    import warnings

    from se3dyn.io.urdf import load_urdf

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mb = load_urdf(path, **options)
    if say is not None:
        for line in mb.urdf.report().splitlines()[1:]:
            say("  urdf " + line.strip())
    return mb.build(), {}


def _model_text(path: str, model) -> str:
    """The model text a results file stores: a model file as given; a URDF's model written
    as a model file (the viewer and ``--resume`` read it)."""
    if _is_urdf(path):
        from se3dyn.io.modelfile import save_model

        return save_model(model)
    return Path(path).read_text(encoding="utf-8")


def _loaded() -> None:
    """The modules of the command are loaded: the garbage collector, paused while they loaded
    (the ``se3dyn`` command only, :mod:`se3dyn.cli.startup`), resumes, their objects frozen
    first (``gc.freeze``: they live as long as the process, no collection walks them again)."""
    from se3dyn.cli import startup

    if startup.GC_PAUSED:
        import gc

        startup.GC_PAUSED = False
        gc.freeze()
        gc.enable()


def cmd_check(args) -> int:
    """Validate model files and print their counts and rank analysis (exit 2 if any is bad)."""
    bad = 0
    for path in args.models:
        try:
            _check_one(path, args.rank_max)
        except _Usage as exc:
            _err(str(exc))
            bad += 1
    if bad and len(args.models) > 1:
        print(f"{bad} of {len(args.models)} model files are invalid", file=sys.stderr)
    return 2 if bad else 0


def _check_one(path: str, rank_max: int) -> None:
    from se3dyn.engine.rank import rank_analysis
    from se3dyn.engine.system import compile_model
    from se3dyn.errors import ModelError

    notes = []
    model, settings = _load(path, notes.append)
    try:
        s = compile_model(model)
    except ModelError as exc:
        raise _Usage(f"{path}: {exc}") from None
    n_free = int(np.sum(~s.node_fixed))
    bodies = int(np.sum(s.node_mass > 0))
    print(f"{path}: ok")
    for line in notes:
        print(line)
    from se3dyn.model.checks import off_axis_joints

    for line in off_axis_joints(model):
        print(f"  WARNING: {line}")
    nn, nj, extra = _counts(model)
    print(f"  model '{model.name}': {nn} nodes ({n_free - extra} free, {bodies} with mass),"
          f" {nj} joints, {len(model.loads)} loads")
    x = np.array([n.position for n in model.nodes], dtype=float).reshape(-1, 3)
    box = np.ptp(x, axis=0) if len(x) else np.zeros(3)
    m = s.node_mass[s.node_mass > 0]
    print(f"  length scale (SI units: m, kg, s): the nodes span {np.linalg.norm(box):.4g} m "
          f"(box {' x '.join(f'{b:.3g}' for b in box)} m)"
          + (f", masses {m.min():.3g} to {m.max():.3g} kg" if m.size else ""))
    from se3dyn.io.modelfile import ELEMENT_SECTIONS

    others = [f"{len(getattr(model, es.key))} {es.key}" for es in ELEMENT_SECTIONS
              if es.key not in ("joints", "loads", "beams", "collisions")
              and getattr(model, es.key, ())]
    if others:  # force elements of the other element types (model attribute = file section)
        print("  force elements: " + ", ".join(others))
    if model.beams:
        n_el = sum(b.elements for b in model.beams)
        n_in = sum(len(b.nodes) - 2 for b in model.beams)
        print(f"  beams: {len(model.beams)} with {n_el} elements in all ({n_in} of the nodes "
              "created by them)")
    if model.markers:
        print(f"  markers: {len(model.markers)} (outputs only: "
              + ", ".join(f"{mk.name} on {mk.node}" for mk in model.markers[:8])
              + (", ..." if len(model.markers) > 8 else "") + ")")
    if model.drives:
        print(f"  drives: {len(model.drives)} (prescribed motion of {len(s.drive_dof)} joint "
              "coordinates: " + ", ".join(f"{d.name} on joint {d.joint!r} " + ", ".join(
                  f"coordinate {i} by {k}" for _, i, k in d.targets) for d in model.drives[:8])
              + (", ..." if len(model.drives) > 8 else "") + ")")
    if model.couplings:
        print(f"  couplings: {len(model.couplings)} (" + ", ".join(
            f"{c.name}: {c.follower[0]!r} = {c.ratio:g} {c.leader[0]!r}"
            + (f" + {c.offset:g}" if c.offset else "") for c in model.couplings[:8])
            + (", ..." if len(model.couplings) > 8 else "") + ")")
    if model.collisions:
        from se3dyn.model.contact import describe

        for line in describe(model, s.contacts):
            print("  " + line)
    kinds: dict[str, int] = {}
    for j in model.joints:
        kinds[j.type] = kinds.get(j.type, 0) + 1
    print("  joints by type: " + (", ".join(f"{k} {v}" for k, v in sorted(kinds.items()))
                                  or "none"))
    print(f"  unknowns {s.nq} (nodal {6 * n_free}, relative {s.nq - 6 * n_free}), "
          f"multipliers {s.nm}, iteration matrix {s.N} x {s.N}")
    if s.nq > rank_max:
        print(f"  rank analysis skipped: {s.nq} unknowns > --rank-max {rank_max}")
    else:
        r = rank_analysis(s)
        print(f"  constraint Jacobian rank {r.rank} of {r.constraints} equations: "
              f"degrees of freedom (mobility) {r.dof}")
        if r.redundant:
            import textwrap

            print(f"  redundant constraint equations ({len(r.redundant)}), left out with zero "
                  "multipliers:")
            shown = r.redundant[:24]
            more = f"; and {len(r.redundant) - 24} more" if len(r.redundant) > 24 else ""
            print(textwrap.fill("; ".join(shown) + more, width=100, initial_indent="    ",
                                subsequent_indent="    "))
        else:
            print("  no redundant constraints")
        from se3dyn.engine.rank import massless_message, massless_motions

        free = massless_motions(s)
        if free:
            raise _Usage(f"{path}: a simulation would stop at t = 0: {massless_message(free)}")
    if settings:
        print("  simulation settings: " + ", ".join(f"{k}={v}" for k, v in settings.items()))
    _check_start(path, s, settings)


def _counts(model) -> tuple[int, int, int]:
    """Nodes and joints as the model file gives them: a composite joint (universal) counts as
    one joint, its intermediate cross node not at all; and the number of those cross nodes."""
    extra = len(model.composites)
    parts = sum(len(p) for p in model.composites.values())
    return len(model.nodes) - extra, len(model.joints) - parts + extra, extra


def _check_start(path: str, s, settings: dict) -> None:
    """What `run` would refuse at t = 0: the settings, the initial accelerations (a singular
    iteration matrix) and, with initial_velocities 'strict', inconsistent velocities; and
    the initial velocities that would be projected."""
    from se3dyn.dynamics.integrator import GeneralizedAlpha, initial_velocity_changes
    from se3dyn.dynamics.run import check_settings
    from se3dyn.errors import ModelError, SimulationError

    if "t_end" in settings and "step" in settings:
        try:
            check_settings(s, **settings)
        except ModelError as exc:
            raise _Usage(f"{path}: simulation settings: {exc}") from None
    opts = {k: settings[k] for k in ("formulation", "redundant", "initial_velocities")
            if k in settings}
    try:
        st = GeneralizedAlpha(**opts).init(s, float(settings.get("t_start", 0.0)))
    except (ModelError, SimulationError) as exc:
        raise _Usage(f"{path}: at t = 0: {exc}") from None
    ch = initial_velocity_changes(s, st)
    if ch:
        worst = max(ch, key=lambda c: max(c["dv"], c["dw"]))
        print(f"  initial velocities the joints do not allow will be projected ({len(ch)} "
              f"nodes; largest change: node {worst['node']!r}, velocity {worst['dv']:.3g} m/s, "
              f"angular velocity {worst['dw']:.3g} rad/s); initial_velocities: strict refuses "
              "them")


# ---------------------------------------------------------------------------------------------
class _Progress:
    """A one-line progress bar on stderr: time reached, steps/s, ETA (terminal only)."""

    def __init__(self, t0: float, t1: float, enabled: bool, i0: int = 0):
        self.t0, self.t1 = t0, t1
        self.i0 = i0  # steps before this run (resumed runs)
        self.enabled = enabled
        self.start = time.perf_counter()
        self.last = 0.0

    def __call__(self, t: float, i: int) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.last < 0.1 and t < self.t1:
            return
        self.last = now
        frac = (t - self.t0) / (self.t1 - self.t0)
        el = now - self.start
        rate = (i - self.i0) / el if el > 0 else 0.0
        eta = el * (1 - frac) / frac if frac > 0 else math.inf
        bar = "#" * int(30 * frac) + "." * (30 - int(30 * frac))
        sys.stderr.write(f"\r  t = {t:10.4f} / {self.t1:g} s [{bar}] {rate:8.1f} steps/s "
                         f"ETA {eta:6.1f} s ")
        sys.stderr.flush()

    def done(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()


class _Terminated(BaseException):
    """SIGTERM: handled like Ctrl-C (results file closed), exit code 143."""


#: Signals received (SIGINT, SIGTERM). While `run` simulates, the handler only records them
#: and the run stops at its next progress report (between chunks of steps, about 0.1 s): an
#: exception raised by a handler while Python runs a weakref callback or a __del__ would be
#: lost, with a traceback printed ("Exception ignored in ...").
_STOP: list[int] = []
_DEFER = [False]


def _on_signal(signum, frame):
    import signal

    _STOP.append(signum)
    if not _DEFER[0]:
        raise KeyboardInterrupt() if signum == signal.SIGINT else _Terminated()


def _check_stop() -> None:
    import signal

    if _STOP:
        raise KeyboardInterrupt() if _STOP[-1] == signal.SIGINT else _Terminated()


def _shield():
    """Ignore SIGINT and SIGTERM while the results file is being closed."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)


def cmd_run(args) -> int:
    """Simulate a model file, stream the results to an HDF5 file, print a summary."""
    import se3dyn.dynamics.run  # noqa: F401  (loaded with the collector paused, see _loaded)
    from se3dyn.engine.system import compile_model
    from se3dyn.errors import ModelError

    # --quiet: no summary; what was changed (initial velocities) or looks wrong goes to stderr
    say = print if not args.quiet else (lambda *a, **k: None)

    _run_threads(args)
    model, settings = _load(args.model, lambda line: print("se3dyn: " + line.strip(),
                                                           file=sys.stderr))
    text = _model_text(args.model, model)  # stored as metadata
    try:
        s = compile_model(model)
    except ModelError as exc:
        raise _Usage(f"{args.model}: {exc}") from None
    if args.resume is not None:
        writer, cfg, path = _resume(args, s, text)
        if writer is None:
            say(f"{path}: the run is complete to t_end = {cfg['t_end']:g} s already; give a "
                  "later --t-end to continue it")
            return 0
        cp = writer.checkpoint
    else:
        writer, cfg, path = _new_results_file(args, s, settings, text)
        cp = None
    _loaded()  # (the results file's writer made: h5py loaded)
    quiet = args.quiet or not sys.stderr.isatty()
    t_from = cp.state.t if cp is not None else float(cfg.get("t_start", 0.0))
    prog = _Progress(t_from, float(cfg["t_end"]), not quiet, cp.steps if cp is not None else 0)
    _announce_run(args, model, s, cfg, path, cp, say)
    t0 = time.perf_counter()
    code, res, failed, stats = _run_into_file(args, s, cfg, cp, writer, path, prog)
    if code is not None:
        return code
    wall = time.perf_counter() - t0
    if failed is not None:
        _err(f"{failed}")
        print(f"  simulation failed; {writer.rows} rows kept in {path}", file=sys.stderr)
        return 1
    _run_summary(args, res, stats, wall, path, writer.rows, say)
    return 0


def _run_threads(args) -> None:
    """The number of threads: ``--threads`` or else ``SE3DYN_THREADS``."""
    from se3dyn.engine.threads import from_environment, set_threads
    from se3dyn.errors import Se3dynError

    if args.threads is None:  # (a bad SE3DYN_THREADS: refused before the results file is made)
        from_environment()
    else:
        try:  # --threads replaces SE3DYN_THREADS; a bad one is said, not passed over in silence
            from_environment()
        except Se3dynError as exc:
            print(f"se3dyn: warning: {exc}; ignored: --threads {args.threads} given",
                  file=sys.stderr)
        set_threads(args.threads)


def _new_results_file(args, s, settings: dict, text: str):
    """The settings of a new run (the file's, the command line's overrides applied), its
    results file's writer and path."""
    from se3dyn.io.h5 import ResultsFileError, ResultsWriter

    cfg = dict(settings)
    cfg.update(_overrides(args))
    for key in ("t_end", "step"):
        if key not in cfg:
            raise _Usage(f"{args.model}: no '{key}' in the file's simulation settings; "
                         f"give --{key.replace('_', '-')}")
    out = Path(args.out if args.out is not None else "out")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _Usage(f"--out {out}: cannot create the folder ({exc.strerror})") from None
    path = out / (Path(args.model).stem + ".h5")
    try:
        writer = ResultsWriter(path, s, model_text=text, settings=cfg,
                               overwrite=args.overwrite)
    except ResultsFileError as exc:
        if "exists" in exc.problem:
            raise _Usage(f"{path}: a results file exists; give --overwrite to replace it, "
                         f"or --resume {path} to continue its run") from None
        raise _Usage(str(exc)) from None
    return writer, cfg, path


def _announce_run(args, model, s, cfg: dict, path: Path, cp, say) -> None:
    """The header of a run: version, files, warnings on the model, its size and settings."""
    from se3dyn._version import __version__
    from se3dyn.model.checks import off_axis_joints

    say(f"se3dyn {__version__}: {args.model} -> {path}"
          + (f" (resumed at t = {cp.state.t:g} s)" if cp is not None else ""))
    for line in off_axis_joints(model):
        print(f"se3dyn: warning: {line}", file=sys.stderr)
    nn, nj, _ = _counts(model)
    say(f"  {nn} nodes, {nj} joints; {s.nq} unknowns, {s.nm} "
          f"multipliers; t_end = {cfg['t_end']} s, h = {cfg['step']} s, "
          f"rho_inf = {cfg.get('rho_inf', 0.9)}, {cfg.get('formulation', 'index2')}")


def _simulate_rows(s, cfg: dict, cp, writer, prog, bound: bool):
    """The run, its rows written to the results file (as they come, or at the end with
    ``global_error: bound``); a signal stops it at its next progress report."""
    import warnings

    from se3dyn.dynamics.run import simulate
    from se3dyn.errors import Se3dynWarning

    def progress(t: float, i: int) -> None:
        _check_stop()
        prog(t, i)

    _DEFER[0] = True
    try:
        with warnings.catch_warnings():  # (the summary below reports them)
            warnings.simplefilter("ignore", Se3dynWarning)
            if bound:  # a run may be repeated: its rows are written when it is done
                res = simulate(s, progress=progress, initial_state=cp, **cfg)
                writer.add_rows(res, None)
            else:
                res = simulate(s, progress=progress, on_rows=writer.add_rows,
                               store=False, initial_state=cp, **cfg)
    finally:
        _DEFER[0] = False
    _check_stop()
    return res


def _run_into_file(args, s, cfg: dict, cp, writer, path: Path, prog):
    """The run with its results file, closed with the run's statistics whatever happens:
    (exit code or None, results, the SimulationError or None, the stored statistics)."""
    from se3dyn.errors import ModelError, SimulationError

    failed = None
    res = None
    resume_hint = f"continue with: se3dyn run {args.model} --resume {path}"
    bound = cfg.get("global_error") == "bound"
    with writer:
        try:
            res = _simulate_rows(s, cfg, cp, writer, prog, bound)
        except SimulationError as exc:
            failed = exc
            res = exc.result
            if bound and res is not None:  # (kept in memory so far: written now)
                writer.add_rows(res, None)
        except ModelError as exc:  # refused before any step: no results file is left
            prog.done()
            _shield()
            writer.close(stats={"failed": True, "message": str(exc)})
            if cp is None:
                path.unlink(missing_ok=True)
            raise _Usage(f"{args.model}: simulation settings: {exc}") from None
        except (KeyboardInterrupt, _Terminated) as exc:
            _shield()
            prog.done()
            what = "interrupted" if isinstance(exc, KeyboardInterrupt) else "terminated"
            writer.close(stats={"failed": True, "message": what})
            if bound:  # (nothing was written: the rows come when the run is done)
                path.unlink(missing_ok=True)
                _err(f"{what}; global_error: bound writes its results when the run is done: "
                     f"nothing kept, {path} removed")
            else:
                _err(f"{what}; results so far kept in {path} ({resume_hint})")
            return 130 if isinstance(exc, KeyboardInterrupt) else 143, res, failed, None
        _shield()
        prog.done()
        stats = _file_stats(res, failed, writer, cp)
        writer.close(stats=stats, settings=cfg)
    return None, res, failed, stats


def _file_stats(res, failed, writer, cp) -> dict:
    """The statistics stored in the results file: those of the whole run when it continues
    another (steps, Newton iterations, energy balance), the failure if any."""
    base_steps = cp.steps if cp is not None else 0
    base_its = writer.base_iterations
    stats = dict(res.stats) if res is not None else {}
    stats.pop("final_state", None)
    stats["steps"] = base_steps + int(stats.get("steps", 0))
    stats["newton_iterations"] = base_its + int(stats.get("newton_iterations", 0))
    if failed is not None:
        stats.update(failed=True, message=str(failed))
    if cp is not None and "energy_balance_error" in stats:  # (the run it continues)
        err, scale = writer.energy_balance()
        stats.update(energy_balance_error=err, energy_scale=scale)
        res.stats.update(energy_balance_error=err, energy_scale=scale)
    return stats


def _run_summary(args, res, stats: dict, wall: float, path: Path, rows: int, say) -> None:
    """The summary of a successful run: steps, iterations, condensation, the run report,
    the constraint violation and the results file."""
    st = res.stats
    st.update(_energy_jump_in(path, st))
    say(f"  {stats['steps']} steps, {stats['newton_iterations']} Newton iterations "
          f"(max {st['max_iterations']} per step), wall time {wall:.2f} s")
    if st.get("condensed"):
        names = ", ".join(repr(n) for n in st["condensed"][:8]) + (
            f" and {len(st['condensed']) - 8} more" if len(st["condensed"]) > 8 else "")
        say(f"  rigid joints {names} condensed for the time loop (matrix "
              f"{st['matrix_size']}; every node and joint reported)")
    for line in run_report(st):
        say("  " + line)
        if args.quiet and ("WARNING" in line or line.startswith("initial velocities")):
            print(f"se3dyn: warning: {line}", file=sys.stderr)  # changes and problems: said
    say(f"  max constraint violation {st['max_constraint']:.2e}")
    say(f"  results: {path} ({rows} rows)")


def _resume(args, s, text: str):
    """The writer reopened on ``--resume RESULTS``, the stored settings (``--t-end`` applied)
    and the path (writer None: nothing to do); usage errors for everything that cannot
    continue bit for bit."""
    import json
    import os

    from se3dyn.io.h5 import ResultsFileError, ResultsWriter, _check_format, _layout, _open, repair

    path = Path(args.resume)
    other = [k for k in _OVERRIDES if k != "t_end" and getattr(args, k) is not None]
    if other:
        raise _Usage(f"--resume {path}: the run continues with its stored settings; only "
                     f"--t-end may be given (not --{other[0].replace('_', '-')})")
    if args.out is not None or args.overwrite:
        raise _Usage(f"--resume {path}: continues that file; --out and --overwrite do not "
                     "apply")
    try:
        repair(path)  # left by kill -9: readable again (not while a writer holds it)
        with _open(os.fspath(path))[0] as f:  # (a truncated file refused at once)
            _check_format(f, os.fspath(path))
            _layout(f, os.fspath(path))  # (a damaged or crafted layout refused)
            stored = f.attrs.get("model", "")
            stored = stored.decode() if isinstance(stored, bytes) else str(stored)
            cfg = json.loads(f.attrs.get("settings", "{}"))
            complete = bool(f.attrs.get("complete", False))
            t_last = float(f["time"][-1]) if f["time"].shape[0] else -math.inf
        if not isinstance(cfg, dict) or not all(
                isinstance(cfg.get(k, 0.0), (int, float)) for k in ("t_end", "step")):
            raise ValueError(f"attribute 'settings' is {cfg!r}, expected the run's settings")
    except ResultsFileError as exc:
        raise _Usage(str(exc)) from None
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:
        raise _Usage(f"--resume {path}: not a readable se3dyn results file ({exc})") from None
    if stored != text:
        raise _Usage(f"--resume {path}: {args.model} is not the model stored in it (the texts "
                     "differ); give the model file the run was started with")
    if "t_end" not in cfg or "step" not in cfg:
        raise _Usage(f"--resume {path}: no simulation settings stored in it")
    if cfg.get("global_error") == "bound":
        raise _Usage(f"--resume {path}: a run with global_error: bound is written when it is "
                     "done and cannot be continued; run it again")
    t_end = float(cfg["t_end"])
    if args.t_end is not None and args.t_end != t_end:
        if cfg.get("tol") is not None:
            raise _Usage(f"--resume {path}: an adaptive run (tol) continues to its own t_end = "
                         f"{t_end:g} s only (its step control depends on the length of the "
                         "run)")
        if args.t_end < t_last:
            raise _Usage(f"--resume {path}: t_end = {args.t_end:g} s is before the end of its "
                         f"rows (t = {t_last:g} s); --resume continues a run, it does not cut "
                         "it")
        cfg["t_end"] = args.t_end
    elif complete and t_last >= t_end:
        return None, cfg, path
    try:
        writer = ResultsWriter.resume(path, s)
    except ResultsFileError as exc:
        raise _Usage(f"{exc}") from None
    return writer, cfg, path


def cmd_sweep(args) -> int:
    """Parameter study on dask.distributed (the opt-in layer se3dyn.sweep, docs/sweep.md)."""
    from se3dyn.errors import ModelError
    from se3dyn.sweep.cli import main as sweep_main

    try:
        return sweep_main(args, _overrides(args))
    except (ModelError, ImportError) as exc:
        raise _Usage(str(exc)) from None


# ---------------------------------------------------------------------------------------------
def _read(path: str):
    from se3dyn.io.h5 import read_results

    if not Path(path).is_file():
        raise _Usage(f"{path}: no such results file")
    from se3dyn.errors import Se3dynError

    try:
        res = read_results(path)
    except Se3dynError as exc:  # the reader's own error class, naming the file
        raise _Usage(str(exc)) from None
    except (OSError, ValueError, KeyError) as exc:
        raise _Usage(f"{path}: not a readable se3dyn results file ({exc})") from None
    if res.stats.get("repaired"):
        kept = (f"{len(res.t)} rows kept up to t = {res.t[-1]:g} s" if len(res.t) else
                "it holds no rows (killed before its first rows reached the disk)")
        print(f"se3dyn: repaired {path}: it was left open by a run that was killed; {kept}",
              file=sys.stderr)
    return res


def _channels(res, names: list[str]) -> list[tuple[str, np.ndarray]]:
    """Channel values by name; names with ``* ? [`` are shell-style patterns
    (e.g. ``node/6/displacement/[xyz]``)."""
    import fnmatch

    from se3dyn.results.channels import get_channel, list_channels

    expanded: list[str] = []
    for name in names:
        if any(ch in name for ch in "*?["):
            hits = fnmatch.filter(list_channels(res), name)
            if not hits:
                raise _Usage(f"no channel matches the pattern {name!r} (see 'se3dyn channels')")
            expanded += hits
        else:
            expanded.append(name)
    out = []
    for name in expanded:
        try:
            out.append((name, np.asarray(get_channel(res, name), dtype=float)))
        except KeyError as exc:
            raise _Usage(str(exc.args[0]) if exc.args else f"unknown channel {name!r}") from None
    return out


def cmd_channels(args) -> int:
    """List the channels of a results file."""
    from se3dyn.results.channels import list_channels

    res = _read(args.results)
    for name in list_channels(res):
        print(name)
    return 0


def cmd_info(args) -> int:
    """What a results file holds: its status (complete, failed, interrupted, cut short), the
    model, the settings and the statistics of the run."""
    from se3dyn.io.h5 import _writer_alive

    res = _read(args.results)
    st = res.stats
    t0, t1 = (float(res.t[0]), float(res.t[-1])) if len(res.t) else (math.nan, math.nan)
    print(f"{args.results}: se3dyn {st.get('se3dyn_version', '?')} results, written "
          f"{st.get('created', '?')}")
    model = st.get("model", "")
    name = next((ln.split(":", 1)[1].strip() for ln in model.splitlines()
                 if ln.startswith("name:")), "?")
    print(f"  model '{name}': {len(res.system.node_names)} nodes, "
          f"{len(res.system.joint_names)} joints (the model file is stored in the results)")
    msg = st.get("message", "")
    if st.get("complete") and not st.get("failed"):
        status = f"complete: t = {t0:g} .. {t1:g} s"
    elif st.get("failed") and msg in ("interrupted", "terminated"):  # (Ctrl-C, SIGTERM)
        status = f"{msg} at t = {t1:.9g} s (se3dyn run MODEL --resume {args.results})"
    elif st.get("failed"):
        status = f"failed at t = {t1:.9g} s: {msg}"
    elif _writer_alive(args.results):  # (its writer's lock is held)
        status = ("being written by a se3dyn run that is still going" + (
            f": t = {t0:g} .. {t1:.9g} s so far" if len(res.t) else ", no rows yet"))
    elif not len(res.t):
        status = ("cut short before its first row (the writer stopped without closing the "
                  "file: killed?); run the model again")
    else:
        status = (f"cut short at t = {t1:.9g} s (the writer stopped without closing the file: "
                  f"killed?); se3dyn run MODEL --resume {args.results} continues it")
    print(f"  status: {status}")
    print(f"  rows: {len(res.t)}")
    sett = st.get("settings") or {}
    if sett:
        print("  settings: " + ", ".join(f"{k}={v}" for k, v in sett.items()))
    keys = [("steps", "steps"), ("rejected", "rejected steps"),
            ("newton_iterations", "Newton iterations"), ("factorizations", "factorisations"),
            ("formulation", "formulation"), ("matrix_size", "matrix size"),
            ("full_matrix_steps", "steps with the full index-2 matrix"),
            ("wall_time", "wall time (s)")]
    have = [f"{label} {st[k]:.4g}" if isinstance(st[k], float) else f"{label} {st[k]}"
            for k, label in keys if k in st]
    if have:
        print("  statistics: " + ", ".join(have))
    if len(res.t) > 1:
        from se3dyn.dynamics.run import energy_jump, energy_rows

        st = dict(st, energy_jump=energy_jump(res.t, energy_rows(res)))
    for line in run_report(st):
        print("  " + line)
    if len(res.constraint):
        print(f"  max constraint violation {float(np.max(res.constraint)):.2e}")
    return 0


def cmd_types(args) -> int:
    """The joint types and element types with their model-file fields."""
    from se3dyn.io.modelfile import ELEMENT_SECTIONS, FIELDS
    from se3dyn.model.joint_types import JOINT_SYNONYMS, JOINT_TYPES

    print("joint types (joints: type):")
    for key in sorted([*JOINT_TYPES, "universal"]):
        if key == "universal":
            params, doc = ("axes",), "two hinges with orthogonal axes through a cross (k = 2)"
        else:
            params, doc = JOINT_TYPES[key].params, JOINT_TYPES[key].doc
        syn = [k for k, v in JOINT_SYNONYMS.items() if v == key]
        print(f"  {key:12s} {doc}; parameters: {', '.join(params) or 'none'}"
              + (f"; also called {', '.join(syn)}" if syn else ""))
    print("element types (model-file sections; docs/model-file.md has every field):")
    for es in ELEMENT_SECTIONS:
        _section_fields(es.key, es.doc, es.fields)
    print("outputs and motion (model-file sections):")
    top = {f.name: f for f in FIELDS["model"]}
    for key, kind in (("markers", "marker"), ("drives", "drive"), ("couplings", "coupling")):
        _section_fields(key, top[key].doc, FIELDS[kind])
    print("control laws (joints: control): PD (kp, kd, target, target_rate), PID (kp, ki, kd, "
          "target, target_rate, limit, sample_time, gear, rotor_inertia, sensor: a sampled "
          "law reading marker/<m>/position/x|y|z, marker/<a>/distance/<b> or "
          "joint/<j>/alpha/<i>); laws of your own in Python: "
          "torque=lambda t, q, v: ...")
    return 0


def _section_fields(key: str, doc: str, fields) -> None:
    """A model-file section and its required and optional fields (se3dyn types)."""
    req = [f.name for f in fields if f.required]
    opt = [f.name for f in fields if not f.required]
    print(f"  {key}: {doc}")
    print(f"      required: {', '.join(req) or 'none'}; optional: {', '.join(opt)}")


def cmd_plot(args) -> int:
    """Plot channels of a results file against time into a PNG (or PDF/SVG): one panel per
    unit, curves that stay visible when they coincide, the legend beside the data."""
    from se3dyn.results.channels import channel_unit

    res = _read(args.results)
    data = _channels(res, args.channels)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise _Usage("plotting needs matplotlib: pip install 'se3dyn[plot]'") from None
    png = _figure_path(args.output, Path(args.results).with_suffix(".png"))
    if args.x is not None:  # x-y plot: one channel against another
        xs = _channels(res, [args.x])
        if len(xs) != 1:
            raise _Usage(f"--x {args.x}: one channel expected, it names {len(xs)}")
        xname, xval = xs[0]
    else:
        xname, xval = "time", res.t
    groups: dict[str, list] = {}
    for name, y in data:
        groups.setdefault(channel_unit(name, res), []).append((name, y))
    n = len(groups)
    fig, axes = plt.subplots(n, 1, figsize=(7.6, 2.2 + 2.2 * n), dpi=110, sharex=True,
                             squeeze=False)
    styles = ["-", "--", "-.", ":"]
    for ax, (unit, curves) in zip(axes[:, 0], groups.items(), strict=True):
        for k, (name, y) in enumerate(curves):
            # dashes cycle with the colours: coinciding curves stay visible
            ax.plot(xval, y, lw=1.4, ls=styles[(k // 10 + k) % len(styles)], label=name)
        ax.set_ylabel(f"[{unit}]" if unit else "(dimensionless)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    xunit = channel_unit(xname, res) if xname != "time" else "s"
    axes[-1, 0].set_xlabel(f"{xname} [{xunit}]" if xunit else xname)
    if args.x is not None and list(groups) == ["m"] and xunit == "m":
        axes[0, 0].set_aspect("equal", adjustable="datalim")  # lengths against a length
    what = ", ".join(sorted({name.rsplit("/", 1)[0] for name, _ in data}))
    title = args.title or (f"{Path(args.results).name}: {what}"
                           + (f" against {xname}" if args.x else ""))
    axes[0, 0].set_title(title if len(title) <= 90 else title[:87] + "...", fontsize=10)
    fig.tight_layout()
    try:
        fig.savefig(png)
    except (OSError, ValueError) as exc:
        raise _Usage(f"-o {png}: cannot write ({getattr(exc, 'strerror', None) or exc})"
                     ) from None
    finally:
        plt.close(fig)
    print(f"wrote {png}")
    return 0


def _figure_path(output: str | None, default: Path) -> Path:
    """Where a figure goes: the default next to the results file; a folder (existing, or given
    with a trailing /) gets the default name inside it; a name needs a suffix matplotlib
    writes (.png, .pdf, .svg); none is added silently."""
    if output is None:
        return default
    p = Path(output)
    if p.is_dir() or output.endswith(("/", "\\")):
        return p / default.name
    if p.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise _Usage(f"-o {output}: expected a file name ending in .png, .pdf or .svg, or a "
                     "folder")
    return p


def cmd_export(args) -> int:
    """Export channels of a results file to CSV (header: time and channel names with their
    units, ``name [unit]``), or the animation to glTF (se3dyn.viewer)."""
    from se3dyn.results.channels import list_channels

    res = _read(args.results)
    if args.gltf is not None:
        if args.channels:
            raise _Usage("--gltf exports the motion of every node; give no channels")
        path = _viewer("export_gltf", res, args.gltf)
        print(f"wrote {path}: {len(res.t)} times, t = {res.t[0]:g} ... {res.t[-1]:g} s")
        return 0
    from se3dyn.results.channels import channel_unit

    names = args.channels or [n for n in list_channels(res) if n != "time"]  # time: column 1
    data = _channels(res, names)
    cols = np.column_stack([res.t] + [y for _, y in data])
    # "name [unit]" (SI; [1]: dimensionless)
    header = ",".join(["time [s]"] + [f"{n.replace(',', '%2C')} [{channel_unit(n, res) or 1}]"
                                      for n, _ in data])
    try:
        np.savetxt(args.csv, cols, delimiter=",", header=header, comments="", fmt="%.17g")
    except OSError as exc:
        raise _Usage(f"--csv {args.csv}: cannot write ({exc.strerror})") from None
    print(f"wrote {args.csv}: {cols.shape[0]} rows, {cols.shape[1]} columns")
    return 0


def cmd_export_fmu(args) -> int:
    """Export a model file as an FMI 2.0 co-simulation FMU (se3dyn.io.fmu): inputs are the
    stepping simulator's inputs, outputs the channels given (default: joint coordinates and
    rates, marker positions)."""
    from se3dyn.errors import Se3dynError
    from se3dyn.io.fmu import SIMULATOR_SETTINGS, export_fmu

    model, settings = _load(args.model)
    if args.step is not None:
        settings["step"] = args.step
    try:
        path = export_fmu(model, args.output, outputs=args.outputs or None,
                          **{k: v for k, v in settings.items() if k in SIMULATOR_SETTINGS})
    except Se3dynError as exc:
        raise _Usage(str(exc)) from None
    print(f"wrote {path}")
    return 0


def cmd_linearize(args) -> int:
    """Linearise a model file about its static equilibrium or its initial state
    (se3dyn.analysis.linearize): print the minimal coordinates and the modes; with
    ``--export``, write the matrices, names and modes to a NumPy ``.npz`` file."""
    from se3dyn.analysis.linearize import linearize
    from se3dyn.analysis.statics import static_equilibrium
    from se3dyn.errors import Se3dynError

    model, _ = _load(args.model)
    try:
        at = static_equilibrium(model) if args.at == "static" else None
        lin = linearize(model, at=at, inputs=args.inputs or (), outputs=args.outputs or ())
        md = lin.modes(args.modes)
    except Se3dynError as exc:
        raise _Usage(str(exc)) from None
    _print_modes(model, lin, md, args.at)
    if args.export:
        data = dict(M=lin.M, C=lin.C, K=lin.K, B=lin.B, C_y=lin.C_y, T=lin.T, A=lin.A,
                    B_x=lin.B_x, names=np.array(lin.names), input_names=np.array(
                        lin.input_names, dtype=str), output_names=np.array(
                        lin.output_names, dtype=str), unknowns=np.array(lin.system.labels[
                            :lin.system.nq]), omega=md.omega, damping=md.damping,
                    rigid=md.rigid, shapes=md.shapes)
        try:
            np.savez(args.export, **data)
        except OSError as exc:
            raise _Usage(f"--export {args.export}: cannot write ({exc.strerror})") from None
        print(f"wrote {args.export}")
    return 0


def _print_modes(model, lin, md, at: str) -> None:
    print(f"{model.name}: {len(lin.names)} minimal coordinates about the "
          f"{'static equilibrium' if at == 'static' else 'initial state'}: "
          + ", ".join(lin.names))
    print("  mode  frequency [Hz]  omega [rad/s]  damping ratio")
    for i in range(len(md)):
        kind = " rigid" if md.rigid[i] else ("" if md.stable[i] else " UNSTABLE")
        print(f"  {i + 1:4d}  {md.frequency[i]:14.6g}  {md.omega[i]:13.6g}  "
              f"{md.damping[i]:13.4g}{kind}")


def cmd_modes(args) -> int:
    """Linearise a model file (as ``se3dyn linearize``), print its modes and write a viewer
    page playing one of them (se3dyn.viewer.modes)."""
    from se3dyn.analysis.linearize import linearize
    from se3dyn.analysis.statics import static_equilibrium
    from se3dyn.errors import Se3dynError
    from se3dyn.viewer.modes import mode_results

    model, _ = _load(args.model)
    try:
        at = static_equilibrium(model) if args.at == "static" else None
        lin = linearize(model, at=at)
        md = lin.modes()
        res = mode_results(lin, args.mode - 1, amplitude=args.amplitude)
    except Se3dynError as exc:
        raise _Usage(str(exc)) from None
    _print_modes(model, lin, md, args.at)
    out = args.output or f"{Path(args.model).stem}_mode{args.mode}.html"
    f = res.stats["frequency"]
    _viewer("write_html", res, out, model=model, model_path=args.model, channels=[],
            title=f"{model.name}: mode {args.mode}, {f:.6g} Hz")
    print(f"wrote {out} (mode {args.mode}: {f:.6g} Hz, amplitude {res.stats['amplitude']:.3g})")
    return 0


def _viewer(func: str, res, *args, **kwargs):
    """Call se3dyn.viewer.<func>; its input errors become one-line usage errors."""
    from se3dyn import viewer
    from se3dyn.errors import ModelError

    try:
        return getattr(viewer, func)(res, *args, **kwargs)
    except (viewer.ViewerError, ModelError) as exc:
        raise _Usage(str(exc)) from None


def cmd_view(args) -> int:
    """Write the 3D viewer page of a results file; without -o open it in the browser."""
    import os
    import tempfile
    import webbrowser

    res = _read(args.results)
    if args.output:
        out = Path(args.output)
    else:
        fd, name = tempfile.mkstemp(prefix=Path(args.results).stem + "-", suffix=".html")
        os.close(fd)
        out = Path(name)
    path = _viewer("write_html", res, out, model_path=args.model, channels=args.channel,
                   traces=args.trace)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    if not args.output:
        webbrowser.open(path.resolve().as_uri())
    return 0


# ---------------------------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    def error(self, message):  # usage errors: exit 2 with one line, as argparse does
        self.print_usage(sys.stderr)
        _err(message)
        raise SystemExit(2)


def _count(text):
    """A positive integer argument."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return int(text)


def _positive(kind):
    def conv(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(v) or (kind == "pos" and v <= 0) or (
                kind == "rho" and not 0 <= v <= 1):
            want = {"pos": "a positive number", "rho": "a number in [0, 1]"}[kind]
            raise argparse.ArgumentTypeError(f"expected {want}, got {text!r}")
        return v

    return conv


def _threads(text):
    """The value of --threads (se3dyn.engine.threads' own check)."""
    from se3dyn.engine.threads import _check
    from se3dyn.errors import Se3dynError

    try:
        return _check(text, "--threads")
    except Se3dynError as exc:
        raise argparse.ArgumentTypeError(str(exc).split(": ", 1)[1]) from None


_OVERRIDES = ("t_end", "step", "rho_inf", "formulation", "tol", "output_step",
              "initial_velocities", "global_error")


def _energy_jump_in(path, stats: dict) -> dict:
    """``{"energy_jump": ...}`` from the energies stored in a results file when the energy
    balance warning fires (:func:`se3dyn.dynamics.run.energy_jump`), else nothing."""
    from se3dyn.dynamics.run import SCALARS, energy_jump, energy_warning

    if "energy_jump" in stats or not energy_warning(stats.get("energy_balance_error", 0.0),
                                                    stats.get("energy_scale", 0.0)):
        return {}
    import h5py

    try:
        with h5py.File(path, "r") as f:
            c = [f["energy/" + k][:] for k in SCALARS[:6]]
            t = f["time"][:]
    except (OSError, KeyError):
        return {}
    n = min(len(t), *(len(x) for x in c))
    jump = energy_jump(t[:n], np.stack([x[:n] for x in c], axis=1))
    return {"energy_jump": jump} if jump is not None else {}


def run_report(stats: dict) -> list[str]:
    """Summary lines on what a run's results may hide: the initial velocities changed to
    satisfy the joints, the local errors of an adaptive run, and the energy balance error
    against the energy in play."""
    out = []
    ch = stats.get("initial_velocity_changes") or []
    if ch:
        worst = max(ch, key=lambda c: max(c["dv"], c["dw"]))
        out.append(f"initial velocities projected onto the joints' velocity constraints "
                   f"({len(ch)} nodes; largest change: node {worst['node']!r}, velocity "
                   f"{worst['dv']:.3g} m/s, angular velocity {worst['dw']:.3g} rad/s); kinetic "
                   f"energy {stats['initial_kinetic_energy_given']:.6g} J given, "
                   f"{stats['initial_kinetic_energy_used']:.6g} J used "
                   "(--initial-velocities strict refuses them)")
    if stats.get("error_estimate") is not None and stats.get("tol") is not None:
        out.append(f"adaptive steps: local error estimates add up to "
                   f"{stats['error_estimate']:.3e} m (tol {stats['tol']:g} m); the global "
                   "error can exceed it where the motion amplifies errors (docs/accuracy.md)")
    ge = stats.get("global_error")
    if ge is not None:  # (from a results file: the scalars only)
        tol = stats.get("tol") or math.inf
        m = stats.get("global_error_refine") or 1
        if m > 1:
            runs = stats.get("global_error_runs") or []
            first = (f"the first run's estimate {runs[0]['global_error']:.3e} m exceeded tol; "
                     if runs else "")
            out.append(f"global error bound: {first}the run repeated on its steps refined {m} "
                       f"times: estimate {ge:.3e} m ({ge / tol:.3g} tol)"
                       + ("  WARNING: still above tol" if ge > tol else ""))
        else:
            at = stats.get("global_error_at")
            out.append(f"global error estimate {ge:.3e} m ({ge / tol:.3g} tol)"
                       + (f" at t = {at:.6g} s" if at is not None else "")
                       + ("  WARNING: above tol; the motion amplifies the local errors, a "
                          "smaller tol (or --global-error bound) brings it down"
                          if ge > tol else ""))
    if stats.get("global_error_until") is not None:
        out.append(f"global error estimated until t = {stats['global_error_until']:.9g} s "
                   f"only (its companion run stopped: {stats.get('global_error_failure', '')})")
    if "energy_balance_error" in stats:
        from se3dyn.dynamics.run import energy_cause, energy_warning

        err, scale = stats["energy_balance_error"], stats["energy_scale"]
        rel = f"{100 * err / scale:.3g} % of" if scale > 0 else "with no"
        warn = ("  WARNING: large" + energy_cause(err, stats.get("energy_jump"))
                if energy_warning(err, scale) else "")
        out.append(f"energy balance error {err:.3e} J ({rel} the energy in play, "
                   f"{scale:.3e} J){warn}")
    if stats.get("condensed_until") is not None:
        out.append(f"rigid joints condensed until t = {stats['condensed_until']:.9g} s, kept "
                   "from there (a step of the condensed model did not converge)")
    return out


def _bound_word(text: str) -> str:
    """The optional value of --global-error: only 'bound'."""
    if text != "bound":
        raise argparse.ArgumentTypeError(f"expected 'bound' or nothing, got {text!r}")
    return text


def _add_overrides(p: argparse.ArgumentParser) -> None:
    """The run-time overrides of the file's simulation settings (run and sweep)."""
    p.add_argument("--t-end", type=_positive("pos"), help="final time (s)")
    p.add_argument("--step", type=_positive("pos"), help="time step (s)")
    p.add_argument("--rho-inf", type=_positive("rho"), help="spectral radius in [0, 1]")
    p.add_argument("--formulation", choices=("index2", "index3"),
                   help="stabilized index-2 (default) or the paper's index-3 form")
    p.add_argument("--tol", type=_positive("pos"),
                   help="adaptive steps: the local position errors (m, RMS over each "
                        "body's mass) add up to TOL over a run of even difficulty "
                        "(docs/accuracy.md)")
    p.add_argument("--global-error", nargs="?", const=True, default=None, type=_bound_word,
                   metavar="bound",
                   help="with --tol: estimate the global position error by a companion run "
                        "on the run's steps taken two at a time (about half the steps again); "
                        "'--global-error bound' also repeats the run on its steps refined until "
                        "the estimate is within TOL (results written when the run is done)")
    p.add_argument("--output-step", type=_positive("pos"),
                   help="store results every OUTPUT_STEP seconds (dense output)")
    p.add_argument("--initial-velocities", choices=("project", "strict"),
                   help="initial velocities the joints do not allow: project them (default; "
                        "reported) or refuse them")


def _overrides(args) -> dict:
    """The overrides given on the command line, as simulation settings."""
    return {k: getattr(args, k) for k in _OVERRIDES if getattr(args, k) is not None}


def _check_args(c) -> None:
    c.add_argument("models", nargs="+", metavar="MODEL")
    c.add_argument("--rank-max", type=int, default=3000,
                   help="skip the rank analysis above this many unknowns (default 3000)")
    c.set_defaults(func=cmd_check)


def _run_args(r) -> None:
    r.add_argument("model")
    _add_overrides(r)
    r.add_argument("--out", help="folder of the results file (default: out); the file is "
                   "named after the model (MODEL.h5)")
    r.add_argument("--overwrite", action="store_true",
                   help="replace an existing results file (refused otherwise)")
    r.add_argument("--resume", metavar="RESULTS",
                   help="continue the run of this results file (finished, failed, interrupted "
                   "or killed) from its last checkpoint, bit for bit as one uninterrupted run; "
                   "with --t-end, further than it was planned")
    r.add_argument("--quiet", action="store_true",
                   help="no progress bar and no summary (what it changed or flags: one line "
                        "each on stderr)")
    r.add_argument("--threads", type=_threads, metavar="N",
                   help="threads of the compiled engine (default: SE3DYN_THREADS or the "
                   "cores; the results do not depend on it)")
    r.set_defaults(func=cmd_run)


def _sweep_args(sw) -> None:
    from se3dyn.sweep.cli import add_arguments  # argument declarations only (no dask)

    add_arguments(sw)
    _add_overrides(sw)
    sw.set_defaults(func=cmd_sweep)


def _results_arg(func):
    def declare(p) -> None:
        p.add_argument("results")
        p.set_defaults(func=func)

    return declare


def _plot_args(pl) -> None:
    pl.add_argument("results")
    pl.add_argument("channels", nargs="+")
    pl.add_argument("-o", "--output", help="PNG, PDF or SVG file, or a folder (default: a PNG "
                    "next to the results file)")
    pl.add_argument("--title", help="title (default: the file and what is plotted)")
    pl.add_argument("--x", metavar="CHANNEL", help="plot against this channel instead of time "
                    "(an x-y plot, e.g. a node's z against its x)")
    pl.set_defaults(func=cmd_plot)


def _export_args(ex) -> None:
    ex.add_argument("results")
    fmt = ex.add_mutually_exclusive_group(required=True)
    fmt.add_argument("--csv", help="CSV file to write")
    fmt.add_argument("--gltf", help="animated glTF 2.0 file to write (.glb or .gltf)")
    ex.add_argument("channels", nargs="*", help="channels (default: all)")
    ex.set_defaults(func=cmd_export)


def _view_args(vw) -> None:
    vw.add_argument("results")
    vw.add_argument("-o", "--output", help="HTML file (default: a temporary file, opened in "
                    "the browser)")
    vw.add_argument("--model", help="draw with this model file (visuals) instead of the "
                    "stored model")
    vw.add_argument("--channel", action="append", metavar="PATTERN",
                    help="channel or pattern to embed for the plot (repeatable)")
    vw.add_argument("--trace", action="append", metavar="NODE", help="node traced first "
                    "(repeatable)")
    vw.set_defaults(func=cmd_view)


def _export_fmu_args(ef) -> None:
    ef.add_argument("model")
    ef.add_argument("-o", "--output", required=True, help="the FMU file to write (.fmu)")
    ef.add_argument("--step", type=float, help="the simulator's step (default: the model "
                    "file's simulation step); communication steps must be multiples of it")
    ef.add_argument("--out-channel", dest="outputs", action="append", metavar="CHANNEL",
                    help="a results channel to output (repeatable; default: every joint "
                    "coordinate and rate and every marker position)")
    ef.set_defaults(func=cmd_export_fmu)


def cmd_import_urdf(args) -> int:
    """Write a URDF file's model as a model file (``se3dyn.load_urdf`` with the options)."""
    from se3dyn.errors import ModelError
    from se3dyn.io.modelfile import save_model

    if not Path(args.urdf).is_file():
        raise _Usage(f"{args.urdf}: no such URDF file")
    options = {"floating_base": args.floating_base, "fixed": args.fixed,
               "mimic": args.mimic, "package_dirs": args.package_dir or ()}
    try:
        model, _ = _load_urdf(args.urdf, print, options)
        save_model(model, args.output)
    except ModelError as exc:
        raise _Usage(str(exc)) from None
    print(f"{args.output}: {len(model.nodes)} nodes, {len(model.joints)} joints written "
          f"from {args.urdf}")
    return 0


def _import_urdf_args(iu) -> None:
    iu.add_argument("urdf")
    iu.add_argument("-o", "--output", required=True, help="the model file to write (.yaml)")
    iu.add_argument("--floating-base", action="store_true",
                    help="the root link a free body (default: clamped)")
    iu.add_argument("--fixed", choices=("keep", "merge"), default="keep",
                    help="fixed joints kept as rigid joints, or their links merged")
    iu.add_argument("--mimic", choices=("enforce", "ignore"), default="enforce",
                    help="<mimic> as exact couplings, or dropped")
    iu.add_argument("--package-dir", action="append", metavar="DIR",
                    help="a folder of ROS packages for package:// meshes (repeatable)")
    iu.set_defaults(func=cmd_import_urdf)


def _linearize_args(li) -> None:
    li.add_argument("model")
    li.add_argument("--at", choices=("static", "initial"), default="static",
                    help="about the static equilibrium (default) or the initial state of a "
                    "run (e.g. a steady spin)")
    li.add_argument("--input", dest="inputs", action="append", metavar="NAME",
                    help="a joint or load name as an input (repeatable)")
    li.add_argument("--output", dest="outputs", action="append", metavar="NAME",
                    help="a joint, node or marker name as an output (repeatable)")
    li.add_argument("--modes", type=_count, help="the lowest modes only")
    li.add_argument("--export", metavar="FILE.npz", help="write the matrices, names and "
                    "modes to a NumPy .npz file")
    li.set_defaults(func=cmd_linearize)


def _modes_args(mo) -> None:
    mo.add_argument("model")
    mo.add_argument("--at", choices=("static", "initial"), default="static",
                    help="about the static equilibrium (default) or the initial state")
    mo.add_argument("--mode", type=_count, default=1, help="the mode to play (1: the slowest)")
    mo.add_argument("--amplitude", type=float, help="scale of the shape (its largest entry "
                    "1); default: a tenth of the model's size")
    mo.add_argument("-o", "--output", metavar="PAGE.html", help="the page (default "
                    "MODEL_modeN.html)")
    mo.set_defaults(func=cmd_modes)


# the subcommands: help line, and the declaration of their arguments
_COMMANDS = {
    "check": ("validate model files; counts and rank analysis", _check_args),
    "run": ("simulate a model file and write the results file", _run_args),
    "sweep": ("parameter study: many runs on dask.distributed", _sweep_args),
    "channels": ("list the channels of a results file", _results_arg(cmd_channels)),
    "info": ("status, settings and statistics of a results file", _results_arg(cmd_info)),
    "types": ("the joint and element types and their fields",
              lambda ty: ty.set_defaults(func=cmd_types)),
    "plot": ("plot channels against time (PNG)", _plot_args),
    "export": ("export channels to CSV, or the motion to glTF", _export_args),
    "view": ("3D viewer page (HTML) of a results file", _view_args),
    "export-fmu": ("export a model as an FMI 2.0 co-simulation FMU (pythonfmu)",
                   _export_fmu_args),
    "import-urdf": ("write a URDF robot as a model file (docs/urdf.md)", _import_urdf_args),
    "linearize": ("linear model and modes about the static equilibrium (.npz export)",
                  _linearize_args),
    "modes": ("the modes of a model, and a viewer page playing one (HTML)", _modes_args),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of the ``se3dyn`` command. With ``command``, only that subcommand's
    arguments are declared (every subcommand is still listed with its help, all that
    ``se3dyn --help`` and a misspelt command need): declaring them all cost ``se3dyn run``
    some 5 ms of its start-up."""
    from se3dyn._version import __version__

    p = _Parser(prog="se3dyn", description="Multibody dynamics on SE(3).")
    p.add_argument("--version", action="version", version=f"se3dyn {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, (text, declare) in _COMMANDS.items():
        sp = sub.add_parser(name, help=text)
        if command is None or command == name:
            declare(sp)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``se3dyn`` console script; returns the exit code."""
    import signal
    import threading

    saved = None
    if threading.current_thread() is threading.main_thread():
        # se3dyn/cli/startup.py made Ctrl-C during start-up quiet; from here on it raises
        # KeyboardInterrupt, and SIGTERM _Terminated, handled below and by `run` (results file
        # closed); the caller's handlers are restored on return
        saved = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
        _STOP.clear()
        signal.signal(signal.SIGINT, _on_signal)
        signal.signal(signal.SIGTERM, _on_signal)
    try:
        return _main(argv)
    finally:
        if saved is not None:
            signal.signal(signal.SIGINT, saved[0])
            signal.signal(signal.SIGTERM, saved[1])


def _main(argv: list[str] | None) -> int:
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        # the subcommand: the first word that is not an option (the top level has no option
        # that takes a value)
        parser = build_parser(next((a for a in argv if not a.startswith("-")), None))
        args, extra = parser.parse_known_args(argv)
        if extra:
            # `export RESULTS --csv FILE CHANNEL...`: channels after the option are channels
            if args.command == "export" and not any(e.startswith("-") for e in extra):
                args.channels = list(args.channels) + extra
            else:
                parser.error("unrecognized arguments: " + " ".join(extra))
        if args.command != "run":  # (run: once it has loaded the model file and h5py)
            _loaded()
        return int(args.func(args))
    except _Usage as exc:
        _err(str(exc))
        return 2
    except BrokenPipeError:
        # the reader of the output went away (`se3dyn check ... | head`): stop quietly, as
        # command-line tools do (128 + SIGPIPE); the rest of the output goes to /dev/null so
        # that the interpreter's last flush of stdout does not fail again
        import os

        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 141
    except Exception as exc:
        from se3dyn.errors import Se3dynError

        if not isinstance(exc, Se3dynError):
            raise
        _err(str(exc))  # (e.g. a bad SE3DYN_THREADS met when the engine is first loaded)
        return 2
    except KeyboardInterrupt:
        _err("interrupted")
        return 130
    except _Terminated:
        _err("terminated")
        return 143


if __name__ == "__main__":
    raise SystemExit(main())
