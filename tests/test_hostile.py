"""No traceback, ever: a generated corpus of hostile model files and Python calls.

A deterministic generator mutates valid model files (fields deleted, duplicated and retyped,
extreme numbers, wrong nesting, bad names, YAML tags, unicode, huge lists, broken text) and
draws hostile arguments for the Python API. Asserted: ``se3dyn check`` and ``se3dyn run``
exit with 0, 1 or 2, a single-line message and no traceback; the Python API raises only
subclasses of :class:`se3dyn.Se3dynError`. The CLI runs in-process (``se3dyn.cli.commands``) for
speed, a few cases in real subprocesses. Plus one test per class of crash found by fuzzing
(huge step counts, nothing to solve, overflowing numbers, unstorable names, tags, API types).
"""

from __future__ import annotations

import contextlib
import importlib
import io
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

import se3dyn as sd
from se3dyn.cli.commands import main
from se3dyn.errors import Se3dynError
from se3dyn.io.modelfile import load_model, loads_model, save_model

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


_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def _dump(doc) -> str:
    return yaml.dump(doc, Dumper=_DUMPER, sort_keys=False, allow_unicode=True, width=10_000)


def _mutate(rng: random.Random, text: str) -> tuple[str, str]:
    """One hostile variant of a valid model file: (kind of mutation, text)."""
    doc = yaml.load(text, Loader=_LOADER)
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
        n = rng.choice([100, 1000, 10_001])
        _set(doc, p, "@@BIG@@")
        big = "[" + ", ".join(rng.choice(["1", "0.5", "x", "[]"]) for _ in range(n)) + "]"
        return kind, _dump(doc).replace("@@BIG@@", big)
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


