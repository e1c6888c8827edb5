"""What a sweep varies and how: model-file paths, value specs, sampling plans.

A *path* addresses one field of a model file by its keys and list indices, joined by dots::

    joints.8.damping.0      # first component of the damping of joint "8"
    nodes.6.mass            # mass of node "6"
    simulation.step         # a simulation setting

Names that contain dots match as a whole (``nodes.arm.tip.mass`` finds node ``arm.tip``).
A field that the file leaves out but the format defines (``joints.1.damping`` on a joint
without a damper, ``simulation.tol``) can be set; anything else is an error listing the valid
keys at that level, raised before any run starts.

A *spec* gives the values of one path, parsed by a small regular-expression grammar (nothing is
ever evaluated)::

    0.1,0.2,0.5          a list (numbers, or words such as index2,index3; true/false)
    0:1:11               START:STOP:N, N values evenly spaced, both ends included
    uniform(A,B)         uniform on [A, B]              (--method random or lhs)
    loguniform(A,B)      log-uniform on [A, B], 0 < A   (--method random or lhs)
    normal(MEAN,SD)      normal distribution            (--method random or lhs)

``grid`` runs the Cartesian product of the lists and ranges (the first path varies slowest).
``random`` and ``lhs`` draw ``samples`` points: every path is mapped from a uniform variable
u in [0, 1) (independent draws, or a Latin hypercube from :mod:`scipy.stats.qmc`) through the
inverse distribution function; a list or range is then sampled uniformly among its values.
"""

from __future__ import annotations

import copy
import difflib
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from se3dyn.errors import ModelError

__all__ = ["SweepSpecError", "ValueSpec", "parse_spec", "Variable", "check_path", "set_path",
           "get_path", "plan_runs", "apply_values", "METHODS"]

METHODS = ("grid", "random", "lhs")
#: Most runs of one sweep (a range's N, a grid's product, --samples): refused before anything
#: is allocated. Its plan holds about 200 bytes per run (193 MB and 2.5 s measured for 10^6
#: runs of two paths) and dask's scheduler about 1 ms per task (some 17 minutes at 10^6).
MAX_RUNS = 10**6


class SweepSpecError(ModelError):
    """Bad sweep input (path, value spec, metric, sampling options): one line naming the item,
    the field, what was expected and what came."""


# ---------------------------------------------------------------------------------------------
# value specs
_NUM = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?"
_INT = re.compile(r"[-+]?\d+")
_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*")
_RANGE = re.compile(rf"\s*({_NUM})\s*:\s*({_NUM})\s*:\s*(\d+)\s*")
_DIST = re.compile(rf"\s*(uniform|loguniform|normal)\s*\(\s*({_NUM})\s*,\s*({_NUM})\s*\)\s*")
_SPEC_HELP = ("a list V1,V2,..., a range START:STOP:N, or a distribution uniform(A,B), "
              "loguniform(A,B) or normal(MEAN,SD)")


@dataclass(frozen=True)
class ValueSpec:
    """The parsed spec of one path.

    Attributes
    ----------
    kind : {"list", "range", "uniform", "loguniform", "normal"}
    values : tuple
        The values of a list or range (empty for a distribution).
    params : tuple of float
        ``(A, B)`` or ``(MEAN, SD)`` of a distribution.
    text : str
        The spec as written.
    """

    kind: str
    values: tuple = ()
    params: tuple = ()
    text: str = ""

    @property
    def discrete(self) -> bool:
        """True for a list or range (usable by a grid)."""
        return self.kind in ("list", "range")

    def from_uniform(self, u: np.ndarray) -> list:
        """Values for uniform variables ``u`` in [0, 1) (inverse distribution function)."""
        u = np.clip(np.asarray(u, dtype=float), 1e-12, 1.0 - 1e-12)
        if self.discrete:
            idx = np.minimum((u * len(self.values)).astype(int), len(self.values) - 1)
            return [self.values[i] for i in idx]
        a, b = self.params
        if self.kind == "uniform":
            x = a + u * (b - a)
        elif self.kind == "loguniform":
            x = np.exp(math.log(a) + u * (math.log(b) - math.log(a)))
        else:
            from scipy.stats import norm

            x = a + b * norm.ppf(u)
        return [float(v) for v in x]


