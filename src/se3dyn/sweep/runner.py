"""Orchestration of a sweep on dask.distributed: plan, resume, submit, collect, summarise."""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import re
import secrets
import sys
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from se3dyn.sweep.execute import TMP_SUFFIX, RunContext, result_name
from se3dyn.sweep.metrics import Metric, check_channels, parse_metric
from se3dyn.sweep.spec import SweepSpecError, Variable, check_path, plan_runs
from se3dyn.sweep.table import Journal, Progress, columns, to_table, write_summary

__all__ = ["run_sweep", "SweepPlan", "prepare", "execute_plan", "SweepInterrupted", "H5_MODES"]

H5_MODES = ("shared", "client", "none")
DEFINITION = "sweep.json"
JOURNAL = "journal.jsonl"


class SweepInterrupted(KeyboardInterrupt):
    """The sweep was interrupted; the summary holds the runs finished so far."""

    def __init__(self, done: int, total: int, out: Path | None):
        super().__init__(f"interrupted: {done} of {total} runs done"
                         + (f"; complete the sweep with --resume --out {out}" if out else ""))
        self.done, self.total, self.out = done, total, out


@dataclass
class SweepPlan:
    """A validated sweep, ready to run (built by :func:`prepare`; no run has started)."""

    ctx: RunContext
    variables: list[Variable]
    runs: list[dict]
    definition: dict
    out: Path | None
    label: str
    seed: int | None
    cols: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------------------------
def _load_base(model) -> tuple[dict, str]:
    """Model-file data and a label from a path, YAML text, a mapping or a Model."""
    from se3dyn.io.modelfile import format_model_data, parse_model_data, save_model
    from se3dyn.model.specs import Model

    if isinstance(model, Model):
        return parse_model_data(save_model(model), filename=model.name), model.name
    if isinstance(model, Mapping):
        try:
            data = json.loads(json.dumps(model))  # a plain deep copy; refuses non-data values
        except (TypeError, ValueError) as exc:
            raise SweepSpecError("model", "mapping", "plain model-file data (dicts, lists, "
                                 "numbers, strings)", str(exc)) from None
        return parse_model_data(format_model_data(data), filename="<mapping>"), "<mapping>"
    if isinstance(model, bytes) or (isinstance(model, str) and "\n" in model):
        return parse_model_data(model, filename="<string>"), "<string>"
    path = Path(os.fspath(model))
    if not path.is_file():
        raise SweepSpecError("MODEL", "path", "an existing model file", str(path))
    return parse_model_data(path.read_bytes(), filename=str(path)), str(path)


def _apply_overrides(data: dict, overrides: Mapping | None) -> None:
    from se3dyn.io.modelfile import FIELDS

    if not overrides:
        return
    known = [f.name for f in FIELDS["simulation"]]
    sim = data.setdefault("simulation", {})
    for key, val in overrides.items():
        if key not in known:
            import difflib

            close = difflib.get_close_matches(str(key), known, n=1)
            raise SweepSpecError("overrides", str(key), "a simulation setting: " +
                                 ", ".join(known), key,
                                 f"did you mean '{close[0]}'?" if close else "")
        if val is not None:
            sim[key] = val