N_FILES = 1200


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The corpus written to files, each with its model when it loads (else None)."""
    d = tmp_path_factory.mktemp("hostile")
    out = []
    for name, kind, text in corpus(N_FILES):
        p = d / f"{name}.yaml"
        p.write_bytes(text.encode("utf-8", "surrogatepass"))
        try:
            model = load_model(p)[0]
        except Se3dynError:
            model = None
        out.append((p, kind, model))
    return d, out


def test_corpus_is_hostile_enough(files):
    _, fs = files
    assert len(fs) == N_FILES
    assert len({k for _, k, _ in fs}) >= 15
    # most mutations are refused; some still load (e.g. a changed number)
    bad = sum(m is None for _, _, m in fs)
    assert N_FILES * 0.4 < bad < N_FILES


def test_corpus_check_and_run_in_process(files):
    d, fs = files
    t0 = time.perf_counter()
    codes = {0: 0, 1: 0, 2: 0}
    for p, kind, _ in fs:
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


def test_corpus_api_save_and_simulate(files):
    """The Python API raises only se3dyn errors on the models of the corpus that load: they
    save, load back and simulate (or fail with a SimulationError)."""
    _, fs = files
    for _, _, model in fs:
        if model is None:
            continue
        loads_model(save_model(model))
        try:
            sd.simulate(model, t_end=0.02, step=0.01)
        except Se3dynError:
            pass


def test_corpus_subprocess_sample(files):
    """A few real processes: the console script, its exit codes and stderr."""
    d, fs = files
    rng = random.Random(SEED)
    sample = rng.sample(fs, 6)
    for p, kind, _ in sample:
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
            cls, lo, hi = rng.choice([(sd.Step, 1, 3), (sd.Ramp, 1, 3), (sd.Sine, 2, 4),
                                      (sd.Table, 2, 2), (sd.Constant, 1, 1)])
            args = [pick() for _ in range(rng.randint(lo, hi))]
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


N_CALLS = 600


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


# ---------------------------------------------------------------------------------------------
# One test per class of crash found by fuzzing (each failed before the fix)
# ---------------------------------------------------------------------------------------------
def _pendulum(**joint):
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("g", fixed=True)
    mb.node("a", position=(0.5, 0, 0), mass=1.0, inertia=(0.01, 0.02, 0.02))
    mb.joint("h", "hinge", "g", "a", axis=(0, 1, 0), at=(0, 0, 0), **joint)
    return mb.build()


@pytest.mark.parametrize("t_end, step", [(1.0, 1e-300), (1.0, 5e-324), (1.0, 1e-9),
                                         (1e6, 1e-6)])
def test_huge_step_counts_are_refused_before_allocating(t_end, step):
    t0 = time.perf_counter()
    with pytest.raises(sd.ModelError, match=r"at most 1e\+08 steps.*larger step") as ei:
        sd.simulate(_pendulum(), t_end=t_end, step=step)
    assert ei.value.field == "step"
    assert time.perf_counter() - t0 < 5


def test_stored_rows_beyond_memory_are_refused(monkeypatch):
    simmod = importlib.import_module("se3dyn.dynamics.settings")  # (where _check_size reads it)

    monkeypatch.setattr(simmod, "_available_memory", lambda: 3e7)
    with pytest.raises(sd.ModelError, match="output_every or output_step"):
        sd.simulate(_pendulum(), t_end=10.0, step=1e-4)
    with pytest.raises(sd.ModelError, match="fit in memory"):
        sd.simulate(_pendulum(), t_end=10.0, step=1e-4, tol=1e-3, output_step=1e-5)
    sd.simulate(_pendulum(), t_end=10.0, step=1e-2)  # small enough


@pytest.mark.parametrize("text", ["simulation: {t_end: 1.0, step: 1.0e-300}",
                                  "simulation: {t_end: 1.0, step: 5.0e-324}",
                                  "simulation: {t_end: 1.0, step: 1.0e-9}"])
def test_command_refuses_huge_step_counts_in_one_line_and_leaves_no_file(tmp_path, text):
    src = SMALL.replace("simulation: {t_end: 1.0, step: 0.01, rho_inf: 0.9}", text)
    (tmp_path / "m.yaml").write_text(src)
    code, _, err = _cli(["run", tmp_path / "m.yaml", "--out", tmp_path / "o", "--quiet"])
    _assert_clean(code, err, text)
    assert code == 2 and "steps" in err
    assert not (tmp_path / "o" / "m.h5").exists()
    code, _, err = _cli(["run", tmp_path / "m.yaml", "--t-end", "1e6", "--step", "1e-6",
                         "--out", tmp_path / "o"])
    assert code == 2 and "1e+12 steps" in err, err


def test_compiled_loop_in_blocks_equals_one_block(monkeypatch):
    """Times and inputs are tabulated in blocks: the same rows, bit for bit, and the same
    failure, whatever the block size and the initial capacity of the recorder."""
    simmod = importlib.import_module("se3dyn.dynamics.run")

    def run():
        m = _pendulum(torque=sd.Sine(0.3, 2.0), damping=0.01)
        a = sd.simulate(m, t_end=0.5, step=0.01, output_every=3)
        bad = _pendulum(torque=lambda t: 0.1 if t < 0.23 else float("nan"))
        with pytest.raises(sd.SimulationError) as ei:
            sd.simulate(bad, t_end=0.5, step=0.01, output_every=2)
        return a, ei.value

    a, ea = run()
    monkeypatch.setattr(simmod, "_BLOCK", 7)
    monkeypatch.setattr(importlib.import_module("se3dyn.dynamics.recorder"), "_INITIAL_ROWS", 2)
    b, eb = run()
    for f in ("t", "H", "v", "vd", "lam", "alpha", "kinetic", "work_actuators", "iterations"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert a.stats["h_min_used"] == b.stats["h_min_used"]
    assert a.stats["h_max_used"] == b.stats["h_max_used"]
    assert a.t[-1] == 0.5 and len(a.t) == 18
    assert str(ea) == str(eb)
    assert np.array_equal(ea.result.t, eb.result.t) and np.array_equal(ea.result.H, eb.result.H)


NOTHING = "se3dyn: 1\nnodes: {g: {fixed: true}}\nsimulation: {t_end: 1.0, step: 0.1}\n"


def test_check_and_run_a_model_with_nothing_to_solve(tmp_path):
    (tmp_path / "m.yaml").write_text(NOTHING)
    code, out, err = _cli(["check", tmp_path / "m.yaml"])
    _assert_clean(code, err, "check")
    assert code == 0 and "mobility) 0" in out and "joints by type: none" in out
    code, out, err = _cli(["run", tmp_path / "m.yaml", "--out", tmp_path, "--quiet"])
    _assert_clean(code, err, "run")
    assert code == 0


@pytest.mark.parametrize("change, item, fld", [
    (dict(type="screw", axis=(0, 1, 0), pitch=1e300), "joint 'j' (screw)", "pitch"),
    (dict(type="hinge", axis=(0, 1, 0), stiffness=1.0, reference=1e300), "joint 'j' (hinge)",
     "reference"),
    (dict(type="hinge", axis=(0, 1, 0), at=(1e300, 0, 0)), "joint 'j' (hinge)", "at"),
])
def test_overflowing_joint_numbers_are_refused(change, item, fld):
    mb = _builder()
    t = change.pop("type")
    with pytest.raises(sd.ModelError) as ei:
        mb.joint("j", t, "a", "b", **change)
    assert ei.value.item == item and ei.value.field == fld


@pytest.mark.parametrize("kw, fld", [(dict(position=(1e300, 0, 0)), "position"),
                                     (dict(velocity=(0, 1e300, 0)), "velocity"),
                                     (dict(mass=1e300, inertia=(1, 1, 1)), "mass"),
                                     (dict(mass=1.0, inertia=(1e300, 1e300, 1e300)), "inertia")])
def test_overflowing_node_numbers_are_refused(kw, fld):
    with pytest.raises(sd.ModelError) as ei:
        _builder().node("n", **kw)
    assert ei.value.item == "node 'n'" and ei.value.field == fld


@pytest.mark.parametrize("old, new, line", [
    ("pitch: 0.01", "pitch: 1.0e+300", 12), ("reference: 0.1", "reference: 1.0e+300", 11),
    ("position: [0.5, 0.0, 0.0]", "position: [1.0e+300, 0.0, 0.0]", 6),
    ("stiffness: 2.0", "stiffness: 1.0e+300", 17)])
def test_overflowing_numbers_in_files_name_file_line_item_and_field(tmp_path, old, new, line):
    (tmp_path / "m.yaml").write_text(SMALL.replace(old, new))
    code, _, err = _cli(["check", tmp_path / "m.yaml"])
    _assert_clean(code, err, new)
    assert code == 2 and f"m.yaml, line {line}:" in err and new.split(":")[0] in err, err


def test_newton_failure_report_survives_non_finite_values():
    from types import SimpleNamespace

    s = sd.compile_model(_pendulum())
    integ = sd.GeneralizedAlpha()
    for fill in (np.nan, np.inf):
        ev = SimpleNamespace(r=np.full(s.nq, fill), phi=np.full(s.nm, fill), f_scale=fill)
        with pytest.raises(sd.NewtonError, match="non-finite") as ei:
            integ._fail(s, 0.1, 0.01, 3, ev, "diverging")
        assert ei.value.item


@pytest.mark.parametrize("bad", ["a\0b", "a\ud800b", "x\ty", "\x1b[31m", "line\nbreak",
                                 "\u202e", "", "n" * 201])
def test_unstorable_names_are_refused_at_build_time(bad):
    for call in (lambda: _builder().node(bad),
                 lambda: _builder().joint(bad, "hinge", "a", "b", axis=(0, 0, 1)),
                 lambda: _builder().load(bad, "b", force=(1, 0, 0)),
                 lambda: _builder().spring_damper(bad, "g", "b", stiffness=1.0),
                 lambda: sd.ModelBuilder(name=bad)):
        with pytest.raises(sd.ModelError, match="name"):
            call()


@pytest.mark.parametrize("escaped", ["a\\0b", "a\\ud800b", "a\\x07b"])
def test_unstorable_names_in_files_exit_2_in_one_line(tmp_path, escaped):
    text = SMALL.replace("  c: {position", f'  "{escaped}": {{position').replace(
        "b: c,", f'b: "{escaped}",').replace("node: c,", f'node: "{escaped}",').replace(
        "b: c, at_a", f'b: "{escaped}", at_a')
    (tmp_path / "m.yaml").write_text(text)
    for cmd in (["check"], ["run", "--t-end", "0.02", "--out", tmp_path, "--quiet"]):
        code, _, err = _cli([cmd[0], tmp_path / "m.yaml", *cmd[1:]])
        _assert_clean(code, err, escaped)
        assert code == 2 and "line 8" in err and "printable" in err, err


@pytest.mark.parametrize("tag", ["!!python/tuple", "!custom", "!!str", "!!float", "!!seq",
                                 "!", "!<tag:yaml.org,2002:str>"])
def test_yaml_tags_are_refused_naming_file_and_line(tmp_path, tag):
    value = "[0.5, 0.0, 0.0]" if tag in ("!!python/tuple", "!custom", "!!seq") else "0.5"
    if value == "0.5":
        text = SMALL.replace("mass: 1.0,", f"mass: {tag} 1.0,")
    else:
        text = SMALL.replace("position: [0.5, 0.0, 0.0]", f"position: {tag} {value}")
    (tmp_path / "m.yaml").write_text(text)
    with pytest.raises(sd.ModelError, match=r"m\.yaml, line 6: .*tag"):
        load_model(tmp_path / "m.yaml")
    code, _, err = _cli(["check", tmp_path / "m.yaml"])
    _assert_clean(code, err, tag)
    assert code == 2


def test_api_errors_are_se3dyn_errors(tmp_path):
    res = sd.simulate(_builder().build(), t_end=0.02, step=0.01)
    with pytest.raises(Se3dynError, match=r"unknown node 'nope'.*valid: g, a, b") as ei:
        res.node_position("nope")
    assert isinstance(ei.value, KeyError)  # still a KeyError for older callers
    for call in (lambda: res.node_position(["a"]), lambda: res.joint_coordinates(["h"]),
                 lambda: res.joint_coordinates("nope"),
                 lambda: res.node_velocity("a", frame="x"),
                 lambda: load_model(None), lambda: load_model(tmp_path),
                 lambda: load_model("a\0b"),
                 lambda: save_model(_builder().build(), tmp_path),
                 lambda: save_model(_builder().build(), "/tmp"),
                 lambda: sd.simulate(_builder().build(), t_end=1.0, step=1e-300),
                 lambda: sd.simulate(_builder().build(), t_end=0.1, step=0.01, progress=5),
                 lambda: sd.simulate(_builder().build(), t_end=0.1, step=0.01, on_output="x"),
                 lambda: sd.simulate(_builder().build(), t_end=0.1, step=0.01, tol=5e-324),
                 lambda: sd.simulate(_builder().build(), t_end=0.1, step=0.01,
                                     max_iter=10**20),
                 lambda: sd.Step("x"), lambda: sd.Step(1.0, start="a"),
                 lambda: sd.Ramp(1.0, duration=np.zeros(3)), lambda: sd.Table([0, 1], "ab"),
                 lambda: sd.Sine(1.0, "x"),
                 lambda: _builder().joint("j", np.array(["hinge"]), "a", "b", axis=(0, 0, 1)),
                 lambda: _builder().joint("j", ["hinge"], "a", "b", axis=(0, 0, 1)),
                 lambda: _builder().node(["n"]), lambda: _builder().load("L", ["b"],
                                                                        force=(1, 0, 0)),
                 lambda: _builder().load(["L"], "b", force=(1, 0, 0)),
                 lambda: _builder().node("n", fixed="no"),
                 lambda: _builder().node("n", fixed=1),
                 lambda: _builder().node("n", mass=True, inertia=(1, 1, 1)),
                 lambda: _builder().node("n", mass="1"),
                 lambda: sd.ModelBuilder(name=None),
                 lambda: _builder().joint("j", "screw", "a", "b", axis=(0, 0, 1), pitch=True)):
        with pytest.raises(Se3dynError):
            call()


def test_error_messages_show_plain_numbers():
    with pytest.raises(sd.ModelError) as ei:
        _builder().node("n", mass=np.float64(-0.5))
    assert "np.float64" not in str(ei.value) and "-0.5" in str(ei.value)
    with pytest.raises(sd.ModelError) as ei:
        _builder().node("n", fixed=True, velocity=(np.float64(1.0), 0, 0))
    assert "np.float64" not in str(ei.value)


def test_export_csv_without_channels_has_time_once(tmp_path):
    (tmp_path / "m.yaml").write_text(SMALL)
    code, _, err = _cli(["run", tmp_path / "m.yaml", "--t-end", "0.05", "--out", tmp_path,
                         "--quiet"])
    assert code == 0, err
    code, _, err = _cli(["export", tmp_path / "m.h5", "--csv", tmp_path / "m.csv"])
    assert code == 0, err
    header = (tmp_path / "m.csv").read_text().splitlines()[0].split(",")
    assert sum(h.startswith("time") for h in header) == 1 and header[0] == "time [s]"


def _console_script():
    exe = Path(sys.executable).parent / "se3dyn"
    return str(exe) if exe.exists() else shutil.which("se3dyn")


@pytest.mark.skipif(not sys.platform.startswith("linux") or not _console_script(),
                    reason="needs /proc and the installed console script")
@pytest.mark.parametrize("sig, code, word", [(signal.SIGINT, 130, "interrupted"),
                                             (signal.SIGTERM, 143, "terminated")])
def test_signals_during_start_up_print_one_line_and_exit(tmp_path, sig, code, word):
    """Ctrl-C (SIGTERM) while the package is still loading (numpy loaded, se3dyn not yet):
    SIGTERM in the first 0.3 s ended the process with no message. On a loaded machine the
    small check can finish before the signal arrives: then it is sent again to a new process
    (a missed signal is not what this test is about)."""
    (tmp_path / "m.yaml").write_text(SMALL)

    def defaults():
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)

    for _ in range(5):
        # signals as from a shell: at their defaults in the child, whatever this process
        # (pytest, or a test before) has set; an ignored signal would be inherited
        p = subprocess.Popen([_console_script(), "check", str(tmp_path / "m.yaml")],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=defaults)
        maps = Path(f"/proc/{p.pid}/maps")
        deadline = time.time() + 60
        while time.time() < deadline and p.poll() is None:
            try:
                if "_multiarray_umath" in maps.read_text():
                    break
            except OSError:
                pass
            time.sleep(0.002)
        p.send_signal(sig)
        out, err = p.communicate(timeout=60)
        if p.returncode == 0 and not err:
            continue  # finished before the signal
        assert "Traceback" not in err, err
        assert p.returncode == code, (p.returncode, err)
        assert err.strip() == f"se3dyn: error: {word}", err
        return
    pytest.skip("the check finished before the signal five times")


def test_storage_grows_as_the_run_goes_up_to_the_rows_expected(monkeypatch):
    simmod = importlib.import_module("se3dyn.dynamics.run")
    sizes = []
    real = simmod._Recorder.results

    def spy(self, stats):
        sizes.append((self.n, len(self.t)))
        return real(self, stats)

    monkeypatch.setattr(simmod._Recorder, "results", spy)
    monkeypatch.setattr(importlib.import_module("se3dyn.dynamics.recorder"), "_INITIAL_ROWS", 16)
    r = sd.simulate(_pendulum(), t_end=1.0, step=0.01)
    assert len(r.t) == 101 and sizes[-1] == (101, 102)  # 16, 32, 64, then the 102 expected
    r = sd.simulate(_pendulum(), t_end=1.0, step=0.01, tol=1e-3, output_step=0.02)
    assert len(r.t) == 51 and sizes[-1] == (51, 51)


# ---------------------------------------------------------------------------------------------
# Issue 28, section 5: results files cut short, damaged or crafted; thread counts; sweeps;
# Python calls. One test per class of failure (each failed before its fix), the generated
# cases kept here as the corpus.
# ---------------------------------------------------------------------------------------------
#: Where results files are cut (% of their bytes): crashed disks and interrupted copies.
CUTS = (10, 25, 50, 75, 90, 95, 99, 99.5, 99.9)
#: ... and at a few bytes (inside the signature and the superblock, and just after it).
CUT_BYTES = (0, 8, 12, 40, 47, 48, 100, 2048)
#: Every command and call that reads a results file (RESULTS and MODEL substituted).
READERS = (("info", "RESULTS"), ("channels", "RESULTS"),
           ("plot", "RESULTS", "time", "-o", "OUT.png"), ("view", "RESULTS", "-o", "OUT.html"),
           ("export", "RESULTS", "--csv", "OUT.csv"), ("export", "RESULTS", "--gltf", "OUT.glb"),
           ("run", "MODEL", "--resume", "RESULTS", "--quiet"),
           ("run", "MODEL", "--resume", "RESULTS", "--t-end", "0.08", "--quiet"),
           ("read_results", "RESULTS"))

# run in a child process (a reader that hangs must not hang the test run): each reader on
# each file given, with its exit code (read_results: 2 for a Se3dynError, 3 for anything
# else), its time and its stderr; with "live", a writer's lock is held on each file
#: Seconds the child running the readers may take (a hang fails the test, not the run).
READER_TIMEOUT = 600
_READERS_CHILD = r"""
import contextlib, fcntl, io, json, os, sys, time
from se3dyn.cli.commands import main
from se3dyn.errors import Se3dynError
from se3dyn.io.h5 import read_results

