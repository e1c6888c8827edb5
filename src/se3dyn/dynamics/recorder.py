"""The stored rows of a run (:class:`_Recorder`) and the checkpoints from which a run continues
bit for bit (:class:`Checkpoint`); see ``on_output``, ``on_rows`` and ``store`` of
:func:`~se3dyn.dynamics.run.simulate`."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from se3dyn.dynamics.reports import _balance_and_scale
from se3dyn.dynamics.state import State
from se3dyn.engine.system import System
from se3dyn.results.results import Results

#: Rows allocated at the start; the recorder grows (doubling) as the run goes.
_INITIAL_ROWS = 4096

#: Names of the scalar columns of a stored row, in order (see ``on_output`` of :func:`simulate`).
SCALARS = ("kinetic", "potential", "spring", "work_actuators", "work_loads", "dissipation",
           "iterations", "residual", "constraint")


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """A point from which a run continues bit for bit (see ``on_rows`` of :func:`simulate`).

    Attributes
    ----------
    state : State
        The integration state after the last row of the block it comes with.
    steps : int
        Steps from ``t_start`` up to ``state`` (a multiple of the checkpoint interval,
        ``CHECKPOINT_EVERY`` rounded up to a multiple of ``output_every``).
    h_next : float
        The step the run takes next (adaptive runs: the controller's step; fixed: ``step``).
    newton_iterations, rejected : int
        Counters of this call up to ``state``.
    rows : int
        Rows stored by this call up to ``state`` (its row included; the initial one too).
    """

    state: State
    steps: int
    h_next: float
    newton_iterations: int = 0
    rejected: int = 0
    rows: int = 0


#: Steps between checkpoints (a multiple of output_every is taken): states (with the linear
#: solver's memory, ``State.solver``) from which a run continues, in any process, exactly as
#: the uninterrupted run, and whose stored rows are exactly those of that run.
CHECKPOINT_EVERY = 1000
#: Bytes of rows held at most in memory by a streamed run (``store=False``) between blocks.
_STREAM_BYTES = 4 << 20
#: Wall time (s) after which rows computed step by step are passed on to ``on_rows``.
_EMIT_EVERY = 0.2


def checkpoint_interval(output_every: int) -> int:
    """Steps between checkpoints: ``CHECKPOINT_EVERY`` rounded up to a multiple of
    ``output_every``."""
    return output_every * math.ceil(CHECKPOINT_EVERY / output_every)


class _Recorder:
    """The stored rows of one run.

    With ``store`` every row is kept: the arrays grow in place (``ndarray.resize``, which
    reallocates without a copy where the C library can, doubling up to the rows expected) and
    are trimmed in place at the end, so the results cost their own size. Without ``store``
    (streamed runs) rows are held only until they are passed on to ``on_rows``: memory stays
    flat whatever the length of the run, and the results keep the first and the last row.
    The summary statistics (energy balance error, largest energy, constraint violation and
    Newton iterations) cover every row either way.
    """

    _FIELDS = ("t", "H", "v", "vd", "lam", "alpha", "scal", "cs")

    def __init__(self, s: System, capacity: int, sink=None, limit: int | None = None, *,
                 store: bool = True, on_rows=None, cond=None, full_ws=None):
        self.s = s
        self.cond = cond  # rows of cond.reduced, passed on as rows of cond.full (condense)
        self.full_ws = full_ws  # the run's workspace of cond.full (its rigid reactions)
        self.out_system = s if cond is None else cond.full
        self.sink = sink
        self.on_rows = on_rows
        self.store = store
        self.limit = limit  # rows expected in all (fixed steps): growth stops there
        self.row_bytes = 8 * (1 + 16 * s.M + 3 * s.nq + s.nm + 9)
        capacity = min(capacity, _INITIAL_ROWS)  # (rows expected; grown as the run goes)
        if not store:
            capacity = max(16, min(capacity, _STREAM_BYTES // self.row_bytes))
        self.n = 0  # rows in the buffer
        self.sent = 0  # rows of the buffer already passed on to on_rows
        self.summarized = 0  # rows of the buffer already in the summary
        self.total = 0  # rows recorded in all
        self.first = None  # (store=False) the first row, kept for the results
        self.pending = None  # the latest checkpoint not yet passed on
        self.last_emit = time.perf_counter()
        self.summary = dict(e0=None, balance=0.0, energy=0.0, constraint=0.0, iterations=0)
        # (np.empty: every row below self.n is written before it is read, by add() or the
        # compiled loop, and nothing reads beyond; a 1000-link chain's 1001 rows are 390 MB,
        # and the first call in a fresh process took 3.92 s with np.zeros against 3.76 s with
        # np.empty, means of 7 alternated fresh-process pairs: docs/performance.md)
        self.t = np.empty(capacity)
        self.H = np.empty((capacity, s.M, 4, 4))
        self.v = np.empty((capacity, s.nq))
        self.vd = np.empty((capacity, s.nq))
        self.lam = np.empty((capacity, s.nm))
        self.alpha = np.empty((capacity, s.nq))
        self.scal = np.empty((capacity, 9))
        #: the contact pairs' states and outputs of the rows (State.ctrl after the PID states;
        #: no columns without contacts; runs with contacts go step by step: add())
        self.ncs = s.inputs.nctrl - s.inputs.contact_ctrl if s.contacts else 0
        self.cs = np.empty((capacity, self.ncs))

    def _resize(self, rows: int) -> None:
        for name in self._FIELDS:
            shape = (rows,) + getattr(self, name).shape[1:]
            try:
                # in place (realloc), zero-filled; refused while anything else references the
                # array (so no local name for it here)
                getattr(self, name).resize(shape)
            except ValueError:
                old = getattr(self, name)
                new = np.zeros(shape)
                k = min(rows, len(old))
                new[:k] = old[:k]
                setattr(self, name, new)
                del old

    def _grow(self):
        n = len(self.t)
        if not self.store:
            self._resize(2 * n)  # rows of one step beyond the buffer (dense output)
            return
        extra = n if self.limit is None or self.limit <= n else min(n, self.limit - n)
        self._resize(n + max(extra, 1))

    def free(self) -> int:
        """Rows that fit in the buffer without growing it."""
        return len(self.t) - self.n

    def add(self, st: State, kin: float, pot: float, spring: float, iters: int, res: float,
            con: float):
        if self.n == len(self.t):
            self._grow()
        i = self.n
        self.t[i] = st.t
        self.H[i] = st.H
        self.v[i] = st.v
        self.vd[i] = st.vd
        self.lam[i] = st.lam
        self.alpha[i] = st.alpha
        self.scal[i] = (kin, pot, spring, st.work_act, st.work_ext, st.dissipated, iters, res,
                        con)
        if self.ncs:
            self.cs[i] = st.ctrl[len(st.ctrl) - self.ncs:]
        self.n += 1
        self.total += 1
        if self.sink is not None:
            self.sink_row(st, self.scal[i])

    def sink_row(self, st: State, scal: np.ndarray) -> None:
        """Pass a stored row on to ``on_output`` (as a state of the model's own system)."""
        self.sink(st if self.cond is None else self.cond.expand(st, self.full_ws),
                  dict(zip(SCALARS, scal.tolist(), strict=True)))

    def added(self, count: int) -> None:
        """``count`` rows were written into the buffer by the compiled loop."""
        self.total += count - self.n
        self.n = count

    def _summarize(self) -> None:
        lo, hi = self.summarized, self.n
        if hi <= lo:
            return
        c = self.scal[lo:hi]
        sm = self.summary
        if sm["e0"] is None:  # the first row: the references of the balance and the scale
            sm["e0"] = c[0, :6].copy()
        err, scale = _balance_and_scale(c, sm["e0"])
        sm["balance"] = max(sm["balance"], err)
        sm["scale"] = max(sm.get("scale", 0.0), scale)
        sm["energy"] = max(sm["energy"], float(np.abs(c[:, 0] + c[:, 1] + c[:, 2]).max()))
        sm["constraint"] = max(sm["constraint"], float(c[:, 8].max()))
        sm["iterations"] = max(sm["iterations"], int(c[:, 6].max()))
        self.summarized = hi

    def _block(self, lo: int, hi: int, stats: dict | None = None, copy: bool = True,
               rows: np.ndarray | None = None) -> Results:
        """Rows ``lo <= r < hi`` (or the rows of the index array ``rows``) as results of the
        model's system."""
        if rows is not None:
            c = self.scal[rows]
            cp = lambda x: x[rows]  # noqa: E731  (a copy)
        else:
            c = self.scal[lo:hi]
            cp = (lambda x: x[lo:hi].copy()) if copy else (lambda x: x[lo:hi])  # noqa: E731
        arr = dict(t=cp(self.t), H=cp(self.H), v=cp(self.v), vd=cp(self.vd),
                   lam=cp(self.lam), alpha=cp(self.alpha))
        extra = dict(contact_rows=cp(self.cs)) if self.ncs else {}
        if self.cond is not None:
            arr["H"], arr["v"], arr["vd"], arr["alpha"], arr["lam"] = (
                self.cond.expand_rows(arr["H"], arr["v"], arr["vd"], arr["alpha"],
                                      arr["lam"]))
        out = Results(system=self.out_system, **arr,
                      kinetic=c[:, 0].copy(), potential=c[:, 1].copy(), spring=c[:, 2].copy(),
                      work_actuators=c[:, 3].copy(), work_loads=c[:, 4].copy(),
                      dissipation=c[:, 5].copy(), iterations=c[:, 6].astype(int),
                      residual=c[:, 7].copy(), constraint=c[:, 8].copy(),
                      stats=stats if stats is not None else {}, **extra)
        if self.cond is not None and len(self.cond.rigid):
            out.defer_multipliers(self.cond.fill_multipliers)
        return out

    def emit(self, checkpoint: Checkpoint | None = None, force: bool = True) -> None:
        """Pass the new rows (and the checkpoint reached after them) on to ``on_rows``; in a
        streamed run, drop them from the buffer. Without ``force``, only when the buffer is
        nearly full or ``_EMIT_EVERY`` seconds have passed."""
        if checkpoint is not None:
            self.pending = checkpoint  # passed on with the next block
        if not force and self.free() > 1 and time.perf_counter() - self.last_emit < _EMIT_EVERY:
            return
        self._summarize()
        checkpoint, self.pending = self.pending, None
        if checkpoint is not None and self.cond is not None and self.on_rows is not None:
            checkpoint = dataclasses.replace(checkpoint,
                                             state=self.cond.expand(checkpoint.state,
                                                                    self.full_ws))
        if self.on_rows is not None and (self.n > self.sent or checkpoint is not None):
            self.on_rows(self._block(self.sent, self.n), checkpoint)
        self.sent = self.n
        self.last_emit = time.perf_counter()
        if not self.store and self.n:
            if self.first is None:
                self.first = self._block(0, 1)
            self._move_last_to_front()

    def uncondense(self, U: np.ndarray | None = None, inputs: dict | None = None) -> None:
        """The run goes on with the rigid joints kept: the rows held become the model's own
        (their rigid joints' multipliers computed now, with the rows' inputs ``U`` (n, nu),
        by default the model's, and the pending checkpoint's with ``inputs``), and so will the
        next ones."""
        c, n, cap = self.cond, self.n, len(self.t)
        rows = c.expand_rows(self.H[:n], self.v[:n], self.vd[:n], self.alpha[:n], self.lam[:n])
        c.fill_rows(self.t[:n], rows[0], rows[3], rows[1], rows[2], rows[4], self.full_ws,
                    U=None if U is None else U[:n])
        for name, arr in zip(("H", "v", "vd", "alpha", "lam"), rows, strict=True):
            new = np.zeros((cap,) + arr.shape[1:])
            new[:n] = arr
            setattr(self, name, new)
        if self.pending is not None:
            self.pending = dataclasses.replace(self.pending,
                                               state=c.expand(self.pending.state,
                                                              self.full_ws, inputs))
        self.s = self.out_system = c.full
        self.cond = None
        s = self.s
        self.row_bytes = 8 * (1 + 16 * s.M + 3 * s.nq + s.nm + 9)

    def truncate(self, n: int) -> None:
        """Keep the first ``n`` rows only (a :class:`~se3dyn.dynamics.simulator.Simulator`
        restored to an earlier state); the summary is made again from them."""
        self.n = self.total = self.sent = n
        self.summarized = 0
        self.summary = dict(e0=None, balance=0.0, energy=0.0, constraint=0.0, iterations=0)

    def _move_last_to_front(self) -> None:
        """(store=False) Keep only the last row, at the front of the buffer."""
        for name in self._FIELDS:
            arr = getattr(self, name)
            arr[0] = arr[self.n - 1]
        self.n = self.sent = self.summarized = 1

    def last_time(self) -> float | None:
        return float(self.t[self.n - 1]) if self.n else None

    def stats(self) -> dict:
        """The summary statistics over every row recorded."""
        self._summarize()
        sm = self.summary
        return dict(rows=self.total, energy_balance_error=sm["balance"],
                    energy_scale=sm.get("scale", 0.0), max_energy=sm["energy"],
                    max_constraint=sm["constraint"], max_iterations=sm["iterations"])

    def results(self, stats: dict) -> Results:
        stats.update(self.stats())
        n = self.n
        if not self.store:
            first = self.first if self.first is not None else (
                self._block(0, 1) if n else None)
            last = self._block(n - 1, n) if n else None
            if self.total <= 1 or first is None or last is None:
                out = first if first is not None else last
                out.stats = stats
                return out
            return Results(system=self.out_system, stats=stats, **{
                f.name: np.concatenate([getattr(first, f.name), getattr(last, f.name)])
                for f in dataclasses.fields(Results) if f.name not in ("system", "stats")
                and getattr(first, f.name) is not None})
        # in place: the trimmed arrays become the results (no copy of the rows)
        self._resize(n)
        return self._block(0, n, stats, copy=False)