def prepare(model, vary, *, method: str = "grid", samples: int | None = None,
            seed: int | None = None, metrics=(), overrides: Mapping | None = None,
            out: str | os.PathLike | None = None, h5: str = "shared") -> SweepPlan:
    """Validate everything and plan the runs (no cluster, no run): see :func:`run_sweep`.

    Raises
    ------
    SweepSpecError, se3dyn.io.modelfile.ModelFileError
        Bad path (listing the valid keys), spec, metric, option or model file.
    """
    from se3dyn._version import __version__
    from se3dyn.engine.system import compile_model
    from se3dyn.errors import ModelError
    from se3dyn.io.modelfile import format_model_data, loads_model
    from se3dyn.model.specs import Model

    if h5 not in H5_MODES:
        raise SweepSpecError("--h5", "h5", "one of " + ", ".join(H5_MODES), h5)
    for name, value, ok, expected in (
            ("model", model, isinstance(model, (str, bytes, os.PathLike, Mapping, Model)),
             "a model file (path or YAML text), its data as a mapping, or a Model"),
            ("vary", vary, isinstance(vary, (str, Mapping, list, tuple)),
             "{path: spec} or 'PATH=SPEC' strings"),
            ("metrics", metrics, isinstance(metrics, (str, Mapping, list, tuple)),
             "{name: 'FUNC(EXPR)'} or 'NAME=FUNC(EXPR)' strings"),
            ("overrides", overrides, overrides is None or isinstance(overrides, Mapping),
             "a mapping of simulation settings"),
            ("out", out, out is None or isinstance(out, (str, os.PathLike)),
             "a folder (str or path) or None")):
        if not ok:
            raise SweepSpecError("sweep", name, expected, value)
    data, label = _load_base(model)
    _apply_overrides(data, overrides)
    # the variables, their paths (before any run starts)
    if isinstance(vary, Mapping):
        variables = [Variable.make(p, s) for p, s in vary.items()]
    elif isinstance(vary, str):
        variables = [Variable.parse(vary)]
    else:
        variables = [Variable.parse(v) for v in vary]
    for v in variables:
        check_path(data, v.path)
    # metrics
    if isinstance(metrics, Mapping):
        mets = [parse_metric(t, name) for name, t in metrics.items()]
    elif isinstance(metrics, str):
        mets = [parse_metric(metrics)]
    else:
        mets = [m if isinstance(m, Metric) else parse_metric(m) for m in metrics]
    names = [m.name for m in mets]
    clash = sorted({n for n in names if names.count(n) > 1} | (set(names) & {v.path for v in
                                                                            variables}))
    if clash:
        raise SweepSpecError(f"--metric {clash[0]}", "NAME", "a name used once", clash[0])
    # the base model must load and simulate settings must be complete
    text = format_model_data(data)
    base_model, settings = loads_model(text, filename=label)
    varied = {v.path for v in variables}
    for key in ("t_end", "step"):
        if key not in settings and f"simulation.{key}" not in varied:
            raise SweepSpecError(label, f"simulation.{key}", f"a value in the file's "
                                 f"simulation settings or --{key.replace('_', '-')}", None)
    try:
        system = compile_model(base_model)
    except ModelError as exc:
        raise SweepSpecError(label, "model", "a model that compiles", str(exc)) from None
    check_channels(mets, system)
    if method != "grid" and seed is None:
        seed = secrets.randbits(32)
    runs = plan_runs(variables, method, samples, seed)
    width = max(4, len(str(len(runs) - 1)))
    out_path = None if out is None else Path(out).resolve()
    if out_path is None:
        h5 = "none"
    definition = {
        "format": "se3dyn-sweep", "version": 1, "se3dyn": __version__, "model": label,
        "model_sha256": hashlib.sha256(text.encode()).hexdigest(),
        "vary": [[v.path, v.spec.text] for v in variables], "method": method,
        "samples": samples, "seed": seed, "metrics": [m.text for m in mets], "runs": len(runs),
    }
    ctx = RunContext(data=data, label=Path(label).name, metrics=mets, h5=h5,
                     runs_dir=None if out_path is None else str(out_path / "runs"), width=width)
    plan = SweepPlan(ctx=ctx, variables=variables, runs=runs, definition=definition,
                     out=out_path, label=label, seed=seed)
    plan.cols = columns([v.path for v in variables], names)
    return plan