readers, model, live, files = json.loads(sys.argv[1])
out = []
for path in files:
    fd = None
    if live:  # a writer holds the file (se3dyn's lock): its readers follow it by SWMR
        fd = os.open(path + ".lock", os.O_RDWR | os.O_CREAT)
        fcntl.flock(fd, fcntl.LOCK_EX)
    for cmd in readers:
        argv = [path if a == "RESULTS" else model if a == "MODEL" else
                a.replace("OUT", path) for a in cmd]
        err = io.StringIO()
        t0 = time.perf_counter()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            if argv[0] == "read_results":
                try:
                    read_results(argv[1])
                    code = 0
                except Se3dynError as exc:
                    code, _ = 2, print("se3dyn: error: " + str(exc), file=sys.stderr)
                except Exception as exc:  # noqa: BLE001
                    code, _ = 3, print(f"{type(exc).__name__}: {exc}", file=sys.stderr)
            else:
                try:
                    code = main(argv)
                except SystemExit as exc:
                    code = exc.code
                except Exception as exc:  # noqa: BLE001
                    code, _ = 3, print(f"Traceback {type(exc).__name__}: {exc}",
                                       file=sys.stderr)
        out.append([path, " ".join(cmd), code, time.perf_counter() - t0, err.getvalue()])
    if fd is not None:
        os.close(fd)