def _scalar(tok: str) -> Any:
    tok = tok.strip()
    if _INT.fullmatch(tok):
        return int(tok)
    if re.fullmatch(_NUM, tok):
        return float(tok)
    if tok in ("true", "false"):
        return tok == "true"
    if _WORD.fullmatch(tok):
        return tok
    raise ValueError(tok)


def parse_spec(text: str, item: str = "--vary") -> ValueSpec:
    """Parse a value spec (see the module docstring); no evaluation, a regular grammar.

    Raises
    ------
    SweepSpecError
        Naming ``item``, what was expected and the text that came.
    """
    if not isinstance(text, str):
        raise SweepSpecError(item, "spec", _SPEC_HELP, text)
    m = _RANGE.fullmatch(text)
    if m:
        a, b, n = float(m.group(1)), float(m.group(2)), int(m.group(3))
        if not 1 <= n <= MAX_RUNS:
            raise SweepSpecError(item, "spec", f"START:STOP:N with N from 1 to {MAX_RUNS:.0e} "
                                 "values (the most runs of a sweep)", text)
        vals = np.linspace(a, b, n) if n > 1 else np.array([a])
        if _INT.fullmatch(m.group(1).strip()) and _INT.fullmatch(m.group(2).strip()) and \
                np.all(vals == np.round(vals)):
            out: tuple = tuple(int(round(v)) for v in vals)
        else:
            out = tuple(float(v) for v in vals)
        if not all(math.isfinite(float(v)) for v in out):
            raise SweepSpecError(item, "spec", "finite START and STOP", text)
        return ValueSpec("range", out, (), text)
    m = _DIST.fullmatch(text)
    if m:
        kind, a, b = m.group(1), float(m.group(2)), float(m.group(3))
        if not (math.isfinite(a) and math.isfinite(b)):
            raise SweepSpecError(item, "spec", f"{kind}(...) with finite parameters", text)
        if kind == "uniform" and not a < b:
            raise SweepSpecError(item, "spec", "uniform(A,B) with A < B", text)
        if kind == "loguniform" and not 0 < a < b:
            raise SweepSpecError(item, "spec", "loguniform(A,B) with 0 < A < B", text)
        if kind == "normal" and not b > 0:
            raise SweepSpecError(item, "spec", "normal(MEAN,SD) with SD > 0", text)
        return ValueSpec(kind, (), (a, b), text)
    if re.match(r"\s*[A-Za-z_]\w*\s*\(", text):
        raise SweepSpecError(item, "spec", "a distribution uniform(A,B), loguniform(A,B) or "
                             "normal(MEAN,SD) with two numbers", text)
    toks = text.split(",")
    try:
        vals = tuple(_scalar(t) for t in toks)
    except ValueError:
        raise SweepSpecError(item, "spec", _SPEC_HELP, text) from None
    if any((isinstance(v, float) and not math.isfinite(v)) or (isinstance(v, str) and v.lower()
           in ("nan", "inf", "infinity")) for v in vals):
        raise SweepSpecError(item, "spec", "finite numbers", text)
    return ValueSpec("list", vals, (), text)


def _spec_from_values(values, item: str) -> ValueSpec:
    """A list spec from a Python sequence of numbers, strings or booleans."""
    out = []
    for v in values:
        if isinstance(v, (bool, np.bool_)):
            out.append(bool(v))
        elif isinstance(v, (int, np.integer)):
            out.append(int(v))
        elif isinstance(v, (float, np.floating)) and math.isfinite(float(v)):
            out.append(float(v))
        elif isinstance(v, str):
            out.append(v)
        else:
            raise SweepSpecError(item, "values", "finite numbers, strings or booleans", v)
    if not out:
        raise SweepSpecError(item, "values", "at least one value", list(values))
    return ValueSpec("list", tuple(out), (), ",".join(str(v) for v in out))


# ---------------------------------------------------------------------------------------------
# paths into the model-file data
def _field_type(section: str, key: str):
    from se3dyn.io.modelfile import FIELDS

    for f in FIELDS.get(section, ()):
        if f.name == key:
            return f.type
    return None


def _level_section(ftype) -> tuple[str, str] | None:
    """(kind, section) of the mapping a field type holds: ("named", sec), ("section", sec)."""
    from se3dyn.io.modelfile import Named, Section

    if isinstance(ftype, Named):
        return ("named", ftype.section)
    if isinstance(ftype, Section):
        return ("section", ftype.name)
    return None


