"""No traceback, ever: a generated corpus of hostile model files and Python calls.

A deterministic generator mutates valid model files (fields deleted, duplicated and retyped,
extreme numbers, wrong nesting, bad names, YAML tags, unicode, huge lists, broken text) and
draws hostile arguments for the Python API. Asserted: ``se3dyn check`` and ``se3dyn run``
exit with 0, 1 or 2, a single-line message and no traceback; the Python API raises only
subclasses of :class:`se3dyn.Se3dynError`. The CLI runs in-process (``se3dyn.cli.main``) for
speed, a few cases in real subprocesses. Plus one test per class of crash found by fuzzing
(huge step counts, nothing to solve, overflowing numbers, unstorable names, tags, API types).
"""

from __future__ import annotations

import contextlib
import io
import math
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

import se3dyn as sd
from se3dyn.cli import main
from se3dyn.errors import Se3dynError
from se3dyn.modelfile import load_model, loads_model, save_model

ROOT = Path(__file__).resolve().parents[1]
SEED = 20261122

# a small model using every section: hinge with spring, screw, spherical, universal, loads,
# spring-damper, visuals, simulation settings
SMALL = """\
se3dyn: 1
name: small
gravity: [0.0, 0.0, -9.81]
nodes:
  g: {position: [0.0, 0.0, 0.0], fixed: true}
  a: {position: [0.5, 0.0, 0.0], mass: 1.0, inertia: [0.01, 0.02, 0.02]}
  b: {position: [1.0, 0.0, 0.0], mass: 0.5, inertia: [0.01, 0.01, 0.01], velocity: [0, 0.1, 0]}
  c: {position: [1.0, 0.5, 0.0], mass: 0.2, inertia: [0.01, 0.01, 0.01]}
joints:
  h: {type: hinge, a: g, b: a, at: [0.0, 0.0, 0.0], axis: [0.0, 1.0, 0.0], stiffness: 1.0,
      reference: 0.1, damping: 0.01, torque: {step: {value: 0.2, start: 0.0, stop: 1.0}}}
  s: {type: screw, a: a, b: b, at: [0.75, 0.0, 0.0], axis: [1.0, 0.0, 0.0], pitch: 0.01}
  u: {type: universal, a: b, b: c, at: [1.0, 0.25, 0.0], axes: [[1, 0, 0], [0, 0, 1]]}
loads:
  push: {node: c, force: [0.0, 1.0, 0.0], at: [1.0, 0.5, 0.0]}
springs:
  sp: {a: g, b: c, at_a: [0.0, 0.5, 0.0], at_b: [1.0, 0.5, 0.0], stiffness: 2.0, damping: 0.1}
visuals:
  rod: {node: a, shape: cylinder, size: [0.01, 0.5], axis: [1, 0, 0]}
simulation: {t_end: 1.0, step: 0.01, rho_inf: 0.9}
"""

BASES = [("small", SMALL)] + [
    (p.stem, p.read_text(encoding="utf-8"))
    for p in (ROOT / "examples" / "a01_simple_pendulum.yaml",
              ROOT / "examples" / "slider_crank_bodies.yaml",
              ROOT / "examples" / "slider_crank.yaml")]

HOSTILE_VALUES = [
    None, True, False, 0, -1, 1, 2**70, -(2**70), 1e300, -1e300, 1e-300, 5e-324, 1e15, 1e16,
    float("nan"), float("inf"), -float("inf"), "", "x", "a\0b", "\u00e9t\u00e9", "\U0001F600",
    "revolute", [], {}, [1, 2], [1, 2, 3, 4], [[1, 2, 3]], [1e300, 0, 0], [0, 0, 0],
    ["a", "b", "c"], {"a": 1}, {"step": {"value": "x"}}, {"sine": {}}, [None] * 3,
    list(range(200)), "1e-4", "0x10", "yes", "~",
]

# YAML fragments inserted as text (tags, control characters, surrogates, broken syntax)
TEXT_SNIPPETS = [
    "!!python/tuple [1, 2, 3]", "!custom 1.0", "!!str 1.0", "!!binary aGVsbG8=",
    "!!python/object/apply:os.system ['true']", "! 1.0", "!<tag:example.com,2000:x> 1",
    '"a\\0b"', '"\\ud800"', '"x\\x07y"', '"\\u202e"', "&anchor 1", "*alias", "[1, 2",
    "{a: 1", "'unterminated", "@", "`", "%YAML 1.1", "---", "...", "1e999", "-.inf", ".nan",
    "0o777", "2001-12-14t21:59:43.10-05:00", "? complex key", "|\n  block", "[" * 60,
    '"' + "\u00ff" * 300 + '"',
]


