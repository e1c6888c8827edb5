"""HDF5 results files: stream a simulation to disk while it runs, and read it back.

The layout is described field by field in ``docs/results-file.md``. This module is optional:
the core package never imports it (``import se3dyn`` works without h5py).

>>> import se3dyn as sd
>>> from se3dyn.h5 import ResultsWriter, read_results
>>> model = sd.examples.slider_crank()
>>> with ResultsWriter("out.h5", sd.compile_model(model)) as w:     # doctest: +SKIP
...     res = sd.simulate(model, 5.0, 1e-2, on_output=w.append)
...     w.close(res.stats)
>>> res2 = read_results("out.h5")                                   # doctest: +SKIP

Robustness: rows are buffered in memory and written, then ``flush()``-ed, at least every
``flush_interval`` seconds of wall time. The file is created with ``libver="latest"`` and put in
SWMR (single-writer / multiple-reader) mode once all datasets exist, so its metadata on disk is
always consistent: a writer killed with ``kill -9`` leaves a readable file holding every row up
to the last flush (``complete`` is then False). :func:`read_results` opens such files directly
(it falls back to a SWMR read when the HDF5 library reports the file as still open for writing).
"""

from __future__ import annotations

import datetime
import json
import os
import time
from dataclasses import dataclass, field
from typing import Any

import h5py
import numpy as np

from se3dyn.channels import joint_units
from se3dyn.errors import Se3dynError
from se3dyn.results import Results
from se3dyn.system import LayoutCounts

__all__ = ["ResultsWriter", "read_results", "ResultsLayout", "ResultsFileError", "FORMAT",
           "FORMAT_VERSION", "ENERGIES", "SOLVER"]