def _keys_text(keys: list[str], wanted: str) -> tuple[str, str]:
    """The valid keys as text (at most 24 shown) and a "did you mean" hint."""
    shown = keys if len(keys) <= 24 else keys[:24] + [f"... ({len(keys)} in all)"]
    close = difflib.get_close_matches(wanted, keys, n=1)
    return (", ".join(shown) if shown else "(none)",
            f"did you mean '{close[0]}'?" if close else "")


def _walk(data: dict, path: str, item: str, create: bool):
    """Follow ``path`` in ``data``; returns ``(container, key)`` of the addressed field.

    Levels are typed by the model-file format (:data:`se3dyn.io.modelfile.FIELDS`): a field that
    the format defines but the file leaves out can be addressed (the last part of the path, or
    an absent section such as ``simulation``, created when ``create``).
    """
    from se3dyn.io.modelfile import FIELDS

    if not isinstance(path, str) or not path.strip() or any(not p for p in path.split(".")):
        raise SweepSpecError(item, "path", "keys and indices joined by dots, e.g. "
                             "joints.8.damping.0 or simulation.step", path)
    parts = path.split(".")
    node: Any = data
    where = "the top level"
    section: tuple[str, str] | None = ("section", "model")  # the format's type of this level
    i = 0
    while True:
        last = i == len(parts) - 1
        if isinstance(node, dict):
            keys = [str(k) for k in node]
            fields = [f.name for f in FIELDS.get(section[1], ())] \
                if section is not None and section[0] == "section" else []
            fields = [f for f in fields if f != "se3dyn"]
            hit = None
            for j in range(len(parts), i, -1):  # the longest run of parts that is a key
                if ".".join(parts[i:j]) in keys:
                    hit = ".".join(parts[i:j]), j
                    break
            if hit is None:
                key = parts[i]
                if key not in fields:
                    valid = keys + [f for f in fields if f not in keys]
                    text, hint = _keys_text(valid, key)
                    raise SweepSpecError(item, "path", f"a key under {where}: {text}", key,
                                         hint)
                if last:
                    return node, key
                sub = _level_section(_field_type(section[1], key))
                if sub is None or sub[0] != "section":
                    whole = ".".join(parts[:i + 1])
                    raise SweepSpecError(item, "path", f"a path ending at '{whole}' (the file "
                                         "does not give it, so it has no parts to address)",
                                         path, f"vary '{whole}' as a whole")
                new: dict = {}
                if create:
                    node[key] = new
                where = f"'{'.'.join(parts[:i + 1])}'"
                node, section, i = new, sub, i + 1
                continue
            key, j = hit
            orig = next(k for k in node if str(k) == key)
            if j == len(parts):
                return node, orig
            if section is not None and section[0] == "named":
                nxt: tuple[str, str] | None = ("section", section[1])
            elif section is not None:
                ftype = _field_type(section[1], key)
                nxt = _level_section(ftype) if ftype is not None else None
            else:
                nxt = None
            where = f"'{'.'.join(parts[:j])}'"
            node, section, i = node[orig], nxt, j
            continue
        if isinstance(node, list):
            tok = parts[i]
            if not re.fullmatch(r"\d+", tok) or int(tok) >= len(node):
                raise SweepSpecError(item, "path", f"an index 0..{len(node) - 1} into {where} "
                                     f"(a list of {len(node)} items)", tok)
            if last:
                return node, int(tok)
            where = f"'{'.'.join(parts[:i + 1])}'"
            node, section, i = node[int(tok)], None, i + 1
            continue
        raise SweepSpecError(item, "path", f"no more keys after {where} (a value: {node!r})",
                             ".".join(parts[i:]))


def check_path(data: dict, path: str, item: str | None = None) -> Any:
    """Check that ``path`` addresses a field of ``data``; returns its current value (None when
    the file leaves the field out).

    Raises
    ------
    SweepSpecError
        A path that does not exist, listing the valid keys at the level where it stops.
    """
    node, key = _walk(data, path, item or f"--vary {path}", create=False)
    if isinstance(node, dict) and key not in node:
        return None
    value = node[key]
    if isinstance(value, dict):
        keys = ", ".join(str(k) for k in value)
        raise SweepSpecError(item or f"--vary {path}", "path", f"a value, not a mapping; add "
                             f"one of its keys: {keys}", path)
    return value


def set_path(data: dict, path: str, value: Any) -> None:
    """Set the field at ``path`` of ``data`` (in place)."""
    node, key = _walk(data, path, f"--vary {path}", create=True)
    node[key] = value