print(json.dumps(out))
"""


def _readers(files, model, live=False, timeout=READER_TIMEOUT):
    """Every reader on every file in a child process: [(path, reader, code, seconds,
    stderr)]; fails if the child does not end within ``timeout`` seconds."""
    import json

    arg = json.dumps([READERS, str(model), live, [str(f) for f in files]])
    try:
        p = subprocess.run([sys.executable, *(["-S"] if sys.flags.no_site else []), "-c",
                            _READERS_CHILD, arg], capture_output=True, text=True,
                           timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"a reader of {len(files)} files still ran after {timeout} s")
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def base_h5(tmp_path_factory):
    """A complete results file of the slider-crank (``se3dyn run EX --t-end 0.05``)."""
    d = tmp_path_factory.mktemp("base")
    code, _, err = _cli(["run", ROOT / "examples" / "slider_crank.yaml", "--t-end", "0.05",
                         "--out", d, "--quiet"])
    assert code == 0, err
    return d / "slider_crank.h5"


def _cut(src: Path, dst: Path, pct: float, flags: bool = False, nbytes: int | None = None
         ) -> Path:
    """``src`` cut to ``pct`` % of its bytes (or to ``nbytes``); ``flags``: its superblock
    marked open for writing, as a live writer's file is."""
    from se3dyn.io.h5 import _lookup3

    n = int(src.stat().st_size * pct / 100) if nbytes is None else nbytes
    data = bytearray(src.read_bytes()[:n])
    if flags:  # status flags (byte 11) and the superblock checksum (version 3, 8-byte offsets)
        data[11] = 5
        data[44:48] = _lookup3(bytes(data[:44])).to_bytes(4, "little")
    dst.write_bytes(bytes(data))
    return dst


def _assert_refused(rows, word, bound=30.0):
    """Each reader refused its file in one line naming it (exit 2), within ``bound`` s."""
    for path, reader, code, secs, err in rows:
        _assert_clean(code, err, f"{reader} on {path}")
        assert code == 2 and word in err and path in err, (reader, path, code, err)
        assert secs < bound, (reader, path, secs)


def test_truncated_results_files_are_refused_at_once_by_every_reader(base_h5, tmp_path):
    """A results file cut at 10..99.9 % (an interrupted copy, a full disk) hung every reader
    inside HDF5's metadata cache, deaf to Ctrl-C and SIGTERM (one `info` asleep after 31
    minutes): it is refused from its superblock before HDF5 reads it. Measured: 1-5 ms per
    reader (the bound asserted is 30 s, for a loaded machine)."""
    files = [_cut(base_h5, tmp_path / f"cut{pct}.h5", pct) for pct in CUTS]
    rows = _readers(files, ROOT / "examples" / "slider_crank.yaml")
    assert len(rows) == len(CUTS) * len(READERS)
    _assert_refused(rows, "is truncated")
    # cut inside the superblock (48 bytes): HDF5 refuses it itself, at once
    files = [_cut(base_h5, tmp_path / f"head{n}.h5", 0, nbytes=n) for n in CUT_BYTES]
    _assert_refused(_readers(files, ROOT / "examples" / "slider_crank.yaml"), "results file")


def _damaged_bytes(src: Path, d: Path, n: int) -> list[Path]:
    """``n`` copies of ``src`` damaged as by a failing disk (past the superblock): zeroed
    blocks of 1 to 4096 bytes, 1 to 100 flipped bits, 2 kB of garbage in the metadata."""
    rng = random.Random(SEED + 5)
    data = src.read_bytes()
    out = []
    for k in range(n):
        b = bytearray(data)
        if k % 3 == 0:
            off, m = rng.randrange(48, len(b)), rng.choice([1, 16, 512, 4096])
            b[off:off + m] = bytes(min(m, len(b) - off))
        elif k % 3 == 1:
            for _ in range(rng.choice([1, 10, 100])):
                i = rng.randrange(48, len(b))
                b[i] ^= 1 << rng.randrange(8)
        else:
            off = rng.randrange(48, 20000)
            b[off:off + 2048] = bytes(rng.randrange(256) for _ in range(2048))
        out.append(d / f"damaged{k}.h5")
        out[-1].write_bytes(bytes(b))
    return out


def test_results_files_with_damaged_bytes_are_read_or_refused_at_once(base_h5, tmp_path):
    """A failing disk: zeroed blocks, flipped bits, garbage. Each reader shows what is intact
    or refuses the file in one line, within seconds (HDF5's SWMR retries hung before).
    Measured: at most 0.5 s per reader, 126 of 216 refused."""
    rows = _readers(_damaged_bytes(base_h5, tmp_path, 24),
                    ROOT / "examples" / "slider_crank.yaml")
    for path, reader, code, secs, err in rows:
        _assert_clean(code, err, f"{reader} on {path}")
        assert code in (0, 2) and secs < 30, (reader, path, code, secs, err)
    assert any(r[2] == 2 for r in rows) and any(r[2] == 0 for r in rows)


def test_a_damaged_file_a_live_writer_holds_is_refused_in_bounded_time(base_h5, tmp_path):
    """The file of a live writer is read as a SWMR reader, which retried a metadata block
    whose checksum fails up to 100 times sleeping 1, 2, 4, ... ns (2^100 ns in all): now 30
    times, about 1 s. Measured: 1.1 s per reader."""
    files = [_cut(base_h5, tmp_path / f"live{pct}.h5", pct, flags=True)
             for pct in (CUTS[0], CUTS[-1])]
    rows = _readers(files, ROOT / "examples" / "slider_crank.yaml", live=True)
    rows = [r for r in rows if not r[1].startswith("run")]  # (refused: another writer)
    _assert_refused(rows, "damaged")


_KILLED_CHILD = r"""
import os, sys
import se3dyn as sd
from se3dyn.io.h5 import ResultsWriter
from se3dyn.io.modelfile import load_model

w = ResultsWriter(sys.argv[1], sd.compile_model(load_model(sys.argv[2])[0]))
w.flush()
os._exit(9)  # as kill -9: nothing closed, the file flagged open, the lock released
"""