# ---------------------------------------------------------------------------------------------
def _check_definition(out: Path, definition: dict, resume: bool) -> dict | None:
    """Compare with the definition stored in ``out``; returns the stored one (or None)."""
    f = out / DEFINITION
    if not f.is_file():
        return None
    try:
        old = json.loads(f.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise SweepSpecError(str(out), DEFINITION, "a readable sweep definition",
                             "an unreadable file") from None
    if not resume:
        raise SweepSpecError(f"--out {out}", "out", "a folder without a sweep (give --resume to"
                             " complete the sweep in it, or another --out)", "a folder with "
                             f"{DEFINITION}")
    keys = ("model_sha256", "vary", "method", "samples", "seed", "metrics", "runs")
    diff = [k for k in keys if old.get(k) != definition.get(k)]
    if diff:
        k = diff[0]
        if k == "model_sha256":
            raise SweepSpecError(f"--resume --out {out}", "model", "the model file and run-time "
                                 "overrides of the stored sweep (sha256 "
                                 f"{str(old.get(k))[:12]}...)",
                                 f"sha256 {definition[k][:12]}...")
        raise SweepSpecError(f"--resume --out {out}", k, f"the same {k} as the stored sweep "
                             f"({old.get(k)!r})", definition.get(k))
    return old


def _finished(row: dict | None, out: Path, ctx: RunContext, retry_failed: bool) -> bool:
    """A run is finished when the journal has its row and, for an ok run with results files,
    its final results file exists."""
    if row is None:
        return False
    if row.get("status") != "ok":
        return not retry_failed
    if ctx.h5 == "none":
        return True
    return (out / "runs" / result_name(int(row["run"]), ctx.width)).is_file()


def _clean_tmp(runs_dir: Path) -> None:
    """Remove the temporary files of runs that were killed while writing (and the lock files
    their writers left, ``.lock`` after the name: se3dyn.io.h5.ResultsWriter)."""
    if runs_dir.is_dir():
        for p in [*runs_dir.glob(f".*{TMP_SUFFIX}"), *runs_dir.glob(f".*{TMP_SUFFIX}.lock")]:
            try:
                p.unlink()
            except OSError:
                pass


def _write_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.client{TMP_SUFFIX}")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _need_distributed() -> None:
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise ImportError("se3dyn sweep runs on dask.distributed, which is not installed: "
                          "pip install 'se3dyn[sweep]'") from None


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def _check_scheduler(scheduler) -> None:
    """A scheduler address is HOST:PORT or PROTOCOL://HOST:PORT (checked before the sweep's
    folder is touched)."""
    if scheduler is not None and (not isinstance(scheduler, str) or not re.fullmatch(
            r"(?:[a-z][a-z0-9+.-]*://)?[^\s/:]+:\d{1,5}", scheduler)):
        raise SweepSpecError("--scheduler", "address", "the address of a running dask "
                             "scheduler, HOST:PORT or tcp://HOST:PORT", scheduler)


def _client(scheduler: str | None, workers: int | None):
    """A dask client: to ``scheduler``, or to a new LocalCluster of ``workers`` processes with
    one thread each, whose scratch space is a temporary folder of its own. Returns (client,
    cluster or None, description, scratch folder to remove after the cluster or None)."""
    import shutil
    import tempfile

    from distributed import Client, LocalCluster

    if scheduler is not None:
        _check_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, ValueError, TypeError) as exc:
            raise SweepSpecError("--scheduler", "address", "the address of a running dask "
                                 "scheduler (tcp://host:port)", scheduler,
                                 f"cannot connect: {exc}") from None
        n = len(client.scheduler_info().get("workers", {}))
        return client, None, f"scheduler {scheduler} ({n} workers now)", None
    n = workers if workers is not None else _cpu_count()
    if not (isinstance(n, int) and not isinstance(n, bool) and n >= 1):
        raise SweepSpecError("--workers", "workers", "a positive number of worker processes", n)
    scratch = tempfile.mkdtemp(prefix="se3dyn-sweep-dask-")  # (not dask-scratch-space/ in TMP)
    try:
        import dask

        with dask.config.set({"temporary-directory": scratch}):  # (the scheduler's too)
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", host="127.0.0.1",
                                   silence_logs=logging.ERROR, local_directory=scratch)
    except BaseException:
        shutil.rmtree(scratch, ignore_errors=True)
        raise
    return Client(cluster), cluster, f"LocalCluster of {n} worker processes", scratch