def get_path(data: dict, path: str) -> Any:
    """The value at ``path`` of ``data`` (None when the file leaves it out)."""
    return check_path(data, path)


# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Variable:
    """One varied path and its spec."""

    path: str
    spec: ValueSpec

    @classmethod
    def parse(cls, text: str) -> Variable:
        """From ``PATH=SPEC``."""
        item = f"--vary {text!r}"
        if not isinstance(text, str) or "=" not in text:
            raise SweepSpecError(item, "PATH=SPEC", "a path and a value spec joined by '=', e.g. "
                                 "joints.8.damping.0=0.5,1,2", text)
        path, spec = text.split("=", 1)
        return cls(path.strip(), parse_spec(spec, f"--vary {path.strip()}"))

    @classmethod
    def make(cls, path: str, spec) -> Variable:
        """From a path and a spec text or a sequence of values."""
        if isinstance(spec, str):
            return cls(str(path), parse_spec(spec, f"--vary {path}"))
        if isinstance(spec, (list, tuple, np.ndarray)):
            return cls(str(path), _spec_from_values(list(spec), f"vary[{path!r}]"))
        if isinstance(spec, (int, float, np.integer, np.floating)):
            return cls(str(path), _spec_from_values([spec], f"vary[{path!r}]"))
        raise SweepSpecError(f"vary[{path!r}]", "spec", "a spec text or a list of values", spec)


def plan_runs(variables: list[Variable], method: str = "grid", samples: int | None = None,
              seed: int | None = None) -> list[dict]:
    """The varied values of every run, in run order: a list of ``{path: value}``.

    Raises
    ------
    SweepSpecError
        Unknown method, grid with a distribution, random/lhs without ``samples``, ...
    """
    if method not in METHODS:
        raise SweepSpecError("--method", "method", "one of " + ", ".join(METHODS), method)
    if not variables:
        raise SweepSpecError("--vary", "PATH=SPEC", "at least one varied path", "none")
    if seed is not None and (isinstance(seed, (bool, np.bool_))
                             or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise SweepSpecError("--seed", "seed", "a whole number >= 0", seed)
    paths = [v.path for v in variables]
    dup = sorted({p for p in paths if paths.count(p) > 1})
    if dup:
        raise SweepSpecError("--vary", "path", "each path once", dup[0])
    if method == "grid":
        if samples is not None:
            raise SweepSpecError("--samples", "samples", "no --samples with --method grid (the "
                                 "grid size is the product of the list lengths)", samples)
        for v in variables:
            if not v.spec.discrete:
                raise SweepSpecError(f"--vary {v.path}", "spec", "a list or range for --method "
                                     "grid (distributions need --method random or lhs)",
                                     v.spec.text)
        size = math.prod(len(v.spec.values) for v in variables)
        if size > MAX_RUNS:
            raise SweepSpecError("--vary", "grid", f"at most {MAX_RUNS:.0e} runs (the product "
                                 "of the lengths of the lists and ranges; fewer values, or "
                                 "--method random or lhs with --samples)", f"{size:.3g} runs")
        runs: list[dict] = [{}]
        for v in variables:
            runs = [dict(r, **{v.path: x}) for r in runs for x in v.spec.values]
        return runs
    if samples is None or isinstance(samples, bool) or not isinstance(samples, (int,
                                                                             np.integer)) \
            or not 1 <= samples <= MAX_RUNS:
        raise SweepSpecError("--samples", "samples", f"a positive number of runs for --method "
                             f"{method} (at most {MAX_RUNS:.0e})", samples)
    rng = np.random.default_rng(seed)
    d = len(variables)
    if method == "random":
        u = rng.random((int(samples), d))
    else:
        from scipy.stats import qmc

        try:
            lhs = qmc.LatinHypercube(d=d, rng=rng)
        except TypeError:  # scipy < 1.15
            lhs = qmc.LatinHypercube(d=d, seed=rng)
        u = lhs.random(int(samples))
    cols = [v.spec.from_uniform(u[:, k]) for k, v in enumerate(variables)]
    return [{v.path: cols[k][i] for k, v in enumerate(variables)} for i in range(int(samples))]


def apply_values(data: dict, values: dict) -> dict:
    """A deep copy of ``data`` with the varied ``values`` set."""
    out = copy.deepcopy(data)
    for path, val in values.items():
        set_path(out, path, val)
    return out