#: Value of the root attribute ``format``.
FORMAT = "se3dyn-results"
#: Value of the root attribute ``format_version`` written by this version; newer ones are refused.
FORMAT_VERSION = 1
#: Datasets of the ``/energy`` group (J), in the order of ``se3dyn.simulate.SCALARS``.
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
    """The layout attributes of a :class:`~se3dyn.system.System` that :class:`Results` needs,
    read from ``/layout`` (no model compilation).

    ``joint_units`` holds, per joint unknown (nk,), ``"rad"`` for a rotation coordinate and
    ``"m"`` for a translation (used by :func:`se3dyn.channels.channel_unit`).
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

    @property
    def nk(self) -> int:
        return int(np.sum(self.joint_k))


def _joint_columns(system) -> tuple[np.ndarray, np.ndarray]:
    """k per joint and the first column of each joint in the nk joint-unknown columns."""
    k = np.asarray(system.joint_k, dtype=np.int64)
    cols = (np.cumsum(k) - k).astype(np.int64)
    return k, cols


# ---------------------------------------------------------------------------------------------
class ResultsWriter:
    """Stream the rows of a simulation to an HDF5 results file.

    Parameters
    ----------
    path : str or PathLike
        File to create (overwritten if it exists).
    system : System or Model
        The compiled system (a Model is compiled here) that is simulated.
    model_text : str, optional
        The YAML model text to store; by default ``se3dyn.modelfile.save_model(system.model)``,
        or ``""`` when the model holds Python callables and cannot be saved.
    settings : dict, optional
        Simulation settings, stored as JSON in the root attribute ``settings``.
    flush_interval : float
        Write buffered rows and flush the file at least this often (seconds of wall time).

    Use ``simulate(..., on_output=writer.append)`` and then :meth:`close` (or a ``with`` block).
    """

    def __init__(self, path: str | os.PathLike, system, *, model_text: str | None = None,
                 settings: dict | None = None, flush_interval: float = 1.0):
        from se3dyn.model import Model
        from se3dyn.system import compile_model

        if isinstance(system, Model):
            system = compile_model(system)
        self.path = os.fspath(path)
        self.system = system
        self.flush_interval = float(flush_interval)
        self.rows = 0
        self.closed = False
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
        if model_text is None:
            model_text = ""
            model = getattr(s, "model", None)
            if model is not None:
                from se3dyn.errors import ModelError
                from se3dyn.modelfile import save_model
                try:
                    model_text = save_model(model)
                except ModelError:
                    model_text = ""

        self._buf: list[tuple] = []
        self._last_flush = time.monotonic()
        f = h5py.File(self.path, "w", libver="latest")
        self.file = f
        try:
            self._create(f, s, k, cols, model_text, settings)
            f.flush()
            f.swmr_mode = True
        except BaseException:
            f.close()
            raise

    # -----------------------------------------------------------------------------------------
    def _create(self, f, s, k, cols, model_text, settings):
        import se3dyn

        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["se3dyn_version"] = se3dyn.__version__
        f.attrs["created"] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
        f.attrs["model"] = model_text
        f.attrs["settings"] = json.dumps(settings or {}, default=str, sort_keys=True)
        f.attrs["complete"] = False
        M, nk, nm = self.M, self.nk, self.nm
        row_bytes = 8 * (1 + M * (3 + 9 + 6 + 6) + 3 * nk + nm + 9)
        self._chunk = int(max(16, min(256, (1 << 20) // max(row_bytes, 1))))
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

    # -----------------------------------------------------------------------------------------
    def append(self, state, scalars: dict) -> None:
        """Add one row (signature of ``simulate``'s ``on_output``)."""
        if self.closed:
            raise ValueError(f"results file '{self.path}': writer is closed")
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
        if time.monotonic() - self._last_flush >= self.flush_interval:
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows and flush the file."""
        if self.closed:
            return
        buf, self._buf = self._buf, []
        if buf:
            n0, nb = self.rows, len(buf)
            cols = list(zip(*buf, strict=True))
            data = {
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
                data[f"energy/{e}"] = en[:, i]
            data["time"] = np.array(cols[0])  # last: a row exists once its time is written
            for name, arr in data.items():
                ds = self._ds[name]
                ds.resize(n0 + nb, axis=0)
                ds[n0:n0 + nb] = arr
            self.rows = n0 + nb
        self.file.flush()
        self._last_flush = time.monotonic()

    def close(self, stats: dict | None = None) -> None:
        """Write the remaining rows, the final ``stats`` (scalars only; e.g. steps,
        newton_iterations, wall_time, failed, failure) and mark the file ``complete``."""
        if self.closed:
            return
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
            f.attrs["rows"] = self.rows
            f.attrs["complete"] = True

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
def _open(path: str) -> h5py.File:
    if not os.path.exists(path):
        raise ResultsFileError(path, "no such file")
    if os.path.isdir(path):
        raise ResultsFileError(path, "is a directory, expected an HDF5 results file")
    try:
        is_h5 = h5py.is_hdf5(path)
    except OSError as e:
        raise ResultsFileError(path, f"cannot be read ({e})") from None
    if not is_h5:
        raise ResultsFileError(path, "not an HDF5 file (expected an se3dyn results file)")
    try:
        return h5py.File(path, "r")
    except OSError as first:
        # a writer that is still running or was killed leaves the file flagged "open for SWMR
        # writing": a SWMR read opens it
        try:
            return h5py.File(path, "r", libver="latest", swmr=True)
        except OSError:
            raise ResultsFileError(path, f"cannot be opened ({first})") from None


def _str(x) -> str:
    return x.decode("utf-8") if isinstance(x, bytes) else str(x)


def read_results(path: str | os.PathLike) -> Results:
    """Load a results file into a :class:`~se3dyn.results.Results`.

    Its ``system`` is a :class:`ResultsLayout` built from ``/layout``; every accessor works as on
    the in-memory results. ``stats`` holds the ``/stats`` attributes plus ``complete`` (False for
    a file whose writer did not close it, e.g. killed), ``rows``, ``model`` (YAML text),
    ``settings`` (dict), ``se3dyn_version`` and ``created``.

    Raises
    ------
    ResultsFileError
        Missing file, not an HDF5 file, not an se3dyn results file, newer format version.
    """
    path = os.fspath(path)
    with _open(path) as f:
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
        try:
            return _read(f, path)
        except KeyError as e:
            raise ResultsFileError(path, f"damaged or incomplete layout ({e})") from None


def _read(f: h5py.File, path: str) -> Results:
    g = f["layout"]
    names = tuple(_str(x) for x in g["node_names"][()])
    jnames = tuple(_str(x) for x in g["joint_names"][()])
    lay = ResultsLayout(
        node_names=names, node_fixed=g["node_fixed"][()].astype(bool),
        node_dofadr=g["node_dofadr"][()].astype(np.int64), joint_names=jnames,
        joint_type=tuple(_str(x) for x in g["joint_type"][()]),
        joint_k=g["joint_k"][()].astype(np.int64),
        joint_dofadr=g["joint_dofadr"][()].astype(np.int64),
        joint_multadr=g["joint_multadr"][()].astype(np.int64),
        joint_columns=g["joint_columns"][()].astype(np.int64),
        joint_units=tuple(_str(x) for x in g["joint_units"][()]),
        composites={c: tuple(p) for c, p in json.loads(_str(g.attrs["composites"])).items()},
        nq=int(g.attrs["nq"]), nm=int(g.attrs["nm"]))
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
    stats["se3dyn_version"] = _str(f.attrs.get("se3dyn_version", ""))
    stats["created"] = _str(f.attrs.get("created", ""))
    stats["path"] = path
    e = {name: d[f"energy/{name}"] for name in ENERGIES}
    return Results(system=lay, t=d["time"], H=H, v=v, vd=vd, lam=d["joints/multipliers"],
                   alpha=alpha, iterations=d["solver/iterations"].astype(int),
                   residual=d["solver/residual"], constraint=d["solver/constraint"],
                   stats=stats, **e)

