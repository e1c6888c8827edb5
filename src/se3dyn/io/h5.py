"""HDF5 results files: stream a simulation to disk while it runs, and read it back.

The layout is described field by field in ``docs/results-file.md``. This module is optional:
the core package never imports it (``import se3dyn`` works without h5py).

>>> import se3dyn as sd
>>> from se3dyn.io.h5 import ResultsWriter, read_results
>>> model = sd.examples.slider_crank()
>>> with ResultsWriter("out.h5", sd.compile_model(model)) as w:     # doctest: +SKIP
...     res = sd.simulate(model, 5.0, 1e-2, on_rows=w.add_rows, store=False)
...     w.close(res.stats)
>>> res2 = read_results("out.h5")                                   # doctest: +SKIP

Robustness: rows are buffered in memory (at most about 4 MB) and written, then
``flush()``-ed, at least every ``flush_interval`` seconds of wall time, with the latest
checkpoint (the complete integration state from which :meth:`ResultsWriter.resume` continues
the run bit for bit). The file is created with ``libver="latest"`` and put in SWMR
(single-writer / multiple-reader) mode once all datasets exist, so its metadata on disk is
always consistent: a writer killed with ``kill -9`` leaves a file holding every row up to the
last flush (``complete`` is then False), flagged as still open for writing. :func:`read_results`
(and so every se3dyn command) repairs such a file on first touch (:func:`repair`, like
``h5clear -s``) once no writer holds its lock, and follows a live writer by a SWMR read.
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import json
import os
import time
import zlib
from dataclasses import dataclass, field
from typing import Any

import h5py
import numpy as np

from se3dyn.engine.system import LayoutCounts, compile_model
from se3dyn.errors import Se3dynError, _short_repr
from se3dyn.results.channels import joint_units
from se3dyn.results.results import Results

__all__ = ["ResultsWriter", "read_results", "repair", "ResultsLayout", "ResultsFileError",
           "FORMAT", "FORMAT_VERSION", "ENERGIES", "SOLVER"]

#: Value of the root attribute ``format``.
FORMAT = "se3dyn-results"
#: Value of the root attribute ``format_version`` written by this version; newer ones are refused.
FORMAT_VERSION = 1
#: Datasets of the ``/energy`` group (J), in the order of ``se3dyn.dynamics.run.SCALARS``.
ENERGIES = ("kinetic", "potential", "spring", "work_actuators", "work_loads", "dissipation")
#: Datasets of the ``/solver`` group.
SOLVER = ("iterations", "residual", "constraint")


class ResultsFileError(Se3dynError, ValueError):
    """A results file that cannot be read (missing, not HDF5, not se3dyn results, too new)."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path = os.fspath(path)
        self.problem = problem
        super().__init__(f"results file '{self.path}': {problem}")


# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ResultsLayout(LayoutCounts):
    """The layout attributes of a :class:`~se3dyn.engine.system.System` that :class:`Results` needs,
    read from ``/layout`` (no model compilation).

    ``joint_units`` holds, per joint unknown (nk,), ``"rad"`` for a rotation coordinate and
    ``"m"`` for a translation (used by :func:`se3dyn.results.channels.channel_unit`).
    """

    node_names: tuple[str, ...]
    node_fixed: np.ndarray
    node_dofadr: np.ndarray
    joint_names: tuple[str, ...]
    joint_type: tuple[str, ...]
    joint_k: np.ndarray
    joint_dofadr: np.ndarray
    joint_multadr: np.ndarray
    joint_columns: np.ndarray
    joint_units: tuple[str, ...]
    composites: dict = field(default_factory=dict)
    nq: int = 0
    nm: int = 0
    model_text: str = ""  # the model file stored with the results (``stats["model"]``)

    @property
    def nk(self) -> int:
        return int(np.sum(self.joint_k))

    @functools.cached_property
    def stored_model(self):
        """The model stored with the results (:class:`~se3dyn.model.specs.Model`), or None
        when there is none, it does not load or its nodes differ from this layout's (loaded
        once)."""
        if not self.model_text:
            return None
        from se3dyn.io.modelfile import loads_model

        try:
            model = loads_model(self.model_text)[0]
        except Exception:  # noqa: BLE001 - a model text that does not load: no model
            return None
        return model if tuple(model.node_names) == tuple(self.node_names) else None

    @property
    def markers(self) -> tuple:
        """The markers of the stored model (read by the marker accessors of :class:`Results`
        and the ``marker/...`` channels); empty without a stored model."""
        m = self.stored_model
        return tuple(m.markers) if m is not None else ()

    @property
    def gravity(self) -> np.ndarray:
        """Gravity of the stored model (3,) (the accelerometers need it); zeros without one."""
        m = self.stored_model
        return np.array(m.gravity, dtype=float) if m is not None else np.zeros(3)

    @functools.cached_property
    def stored_system(self):
        """The compiled stored model when its nodes, joints and unknowns match this layout, else
        None (compiled once; the joint sensors of :class:`Results` take the joints' node B,
        attachment frames and axes from it)."""
        m = self.stored_model
        if m is None:
            return None
        try:
            cand = compile_model(m)
        except Exception:  # noqa: BLE001 - a stored model that does not compile: no geometry
            return None
        if (tuple(cand.node_names) == tuple(self.node_names)
                and tuple(cand.joint_names) == tuple(self.joint_names)
                and int(cand.nq) == int(self.nq) and int(cand.nm) == int(self.nm)):
            return cand
        return None


def _joint_columns(system) -> tuple[np.ndarray, np.ndarray]:
    """k per joint and the first column of each joint in the nk joint-unknown columns."""
    k = np.asarray(system.joint_k, dtype=np.int64)
    cols = (np.cumsum(k) - k).astype(np.int64)
    return k, cols


# ---------------------------------------------------------------------------------------------
#: Bytes of rows buffered in memory at most before they are written to the file.
_WRITE_BYTES = 4 << 20
#: Header of a restart slot (float64 values), followed by the state (see _pack_state).
_SLOT_HEADER = ("sequence", "rows", "steps", "newton_iterations", "rejected", "h_next", "crc32",
                "length")


