"""The sweep's bookkeeping on disk: the journal of finished runs, the summary table, progress.

Files in the output folder ``DIR``::

    DIR/sweep.json      the definition of the sweep (checked by --resume)
    DIR/journal.jsonl   one JSON line per finished run, appended (and flushed) by the client as
                        each row arrives: the marker that a run is done
    DIR/summary.csv     one row per run, sorted by run number, rewritten atomically at the end
                        (and on interruption); DIR/summary.parquet too when pyarrow is present
    DIR/runs/0007.h5    the results file of run 7 (renamed into place only once complete)

Only the client writes the journal and the summary, and it keeps one row per run number (the
last one), so a run re-executed after a worker died never gives two rows.
"""

from __future__ import annotations

import csv
import json
import math
import os
import sys
import time
from pathlib import Path

__all__ = ["Journal", "write_summary", "read_summary_csv", "columns", "Progress", "to_table"]

FIXED_BEFORE = ("run",)
FIXED_AFTER = ("status", "message", "wall_time", "steps", "newton_iterations")
TRAILING = ("worker", "results")


def columns(paths: list[str], metric_names: list[str]) -> list[str]:
    """Column order of the summary."""
    return [*FIXED_BEFORE, *paths, *FIXED_AFTER, *metric_names, *TRAILING]


class Journal:
    """Append-only JSON-lines record of finished runs (the client's only incremental write)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self._fh = None

    def read(self) -> dict[int, dict]:
        """The rows recorded so far, one per run number (the last one); a torn last line (the
        client was killed while writing it) is ignored."""
        rows: dict[int, dict] = {}
        if not self.path.is_file():
            return rows
        with open(self.path, encoding="utf-8") as fh:
            for line in fh:
                try:
                    row = json.loads(line)
                    rows[int(row["run"])] = row
                except (ValueError, KeyError, TypeError):
                    continue
        return rows

    def append(self, row: dict) -> None:
        if self._fh is None:
            self._fh = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 (kept open)
        self._fh.write(json.dumps(row, default=str) + "\n")
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(v)
    return str(v)


def _atomic_write(path: Path, write) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_summary(folder: Path, rows: list[dict], cols: list[str]) -> list[Path]:
    """Write ``summary.csv`` (and ``summary.parquet`` when pyarrow is importable) atomically;
    returns the files written."""
    folder = Path(folder)

    def csv_(tmp):
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            for r in rows:
                w.writerow([_cell(r.get(c)) for c in cols])

    out = [folder / "summary.csv"]
    _atomic_write(out[0], csv_)
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return out
    arrays = {}
    for c in cols:
        vals = [r.get(c) for r in rows]
        present = [v for v in vals if v is not None]
        if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
            arrays[c] = pa.array(vals, type=pa.int64())
        elif present and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                             for v in present):
            arrays[c] = pa.array([None if v is None else float(v) for v in vals],
                                 type=pa.float64())
        elif present and all(isinstance(v, bool) for v in present):
            arrays[c] = pa.array(vals, type=pa.bool_())
        else:
            arrays[c] = pa.array([None if v is None else str(v) for v in vals],
                                 type=pa.string())
    out.append(folder / "summary.parquet")
    _atomic_write(out[1], lambda tmp: pq.write_table(pa.table(arrays), tmp))
    return out


def read_summary_csv(path: str | os.PathLike) -> list[dict]:
    """Rows of a ``summary.csv`` as dicts (numbers converted, empty cells as None)."""
    def conv(s: str):
        if s == "":
            return None
        for f in (int, float):
            try:
                return f(s)
            except ValueError:
                pass
        return s

    with open(path, newline="", encoding="utf-8") as fh:
        return [{k: conv(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def to_table(rows: list[dict], cols: list[str], as_frame: bool | None):
    """The summary as a pandas DataFrame (``as_frame`` True, or None and pandas importable) or
    as a list of dicts in column order."""
    if as_frame is not False:
        try:
            import pandas as pd
        except ImportError:
            if as_frame:
                raise ImportError("as_frame=True needs pandas: pip install pandas") from None
        else:
            return pd.DataFrame([[r.get(c) for c in cols] for r in rows], columns=cols)
    return [{c: r.get(c) for c in cols} for r in rows]


class Progress:
    """One line on stderr: runs done of total, failed, rate and ETA (terminal only)."""

    def __init__(self, total: int, already: int, enabled: bool, stream=None):
        self.total, self.already = total, already
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()
        self.last = 0.0
        self.done = self.failed = 0

    def text(self, now: float | None = None) -> str:
        el = (now if now is not None else time.perf_counter()) - self.start
        todo = self.total - self.already
        frac = self.done / todo if todo else 1.0
        eta = el * (todo - self.done) / self.done if self.done else math.inf
        bar = "#" * int(30 * frac) + "." * (30 - int(30 * frac))
        eta_s = f"{eta:6.0f} s" if math.isfinite(eta) else "     ? s"
        return (f"  runs {self.already + self.done:>{len(str(self.total))}d} / {self.total} "
                f"[{bar}] {self.failed} failed, {self.done / el if el > 0 else 0.0:5.2f} runs/s,"
                f" ETA {eta_s}")

    def update(self, failed: bool) -> None:
        self.done += 1
        self.failed += bool(failed)
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.last < 0.1 and self.already + self.done < self.total:
            return
        self.last = now
        self.stream.write("\r" + self.text(now) + " ")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