# ---------------------------------------------------------------------------------------------
def run_sweep(model, vary, *, method: str = "grid", samples: int | None = None,
              seed: int | None = None, metrics=(), out: str | os.PathLike | None = None,
              overrides: Mapping | None = None, workers: int | None = None,
              scheduler: str | None = None, client=None, resume: bool = False,
              retry_failed: bool = False, h5: str = "shared", progress: bool | None = None,
              as_frame: bool | None = None, log: Callable[[str], None] | None = None):
    """Run a parameter study on dask.distributed and return its summary table.

    Also available as ``se3dyn.sweep(...)``; the command line is ``se3dyn sweep``
    (``docs/sweep.md``).

    Parameters
    ----------
    model : str, os.PathLike, Mapping or Model
        A model file (path or YAML text), its data as a mapping, or a built Model (saved to
        model-file data first; built-in time functions only).
    vary : Mapping or sequence of str
        ``{path: spec}`` (a spec text such as ``"0.1,0.2"``, ``"0:1:11"``, ``"uniform(0,1)"``,
        or a list of values), or ``"PATH=SPEC"`` strings; see :mod:`se3dyn.sweep.spec`.
    method : {"grid", "random", "lhs"}
        Full grid of the lists/ranges, or ``samples`` random or Latin-hypercube points.
    samples : int, optional
        Number of runs of a random or LHS sweep.
    seed : int, optional
        Seed of random and LHS sampling (drawn and stored in ``sweep.json`` when omitted).
    metrics : Mapping or sequence of str
        ``{name: "max(abs(CHANNEL))"}`` or ``"NAME=FUNC(EXPR)"`` strings, see
        :mod:`se3dyn.sweep.metrics`.
    out : path, optional
        Output folder (``summary.csv``, ``runs/*.h5``, ``journal.jsonl``, ``sweep.json``);
        None: nothing is written and no results files are made.
    overrides : Mapping, optional
        Simulation settings applied over the file's (``t_end``, ``step``, ``rho_inf``, ...);
        a varied ``simulation.*`` path wins over both.
    workers : int, optional
        Worker processes of the LocalCluster started when neither ``scheduler`` nor ``client``
        is given (default: one per core).
    scheduler : str, optional
        Address ``tcp://host:port`` of a running dask scheduler.
    client : distributed.Client, optional
        An existing client (left open).
    resume : bool
        Complete the sweep already in ``out``: run only the runs that are not finished (no
        journal row, or an ok row whose results file is missing).
    retry_failed : bool
        With ``resume``: run the failed runs again too.
    h5 : {"shared", "client", "none"}
        Results files written by the workers into ``out/runs`` (``out`` must be the same path
        on every worker: a shared directory), sent back to the client which writes them, or
        not written.
    progress : bool, optional
        Progress bar on stderr (default: when stderr is a terminal).
    as_frame : bool, optional
        Return a pandas DataFrame (True; default when pandas is importable) or a list of dicts
        (False).
    log : callable(str), optional
        Receives a few lines about the sweep (the CLI prints them).

    Returns
    -------
    pandas.DataFrame or list of dict
        One row per run, sorted by run number: ``run``, the varied paths, ``status``,
        ``message``, ``wall_time``, ``steps``, ``newton_iterations``, the metrics, ``worker``,
        ``results``.

    Raises
    ------
    SweepSpecError
        Bad input, before any run starts.
    SweepInterrupted
        On Ctrl-C, after writing the summary of the finished runs.
    """
    plan = prepare(model, vary, method=method, samples=samples, seed=seed, metrics=metrics,
                   overrides=overrides, out=out, h5=h5)
    return execute_plan(plan, workers=workers, scheduler=scheduler, client=client,
                        resume=resume, retry_failed=retry_failed, progress=progress,
                        as_frame=as_frame, log=log)


