"""One run of a sweep, as a worker executes it (no dask here: usable and testable alone).

:func:`execute_run` sets the varied values in the model-file data, loads the model with the
model-file rules (:func:`se3dyn.io.modelfile.loads_model`), simulates it with the fully compiled
fixed-step loop, evaluates the metrics, writes the results file and returns the summary row.
Every failure of the run (invalid value, Newton failure, anything else) becomes a row with
``status = "failed"`` and a one-line message: a run never raises.

Results files are written with :class:`se3dyn.io.h5.ResultsWriter` (the writer of ``se3dyn run``)
under a temporary name in the target folder and renamed with :func:`os.replace` once closed, so a
file under its final name is always complete.
"""

from __future__ import annotations

import json
import math
import os
import socket
import tempfile
import time
import uuid
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from se3dyn.sweep.spec import apply_values

if TYPE_CHECKING:
    from se3dyn.sweep.metrics import Metric

__all__ = ["RunContext", "execute_run", "result_name", "TMP_SUFFIX", "warm_up"]

#: Suffix of results files being written (never taken for finished ones).
TMP_SUFFIX = ".tmp"


def result_name(run: int, width: int) -> str:
    """File name of run ``run``'s results file: ``0007.h5`` (zero-padded to ``width``)."""
    return f"{run:0{width}d}.h5"


@dataclass
class RunContext:
    """What every run of a sweep shares (sent once to each worker).

    Attributes
    ----------
    data : dict
        The model-file data with the run-time overrides applied (see
        :func:`se3dyn.io.modelfile.parse_model_data`).
    label : str
        Name of the model in messages (the file name).
    metrics : list of Metric
    h5 : {"shared", "client", "none"}
        Results files written into ``runs_dir`` by the worker, sent back to the client as
        bytes, or not written.
    runs_dir : str or None
        Folder of the results files (mode "shared": as seen by the workers).
    width : int
        Zero padding of the run number in file names.
    """

    data: dict
    label: str = "model"
    metrics: list[Metric] = field(default_factory=list)
    h5: str = "none"
    runs_dir: str | None = None
    width: int = 4


class _Row:
    """The state attributes :meth:`se3dyn.io.h5.ResultsWriter.append` reads, from a stored row."""

    __slots__ = ("t", "H", "v", "vd", "alpha", "lam")

    def __init__(self, res, i: int):
        self.t = res.t[i]
        self.H = res.H[i]
        self.v = res.v[i]
        self.vd = res.vd[i]
        self.alpha = res.alpha[i]
        self.lam = res.lam[i]


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _write_h5(path: Path, system, res, text: str, cfg: dict, stats: dict) -> None:
    """Write ``res`` to ``path`` through a temporary file renamed when complete."""
    from se3dyn.io.h5 import ENERGIES, ResultsWriter

    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}{TMP_SUFFIX}")
    try:
        with ResultsWriter(tmp, system, model_text=text, settings=cfg,
                           flush_interval=math.inf) as w:
            for i in range(len(res.t)):
                sc = {e: getattr(res, e)[i] for e in ENERGIES}
                sc.update(iterations=res.iterations[i], residual=res.residual[i],
                          constraint=res.constraint[i])
                w.append(_Row(res, i), sc)
            w.close(stats=stats)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _validated_settings(sim: dict, label: str) -> dict:
    """The simulation settings as ``loads_model`` returns them (validated by its rules)."""
    from se3dyn.io.modelfile import format_model_data, loads_model

    doc = {"se3dyn": 1, "nodes": {"n": {"fixed": True}}, "simulation": sim}
    return loads_model(format_model_data(doc), filename=label)[1]