class ResultsWriter:
    """Stream the rows of a simulation to an HDF5 results file.

    Parameters
    ----------
    path : str or PathLike
        File to create.
    system : System or Model
        The compiled system (a Model is compiled here) that is simulated.
    model_text : str, optional
        The YAML model text to store; by default ``se3dyn.io.modelfile.save_model(system.model)``,
        or ``""`` when the model holds Python callables and cannot be saved.
    settings : dict, optional
        Simulation settings, stored as JSON in the root attribute ``settings``.
    flush_interval : float
        Write buffered rows and flush the file at least this often (seconds of wall time).
    overwrite : bool
        Replace an existing file (default); False refuses with a :class:`ResultsFileError`.

    The file is locked while the writer is open (``fcntl.flock`` on ``PATH.lock``, removed at
    :meth:`close`): a second writer of the same file is refused with a
    :class:`ResultsFileError` naming the process that holds it.

    Use ``simulate(..., on_rows=writer.add_rows, store=False)`` (rows in blocks, memory flat) or
    ``simulate(..., on_output=writer.append)`` (row by row), then :meth:`close` (or a
    ``with`` block). :meth:`resume` reopens a file to continue its run.
    """

    def __init__(self, path: str | os.PathLike, system, *, model_text: str | None = None,
                 settings: dict | None = None, flush_interval: float = 1.0,
                 overwrite: bool = True, _resume: bool = False):
        from se3dyn.engine.system import compile_model
        from se3dyn.model.specs import Model

        if isinstance(system, Model):
            system = compile_model(system)
        self.path = os.fspath(path)
        self.system = system
        self.flush_interval = float(flush_interval)
        self.rows = 0
        self.closed = False
        self.checkpoint = None  # the latest checkpoint written (resume: the one read)
        self.base_iterations = 0  # Newton iterations before the checkpoint resumed from
        self._skip = 0  # rows to skip (resume: the first row is the stored checkpoint's)
        self._run_skip = 0
        self._run_base = 0  # rows in the file before the run
        self._pending_cp = None
        self._seq = 0
        s = system
        self.M = len(s.node_names)
        self.m = len(s.joint_names)
        self._fixed = np.asarray(s.node_fixed, dtype=bool)
        self._nodedof = np.asarray(s.node_dofadr, dtype=np.int64)
        k, cols = _joint_columns(s)
        self.nk = int(k.sum())
        # index of each joint unknown in the nq vector, in /joints/* column order
        self._jidx = np.concatenate(
            [np.arange(int(s.joint_dofadr[j]), int(s.joint_dofadr[j]) + int(k[j]))
             for j in range(self.m)] or [np.zeros(0)]).astype(np.int64)
        free = np.flatnonzero(~self._fixed)
        self._free = free
        self._freeidx = (self._nodedof[free][:, None] + np.arange(6)).astype(np.int64)
        self.nm = 6 * self.m
        self._buf: list[tuple] = []  # rows given one by one (append)
        self._blocks: list[dict] = []  # rows in file layout, not yet written
        self._buf_bytes = 0
        self._row_bytes = 8 * (1 + self.M * 24 + 3 * self.nk + self.nm + 9)
        self._chunk = int(max(16, min(256, (1 << 20) // max(self._row_bytes, 1))))
        # chunk cache per dataset: rows are written in order, whole blocks at a time, so two
        # chunks of the widest dataset are all it needs (HDF5 2.0's default of 8 MiB per
        # dataset would grow a writer of the 17 datasets by some 140 MB as the run goes)
        self._cache = 2 * self._chunk * 8 * max(9 * self.M, self.nk, self.nm, 1)
        self._last_flush = time.monotonic()
        self._lock = _FileLock(self.path)
        try:
            if _resume:
                self.file = self._reopen(s)
                return
            if not overwrite and os.path.exists(self.path):
                raise ResultsFileError(self.path, "exists (not overwritten)")
            if model_text is None:
                model_text = ""
                model = getattr(s, "model", None)
                if model is not None:
                    from se3dyn.errors import ModelError
                    from se3dyn.io.modelfile import save_model
                    try:
                        model_text = save_model(model)
                    except ModelError:
                        model_text = ""
            f = h5py.File(self.path, "w", libver="latest", rdcc_nbytes=self._cache)
            self.file = f
            try:
                self._create(f, s, k, cols, model_text, settings)
                f.flush()
                f.swmr_mode = True
            except BaseException:
                f.close()
                raise
        except BaseException:
            self._lock.release()
            raise

    # -----------------------------------------------------------------------------------------
    @classmethod
    def resume(cls, path: str | os.PathLike, system, *,
               flush_interval: float = 1.0) -> ResultsWriter:
        """Reopen a results file (complete, failed or left by a killed run) to continue its
        run: the file is locked and repaired if needed, the rows after its last checkpoint are
        dropped, and ``writer.checkpoint`` is the :class:`~se3dyn.dynamics.run.Checkpoint` to give
        ``simulate(..., initial_state=writer.checkpoint, on_rows=writer.add_rows)`` (whose first
        row, the checkpoint's own, is not written again).

        Raises
        ------
        ResultsFileError
            No such file, another writer holds it, no checkpoint stored, or a file of another
            model (layout).
        """
        return cls(path, system, flush_interval=flush_interval, _resume=True)

    def _reopen(self, s) -> h5py.File:
        from se3dyn.dynamics.recorder import Checkpoint

        path = self.path
        if not os.path.isfile(path):
            raise ResultsFileError(path, "no such file")
        # a run killed with kill -9 left the file flagged open (this writer holds the lock)
        _clear_status_flags(path, check_lock=False)
        try:
            f = h5py.File(path, "r+", libver="latest", rdcc_nbytes=self._cache)
        except OSError as exc:
            raise ResultsFileError(path, f"cannot be opened for writing ({exc})") from None
        try:
            _check_format(f, path)
            lay = _layout(f, path)
            if (lay.node_names != tuple(s.node_names) or lay.joint_names != tuple(s.joint_names)
                    or lay.nq != s.nq or lay.nm != s.nm):
                raise ResultsFileError(path, "holds the results of another model (nodes, "
                                       "joints or unknowns differ)")
            if not isinstance(f.get("stats"), h5py.Group):
                raise ResultsFileError(path, "damaged: /stats: expected a group (the "
                                       "statistics of the run), got nothing")
            if "restart" not in f:
                raise ResultsFileError(path, "has no checkpoint (written by an older se3dyn or "
                                       "stopped before its first checkpoint); run it again")
            cp = _read_checkpoint(f, s)
            if cp is None:
                raise ResultsFileError(path, "has no checkpoint yet (the run stopped before "
                                       "its first one); run it again")
            (state, rows, steps, its, rejected, h_next), self._seq = cp
            self._ds = {name: f[name] for name in _SERIES}
            self._chunk = f["time"].chunks[0]
            for ds in self._ds.values():  # drop the rows after the checkpoint
                if ds.shape[0] > rows:
                    ds.resize(rows, axis=0)
            self.rows = rows
            self._slots = f["restart/state"]
            self._memory = f["restart/solver"]
            for key in list(f["stats"].attrs):
                del f["stats"].attrs[key]
            f.attrs["complete"] = False
            f.flush()
            f.swmr_mode = True
        except (KeyError, TypeError, ValueError, IndexError, OSError, RuntimeError) as e:
            f.close()
            if isinstance(e, ResultsFileError):
                raise
            raise ResultsFileError(path, f"damaged or incomplete ({type(e).__name__}: {e})"
                                   ) from None
        except BaseException:
            f.close()
            raise
        self.checkpoint = Checkpoint(state, steps, h_next, its, rejected, rows)
        self.base_iterations = its
        self._skip = self._run_skip = 1
        self._run_base = rows
        return f

    # -----------------------------------------------------------------------------------------
    def _create(self, f, s, k, cols, model_text, settings):
        from se3dyn._version import __version__

        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["se3dyn_version"] = __version__
        f.attrs["created"] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
        f.attrs["model"] = model_text
        f.attrs["settings"] = json.dumps(settings or {}, default=str, sort_keys=True)
        f.attrs["complete"] = False
        M, nk, nm = self.M, self.nk, self.nm
        self._ds: dict[str, h5py.Dataset] = {}

        def mk(name, shape, dtype=np.float64, units=""):
            maxshape = (None,) + tuple(None if d == 0 else d for d in shape)
            chunks = (self._chunk,) + tuple(max(1, d) for d in shape)
            ds = f.create_dataset(name, shape=(0,) + shape, maxshape=maxshape, chunks=chunks,
                                  dtype=dtype)
            ds.attrs["units"] = units
            self._ds[name] = ds

        mk("nodes/position", (M, 3), units="m")
        mk("nodes/rotation", (M, 3, 3), units="1")
        mk("nodes/velocity", (M, 6), units="m/s, rad/s (material frame)")
        mk("nodes/acceleration", (M, 6), units="m/s^2, rad/s^2 (material frame)")
        mk("joints/alpha", (nk,), units="rad or m (see /layout/joint_units)")
        mk("joints/velocity", (nk,), units="rad/s or m/s (see /layout/joint_units)")
        mk("joints/acceleration", (nk,), units="rad/s^2 or m/s^2 (see /layout/joint_units)")
        mk("joints/multipliers", (nm,), units="N, N m")
        for e in ENERGIES:
            mk(f"energy/{e}", (), units="J")
        mk("solver/iterations", (), dtype=np.int32)
        mk("solver/residual", ())
        mk("solver/constraint", ())
        mk("time", (), units="s")  # extended last in every batch

        g = f.create_group("layout")
        strs = h5py.string_dtype("utf-8")
        g.create_dataset("node_names", data=np.array(list(s.node_names), dtype=object),
                         dtype=strs, shape=(M,))
        g.create_dataset("node_fixed", data=self._fixed.astype(np.int8), shape=(M,))
        g.create_dataset("node_dofadr", data=self._nodedof, shape=(M,))
        g.create_dataset("joint_names", data=np.array(list(s.joint_names), dtype=object),
                         dtype=strs, shape=(self.m,))
        jt = tuple(getattr(s, "joint_type", ("",) * self.m))
        g.create_dataset("joint_type", data=np.array(list(jt), dtype=object), dtype=strs,
                         shape=(self.m,))
        g.create_dataset("joint_k", data=k, shape=(self.m,))
        g.create_dataset("joint_dofadr", data=np.asarray(s.joint_dofadr, dtype=np.int64),
                         shape=(self.m,))
        g.create_dataset("joint_multadr", data=np.asarray(s.joint_multadr, dtype=np.int64),
                         shape=(self.m,))
        g.create_dataset("joint_columns", data=cols, shape=(self.m,))
        g.create_dataset("joint_units", data=np.array(list(joint_units(s)), dtype=object),
                         dtype=strs, shape=(nk,))
        g.attrs["composites"] = json.dumps({c: list(p) for c, p in s.composites.items()})
        g.attrs["nq"] = int(s.nq)
        g.attrs["nm"] = int(s.nm)
        f.create_group("stats")  # attributes written by close()
        r = f.create_group("restart")
        n = len(_SLOT_HEADER) + _state_length(s)
        self._slots = r.create_dataset("state", shape=(2, n), dtype=np.float64,
                                       fillvalue=np.nan)
        r.attrs["header"] = ", ".join(_SLOT_HEADER)
        r.attrs["state"] = _STATE_DOC
        self._memory = r.create_dataset("solver", shape=(2, 0), maxshape=(2, None),
                                        chunks=(2, 4096), dtype=np.float64, fillvalue=np.nan)
        self._memory.attrs["content"] = _MEMORY_DOC

    # -----------------------------------------------------------------------------------------
    def append(self, state, scalars: dict) -> None:
        """Add one row (signature of ``simulate``'s ``on_output``)."""
        if self.closed:
            raise ValueError(f"results file '{self.path}': writer is closed")
        if self._skip:
            self._skip -= 1
            return
        H = np.asarray(state.H)
        vel = np.zeros((self.M, 6))
        acc = np.zeros((self.M, 6))
        v = np.asarray(state.v)
        vd = np.asarray(state.vd)
        vel[self._free] = v[self._freeidx]
        acc[self._free] = vd[self._freeidx]
        self._buf.append((
            float(state.t), H[:, :3, 3].copy(), H[:, :3, :3].copy(), vel, acc,
            np.asarray(state.alpha)[self._jidx], v[self._jidx], vd[self._jidx],
            np.array(state.lam, dtype=float),
            [float(scalars[e]) for e in ENERGIES], int(scalars["iterations"]),
            float(scalars["residual"]), float(scalars["constraint"])))
        self._buf_bytes += self._row_bytes
        self._maybe_flush()

    def add_rows(self, block: Results, checkpoint=None) -> None:
        """Add a block of rows and the checkpoint reached after them (signature of
        ``simulate``'s ``on_rows``); the checkpoint is stored with the next flush."""
        if self.closed:
            raise ValueError(f"results file '{self.path}': writer is closed")
        self._take_rows()
        lo = min(self._skip, len(block.t))
        self._skip -= lo
        n = len(block.t) - lo
        if n:
            sl = slice(lo, None)
            H = block.H[sl]
            v, vd = block.v[sl], block.vd[sl]
            vel = np.zeros((n, self.M, 6))
            acc = np.zeros((n, self.M, 6))
            vel[:, self._free] = v[:, self._freeidx]
            acc[:, self._free] = vd[:, self._freeidx]
            d = {"nodes/position": H[:, :, :3, 3], "nodes/rotation": H[:, :, :3, :3],
                 "nodes/velocity": vel, "nodes/acceleration": acc,
                 "joints/alpha": block.alpha[sl][:, self._jidx],
                 "joints/velocity": v[:, self._jidx], "joints/acceleration": vd[:, self._jidx],
                 "joints/multipliers": block.lam[sl],
                 "solver/iterations": block.iterations[sl].astype(np.int32),
                 "solver/residual": block.residual[sl],
                 "solver/constraint": block.constraint[sl]}
            for e in ENERGIES:
                d[f"energy/{e}"] = getattr(block, e)[sl]
            d["time"] = block.t[sl]
            self._blocks.append(d)
            self._buf_bytes += n * self._row_bytes
        if checkpoint is not None:
            # its rows in the file: those before the run, plus the run's (the checkpoint
            # counts from the run's first row, which a resumed file already holds)
            self._pending_cp = (checkpoint, self._run_base + checkpoint.rows - self._run_skip)
        self._maybe_flush()

    def _take_rows(self) -> None:
        """Turn the rows given one by one into a block (keeps the order of rows)."""
        buf, self._buf = self._buf, []
        if not buf:
            return
        nb = len(buf)
        cols = list(zip(*buf, strict=True))
        d = {
            "nodes/position": np.stack(cols[1]), "nodes/rotation": np.stack(cols[2]),
            "nodes/velocity": np.stack(cols[3]), "nodes/acceleration": np.stack(cols[4]),
            "joints/alpha": np.stack(cols[5]), "joints/velocity": np.stack(cols[6]),
            "joints/acceleration": np.stack(cols[7]),
            "joints/multipliers": np.stack(cols[8]),
            "solver/iterations": np.array(cols[10], dtype=np.int32),
            "solver/residual": np.array(cols[11]),
            "solver/constraint": np.array(cols[12]),
        }
        en = np.array(cols[9]).reshape(nb, len(ENERGIES))
        for i, e in enumerate(ENERGIES):
            d[f"energy/{e}"] = en[:, i]
        d["time"] = np.array(cols[0])
        self._blocks.append(d)

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self.flush_interval:
            self.flush()
        elif self._buf_bytes >= _WRITE_BYTES:
            self._write()

    def _write(self) -> None:
        """Write the buffered rows to the datasets (time last: a row exists once its time is
        written), then the latest checkpoint whose rows are all written."""
        self._take_rows()
        blocks, self._blocks = self._blocks, []
        self._buf_bytes = 0
        if blocks:
            n0 = self.rows
            nb = sum(len(b["time"]) for b in blocks)
            for name in _SERIES:
                arr = blocks[0][name] if len(blocks) == 1 else np.concatenate(
                    [b[name] for b in blocks])
                ds = self._ds[name]
                ds.resize(n0 + nb, axis=0)
                ds[n0:n0 + nb] = arr
            self.rows = n0 + nb
        if self._pending_cp is not None and self._pending_cp[1] <= self.rows:
            cp, rows = self._pending_cp
            self._pending_cp = None
            self._seq += 1
            slot, memory = _pack_slot(self.system, cp, rows, self._seq, self.base_iterations)
            if memory is not None:  # the linear solver's memory first: the slot validates it
                ds = self._memory
                if ds.shape[1] < len(memory):
                    ds.resize(len(memory), axis=1)
                row = np.full(ds.shape[1], np.nan)
                row[:len(memory)] = memory
                ds[self._seq % 2] = row
            self._slots[self._seq % 2] = slot
            self.checkpoint = cp

    def energy_balance(self, chunk: int = 1 << 16) -> tuple[float, float]:
        """(largest energy balance drift, energy in play) over every row of the file, from
        its first row (:func:`se3dyn.dynamics.run.energy_balance_check`): a resumed run is
        measured as the one run it continues, not from the row it resumed at. The buffered
        rows are written first; the file is read ``chunk`` rows at a time."""
        from se3dyn.dynamics.reports import _balance_and_scale

        self.flush()
        n = self.rows
        if n == 0:
            return 0.0, 0.0
        ds = [self._ds[f"energy/{e}"] for e in ENERGIES]
        ref = np.array([d[0] for d in ds])
        err = scale = 0.0
        for a in range(0, n, chunk):
            c = np.stack([d[a:min(a + chunk, n)] for d in ds], axis=1)
            e, s = _balance_and_scale(c, ref)
            err, scale = max(err, e), max(scale, s)
        return err, scale

    def flush(self) -> None:
        """Write the buffered rows (and the latest checkpoint) and flush the file."""
        if self.closed:
            return
        self._write()
        self.file.flush()
        self._last_flush = time.monotonic()

    def close(self, stats: dict | None = None, settings: dict | None = None) -> None:
        """Write the remaining rows, the final ``stats`` (scalars only; e.g. steps,
        newton_iterations, wall_time, failed, failure) and, if given, new ``settings`` (a
        resumed run to a later t_end), mark the file ``complete`` and release its lock."""
        if self.closed:
            return
        try:
            self.flush()
            self.file.close()
            self.closed = True
            # attributes cannot be created in SWMR mode: reopen normally for the final ones
            with h5py.File(self.path, "r+", libver="latest") as f:
                g = f["stats"]
                for key, val in (stats or {}).items():
                    val = _attr_value(val)
                    if val is not None:
                        g.attrs[str(key)] = val
                if settings is not None:
                    f.attrs["settings"] = json.dumps(settings, default=str, sort_keys=True)
                f.attrs["rows"] = self.rows
                f.attrs["complete"] = True
        finally:
            self.closed = True
            self._lock.release()

    def __enter__(self) -> ResultsWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.closed:
            return
        stats = None
        if exc is not None:
            res = getattr(exc, "result", None)
            stats = dict(getattr(res, "stats", None) or {})
            stats.update(failed=True, failure=f"{type(exc).__name__}: {exc}")
        self.close(stats)


_SERIES = ("nodes/position", "nodes/rotation", "nodes/velocity", "nodes/acceleration",
           "joints/alpha", "joints/velocity", "joints/acceleration", "joints/multipliers") + \
    tuple(f"energy/{e}" for e in ENERGIES) + tuple(f"solver/{s}" for s in SOLVER) + ("time",)

_STATE_DOC = ("t, h_last, work_act, work_ext, dissipated, power (3), number of dropped "
              "equations nr, dropped (nm, first nr used), H (M x 16), HJ (m x 16), v, vd, a "
              "(nq each), lam (nm), alpha (nq), the states of State.ctrl (the PID states "
              "(z, e), 2 per PID-controlled coordinate, then 19 per contact pair), nv (the "
              "values of the linear solver's memory in /restart/solver, -1: none)")
_MEMORY_DOC = ("State.solver.ref of the checkpoint in the slot of the same index of "
               "/restart/state (its first nv values): the iteration matrix of the last full "
               "sparse LU factorisation, whose pivot sequence the next steps reuse; index 2: "
               "one more value, the mode of the iteration (0 split, 1 full matrix)")


def _nctrl(s) -> int:
    """The states a step carries (State.ctrl): 2 per PID-controlled coordinate, 19 per
    contact pair."""
    ins = getattr(s, "inputs", None)
    return int(getattr(ins, "nctrl", 2 * len(getattr(ins, "pid_slots", ()))))


def _state_length(s) -> int:
    M, m, nq, nm = len(s.node_names), len(s.joint_names), int(s.nq), int(s.nm)
    return 9 + nm + 16 * (M + m) + 4 * nq + nm + _nctrl(s) + 1


def _pack_slot(s, cp, rows: int, seq: int, base_its: int):
    """One restart slot (the header and the checkpoint's complete integration state) and the
    values of the linear solver's memory (None: none); the CRC covers both."""
    st = cp.state
    nm = int(s.nm)
    dropped = np.zeros(nm)
    dropped[:len(st.dropped)] = st.dropped
    mem = getattr(st, "solver", None)
    memory = None if mem is None else np.asarray(mem.ref, dtype=np.float64)
    payload = np.concatenate([
        [st.t, st.h_last, st.work_act, st.work_ext, st.dissipated], np.asarray(st.power),
        [len(st.dropped)], dropped, np.asarray(st.H).ravel(), np.asarray(st.HJ).ravel(),
        st.v, st.vd, st.a, st.lam, st.alpha, np.asarray(st.ctrl, dtype=float),
        [-1 if memory is None else len(memory)]]).astype(np.float64)
    head = np.array([seq, rows, cp.steps, base_its + cp.newton_iterations, cp.rejected,
                     cp.h_next, 0.0, len(payload)], dtype=np.float64)
    parts = [head, payload] + ([] if memory is None else [memory])
    head[6] = zlib.crc32(np.concatenate(parts).tobytes())
    return np.concatenate([head, payload]), memory


def _read_checkpoint(f: h5py.File, s):
    """The newest valid restart slot whose rows are all in the file: ((State, rows, steps,
    newton_iterations, rejected, h_next), sequence), or None. A slot half written when the
    writer was killed fails its CRC, and one whose rows did not reach the disk is passed
    over: the other one is used."""
    from se3dyn.dynamics.state import State

    present = min(f[name].shape[0] for name in _SERIES)
    slots = f["restart/state"][()]
    memories = f["restart/solver"][()] if "restart/solver" in f else np.zeros((2, 0))
    best = None
    for k, slot in enumerate(slots):
        head, payload = slot[:len(_SLOT_HEADER)].copy(), slot[len(_SLOT_HEADER):]
        if not np.all(np.isfinite(head)) or int(head[7]) != len(payload):
            continue
        nv = int(payload[-1]) if np.isfinite(payload[-1]) else -2
        if nv < -1 or nv > memories.shape[1]:
            continue
        memory = None if nv < 0 else memories[k, :nv].copy()
        crc = head[6]
        head[6] = 0.0
        parts = [head, payload] + ([] if memory is None else [memory])
        if zlib.crc32(np.concatenate(parts).tobytes()) != crc:
            continue
        if int(head[1]) > present:
            continue
        if best is None or head[0] > best[0][0]:
            best = (head, payload, memory)
    if best is None:
        return None
    head, p, memory = best
    M, m, nq, nm = len(s.node_names), len(s.joint_names), int(s.nq), int(s.nm)
    pos = [0]

    def take(n):
        out = p[pos[0]:pos[0] + n].copy()
        pos[0] += n
        return out

    t, h_last, w_act, w_ext, diss = take(5)
    power = take(3)
    nr = int(take(1)[0])
    dropped = take(nm)[:nr].astype(np.int64)
    H = take(16 * M).reshape(M, 4, 4)
    HJ = take(16 * m).reshape(m, 4, 4)
    v, vd, a = take(nq), take(nq), take(nq)
    lam, alpha = take(nm), take(nq)
    extra = {"ctrl": take(_nctrl(s))}
    if memory is not None:
        from se3dyn.engine.memory import SolverMemory

        extra["solver"] = SolverMemory(ref=memory)
    st = State(t=float(t), H=H, HJ=HJ, v=v, vd=vd, a=a, lam=lam, alpha=alpha,
               work_act=float(w_act), work_ext=float(w_ext), dissipated=float(diss),
               power=power, dropped=dropped, h_last=float(h_last), **extra)
    return ((st, int(head[1]), int(head[2]), int(head[3]), int(head[4]), float(head[5])),
            int(head[0]))


# ---------------------------------------------------------------------------------------------
class _FileLock:
    """An exclusive ``fcntl.flock`` on ``PATH.lock`` for a writer of ``PATH`` (released and
    removed by :meth:`release`; the kernel releases it when the process dies)."""

    def __init__(self, path: str):
        self.path = path
        self.lockpath = path + ".lock"
        self.fd = None
        try:
            import fcntl
        except ImportError:  # pragma: no cover - no flock on this platform
            return
        while True:
            try:
                fd = os.open(self.lockpath, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise ResultsFileError(path, f"cannot create the lock file {self.lockpath} "
                                       f"({exc.strerror})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                try:
                    pid = os.read(fd, 32).decode("ascii", "replace").strip()
                finally:
                    os.close(fd)
                who = f" (process {pid})" if pid.isdigit() else ""
                raise ResultsFileError(path, f"is being written by another se3dyn run{who}; "
                                       "wait for it to end or write elsewhere") from None
            # the previous holder may have removed the file between our open and flock
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.lockpath))
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode("ascii"))
        self.fd = fd

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            os.unlink(self.lockpath)
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None


def _writer_alive(path: str) -> bool:
    """Whether a se3dyn writer holds the lock of ``path`` now."""
    lockpath = os.fspath(path) + ".lock"
    if not os.path.exists(lockpath):
        return False
    try:
        import fcntl
    except ImportError:  # pragma: no cover
        return False
    try:
        fd = os.open(lockpath, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)
    return False


def _lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle``, the checksum of HDF5 metadata
    (``H5_checksum_lookup3``)."""
    mask = 0xFFFFFFFF

    def rot(x, k):
        return ((x << k) | (x >> (32 - k))) & mask

    n = len(data)
    a = b = c = (0xDEADBEEF + n + initval) & mask
    i = 0
    while n > 12:
        a = (a + int.from_bytes(data[i:i + 4], "little")) & mask
        b = (b + int.from_bytes(data[i + 4:i + 8], "little")) & mask
        c = (c + int.from_bytes(data[i + 8:i + 12], "little")) & mask
        a = (a - c) & mask; a ^= rot(c, 4); c = (c + b) & mask  # noqa: E702
        b = (b - a) & mask; b ^= rot(a, 6); a = (a + c) & mask  # noqa: E702
        c = (c - b) & mask; c ^= rot(b, 8); b = (b + a) & mask  # noqa: E702
        a = (a - c) & mask; a ^= rot(c, 16); c = (c + b) & mask  # noqa: E702
        b = (b - a) & mask; b ^= rot(a, 19); a = (a + c) & mask  # noqa: E702
        c = (c - b) & mask; c ^= rot(b, 4); b = (b + a) & mask  # noqa: E702
        n -= 12
        i += 12
    if n == 0:
        return c
    tail = data[i:i + n] + bytes(12 - n)
    a = (a + int.from_bytes(tail[0:4], "little")) & mask
    b = (b + int.from_bytes(tail[4:8], "little")) & mask
    c = (c + int.from_bytes(tail[8:12], "little")) & mask
    c ^= b; c = (c - rot(b, 14)) & mask  # noqa: E702
    a ^= c; a = (a - rot(c, 11)) & mask  # noqa: E702
    b ^= a; b = (b - rot(a, 25)) & mask  # noqa: E702
    c ^= b; c = (c - rot(b, 16)) & mask  # noqa: E702
    a ^= c; a = (a - rot(c, 4)) & mask  # noqa: E702
    b ^= a; b = (b - rot(a, 14)) & mask  # noqa: E702
    c ^= b; c = (c - rot(b, 24)) & mask  # noqa: E702
    return c


_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _superblock(path: str) -> tuple[int, int, int] | None:
    """The superblock of a version 2 or 3 (``libver="latest"``, as se3dyn writes) at the start
    of ``path``: (size of offsets, status flags, end-of-file address), or None for another
    superblock or one whose checksum (lookup3) does not match."""
    with open(path, "rb") as fh:
        head = fh.read(12)
        if len(head) < 12 or head[:8] != _SIGNATURE or head[8] not in (2, 3):
            return None
        osize = head[9]
        fh.seek(0)
        sb = fh.read(12 + 4 * osize + 4)
    if len(sb) < 12 + 4 * osize + 4 or osize not in (2, 4, 8, 16, 32):
        return None
    if _lookup3(sb[:-4]) != int.from_bytes(sb[-4:], "little"):
        return None
    return osize, sb[11], int.from_bytes(sb[12 + 2 * osize:12 + 3 * osize], "little")


def _clear_status_flags(path: str, check_lock: bool = True) -> bool:
    """Clear the superblock's file-consistency flags that a writer killed while the file was
    open (kill -9, a crash) leaves set, as ``h5clear -s`` does; True if they were set.

    A file with these flags opens only as a SWMR reader, so ordinary HDF5 tools refuse it.
    Only superblocks of version 2 and 3 (``libver="latest"``, as se3dyn writes) carry them;
    the superblock checksum (lookup3) is rewritten. Never done while a writer holds the file
    (``check_lock=False``: the caller holds its lock).
    """
    if check_lock and _writer_alive(path):
        return False
    sb = _superblock(path)
    if sb is None or sb[1] == 0:
        return False  # not a superblock we understand, or no flags: leave it alone
    osize, _, eoa = sb
    with open(path, "r+b") as fh:
        body = bytearray(fh.read(12 + 4 * osize))
        body[11] = 0
        fh.seek(0)
        fh.write(bytes(body) + _lookup3(bytes(body)).to_bytes(4, "little"))
        fh.flush()
        os.fsync(fh.fileno())
    # space the writer had allocated but not yet written: the library refuses a file shorter
    # than its end-of-allocation address ("truncated file")
    if os.path.getsize(path) < eoa:
        os.truncate(path, eoa)
    return True


def repair(path: str | os.PathLike) -> bool:
    """Make a results file left by a killed writer (kill -9, a crash, a power cut) open in
    every HDF5 tool again: clears its superblock status flags (like ``h5clear -s``). Rows up
    to the writer's last flush are kept. Returns True if the file needed it; False for an
    intact file and for one a writer is still writing (``PATH.lock`` held)."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ResultsFileError(path, "no such file")
    try:
        return _clear_status_flags(path)
    except OSError as exc:
        raise ResultsFileError(path, f"cannot be repaired ({exc.strerror or exc})") from None


def _attr_value(val: Any):
    """An HDF5-storable version of a stats value, or None to skip it."""
    if isinstance(val, (bool, np.bool_)):
        return bool(val)
    if isinstance(val, (int, np.integer)):
        return int(val)
    if isinstance(val, (float, np.floating)):
        return float(val)
    if isinstance(val, str):
        return val
    return None


# ---------------------------------------------------------------------------------------------
#: Reads of a metadata block a SWMR reader tries before it gives up. HDF5 retries a block
#: whose checksum fails (the writer may be rewriting it) sleeping 1, 2, 4, ... ns between
#: tries; its default of 100 tries sleeps some 2^100 ns on a damaged or truncated file, inside
#: the library where Ctrl-C cannot reach. 30 tries give up after about 1 s of sleep in all.
SWMR_READ_ATTEMPTS = 30


def _swmr_open(path: str) -> h5py.File:
    """Open ``path`` as a SWMR reader (a live writer's file) with at most
    :data:`SWMR_READ_ATTEMPTS` reads of a metadata block."""
    import ctypes

    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_fclose_degree(h5py.h5f.CLOSE_STRONG)
    fapl.set_libver_bounds(h5py.h5f.LIBVER_LATEST, h5py.h5f.LIBVER_LATEST)
    try:  # not wrapped by h5py: the function of the HDF5 library h5py links
        setter = ctypes.CDLL(h5py.h5p.__file__).H5Pset_metadata_read_attempts
    except (OSError, AttributeError):  # pragma: no cover - a build without it
        setter = None
    if setter is not None:
        setter.argtypes = [ctypes.c_int64, ctypes.c_uint]
        setter.restype = ctypes.c_int
        setter(fapl.id, SWMR_READ_ATTEMPTS)
    fid = h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ,
                        fapl=fapl)
    return h5py.File(fid)


def _open(path: str) -> tuple[h5py.File, bool]:
    """Open a results file for reading: (file, repaired). A file left flagged open by a killed
    writer is repaired first (:func:`repair`), one a live writer holds is read as a SWMR
    reader, and a file shorter than its superblock's end-of-file address (cut short: an
    interrupted copy, a full or damaged disk) is refused before HDF5 reads it."""
    if not os.path.exists(path):
        raise ResultsFileError(path, "no such file")
    if os.path.isdir(path):
        raise ResultsFileError(path, "is a directory, expected an HDF5 results file")
    try:
        is_h5 = h5py.is_hdf5(path)
        sb = _superblock(path)
        size = os.path.getsize(path)
    except OSError as e:
        raise ResultsFileError(path, f"cannot be read ({e.strerror or e})") from None
    if not is_h5:
        raise ResultsFileError(path, "not an HDF5 file (expected an se3dyn results file)")
    if sb is not None and sb[1] == 0 and size < sb[2]:
        raise ResultsFileError(path, f"is truncated: {size} bytes of the {sb[2]} its "
                               "superblock records (cut short: an interrupted copy or a full "
                               "or damaged disk?); nothing can be read from it")
    try:
        return h5py.File(path, "r"), False
    except OSError as first:
        problem = f"cannot be opened ({first})"
    if _writer_alive(path):  # a run is writing it: follow it
        try:
            return _swmr_open(path), False
        except OSError as exc:
            raise ResultsFileError(path, f"cannot be opened while it is written ({exc})"
                                   ) from None
    # a writer that was killed leaves the file flagged "open for SWMR writing": the flags are
    # cleared (like h5clear -s)
    try:
        repaired = _clear_status_flags(path)
    except OSError:
        repaired = False
    if repaired:
        try:
            return h5py.File(path, "r"), True
        except OSError as exc:
            problem = f"is damaged: cannot be opened after its repair ({exc})"
    raise ResultsFileError(path, problem)


def _str(x) -> str:
    return x.decode("utf-8") if isinstance(x, bytes) else str(x)


def read_results(path: str | os.PathLike) -> Results:
    """Load a results file into a :class:`~se3dyn.results.results.Results`.

    Its ``system`` is a :class:`ResultsLayout` built from ``/layout``; every accessor works as on
    the in-memory results. ``stats`` holds the ``/stats`` attributes plus ``complete`` (False for
    a file whose writer did not close it, e.g. killed), ``rows``, ``model`` (YAML text),
    ``settings`` (dict), ``se3dyn_version`` and ``created``, and ``repaired`` (True when the
    file had been left flagged open by a killed writer and was repaired on this first read,
    see :func:`repair`).

    Raises
    ------
    ResultsFileError
        Missing file, not an HDF5 file, not an se3dyn results file, newer format version.
    """
    if not isinstance(path, str | os.PathLike):
        raise ResultsFileError(repr(path), f"expected a file name (str or path), got "
                               f"{type(path).__name__}")
    path = os.fspath(path)
    f, repaired = _open(path)
    with f:
        try:
            res = _read(f, path)
        except ResultsFileError:
            raise
        except (KeyError, TypeError, ValueError, IndexError, OSError, RuntimeError) as e:
            # (h5py: a missing or misshapen object, a dataset whose chunks cannot be read)
            raise ResultsFileError(path, f"damaged or incomplete ({type(e).__name__}: {e})"
                                   ) from None
    res.stats["repaired"] = repaired
    return res


def _check_format(f: h5py.File, path: str) -> None:
    """The root attributes ``format`` and ``format_version`` of an se3dyn results file."""
    fmt = _str(f.attrs.get("format", ""))
    if fmt != FORMAT:
        raise ResultsFileError(path, f"attribute 'format' is {fmt!r}, expected {FORMAT!r} "
                                     "(not an se3dyn results file)")
    ver = f.attrs.get("format_version")
    try:
        ver = int(ver)
    except (TypeError, ValueError):
        raise ResultsFileError(path, f"attribute 'format_version' is {ver!r}, expected an "
                                     "integer") from None
    if ver > FORMAT_VERSION:
        raise ResultsFileError(path, f"format_version {ver} is newer than the supported "
                                     f"{FORMAT_VERSION}; upgrade se3dyn")


def _layout(f: h5py.File, path: str) -> ResultsLayout:
    """The ``/layout`` of a results file, checked against itself and against the shapes and
    types of the row datasets (a damaged or crafted file is refused naming what is wrong,
    before anything is allocated from its counts)."""

    def bad(what: str, expected: str, got) -> ResultsFileError:
        shown = " ".join(_short_repr(got).split())  # (one line)
        return ResultsFileError(path, f"damaged: {what}: expected {expected}, got {shown}")

    def dataset(name: str, kinds: str = "iuf") -> h5py.Dataset:
        obj = f.get(name)
        if not isinstance(obj, h5py.Dataset):
            raise bad(f"/{name}", "a dataset", "a group" if isinstance(obj, h5py.Group)
                      else "nothing")
        if obj.dtype.kind not in kinds:
            raise bad(f"/{name}", "numbers" if kinds == "iuf" else "text", str(obj.dtype))
        return obj

    def ints(name: str, n: int, lo: int, hi: int) -> np.ndarray:
        ds = dataset(f"layout/{name}", "iu")
        if ds.shape != (n,):
            raise bad(f"/layout/{name}", f"shape ({n},)", ds.shape)
        a = ds[()].astype(np.int64)
        if a.size and (a.min() < lo or a.max() > hi):
            raise bad(f"/layout/{name}", f"values in [{lo}, {hi}]", a)
        return a

    def texts(name: str) -> tuple[str, ...]:
        ds = dataset(f"layout/{name}", "OSU")
        if ds.ndim != 1:
            raise bad(f"/layout/{name}", "a list of names", ds.shape)
        return tuple(_str(x) for x in ds[()])

    def count(name: str) -> int:
        v = f["layout"].attrs.get(name)
        if not isinstance(v, (int, np.integer)) or isinstance(v, (bool, np.bool_)):
            raise bad(f"/layout attribute '{name}'", "an integer", v)
        return int(v)

    if not isinstance(f.get("layout"), h5py.Group):
        raise bad("/layout", "a group", "nothing" if "layout" not in f else "a dataset")
    names, jnames = texts("node_names"), texts("joint_names")
    M, m = len(names), len(jnames)
    fixed = ints("node_fixed", M, 0, 1).astype(bool)
    jk = ints("joint_k", m, 0, 6)
    nk = int(jk.sum())
    nq, nm = count("nq"), count("nm")
    if nq != 6 * int(np.sum(~fixed)) + nk:
        raise bad("/layout attribute 'nq'", f"6 per free node plus the joints' coordinates, "
                  f"{6 * int(np.sum(~fixed)) + nk}", nq)
    if nm != 6 * m:
        raise bad("/layout attribute 'nm'", f"6 per joint, {6 * m}", nm)
    dof = ints("node_dofadr", M, -1, max(nq - 6, -1))
    if np.any(dof[~fixed] < 0):
        raise bad("/layout/node_dofadr", "the first unknown of every free node", dof)
    jdof = ints("joint_dofadr", m, -1, nq)
    if np.any((jk > 0) & ((jdof < 0) | (jdof + jk > nq))):
        raise bad("/layout/joint_dofadr", f"the first unknown of every joint, in [0, {nq})",
                  jdof)
    jmult = ints("joint_multadr", m, 0, max(nm - 6, 0))
    jcols = ints("joint_columns", m, 0, nk)
    if np.any(jcols + jk > nk):
        raise bad("/layout/joint_columns", f"columns of the {nk} joint coordinates", jcols)
    jtype, units = texts("joint_type"), texts("joint_units")
    if len(jtype) != m or len(units) != nk:
        raise bad("/layout/joint_type, joint_units", f"{m} and {nk} names",
                  (len(jtype), len(units)))
    try:
        comp = json.loads(_str(f["layout"].attrs.get("composites", "{}")))
        composites = {str(c): tuple(str(x) for x in p) for c, p in comp.items()}
    except (ValueError, TypeError, AttributeError):
        raise bad("/layout attribute 'composites'", "a JSON object of lists of names",
                  f["layout"].attrs.get("composites")) from None
    shapes = {"time": (), "nodes/position": (M, 3), "nodes/rotation": (M, 3, 3),
              "nodes/velocity": (M, 6), "nodes/acceleration": (M, 6), "joints/alpha": (nk,),
              "joints/velocity": (nk,), "joints/acceleration": (nk,),
              "joints/multipliers": (nm,), **{f"energy/{e}": () for e in ENERGIES},
              **{f"solver/{x}": () for x in SOLVER}}
    for name, tail in shapes.items():
        ds = dataset(name)
        if ds.shape[1:] != tail or ds.ndim != 1 + len(tail):
            raise bad(f"/{name}", f"shape (rows, {', '.join(map(str, tail))})".replace(
                ", )", ")"), ds.shape)
    return ResultsLayout(
        node_names=names, node_fixed=fixed, node_dofadr=dof, joint_names=jnames,
        joint_type=jtype, joint_k=jk, joint_dofadr=jdof, joint_multadr=jmult,
        joint_columns=jcols, joint_units=units, composites=composites, nq=nq, nm=nm)


def _read(f: h5py.File, path: str) -> Results:
    _check_format(f, path)
    lay = _layout(f, path)
    series = ["time", "nodes/position", "nodes/rotation", "nodes/velocity",
              "nodes/acceleration", "joints/alpha", "joints/velocity", "joints/acceleration",
              "joints/multipliers"] + [f"energy/{e}" for e in ENERGIES] + \
        [f"solver/{s}" for s in SOLVER]
    # only rows present in every dataset (time is extended last when writing)
    n = min(f[name].shape[0] for name in series)
    d = {name: f[name][:n] for name in series}
    M, nq = lay.M, lay.nq
    H = np.zeros((n, M, 4, 4))
    H[:, :, :3, :3] = d["nodes/rotation"]
    H[:, :, :3, 3] = d["nodes/position"]
    H[:, :, 3, 3] = 1.0
    v = np.zeros((n, nq))
    vd = np.zeros((n, nq))
    alpha = np.zeros((n, nq))
    free = np.flatnonzero(~lay.node_fixed)
    for i in free:
        a = lay.node_dofadr[i]
        v[:, a:a + 6] = d["nodes/velocity"][:, i]
        vd[:, a:a + 6] = d["nodes/acceleration"][:, i]
    for j in range(lay.m):
        k = int(lay.joint_k[j])
        if k:
            a, c = lay.joint_dofadr[j], lay.joint_columns[j]
            v[:, a:a + k] = d["joints/velocity"][:, c:c + k]
            vd[:, a:a + k] = d["joints/acceleration"][:, c:c + k]
            alpha[:, a:a + k] = d["joints/alpha"][:, c:c + k]
    stats: dict[str, Any] = {}
    if not isinstance(f.get("stats"), h5py.Group):
        raise ResultsFileError(path, "damaged: /stats: expected a group (the statistics of the "
                               "run), got " + ("nothing" if "stats" not in f else "a dataset"))
    for key, val in f["stats"].attrs.items():
        stats[key] = _str(val) if isinstance(val, (bytes, str)) else \
            (val.item() if isinstance(val, np.generic) else val)
    stats["complete"] = bool(f.attrs.get("complete", False))
    stats["rows"] = n
    stats["model"] = _str(f.attrs.get("model", ""))
    try:
        stats["settings"] = json.loads(_str(f.attrs.get("settings", "{}")))
    except ValueError:
        stats["settings"] = {}
    if not isinstance(stats["settings"], dict):  # (as unreadable JSON: none)
        stats["settings"] = {}
    stats["se3dyn_version"] = _str(f.attrs.get("se3dyn_version", ""))
    stats["created"] = _str(f.attrs.get("created", ""))
    stats["path"] = path
    e = {name: d[f"energy/{name}"] for name in ENERGIES}
    lay = dataclasses.replace(lay, model_text=stats["model"])
    return Results(system=lay, t=d["time"], H=H, v=v, vd=vd, lam=d["joints/multipliers"],
                   alpha=alpha, iterations=d["solver/iterations"].astype(int),
                   residual=d["solver/residual"], constraint=d["solver/constraint"],
                   stats=stats, **e)