def execute_plan(plan: SweepPlan, *, workers: int | None = None, scheduler: str | None = None,
                 client=None, resume: bool = False, retry_failed: bool = False,
                 progress: bool | None = None, as_frame: bool | None = None,
                 log: Callable[[str], None] | None = None):
    """Run a plan made by :func:`prepare`; the options and the result are those of
    :func:`run_sweep`."""
    _check_options(plan, workers, scheduler, client, resume, retry_failed, progress, as_frame,
                   log)
    say = log or (lambda _msg: None)
    out_p, ctx, total = plan.out, plan.ctx, len(plan.runs)
    rows: dict[int, dict] = {}
    journal = None
    if out_p is not None:
        rows, journal = _open_out(plan, resume, say)
    todo = [i for i in range(total)
            if out_p is None or not _finished(rows.get(i), out_p, ctx, retry_failed)]
    already = total - len(todo)
    if plan.seed is not None:
        say(f"  {plan.definition['method']} sampling, seed {plan.seed}")
    if already:
        say(f"  {already} of {total} runs already done; {len(todo)} to run")
    show = sys.stderr.isatty() if progress is None else bool(progress)
    prog = Progress(total, already, show)
    cluster = own = scratch = None
    name = f"se3dyn-sweep-{uuid.uuid4().hex[:12]}"
    interrupted = False
    t0 = time.perf_counter()
    try:
        if todo:
            _need_distributed()
            if client is None:
                client, cluster, desc, scratch = _client(scheduler, workers)
                own = client
                say(f"  on a {desc}")
            futures = _submit(client, name, plan, todo)
            interrupted = _collect_all(client, futures, plan, rows, journal, prog)
    finally:
        prog.close()
        if journal is not None:
            journal.close()
        _release(client, bool(todo), name, own, cluster, scratch)
        if out_p is not None:
            _clean_tmp(out_p / "runs")
            table_rows = [rows[i] for i in sorted(rows)]
            write_summary(out_p, table_rows, plan.cols)
    wall = time.perf_counter() - t0
    done = len(rows)
    if interrupted:
        raise SweepInterrupted(done, total, out_p)
    failed = sum(1 for r in rows.values() if r.get("status") != "ok")
    say(f"  {total} runs: {total - failed} ok, {failed} failed ({len(todo)} executed in "
        f"{wall:.1f} s)")
    return to_table([rows[i] for i in sorted(rows)], plan.cols, as_frame)


def _check_options(plan: SweepPlan, workers, scheduler, client, resume, retry_failed, progress,
                   as_frame, log) -> None:
    """Refuse bad options of :func:`execute_plan`."""
    for name, value in (("resume", resume), ("retry_failed", retry_failed),
                        ("progress", progress), ("as_frame", as_frame)):
        if not (isinstance(value, bool) or value is None and name in ("progress", "as_frame")):
            raise SweepSpecError("sweep", name, "True or False" + (
                " (or None: the default)" if name in ("progress", "as_frame") else ""), value)
    if log is not None and not callable(log):
        raise SweepSpecError("sweep", "log", "a function of one str, or None", log)
    if client is not None and not all(hasattr(client, a) for a in ("submit",
                                                                    "register_plugin")):
        raise SweepSpecError("sweep", "client", "a distributed.Client, or None", client)
    if resume and plan.out is None:
        raise SweepSpecError("sweep", "resume", "an 'out' folder holding the sweep to "
                             "complete", None)
    _check_scheduler(scheduler)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise SweepSpecError("--workers", "workers", "a positive number of worker processes",
                             workers)
    if retry_failed and not resume:
        raise SweepSpecError("sweep", "retry_failed", "resume=True as well (it runs the failed "
                             "runs of a resumed sweep again)", retry_failed)