# ---------------------------------------------------------------------------------------------
def _paths(doc, prefix=()):
    """Every (path, value) in a nested dict/list document."""
    out = [(prefix, doc)]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += _paths(v, prefix + (i,))
    return out


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def _set(doc, path, value):
    _get(doc, path[:-1])[path[-1]] = value


def _dump(doc) -> str:
    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True, width=10_000)


def _mutate(rng: random.Random, text: str) -> tuple[str, str]:
    """One hostile variant of a valid model file: (kind of mutation, text)."""
    doc = yaml.safe_load(text)
    paths = [p for p, _ in _paths(doc) if p]
    kind = rng.choice(["delete", "retype", "retype", "extreme", "nest", "rename", "duplicate",
                       "tag", "unicode", "biglist", "jointtype", "badref", "sim", "text",
                       "truncate", "multi", "nothing"])
    if kind == "delete":
        p = rng.choice(paths)
        parent = _get(doc, p[:-1])
        del parent[p[-1]]
    elif kind == "retype":
        _set(doc, rng.choice(paths), rng.choice(HOSTILE_VALUES))
    elif kind == "extreme":
        nums = [p for p, v in _paths(doc) if p and isinstance(v, int | float)
                and not isinstance(v, bool)]
        for p in rng.sample(nums, min(len(nums), rng.randint(1, 3))):
            _set(doc, p, rng.choice([1e300, -1e300, 1e308, 5e-324, 1e-300, 1e16, -1e16, 1e15,
                                     0.0, -0.0, 2**64, 1e-12, 1e12]))
    elif kind == "nest":
        p = rng.choice(paths)
        v = _get(doc, p)
        _set(doc, p, rng.choice([[v], {"x": v}, [[v]], {"value": v}]))
    elif kind == "rename":
        sec = rng.choice([k for k in ("nodes", "joints", "loads", "springs", "visuals")
                          if isinstance(doc.get(k), dict) and doc[k]])
        old = rng.choice(list(doc[sec]))
        new = rng.choice(["a\0b", "x\ty", "\x07", "line\nbreak", "", " ", "\u202e", "n" * 500,
                          "\u00e9", "cross:1", "a:cross", "1", "g", "\x1b[31m", "é\x7f"])
        doc[sec] = {(new if k == old else k): v for k, v in doc[sec].items()}
        if sec == "nodes":  # references follow half of the time
            if rng.random() < 0.5:
                for sec2 in ("joints", "loads", "springs", "visuals"):
                    for item in (doc.get(sec2) or {}).values():
                        if isinstance(item, dict):
                            for f in ("a", "b", "node"):
                                if item.get(f) == old:
                                    item[f] = new
    elif kind == "duplicate":
        lines = text.splitlines()
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
        return kind, "\n".join(lines) + "\n"
    elif kind == "tag":
        p = rng.choice(paths)
        _set(doc, p, "@@SNIP@@")
        snip = rng.choice(TEXT_SNIPPETS[:7])
        return kind, _dump(doc).replace("'@@SNIP@@'", snip).replace("@@SNIP@@", snip)
    elif kind == "unicode":
        p = rng.choice(paths)
        s = "".join(chr(rng.choice([rng.randint(0x20, 0x7e), rng.randint(0xa0, 0x2fff),
                                    rng.randint(0x1f300, 0x1f6ff)])) for _ in range(8))
        _set(doc, p, s)
    elif kind == "biglist":
        p = rng.choice(paths)
        n = rng.choice([1000, 20_000, 200_000])
        _set(doc, p, [rng.random() for _ in range(n)] if n <= 20_000 else "@@BIG@@")
        if n > 20_000:
            return kind, _dump(doc).replace("@@BIG@@", "[" + ", ".join(["1"] * n) + "]")
    elif kind == "jointtype":
        j = doc.get("joints") or {}
        if j:
            name = rng.choice(list(j))
            if isinstance(j[name], dict):
                j[name]["type"] = rng.choice(["hinge", "prismatic", "cylindrical", "spherical",
                                              "planar", "screw", "general", "universal",
                                              "rigid", "revolute", "HINGE", ["hinge"], 1])
    elif kind == "badref":
        j = doc.get("joints") or {}
        if j:
            item = j[rng.choice(list(j))]
            if isinstance(item, dict):
                item[rng.choice(["a", "b"])] = rng.choice(["nope", ["g"], 1, None, "", "a\0"])
    elif kind == "sim":
        sim = doc.setdefault("simulation", {})
        if isinstance(sim, dict):
            sim[rng.choice(["t_end", "step", "rho_inf", "tol", "output_step", "h_min",
                            "h_max", "formulation", "output_every", "t_start", "max_iter",
                            "bogus"])] = rng.choice(
                [1e-300, 5e-324, 1e-9, -1.0, 0.0, 1e300, 2.0, "index3", "x", 10**20, 0, 3,
                 None, [1], float("nan")])
    elif kind == "text":
        lines = _dump(doc).splitlines()
        i = rng.randrange(len(lines))
        snip = rng.choice(TEXT_SNIPPETS)
        if ": " in lines[i] and rng.random() < 0.7:
            head = lines[i].split(": ", 1)[0]
            lines[i] = f"{head}: {snip}"
        else:
            lines.insert(i, snip)
        return kind, "\n".join(lines) + "\n"
    elif kind == "truncate":
        return kind, text[: rng.randrange(len(text))]
    elif kind == "multi":
        for _ in range(rng.randint(2, 5)):
            paths = [p for p, _ in _paths(doc) if p]
            if not paths:
                break
            _set(doc, rng.choice(paths), rng.choice(HOSTILE_VALUES))
    return kind, _dump(doc)