def execute_run(ctx: RunContext, run: int, values: dict, cache: OrderedDict | None = None
                ) -> dict:
    """Run one variant and return its summary row (never raises for a failing run).

    Parameters
    ----------
    ctx : RunContext
    run : int
        Run number (its results file is ``result_name(run, ctx.width)``).
    values : dict
        ``{path: value}`` of this run.
    cache : OrderedDict, optional
        Per-worker cache of compiled systems keyed by the varied model values: runs that vary
        only ``simulation.*`` settings build the model once per worker.

    Returns
    -------
    dict
        ``run``, the varied values, ``status`` ("ok" or "failed"), ``message``, ``wall_time``
        (s, in the worker), ``steps``, ``newton_iterations``, the metrics, ``worker``
        (host:pid) and ``results`` (the file name, or "" when none was written); in mode
        "client" also ``_h5`` (the file's bytes).
    """
    from se3dyn.dynamics.run import simulate
    from se3dyn.engine.system import compile_model
    from se3dyn.errors import ModelError, SimulationError
    from se3dyn.io.modelfile import format_model_data, loads_model

    t0 = time.perf_counter()
    row: dict[str, Any] = {"run": int(run), **values, "status": "ok", "message": "",
                           "wall_time": math.nan, "steps": 0, "newton_iterations": 0}
    for m in ctx.metrics:
        row[m.name] = math.nan
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    row["results"] = ""
    label = f"{ctx.label} (run {run}: " + ", ".join(f"{p}={v}" for p, v in values.items()) + ")"
    res = system = text = None
    cfg: dict = {}
    failure = None
    try:
        data = apply_values(ctx.data, values)
        text = format_model_data(data)
        key = json.dumps([[p, v] for p, v in values.items() if not p.startswith("simulation.")])
        if cache is not None and key in cache:
            system = cache[key]
            cache.move_to_end(key)
            cfg = _validated_settings(data.get("simulation") or {}, label)
        else:
            model, cfg = loads_model(text, filename=label)
            system = compile_model(model)
            if cache is not None:
                cache[key] = system
                while len(cache) > 4:
                    cache.popitem(last=False)
        try:
            res = simulate(system, **cfg)
        except SimulationError as exc:
            res, failure = exc.result, _one_line(exc)
    except ModelError as exc:
        # the loader names this run's generated text ("<label>, line n: "): drop that prefix,
        # the row already names the run and its values
        msg = str(exc)
        failure = _one_line(msg[len(label):].split(": ", 1)[-1] if msg.startswith(label)
                            else msg)
    except Exception as exc:  # a failed run never stops the others: report, do not raise
        failure = _one_line(f"{type(exc).__name__}: {exc}")
    if res is not None:
        row["steps"] = int(res.stats.get("steps", len(res.t) - 1))
        row["newton_iterations"] = int(res.stats.get("newton_iterations", 0))
    if failure is None:
        try:
            for m in ctx.metrics:
                row[m.name] = m.evaluate(res)
        except (KeyError, ValueError) as exc:
            msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            failure = _one_line(f"metric: {msg}")
    if res is not None and ctx.h5 != "none":
        stats = {k: v for k, v in res.stats.items() if k != "final_state"}
        if failure is not None:
            stats.update(failed=True, message=failure)
        name = result_name(run, ctx.width)
        try:
            if ctx.h5 == "shared":
                folder = Path(ctx.runs_dir or ".")
                if not folder.is_dir():
                    raise OSError(f"results folder {folder} not found on host "
                                  f"{socket.gethostname()} (not a shared directory? use "
                                  "--h5 client or --h5 none)")
                _write_h5(folder / name, system, res, text, cfg, stats)
            else:
                with tempfile.TemporaryDirectory(prefix="se3dyn-sweep-") as tmpdir:
                    p = Path(tmpdir) / name
                    _write_h5(p, system, res, text, cfg, stats)
                    row["_h5"] = p.read_bytes()
            row["results"] = f"runs/{name}"
        except OSError as exc:
            failure = _one_line(f"results file: {exc}") if failure is None else failure
    if failure is not None:
        row["status"], row["message"] = "failed", failure
    row["wall_time"] = time.perf_counter() - t0
    return row


def warm_up() -> float:
    """Import se3dyn and load its compiled kernels in this process, with one thread for the
    element kernels (the sweep runs one process per core); returns the seconds taken."""
    t0 = time.perf_counter()
    import se3dyn.io.h5  # noqa: F401  (h5py)
    from se3dyn.dynamics.run import simulate
    from se3dyn.engine.threads import set_threads
    from se3dyn.model.builder import ModelBuilder

    set_threads(1)  # (the sweep keeps every core busy with runs)

    mb = ModelBuilder(gravity=(0.0, 0.0, -9.81), name="warm-up")
    mb.node("ground", fixed=True)
    mb.node("bob", position=(0.5, 0.0, 0.0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("hinge", "hinge", "ground", "bob", axis=(0.0, 1.0, 0.0), at=(0.0, 0.0, 0.0))
    simulate(mb.build(), t_end=0.02, step=0.01)
    return time.perf_counter() - t0