def test_a_file_killed_before_its_first_rows_is_repaired_with_a_message(tmp_path):
    """kill -9 in the first second of a run, then `se3dyn info FILE`: an IndexError while
    printing the repair notice (5 of 5), the file having no rows."""
    path = tmp_path / "k.h5"
    model = ROOT / "examples" / "slider_crank.yaml"
    p = subprocess.run([sys.executable, "-c", _KILLED_CHILD, str(path), str(model)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 9, p.stderr
    code, out, err = _cli(["info", path])
    _assert_clean(code, err, "info")
    assert code == 0, err
    assert "repaired" in err and "holds no rows" in err and "rows: 0" in out, (out, err)


def test_info_on_a_file_being_written_says_so(tmp_path):
    """`se3dyn info` on a file another `se3dyn run` is still writing reported it as "cut
    short ... killed?"."""
    model = ROOT / "examples" / "a01_simple_pendulum.yaml"
    path = tmp_path / "a01_simple_pendulum.h5"
    proc = subprocess.Popen([sys.executable, "-m", "se3dyn.cli", "run", str(model), "--t-end",
                             "2000", "--step", "1e-3", "--out", str(tmp_path), "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 120
        out = ""
        while time.time() < deadline and proc.poll() is None:
            if path.exists():
                code, out, err = _cli(["info", path])
                _assert_clean(code, err, "info")
                if "so far" in out:
                    break
            time.sleep(0.2)
        assert "status: being written by a se3dyn run that is still going: t = 0 .." in out, out
        assert "killed" not in out
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
    code, out, err = _cli(["info", path])
    assert code == 0 and "status: terminated at t = " in out and "--resume" in out, out


#: Thread counts that are not one (environment, --threads, set_threads).
BAD_THREADS = ("0", "-1", "abc", "1.5", "0x10", "9" * 5000, "", " ", "\u00b2", "255",
               "2147483648", "1e3", "+3")


@pytest.mark.parametrize("value", BAD_THREADS)
def test_bad_thread_counts_in_the_environment_are_refused_in_one_line(tmp_path, monkeypatch,
                                                                      value):
    """SE3DYN_THREADS=0 (and -1, abc, 1.5, 0x10, a 5000-digit value): an uncaught error in
    `check`, and `run` left a 0-row file; with --threads given, that count is used."""
    model = ROOT / "examples" / "a01_simple_pendulum.yaml"
    monkeypatch.setenv("SE3DYN_THREADS", value)
    if value.strip() == "":  # unset or empty: the default
        return
    code, _, err = _cli(["run", model, "--t-end", "0.01", "--out", tmp_path, "--quiet"])
    _assert_clean(code, err, value)
    assert code == 2 and "SE3DYN_THREADS" in err and "from 1 to 254" in err, err
    assert not list(tmp_path.iterdir())  # no results file left
    code, out, err = _cli(["run", model, "--t-end", "0.01", "--out", tmp_path, "--quiet",
                           "--threads", "2"])
    assert code == 0, err
    assert sd.get_threads() == 2
    # (the bad value is not passed over in silence: one warning line names it)
    warned = [ln for ln in err.splitlines() if "SE3DYN_THREADS" in ln]
    assert len(warned) == 1 and "ignored: --threads 2 given" in warned[0], err


def test_bad_thread_counts_in_the_environment_of_a_fresh_process(tmp_path):
    """`se3dyn check` reads SE3DYN_THREADS when it first loads the engine (rank analysis)."""
    import os

    model = ROOT / "examples" / "a01_simple_pendulum.yaml"
    for value in BAD_THREADS[:6]:
        env = dict(os.environ, SE3DYN_THREADS=value)
        p = subprocess.run([sys.executable, "-m", "se3dyn.cli", "check", str(model)],
                           capture_output=True, text=True, timeout=120, env=env)
        _assert_clean(p.returncode, p.stderr, value[:20])
        assert p.returncode == 2 and "SE3DYN_THREADS" in p.stderr, p.stderr
        assert len(p.stderr.splitlines()) == 1 and len(p.stderr) < 300


@pytest.mark.parametrize("value", [v for v in BAD_THREADS if v.strip()])
def test_bad_thread_counts_on_the_command_line_are_usage_errors(tmp_path, value):
    code, _, err = _cli(["run", ROOT / "examples" / "a01_simple_pendulum.yaml", "--threads",
                         value, "--out", tmp_path, "--quiet"])
    _assert_clean(code, err, value[:20])
    assert code == 2 and "argument --threads: expected a whole number of threads from 1 to " \
        "254" in err, err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("value", [0, -1, 255, 2**31, 10**30, 1.5, 2.0, True, "x", None,
                                   np.int64(2**40), [2]])
def test_bad_thread_counts_in_python_are_se3dyn_errors(value):
    """set_threads(10**30): a binding TypeError."""
    before = sd.get_threads()
    if value is None:  # the environment's or the cores: valid
        sd.set_threads(value)
        sd.set_threads(before)
        return
    with pytest.raises(Se3dynError, match=r"set_threads\(n\): expected a whole number of "
                                          r"threads from 1 to 254, got"):
        sd.set_threads(value)
    assert sd.get_threads() == before


@pytest.mark.parametrize("value", [2147483648, 100_000_001, 10**30])
def test_output_every_beyond_any_run_is_refused_by_check_run_and_simulate(tmp_path, value):
    """output_every: 2147483648 passed `check` and died in `run`; simulate(output_every=
    10**30): a binding TypeError."""
    with pytest.raises(sd.ModelError, match="output_every.*at most 1e\\+08") as ei:
        sd.simulate(_pendulum(), t_end=0.02, step=0.01, output_every=value)
    assert ei.value.field == "output_every"
    text = SMALL.replace("simulation: {t_end: 1.0, step: 0.01, rho_inf: 0.9}",
                         f"simulation: {{t_end: 0.05, step: 0.01, output_every: {value}}}")
    (tmp_path / "m.yaml").write_text(text)
    for argv in (["check", tmp_path / "m.yaml"],
                 ["run", tmp_path / "m.yaml", "--out", tmp_path / "o", "--quiet"]):
        code, _, err = _cli(argv)
        _assert_clean(code, err, argv[0])
        assert code == 2 and "output_every" in err and "at most 1e+08" in err, err
    assert not (tmp_path / "o" / "m.h5").exists()
    r = sd.simulate(_pendulum(), t_end=0.05, step=0.01, output_every=100_000_000)
    assert len(r.t) == 2  # the start and the end


def _replace(f, name, data):
    del f[name]
    f[name] = data


#: Crafted or damaged results files: (name, change of the h5py.File, what the readers say).
#: "damaged": every reader refuses the file in one line; "motion": view and export --gltf
#: refuse it naming the field, the other readers show what it holds.
CRAFTED = [
    ("composites_not_json", lambda f: f["layout"].attrs.__setitem__("composites", "{not"),
     "damaged"),
    ("nq_text", lambda f: f["layout"].attrs.__setitem__("nq", "x"), "damaged"),
    ("nq_huge", lambda f: f["layout"].attrs.__setitem__("nq", 10**12), "damaged"),
    ("nq_negative", lambda f: f["layout"].attrs.__setitem__("nq", -5), "damaged"),
    ("nm_wrong", lambda f: f["layout"].attrs.__setitem__("nm", 7), "damaged"),
    ("node_fixed_longer", lambda f: _replace(f, "layout/node_fixed", np.zeros(12, np.int8)),
     "damaged"),
    ("node_fixed_two", lambda f: _replace(f, "layout/node_fixed", np.full(9, 2, np.int8)),
     "damaged"),
    ("node_dofadr_out", lambda f: _replace(f, "layout/node_dofadr",
                                           np.full(9, 10**9, np.int64)), "damaged"),
    ("joint_k_negative", lambda f: _replace(f, "layout/joint_k", -np.ones(8, np.int64)),
     "damaged"),
    ("joint_columns_out", lambda f: _replace(f, "layout/joint_columns",
                                             np.full(8, 7, np.int64)), "damaged"),
    ("node_names_numbers", lambda f: _replace(f, "layout/node_names", np.arange(9)),
     "damaged"),
    ("no_layout", lambda f: f.__delitem__("layout"), "damaged"),
    ("time_group", lambda f: (f.__delitem__("time"), f.create_group("time")), "damaged"),
    ("time_text", lambda f: _replace(f, "time", np.array([b"a"] * 6)), "damaged"),
    ("position_shape", lambda f: _replace(f, "nodes/position", np.zeros((6, 2, 3))),
     "damaged"),
    ("no_multipliers", lambda f: f.__delitem__("joints/multipliers"), "damaged"),
    ("no_stats", lambda f: f.__delitem__("stats"), "damaged"),
    ("format_version_text", lambda f: f.attrs.__setitem__("format_version", "x"),
     "format_version"),
    ("nan_rotation", lambda f: f["nodes/rotation"].__setitem__((2, 3), np.nan), "rotation"),
    ("zero_rotation", lambda f: f["nodes/rotation"].__setitem__((2, 3), 0.0), "rotation"),
    ("mirrored_rotation", lambda f: f["nodes/rotation"].__setitem__((2, 3), -np.eye(3)),
     "rotation"),
    ("nan_time", lambda f: f["time"].__setitem__(3, np.nan), "'t'"),
    ("time_backwards", lambda f: f["time"].__setitem__(3, -1.0), "'t'"),
    ("inf_position", lambda f: f["nodes/position"].__setitem__((1, 2), np.inf), "position"),
    ("settings_list", lambda f: f.attrs.__setitem__("settings", "[1, 2]"), None),
    ("settings_wrong", lambda f: f.attrs.__setitem__("settings", '{"t_end": "x"}'), None),
]


def test_crafted_and_damaged_results_files_get_one_line_errors(base_h5, tmp_path):
    """A wrong layout attribute, a longer node_fixed, nq = 10**12 (a 43.7 TiB allocation),
    /time as a group, /stats deleted before --resume, NaN or zero rotations or a NaN time in
    view / export --gltf (a JSON ValueError, a LinAlgError): one-line errors, never a
    traceback."""
    import h5py

    files = []
    for name, change, _ in CRAFTED:
        p = tmp_path / f"{name}.h5"
        shutil.copy(base_h5, p)
        with h5py.File(p, "r+") as f:
            change(f)
        files.append(p)
    rows = _readers(files, ROOT / "examples" / "slider_crank.yaml")
    expect = {str(p): (name, word) for p, (name, _, word) in zip(files, CRAFTED, strict=True)}
    for path, reader, code, secs, err in rows:
        _assert_clean(code, err, f"{reader} on {path}")
        name, word = expect[path]
        if word in ("damaged", "format_version"):
            if name == "no_stats" and reader == "run MODEL --resume RESULTS --quiet":
                assert code == 0  # (complete: nothing to continue, nothing read)
            else:
                assert code == 2 and word in err, (reader, path, err)
        elif word is not None and reader.startswith(("view", "export RESULTS --gltf")):
            assert code == 2 and word in err and "expected" in err, (reader, path, err)
        assert secs < 30, (reader, path, secs)


@pytest.mark.parametrize("com", [(1e15, 0, 0), (1e15, 1e15, 1e15), (-1e15, 1e15, 0),
                                 (0, 0, 1e15), (1e6, 0, 0), (0, 2e4, 0)])
def test_a_centre_of_mass_beyond_the_digits_of_the_inertia_is_refused(com, tmp_path):
    """com at its documented bound (1e15): a LinAlgError from the condensation of the rigid
    joints (a unit multiplier lost against gravity moments of 1e16 N m), and `check` said
    the node "can move with no mass" (its inertia about the centre of mass lost in the
    round-off of m |c|^2)."""
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("g", fixed=True)
    with pytest.raises(sd.ModelError, match=r"within .* m of the node") as ei:
        mb.node("a", com=com, mass=1.0, inertia=(0.01, 0.02, 0.02))
    assert ei.value.item == "node 'a'" and ei.value.field == "com"
    text = SMALL.replace("a: {position: [0.5, 0.0, 0.0], mass: 1.0,",
                         f"a: {{position: [0.5, 0.0, 0.0], com: {list(com)}, mass: 1.0,")
    (tmp_path / "m.yaml").write_text(text)
    code, _, err = _cli(["check", tmp_path / "m.yaml"])
    _assert_clean(code, err, "check")
    assert code == 2 and "'com'" in err and "no mass" not in err, err


def test_a_far_centre_of_mass_within_the_range_condenses_and_checks(tmp_path):
    """The largest offset accepted (1e4 m for m = 1, J = 0.01): the condensed run and the
    full one agree, and `check` finds no motion without mass."""
    from se3dyn.engine.rank import massless_motions

    for c in (1e4, 1e4 * (1 - 1e-12)):
        mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
        mb.node("g", fixed=True)
        mb.node("a", com=(c, 0, 0), mass=1.0, inertia=(0.01, 0.02, 0.02))
        mb.node("b", position=(0.5, 0, 0), mass=1.0, inertia=(0.01, 0.02, 0.02))
        mb.joint("h", "hinge", "g", "a", axis=(0, 1, 0))
        mb.joint("r", "rigid", "a", "b")
        m = mb.build()
        assert massless_motions(sd.compile_model(m)) == []
        a = sd.simulate(m, 0.05, 0.01)
        b = sd.simulate(m, 0.05, 0.01, condense=False)
        np.testing.assert_allclose(a.joint_coordinates("h"), b.joint_coordinates("h"),
                                   rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(a.joint_multipliers("r"), b.joint_multipliers("r"),
                                   rtol=1e-6, atol=1e-6 * np.abs(b.joint_multipliers("r")).max())


def test_condensation_of_bodies_with_large_forces_does_not_fail():
    """The rigid joints' multipliers are recovered from residual differences: with gravity
    moments of 1e18 N m a unit multiplier vanished in them (LinAlgError: Singular matrix).
    The condensed run moves as the full one."""
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("g", fixed=True)
    mb.node("a", mass=1e12, inertia=(1e12, 1e12, 1e12), com=(9e4, 0, 0))
    mb.node("b", position=(0.5, 0, 0), mass=1e12, inertia=(1e12, 1e12, 1e12), com=(9e4, 0, 0))
    mb.joint("h", "spherical", "g", "a")
    mb.joint("r", "rigid", "a", "b")
    m = mb.build()
    a = sd.simulate(m, 0.02, 0.01)
    b = sd.simulate(m, 0.02, 0.01, condense=False)
    assert a.stats.get("condensed")
    assert np.all(np.isfinite(a.joint_multipliers("r")))
    np.testing.assert_allclose(a.node_position("b"), b.node_position("b"), rtol=0, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# sweeps
SWEEP_EX = ROOT / "examples" / "slider_crank.yaml"
#: Sweep command lines refused before anything is allocated or any run starts (flags only).
SWEEP_FLAGS = [
    (["--vary", "simulation.step=0.01:0.02:99999999999"], "N from 1 to 1e+06"),
    (["--vary", "simulation.step=0.01:0.02:1000001"], "N from 1 to 1e+06"),
    (["--vary", "simulation.step=uniform(0.01,0.02)", "--method", "random", "--samples",
      "99999999999"], "(at most 1e+06)"),
    (["--vary", "simulation.step=uniform(0.01,0.02)", "--method", "lhs", "--samples",
      "1000001"], "(at most 1e+06)"),
    ([a for i in (2, 3, 4, 5, 6, 7, 8) for k in (0, 1, 2)
      for a in ("--vary", f"nodes.{i}.position.{k}=0.1,0.2,0.3")], "at most 1e+06 runs"),
    (["--vary", "simulation.step=0.01:0.02:1000", "--vary", "simulation.t_end=1:2:1001"],
     "at most 1e+06 runs"),
    (["--vary", "simulation.step=uniform(0.01,0.02)", "--method", "random", "--samples", "3",
      "--seed", "-1"], "seed"),
    (["--vary", "simulation.step=0.01,0.02", "--seed", "-5"], "seed"),
    (["--vary", "simulation.step=0.01,0.02", "--scheduler", "notaurl"], "--scheduler"),
    (["--vary", "simulation.step=0.01,0.02", "--scheduler", "tcp://"], "--scheduler"),
    (["--vary", "simulation.step=0.01,0.02", "--scheduler", "host:port"], "--scheduler"),
    (["--vary", "simulation.step=0.01,0.02", "--scheduler", ""], "--scheduler"),
    (["--vary", "simulation.step=0.01,0.02", "--retry-failed"], "retry_failed"),
]


@pytest.mark.parametrize("flags, word", SWEEP_FLAGS)
def test_sweep_flags_are_refused_in_one_line_before_anything_is_made(tmp_path, flags, word):
    """--vary simulation.step=0.01:0.02:99999999999 and --samples 99999999999 allocated
    hundreds of GiB (MemoryError); a 30-path grid filled 8 GiB in 30 s; --seed -1 and
    --scheduler notaurl passed through to numpy and dask errors."""
    t0 = time.perf_counter()
    code, _, err = _cli(["sweep", SWEEP_EX, *flags, "--out", tmp_path / "sw", "--t-end",
                         "0.02", "--quiet"])
    _assert_clean(code, err, " ".join(flags)[:80])
    assert code == 2 and word in err, err
    assert not (tmp_path / "sw").exists()  # nothing written: the same --out works afterwards
    assert time.perf_counter() - t0 < 30


def _sweep_calls():
    """Hostile Python calls of se3dyn.sweep, each (description, call): all refused before any
    cluster starts."""
    ex, v = str(SWEEP_EX), {"simulation.step": "0.01,0.02"}
    kw = dict(overrides={"t_end": 0.02}, workers=1)
    calls = [("sweep(None)", lambda: sd.sweep(None, v)),
             ("sweep(5)", lambda: sd.sweep(5, v)),
             ("sweep(ex, None)", lambda: sd.sweep(ex, None)),
             ("sweep(ex, 5)", lambda: sd.sweep(ex, 5))]
    for name, bad in (("out", 5), ("out", 1.5), ("out", ["x"]), ("client", "x"),
                      ("client", 5), ("as_frame", "x"), ("as_frame", 1), ("progress", "x"),
                      ("progress", 0), ("resume", "yes"), ("resume", 1),
                      ("retry_failed", "x"), ("log", "x"), ("log", 5), ("metrics", 5),
                      ("metrics", None), ("overrides", "x"), ("overrides", [1]),
                      ("workers", 0), ("workers", True), ("workers", 1.5),
                      ("scheduler", 5), ("scheduler", "notaurl"), ("h5", 5), ("method", 5),
                      ("seed", -1), ("seed", 1.5), ("seed", "x"), ("samples", 10**11)):
        args = dict(kw, **{name: bad})
        if name in ("seed", "samples"):
            args.update(method="random", samples=args.get("samples", 2))
            vv = {"simulation.step": "uniform(0.01,0.02)"}
        else:
            vv = v
        calls.append((f"sweep(ex, vary, {name}={bad!r})",
                      lambda args=args, vv=vv: sd.sweep(ex, vv, **args)))
    calls += [("sweep(ex, vary, resume=True) without out",
               lambda: sd.sweep(ex, v, resume=True, **kw)),
              ("sweep(ex, vary, retry_failed=True) without resume",
               lambda: sd.sweep(ex, v, out="x", retry_failed=True, **kw)),
              ("sweep(ex, {step: 0:1:10**11})",
               lambda: sd.sweep(ex, {"simulation.step": "0.01:0.02:100000000000"}, **kw))]
    return calls


def test_sweep_calls_raise_se3dyn_errors_before_any_run(monkeypatch):
    """sd.sweep(None), sweep(out=5), sweep(client='x'): raw exceptions; sweep(as_frame='x')
    claimed pandas was missing; sweep(progress='x') and sweep(out=None, resume=True) were
    accepted."""
    import se3dyn.sweep.runner as runner

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(runner, "_client", no_cluster)
    for what, call in _sweep_calls():
        try:
            call()
        except Se3dynError:
            continue
        except Exception as exc:  # noqa: BLE001
            pytest.fail(f"{what}: {type(exc).__name__}: {exc}")
        pytest.fail(f"{what}: accepted")


def test_a_sweep_leaves_no_scratch_folder_in_tmp(tmp_path, monkeypatch):
    """An empty dask-scratch-space/ was left in $TMPDIR by every local sweep."""
    import tempfile

    pytest.importorskip("distributed")
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    monkeypatch.setenv("TMPDIR", str(tmp))
    rows = sd.sweep(str(SWEEP_EX), {"simulation.step": "0.01,0.02"}, workers=1,
                    overrides={"t_end": 0.02}, out=tmp_path / "sw", as_frame=False,
                    progress=False)
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert list(tmp.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# Python calls (the sweep's above)
def _python_calls(tmp: Path):
    """Hostile calls of the public API outside the model builder, each (description, call):
    every one must raise a Se3dynError (a KeyError or ValueError too where it was one)."""
    from se3dyn import viewer
    from se3dyn.io.h5 import read_results
    from se3dyn.results.channels import get_channel

    model = _pendulum()
    res = sd.simulate(model, t_end=0.02, step=0.01)
    calls = []
    for arg in (None, 5, 1.5, b"x", ["a.h5"], object()):
        calls.append((f"read_results({arg!r})", lambda a=arg: read_results(a)))
        calls.append((f"save_model({arg!r})", lambda a=arg: save_model(a)))
        calls.append((f"write_html({arg!r}, path)",
                      lambda a=arg: viewer.write_html(a, tmp / "x.html")))
        calls.append((f"export_gltf({arg!r}, path)",
                      lambda a=arg: viewer.export_gltf(a, tmp / "x.glb")))
        calls.append((f"html_page({arg!r})", lambda a=arg: viewer.html_page(a)))
        if arg is not None:
            calls.append((f"write_html(res, {arg!r})",
                          lambda a=arg: viewer.write_html(res, a)))
            calls.append((f"export_gltf(res, {arg!r})",
                          lambda a=arg: viewer.export_gltf(res, a)))
    calls.append(("write_html(res, None)", lambda: viewer.write_html(res, None)))
    for name in ("ghost", None, 5, ""):
        calls.append((f"Model.node({name!r})", lambda n=name: model.node(n)))
        calls.append((f"Model.joint({name!r})", lambda n=name: model.joint(n)))
        calls.append((f"get_channel(res, {name!r})", lambda n=name: get_channel(res, n)))
    for args in (("x",), ("x", 1.0), (1.0, "x"), (-1.0,), (1.0, -2.0), ([1.0, "x"],),
                 (float("nan"),), (1.0, 0.0, "y"), (1.0, 0.0, 0.0, 5j), ([[1.0, 2.0]],)):
        calls.append((f"PD(*{args!r})", lambda a=args: sd.PD(*a)))
    for args in ((5,), ("x",), (None,), (lambda t: t, -1.0), (lambda t: t, "x"),
                 (lambda t: t, float("nan"))):
        calls.append((f"Callable(*{args!r})", lambda a=args: sd.Callable(*a)))
    drivers = {"h": sd.Ramp(1.0, duration=1.0)}
    calls.append(("kinematics(10**7 output times)",  # (80 MB of times; rows of 8 GB)
                  lambda: sd.kinematics(model, drivers, np.linspace(0.0, 1.0, 10**7))))
    for steps in (10**9, 10**30, 0, -1, 1.5, True):
        calls.append((f"static_equilibrium(load_steps={steps!r})",
                      lambda n=steps: sd.static_equilibrium(model, load_steps=n)))
    return calls


def test_python_calls_raise_se3dyn_errors(tmp_path, monkeypatch):
    """read_results(None), save_model(None), write_html(None), kinematics with 10^7 output
    times, Model.node('ghost') and get_channel(res, 'nope') as bare KeyErrors; PD('x') and
    Callable(5) accepted; static_equilibrium(load_steps=10**9) ran on without end."""
    simmod = importlib.import_module("se3dyn.dynamics.settings")
    monkeypatch.setattr(simmod, "_available_memory", lambda: 2.0**30)  # (1 GiB, as measured)
    calls = _python_calls(tmp_path)
    for what, call in calls:
        t0 = time.perf_counter()
        try:
            call()
        except Se3dynError as exc:
            assert "\n" not in str(exc), what
            assert time.perf_counter() - t0 < 30, what
            continue
        except Exception as exc:  # noqa: BLE001
            pytest.fail(f"{what}: {type(exc).__name__}: {exc}")
        pytest.fail(f"{what}: accepted")


def test_unknown_names_are_still_key_errors():
    model = _pendulum()
    with pytest.raises(KeyError, match="unknown node 'ghost'"):
        model.node("ghost")
    from se3dyn.results.channels import get_channel

    with pytest.raises(KeyError, match="unknown channel 'nope'"):
        get_channel(sd.simulate(model, t_end=0.02, step=0.01), "nope")


DAMPED = """\
se3dyn: 1
name: damped
gravity: [0.0, -9.81, 0.0]
nodes:
  ground: {position: [0.0, 0.0, 0.0], fixed: true}
  bob: {position: [1.0, 0.0, 0.0], mass: 1000.0, inertia: [1.0, 1.0, 1.0]}
joints:
  O: {type: hinge, a: ground, b: bob, at: [0.0, 0.0, 0.0], axis: [0.0, 0.0, 1.0],
      damping: 20000.0}
simulation: {t_end: 20.0, step: 1.0e-2, rho_inf: 0.9}
"""


def test_a_resumed_run_reports_the_energy_balance_of_the_whole_run(tmp_path):
    """A resumed run's summary measured the energy balance from the row it resumed at: a
    damped pendulum at rest by then has next to no energy in play, and an exact run read
    "energy balance error 1.153e-11 J (100 % of the energy in play) WARNING: large"."""
    (tmp_path / "damped.yaml").write_text(DAMPED)
    model = tmp_path / "damped.yaml"

    def energy(out):
        return [ln.strip() for ln in out.splitlines() if "energy balance error" in ln]

    code, _, err = _cli(["run", model, "--out", tmp_path / "a", "--quiet"])
    assert code == 0, err
    # (not --quiet: the summaries are read)
    code, out, err = _cli(["run", model, "--resume", tmp_path / "a" / "damped.h5", "--t-end",
                           "40"])
    assert code == 0, err
    resumed = energy(out)
    code, out, err = _cli(["run", model, "--t-end", "40", "--out", tmp_path / "b"])
    assert code == 0, err
    whole = energy(out)
    assert len(whole) == 1 and resumed == whole and "WARNING" not in whole[0], (resumed, whole)
    code, out, _ = _cli(["info", tmp_path / "a" / "damped.h5"])
    assert energy(out) == whole


# ---------------------------------------------------------------------------------------------
# A second generated file corpus: the element sections added since the first (beams,
# bushings), with springs, loads and visuals; every file is checked and run, the results of a
# sample viewed and exported, and every 7th run resumed.
ELEMENTS = """\
se3dyn: 1
name: elements
gravity: [0.0, 0.0, -9.81]
nodes:
  g: {position: [0.0, 0.0, 0.0], fixed: true}
  a: {position: [0.5, 0.0, 0.0], mass: 1.0, inertia: [0.01, 0.02, 0.02]}
  e: {position: [0.0, 0.0, 0.3], mass: 2.0, inertia: [0.1, 0.1, 0.1]}
  t: {position: [1.5, 0.0, 0.0]}
joints:
  h: {type: hinge, a: g, b: a, at: [0.0, 0.0, 0.0], axis: [0.0, 1.0, 0.0], damping: 0.01}
beams:
  bar: {a: a, b: t, elements: 2, EA: 1.0e6, GA: 4.0e5, GJ: 50.0, EI: 80.0,
        mass_per_length: 0.5, rotary_inertia: [1.0e-4, 5.0e-5, 5.0e-5], damping: 1.0e-4}
bushings:
  mount: {a: g, b: e, at: [0.0, 0.0, 0.3], stiffness: [2.0e4, 2.0e4, 3.0e4, 100, 100, 100],
          damping: [20, 20, 30, 0.1, 0.1, 0.1]}
springs:
  sp: {a: g, b: a, at_a: [0.0, 0.5, 0.0], at_b: [0.5, 0.0, 0.0], stiffness: 2.0,
       damping: 0.1}
loads:
  push: {node: e, force: [0.0, 1.0, 0.0], at: [0.0, 0.0, 0.3], force_frame: body}
visuals:
  rod: {node: a, shape: cylinder, size: [0.01, 0.5], axis: [1, 0, 0]}
  box: {node: e, shape: box, size: [0.2, 0.1, 0.1], color: orange}
simulation: {t_end: 0.05, step: 0.01, rho_inf: 0.9}
"""

BASES2 = [("elements", ELEMENTS)] + [
    (p.stem, p.read_text(encoding="utf-8"))
    for p in (ROOT / "examples" / "slider_crank_flexible.yaml",
              ROOT / "examples" / "a03_andrews_squeezer.yaml")]
N_FILES2 = 450


def corpus2(n: int) -> list[tuple[str, str, str]]:
    rng = random.Random(SEED + 28)
    return [(f"{k:04d}-{base}-{kind}", kind, mutated) for k in range(n)
            for base, text in [BASES2[k % len(BASES2)]] for kind, mutated in [_mutate(rng, text)]]


def test_second_corpus_check_run_view_export_resume(tmp_path):
    """The commands on the second corpus: check, run (--threads 1 on every 5th file), and on
    the results of every 10th run that succeeded: info, channels, view, export --csv and
    --gltf, run --resume --t-end 0.06; all exit 0, 1 or 2 with one line and no traceback."""
    pytest.importorskip("pygltflib")
    fs = corpus2(N_FILES2)
    assert len(fs) == N_FILES2 and len({k for _, k, _ in fs}) >= 15
    codes = {0: 0, 1: 0, 2: 0}
    commands = ran = 0
    for i, (name, _kind, text) in enumerate(fs):
        p = tmp_path / f"{name}.yaml"
        p.write_bytes(text.encode("utf-8", "surrogatepass"))
        code, _, err = _cli(["check", p])
        _assert_clean(code, err, f"check {name}")
        codes[code] += 1
        commands += 1
        if code != 0:
            continue
        out = tmp_path / "out" / name
        argv = ["run", p, "--t-end", "0.05", "--quiet", "--out", out] + (
            ["--threads", "1"] if i % 5 == 0 else [])
        code, _, err = _cli(argv)
        _assert_clean(code, err, f"run {name}")
        codes[code] += 1
        commands += 1
        h5 = out / f"{name}.h5"
        if code == 2 or not h5.exists():
            continue
        ran += 1
        if ran % 10:
            continue
        for cmd in (["info", h5], ["channels", h5], ["view", h5, "-o", out / "v.html"],
                    ["export", h5, "--csv", out / "c.csv"],
                    ["export", h5, "--gltf", out / "g.glb"],
                    ["run", p, "--resume", h5, "--t-end", "0.06", "--quiet"]):
            code, _, err = _cli(cmd)
            _assert_clean(code, err, f"{cmd[0]} {name}")
            commands += 1
    assert codes[0] > 0 and codes[2] > 0 and ran >= 50, (codes, ran)
    assert commands >= N_FILES2 + ran + 6 * (ran // 10), commands


def test_second_corpus_bases_are_valid(tmp_path):
    for name, text in BASES2:
        (tmp_path / f"{name}.yaml").write_text(text)
        code, _, err = _cli(["run", tmp_path / f"{name}.yaml", "--t-end", "0.02", "--out",
                             tmp_path, "--quiet"])
        assert code == 0, (name, err)