def corpus(n: int) -> list[tuple[str, str, str]]:
    rng = random.Random(SEED)
    out = []
    for k in range(n):
        base, text = BASES[k % len(BASES)]
        kind, mutated = _mutate(rng, text)
        out.append((f"{k:04d}-{base}-{kind}", kind, mutated))
    return out


def _cli(argv) -> tuple[int, str, str]:
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code
    return code, out.getvalue(), err.getvalue()


def _assert_clean(code, err, what):
    assert code in (0, 1, 2), f"{what}: exit {code}\n{err}"
    assert "Traceback" not in err, f"{what}:\n{err}"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    errs = [ln for ln in lines if ln.startswith("se3dyn: error:")]
    if code != 0:
        assert len(errs) == 1, f"{what}: expected one error line, got\n{err}"
    assert len(errs) <= 1, f"{what}:\n{err}"


N_FILES = 900


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    out = []
    for name, kind, text in corpus(N_FILES):
        p = d / f"{name}.yaml"
        p.write_bytes(text.encode("utf-8", "surrogatepass"))
        out.append((p, kind))
    return d, out


def test_corpus_is_hostile_enough(files):
    _, fs = files
    assert len(fs) == N_FILES
    kinds = {k for _, k in fs}
    assert len(kinds) >= 15
    # most mutations are refused; some still load (e.g. a changed number)
    bad = 0
    for p, _ in fs:
        try:
            load_model(p)
        except Se3dynError:
            bad += 1
    assert N_FILES * 0.4 < bad < N_FILES


def test_corpus_check_and_run_in_process(files):
    d, fs = files
    t0 = time.perf_counter()
    codes = {0: 0, 1: 0, 2: 0}
    for p, kind in fs:
        code, _, err = _cli(["check", p])
        _assert_clean(code, err, f"check {p.name} ({kind})")
        codes[code] += 1
        if code == 0:
            code, _, err = _cli(["run", p, "--t-end", "0.02", "--step", "0.01", "--quiet",
                                 "--out", d / "out"])
            _assert_clean(code, err, f"run {p.name} ({kind})")
            codes[code] += 1
    assert codes[2] > 0 and codes[0] > 0
    assert time.perf_counter() - t0 < 120


def test_corpus_api_load_model(files):
    """The Python API raises only se3dyn errors on the corpus: load, save, simulate."""
    _, fs = files
    for p, kind in fs:
        try:
            model, settings = load_model(p)
        except Se3dynError:
            continue
        text = save_model(model)
        loads_model(text)
        try:
            sd.simulate(model, t_end=0.02, step=0.01)
        except Se3dynError:
            pass


def test_corpus_subprocess_sample(files):
    """A few real processes: the console script, its exit codes and stderr."""
    d, fs = files
    rng = random.Random(SEED)
    sample = rng.sample(fs, 6)
    for p, kind in sample:
        for args in (["check", p], ["run", p, "--t-end", "0.02", "--step", "0.01", "--out",
                                    d / "sub"]):
            r = subprocess.run([sys.executable, "-m", "se3dyn.cli", *map(str, args)],
                               capture_output=True, text=True, timeout=120)
            _assert_clean(r.returncode, r.stderr, f"{args[0]} {p.name} ({kind})")


# ---------------------------------------------------------------------------------------------
# Hostile Python calls
# ---------------------------------------------------------------------------------------------
API_VALUES = HOSTILE_VALUES + [np.array([1.0, 2.0]), np.array(["hinge"]), np.nan, object(),
                               lambda t: "x", lambda t: 1 / 0, b"bytes", 1j, (1, 2, 3),
                               np.zeros((3, 3)), np.eye(3), set()]