def _open_out(plan: SweepPlan, resume: bool, say) -> tuple[dict[int, dict], Journal]:
    """The output folder made (the definition written, a stale journal dropped): the rows
    of its journal (resume) and the journal opened for appending."""
    out_p, total = plan.out, len(plan.runs)
    if out_p.exists() and not out_p.is_dir():
        raise SweepSpecError("--out", "out", "a folder", str(out_p))
    stored = _check_definition(out_p, plan.definition, resume)
    if resume and stored is None:
        say(f"  nothing to resume in {out_p}: a new sweep")
    if stored is None and (out_p / JOURNAL).exists():
        (out_p / JOURNAL).unlink()  # rows of no known sweep
    try:
        (out_p / "runs").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SweepSpecError("--out", "out", "a folder that can be created",
                             str(out_p), exc.strerror or "") from None
    (out_p / DEFINITION).write_text(json.dumps(plan.definition, indent=1) + "\n",
                                    encoding="utf-8")
    journal = Journal(out_p / JOURNAL)
    rows = {r: row for r, row in journal.read().items() if 0 <= r < total}
    _clean_tmp(out_p / "runs")
    return rows, journal


def _submit(client, name: str, plan: SweepPlan, todo: list[int]) -> dict:
    """The sweep's plugin registered on the workers and its runs submitted: future -> run."""
    from se3dyn.sweep.worker import SweepPlugin, run_task

    client.register_plugin(SweepPlugin(name, plan.ctx), name=name)
    futures = {}
    for i in todo:
        fut = client.submit(run_task, name, i, plan.runs[i], key=f"{name}-run-{i}",
                            pure=False)
        futures[fut] = i
    return futures


def _collect_all(client, futures: dict, plan: SweepPlan, rows: dict, journal, prog) -> bool:
    """The rows of the runs as they finish, into ``rows`` (and the journal, and their results
    files into the output folder); True when interrupted (Ctrl-C: the rest cancelled)."""
    from distributed import as_completed

    out_p, ctx = plan.out, plan.ctx
    try:
        for fut in as_completed(list(futures)):
            i = futures.pop(fut)
            row = _collect(fut, i, plan)
            data = row.pop("_h5", None)
            if data is not None and out_p is not None:
                try:
                    _write_bytes(out_p / "runs" / result_name(i, ctx.width), data)
                except OSError as exc:
                    row.update(status="failed", message=f"results file: {exc}",
                               results="")
            if journal is not None:
                journal.append(row)  # the marker first: a row in the summary is done
            rows[i] = row
            prog.update(row["status"] != "ok")
            fut.release()
    except KeyboardInterrupt:
        client.cancel(list(futures))
        return True
    return False


def _release(client, submitted: bool, name: str, own, cluster, scratch) -> None:
    """The sweep's plugin unregistered, the client and cluster made for the sweep closed and
    their scratch folder removed."""
    if client is not None and submitted:
        try:
            client.unregister_worker_plugin(name)
        except Exception:  # noqa: BLE001 - a closing cluster; nothing left to undo
            pass
    if own is not None:
        own.close()
    if cluster is not None:
        cluster.close()
    if scratch is not None:
        import shutil

        shutil.rmtree(scratch, ignore_errors=True)


def _collect(fut, i: int, plan: SweepPlan) -> dict:
    """The row of a finished future; a task that dask gave up on (e.g. its workers kept dying:
    KilledWorker) becomes a failed row."""
    try:
        return fut.result()
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # noqa: BLE001 - KilledWorker, cancelled, lost: a failed row
        err: Any = exc
    row: dict[str, Any] = {"run": i, **plan.runs[i], "status": "failed",
                           "message": " ".join(f"{type(err).__name__}: {err}".split()),
                           "wall_time": math.nan, "steps": 0, "newton_iterations": 0}
    for m in plan.ctx.metrics:
        row[m.name] = math.nan
    row.update(worker="", results="")
    return row