def _builder():
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("g", fixed=True)
    mb.node("a", position=(0.5, 0, 0), mass=1.0, inertia=(0.01, 0.02, 0.02))
    mb.node("b", position=(1, 0, 0), mass=1.0, inertia=(0.01, 0.01, 0.01))
    mb.joint("h", "hinge", "g", "a", axis=(0, 1, 0), at=(0, 0, 0))
    return mb


def _api_calls(n: int):
    """n hostile calls, each a (description, zero-argument callable)."""
    rng = random.Random(SEED + 1)
    res = sd.simulate(_builder().build(), t_end=0.02, step=0.01)
    calls = []

    def pick():
        return rng.choice(API_VALUES)

    node_kw = ["position", "orientation", "mass", "inertia", "principal_axes", "fixed",
               "velocity", "angular_velocity", "velocity_frame", "com"]
    joint_kw = ["axis", "axes", "normal", "pitch", "A", "stiffness", "reference", "damping",
                "actuator", "torque", "force", "control", "at"]
    types = ["hinge", "prismatic", "cylindrical", "spherical", "planar", "screw", "general",
             "universal", "rigid"]
    for k in range(n):
        which = k % 10
        if which == 0:
            kw = {rng.choice(node_kw): pick() for _ in range(rng.randint(1, 3))}
            name = pick() if rng.random() < 0.3 else "n"
            calls.append((f"node({name!r}, **{kw!r})",
                          lambda name=name, kw=kw: _builder().node(name, **kw)))
        elif which in (1, 2):
            kw = {rng.choice(joint_kw): pick() for _ in range(rng.randint(1, 3))}
            t = pick() if rng.random() < 0.2 else rng.choice(types)
            na, nb = (pick(), "b") if rng.random() < 0.2 else ("a", "b")
            calls.append((f"joint({t!r}, {na!r}, **{kw!r})",
                          lambda t=t, na=na, nb=nb, kw=kw: _jb(t, na, nb, kw)))
        elif which == 3:
            kw = {rng.choice(["force", "torque", "at", "force_frame", "torque_frame"]): pick()
                  for _ in range(rng.randint(1, 2))}
            node = pick() if rng.random() < 0.3 else "b"
            calls.append((f"load({node!r}, **{kw!r})",
                          lambda node=node, kw=kw: _builder().load("L", node, **kw)))
        elif which == 4:
            kw = {rng.choice(["at_a", "at_b", "stiffness", "damping", "length"]): pick()
                  for _ in range(rng.randint(1, 2))}
            kw.setdefault("stiffness", 1.0)
            calls.append((f"spring_damper(**{kw!r})",
                          lambda kw=kw: _builder().spring_damper("s", "g", "b", **kw)))
        elif which == 5:
            kw = {rng.choice(["t_end", "step", "rho_inf", "t_start", "output_every", "tol",
                              "h_min", "h_max", "output_step", "formulation", "engine",
                              "newton", "progress", "redundant", "max_iter"]): pick()
                  for _ in range(rng.randint(1, 2))}
            kw.setdefault("t_end", 0.02)
            kw.setdefault("step", 0.01)
            calls.append((f"simulate(**{kw!r})",
                          lambda kw=kw: sd.simulate(_builder().build(), **kw)))
        elif which == 6:
            f = rng.choice(["node_position", "node_velocity", "node_acceleration",
                            "joint_coordinates", "joint_multipliers", "node_rotation"])
            arg = pick() if rng.random() < 0.7 else "nope"
            calls.append((f"Results.{f}({arg!r})",
                          lambda f=f, arg=arg: getattr(res, f)(arg)
                          if hasattr(res, f) else res.node_position(arg)))
        elif which == 7:
            cls = rng.choice([sd.Step, sd.Ramp, sd.Sine, sd.Table, sd.PD])
            args = [pick() for _ in range(rng.randint(1, 3))]
            calls.append((f"{cls.__name__}(*{args!r})",
                          lambda cls=cls, args=args: cls(*args)))
        elif which == 8:
            arg = pick()
            calls.append((f"load_model({arg!r})",
                          lambda arg=arg: load_model(arg)))
        else:
            kw = {rng.choice(["gravity", "name"]): pick()}
            calls.append((f"ModelBuilder(**{kw!r})", lambda kw=kw: sd.ModelBuilder(**kw)))
    return calls


def _jb(t, na, nb, kw):
    mb = _builder()
    mb.joint("j", t, na, nb, **kw)
    return mb.build()


N_CALLS = 400


def test_api_calls_raise_only_se3dyn_errors():
    calls = _api_calls(N_CALLS)
    assert len(calls) == N_CALLS
    for what, call in calls:
        try:
            call()
        except Se3dynError:
            pass
        except Exception as exc:  # noqa: BLE001
            pytest.fail(f"{what}: {type(exc).__name__}: {exc}")


def test_corpus_size():
    assert N_FILES + N_CALLS >= 1000
