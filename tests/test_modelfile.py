"""YAML model files (se3dyn.io.modelfile): equivalence with the Python models, round trips, the
generated schema and reference, and clean errors for malformed files."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import se3dyn as sd
from se3dyn.io.modelfile import (
    ModelFileError,
    json_schema,
    load_model,
    loads_model,
    markdown_reference,
    save_model,
)

ROOT = Path(__file__).resolve().parents[1]
SLIDER_YAML = ROOT / "examples" / "slider_crank.yaml"
SCHEMA_FILE = ROOT / "docs" / "model-file.schema.json"
DOC_FILE = ROOT / "docs" / "model-file.md"

TIMES = (-1.0, 0.0, 0.1, 0.5, 1.0, 1.25, 1.999, 2.0, 2.5, 3.7, 10.0)


# -------------------------------------------------------------------------------------------------
# model comparison: every field, numpy equality; time functions by value (and rate) at many times
# -------------------------------------------------------------------------------------------------
def _eq(a, b, what):
    if a is None or b is None:
        assert a is None and b is None, what
        return
    np.testing.assert_array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                                  err_msg=what)


def _tf_eq(f, g, what):
    if f is None or g is None:
        assert f is None and g is None, what
        return
    for t in TIMES:
        _eq(f(t), g(t), f"{what} at t={t}")
        if not isinstance(f, sd.Callable):
            _eq(f.rate(t), g.rate(t), f"{what}.rate at t={t}")


def assert_models_equal(m1: sd.Model, m2: sd.Model):
    assert m1.name == m2.name
    _eq(m1.gravity, m2.gravity, "gravity")
    assert m1.composites == m2.composites
    assert [n.name for n in m1.nodes] == [n.name for n in m2.nodes]
    for a, b in zip(m1.nodes, m2.nodes, strict=True):
        for f in ("position", "orientation", "mass", "velocity"):
            _eq(getattr(a, f), getattr(b, f), f"node {a.name} {f}")
        # ModelBuilder keeps R J' R^T from principal axes unsymmetrised (asymmetric in the last
        # bit) but symmetrises a full tensor, so a file (full tensor) gives the symmetric part,
        # bit for bit: 0.5 (J + J^T).
        _eq(0.5 * (a.inertia + a.inertia.T), b.inertia, f"node {a.name} inertia")
        np.testing.assert_allclose(a.inertia, b.inertia, rtol=0,
                                   atol=2e-16 * np.abs(a.inertia).max(initial=0.0))
        assert a.fixed == b.fixed
    assert [j.name for j in m1.joints] == [j.name for j in m2.joints]
    for a, b in zip(m1.joints, m2.joints, strict=True):
        w = f"joint {a.name}"
        assert (a.type, a.node_a, a.node_b, a.composite) == (b.type, b.node_a, b.node_b,
                                                             b.composite), w
        assert set(a.params) == set(b.params), w
        for k in a.params:
            _eq(a.params[k], b.params[k], f"{w} param {k}")
        for f in ("A", "stiffness", "reference", "damping", "at"):
            _eq(getattr(a, f), getattr(b, f), f"{w} {f}")
        _tf_eq(a.actuator, b.actuator, f"{w} actuator")
        assert (a.control is None) == (b.control is None), w
        if a.control is not None:
            _eq(a.control.kp, b.control.kp, f"{w} kp")
            _eq(a.control.kd, b.control.kd, f"{w} kd")
            _tf_eq(a.control.target, b.control.target, f"{w} target")
            _tf_eq(a.control.target_rate, b.control.target_rate, f"{w} target_rate")
    assert [ld.name for ld in m1.loads] == [ld.name for ld in m2.loads]
    for a, b in zip(m1.loads, m2.loads, strict=True):
        assert a.node == b.node
        _tf_eq(a.force, b.force, f"load {a.name} force")
        _tf_eq(a.torque, b.torque, f"load {a.name} torque")
        _eq(a.at, b.at, f"load {a.name} at")
        assert (a.force_frame, a.torque_frame) == (b.force_frame, b.torque_frame), a.name
    for kind in ("springs", "bushings"):
        assert [e.name for e in getattr(m1, kind)] == [e.name for e in getattr(m2, kind)]
        for a, b in zip(getattr(m1, kind), getattr(m2, kind), strict=True):
            assert (a.node_a, a.node_b) == (b.node_a, b.node_b), f"{kind} {a.name}"
            fields = (("at_a", "at_b", "stiffness", "damping", "length") if kind == "springs"
                      else ("at", "stiffness", "damping", "orientation", "deformation"))
            for f in fields:
                _eq(getattr(a, f), getattr(b, f), f"{kind} {a.name} {f}")


def _rot(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def everything_model() -> sd.Model:
    """Every joint type, springs, dampers, every built-in time function, PD control, loads,
    orientations, principal axes, full tensors, initial velocities and attachment points."""
    mb = sd.ModelBuilder(gravity=(0.1, -0.2, -9.81), name="everything")
    mb.node("ground", position=(0, 0, 0), fixed=True)
    R = _rot((1, 2, 3), 0.7)
    for i in range(1, 10):
        mb.node(f"b{i}", position=(0.1 * i, 0.2, -0.3 * i), mass=0.5 + i,
                inertia=(1e-2 * i, 2e-2, 1e-2 * i + 1e-2))  # J3 <= J1 + J2
    mb.node("oriented", position=(1, 1, 1), orientation=R, mass=2.0, inertia=(1.0, 2.0, 3.0),
            principal_axes=_rot((0, 1, 1), 0.3), velocity=(1, 2, 3), angular_velocity=(0.1, 0, 0),
            velocity_frame="material")
    mb.node("tensor", position=(-1, 0.5, 2), mass=1.5,
            inertia=[[2.0, 0.1, 0.0], [0.1, 3.0, 0.2], [0.0, 0.2, 4.0]],
            velocity=(0, 0, -1), angular_velocity=(0.3, 0.2, 0.1))
    mb.node("massless", position=(0.5, 0.5, 0.5))
    mb.node("arm", position=(1.2, 1.0, 1.4), mass=0.3, inertia=(1e-3, 1e-3, 1e-3))
    mb.joint("rigid", "rigid", "ground", "b1")
    mb.joint("hinge", "hinge", "ground", "b2", axis=(0, 0, 1), stiffness=2.5, reference=0.1,
             damping=0.3, torque=sd.Ramp(1.5, start=0.5, duration=2.0))
    mb.joint("prismatic", "prismatic", "ground", "b3", axis=(0.6, 0.8, 0.0),
             force=sd.Table([0, 1, 2.5], [0.0, 2.0, -1.0]),
             control=sd.PD(kp=10.0, kd=1.0, target=sd.Sine(0.2, 0.5, phase=0.3, offset=0.1)))
    mb.joint("cylindrical", "cylindrical", "ground", "b4", axis=(0, 1, 0), stiffness=(1.0, 2.0),
             actuator=sd.Step([1.0, 2.0], 0.5, 1.5),
             control=sd.PD(kp=(1, 2), kd=(0.1, 0.2),
                           target=sd.Table([0, 1, 2], [[0, 0], [1, 0.5], [1, 1]]),
                           target_rate=sd.Constant([0.0, 0.0])))
    mb.joint("spherical", "spherical", "ground", "b5", axes=R.T, damping=0.3,
             actuator=sd.Constant([0.0, 0.0, 1.0]))
    mb.joint("planar", "planar", "ground", "b6", normal=(0, 0, 1), axes=[(1, 0, 0), (0, 1, 0)],
             stiffness=5.0)
    mb.joint("planar2", "planar", "b6", "tensor", normal=(0, 1, 0))
    mb.joint("screw", "screw", "ground", "b7", axis=(1, 0, 0), pitch=0.01, actuator=0.5)
    A = np.zeros((6, 2))
    A[2, 0] = 1.0
    A[5, 1] = 1.0
    mb.joint("general", "general", "ground", "b8", A=A, damping=(0.5, 0.0),
             control=sd.PD(kp=(3.0, 4.0), target=(0.1, 0.2)))
    mb.joint("general1", "general", "b8", "massless", A=[0, 0, 0, 1, 0, 0])
    mb.joint("cardan", "universal", "ground", "b9", axes=[(1, 0, 0), (0, 1, 0)],
             stiffness=(1.0, 2.0), damping=0.1, torque=sd.Sine([1.0, 2.0], 1.0),
             control=sd.PD(kp=(3.0, 4.0), kd=0.5, target=sd.Step([0.1, 0.2], 0.0, 1.0)),
             at=(0.85, 0.2, -2.5))
    mb.joint("weld", "rigid", "b9", "oriented", at=(1.0, 0.5, 0.0))
    mb.joint("offset_hinge", "hinge", "oriented", "arm", axis=(0, 0, 1), at=(1.1, 1.0, 1.2),
             damping=0.2)
    mb.load("push", "b2", force=sd.Sine([0.0, 0.0, 1.0], 2.0, offset=[1.0, 0.0, 0.0]),
            torque=sd.Ramp([0.0, 0.1, 0.0], duration=0.5))
    mb.load("constant", "b3", force=(0.0, 0.0, 1.0))
    mb.load("stepper", "tensor", torque=sd.Step([1.0, 0.0, 0.0], start=1.0))
    mb.spring_damper("spring", "ground", "tensor", at_a=(0.1, 0.2, 0.3), stiffness=3.0,
                     damping=0.1, length=0.5)
    K = np.array([[4.0, 0.5, 0, 0, 0.1, 0], [0.5, 3.0, 0, 0, 0, 0], [0, 0, 2.0, 0, 0, 0],
                  [0, 0, 0, 1.0, 0, 0], [0.1, 0, 0, 0, 1.5, 0], [0, 0, 0, 0, 0, 0.5]])
    mb.bushing("mount", "ground", "tensor", at=(-1.0, 0.4, 1.9), stiffness=K,
               damping=(0.1, 0.2, 0.3, 0.01, 0.02, 0.03))
    mb.bushing("diag", "b5", "arm", stiffness=(1, 2, 3, 4, 5, 6), orientation=R,
               deformation=(0.01, 0.0, -0.02, 0.1, 0.2, 0.0))
    mb.collision("floor", "ground", "plane", at=(0, 0, -3.0), normal=(0.1, 0, 1),
                 material=sd.ContactMaterial(stiffness=1e7, restitution=0.3, friction=0.8))
    mb.collision("knob", "tensor", "sphere", size=0.05, at=(0.1, 0.2, 0.3),
                 material=sd.ContactMaterial(young=2e11, poisson=0.28, stiction_length=1e-4),
                 exclude=("arm",))
    mb.collision("rod", "tensor", "capsule", size=0.02, length=0.3, axis=(0, 1, 1))
    return mb.build()


# -------------------------------------------------------------------------------------------------
# 1. the paper's slider-crank from YAML equals the Python example
# -------------------------------------------------------------------------------------------------
def test_slider_crank_yaml_equals_python_model():
    model, cfg = load_model(SLIDER_YAML)
    assert_models_equal(model, sd.examples.slider_crank())
    assert cfg == sd.examples.SLIDER_CRANK_SETTINGS
    axis = np.asarray(model.joint("7").params["axis"], dtype=float)
    assert abs(np.linalg.norm(axis) - 1.0) <= 1e-15


def test_slider_crank_yaml_simulates_identically():
    ref = sd.simulate(sd.examples.slider_crank(), t_end=0.5, step=1e-2)
    res = sd.simulate(load_model(SLIDER_YAML)[0], t_end=0.5, step=1e-2)
    np.testing.assert_allclose(res.t, ref.t, rtol=0, atol=0)
    np.testing.assert_allclose(res.H[:, :, :3, 3], ref.H[:, :, :3, 3], rtol=0, atol=1e-12)


def test_load_accepts_path_str_text_and_bytes(tmp_path):
    text = SLIDER_YAML.read_text(encoding="utf-8")
    for src in (str(SLIDER_YAML), SLIDER_YAML, text, text.encode("utf-8")):
        model, cfg = load_model(src)
        assert model.name == "slider_crank" and cfg["t_end"] == 5.0


# -------------------------------------------------------------------------------------------------
# 2. round trips
# -------------------------------------------------------------------------------------------------
def test_round_trip_examples_model(tmp_path):
    m = sd.examples.slider_crank()
    p = tmp_path / "sc.yaml"
    text = save_model(m, p, settings=sd.examples.SLIDER_CRANK_SETTINGS)
    assert p.read_text(encoding="utf-8") == text
    m2, cfg = load_model(p)
    assert_models_equal(m, m2)
    assert cfg == sd.examples.SLIDER_CRANK_SETTINGS


def test_round_trip_every_feature():
    m = everything_model()
    text = save_model(m, settings={"t_end": 1.0, "step": 1e-3, "max_iter": 30})
    m2, cfg = loads_model(text)
    assert_models_equal(m, m2)
    assert cfg == {"t_end": 1.0, "step": 1e-3, "max_iter": 30}
    assert isinstance(cfg["max_iter"], int)
    # idempotent: a second round writes the same text
    assert save_model(m2, settings=cfg) == text
    m3, _ = loads_model(save_model(m2, settings=cfg))
    assert_models_equal(m, m3)


def test_save_of_loaded_text_is_stable():
    text = SLIDER_YAML.read_text(encoding="utf-8")
    m, cfg = loads_model(text)
    t1 = save_model(m, settings=cfg)
    t2 = save_model(*loads_model(t1)[:1], settings=loads_model(t1)[1])
    assert t1 == t2


def test_equivalent_spellings_give_the_same_model():
    base = ("se3dyn: 1\nnodes:\n  g: {fixed: true}\n  b: {mass: 1, inertia: [1e-3, 1e-3, 1e-3]}\n"
            "joints:\n  j: {type: hinge, a: g, b: b, axis: [1, 0, 0], torque: %s}\n")
    models = [loads_model(base % s)[0] for s in
              ("0.5", "[0.5]", "{constant: {value: 0.5}}", "{step: {value: 0.5, start: -1e9}}")]
    for m in models[1:]:
        _tf_eq(models[0].joint("j").actuator, m.joint("j").actuator, "torque")


# -------------------------------------------------------------------------------------------------
# 3. schema and reference are generated from the field table
# -------------------------------------------------------------------------------------------------
def test_schema_file_is_generated():
    assert SCHEMA_FILE.read_text(encoding="utf-8") == json.dumps(json_schema(), indent=2) + "\n"
    assert json.loads(SCHEMA_FILE.read_text(encoding="utf-8")) == json_schema()


def test_docs_contain_generated_reference():
    assert markdown_reference() in DOC_FILE.read_text(encoding="utf-8")


def test_schema_validates_slider_crank_and_rejects_unknown_keys():
    jsonschema = pytest.importorskip("jsonschema")
    schema = json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    doc = yaml.safe_load(SLIDER_YAML.read_text(encoding="utf-8"))
    jsonschema.validate(doc, schema)
    jsonschema.validate(yaml.safe_load(save_model(everything_model())), schema)
    doc["nodes"]["3"]["mas"] = 1.0
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(doc, schema)


# -------------------------------------------------------------------------------------------------
# 4. malformed files: one clear ModelFileError naming file, line, item and field
# -------------------------------------------------------------------------------------------------
BASE = """\
se3dyn: 1
name: pendulum
gravity: [0, 0, -9.81]
nodes:
  ground: {position: [0, 0, 0], fixed: true}
  bob: {position: [1, 0, 0], mass: 1.0, inertia: [1.0e-3, 1.0e-3, 1.0e-3]}
joints:
  pivot: {type: hinge, a: ground, b: bob, axis: [0, 1, 0]}
"""


def _sub(old, new, text=BASE):
    assert old in text
    return text.replace(old, new, 1)


BOMB = "se3dyn: 1\n" + "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8))

# (id, text or bytes, line or None, substrings of the message)
CASES = [
    ("wrong-type", _sub("mass: 1.0", "mass: heavy"), 6, ["node 'bob'", "'mass'", "'heavy'"]),
    ("bool-as-number", _sub("mass: 1.0", "mass: true"), 6, ["node 'bob'", "mass"]),
    ("nan", _sub("mass: 1.0", "mass: .nan"), 6, ["node 'bob'", "mass", "finite"]),
    ("inf", _sub("[1, 0, 0]", "[1, .inf, 0]"), 6, ["node 'bob'", "position[1]", "finite"]),
    ("huge-int", _sub("mass: 1.0", "mass: 1" + "0" * 5000), 6, ["node 'bob'", "mass"]),
    ("short-vector", _sub("[1, 0, 0]", "[1, 0]"), 6, ["node 'bob'", "position", "3 numbers"]),
    ("string-vector", _sub("[1, 0, 0]", "'1, 0, 0'"), 6, ["node 'bob'", "position"]),
    ("non-mapping-node", _sub("{position: [0, 0, 0], fixed: true}", "3"), 5,
     ["node 'ground'", "mapping"]),
    ("null-node", _sub("{position: [0, 0, 0], fixed: true}", ""), 5, ["node 'ground'"]),
    ("list-document", "- 1\n- 2\n", 1, ["model", "mapping"]),
    ("scalar-document", "hello\n", 1, ["model", "mapping"]),
    ("empty-document", "", None, ["se3dyn", "empty"]),
    ("missing-version", BASE.split("\n", 1)[1], 1, ["se3dyn", "version"]),
    ("unsupported-version", _sub("se3dyn: 1", "se3dyn: 2"), 1, ["se3dyn", "version 1", "2"]),
    ("string-version", _sub("se3dyn: 1", "se3dyn: '1'"), 1, ["se3dyn", "version"]),
    ("duplicate-node", BASE.replace("joints:", "  bob: {position: [0, 0, 1]}\njoints:"), 7,
     ["node 'bob'", "already defined at line 6"]),
    ("duplicate-field", _sub("mass: 1.0", "mass: 1.0, mass: 2.0"), 6,
     ["node 'bob'", "'mass'", "already given"]),
    ("duplicate-top-key", BASE + "name: again\n", 9, ["model", "'name'", "line 2"]),
    ("unknown-field", _sub("position: [1", "posiiton: [1"), 6,
     ["node 'bob'", "posiiton", "did you mean 'position'"]),
    ("unknown-top-key", BASE + "jionts: {}\n", 9, ["jionts", "did you mean 'joints'"]),
    ("unknown-joint-type", _sub("type: hinge", "type: hinje"), 8,
     ["joint 'pivot'", "type", "did you mean 'hinge'"]),
    ("unknown-node-ref", _sub("b: bob", "b: bobb"), 8, ["joint 'pivot'", "'b'", "'bob'"]),
    ("non-unit-axis", _sub("axis: [0, 1, 0]", "axis: [0, 2, 0]"), 8,
     ["joint 'pivot'", "axis", "unit"]),
    ("param-for-wrong-type", _sub("axis: [0, 1, 0]", "axis: [0, 1, 0], pitch: 0.1"), 8,
     ["joint 'pivot'", "pitch"]),
    ("mass-without-inertia", _sub(", inertia: [1.0e-3, 1.0e-3, 1.0e-3]", ""), 6,
     ["node 'bob'", "inertia"]),
    ("not-positive-definite", _sub("[1.0e-3, 1.0e-3, 1.0e-3]", "[1.0e-3, -1.0e-3, 1.0e-3]"), 6,
     ["node 'bob'", "inertia", "positive-definite"]),
    ("bad-rotation", _sub("fixed: true}", "orientation: [[1, 0, 0], [0, 1, 0], [0, 0, 2]]}"),
     5, ["node 'ground'", "orientation"]),
    ("free-massless-node", BASE.replace("joints:", "  lonely: {position: [0, 0, 5]}\njoints:"),
     7, ["node 'lonely'", "mass"]),
    ("load-on-fixed-node", BASE + "loads:\n  l: {node: ground, force: [0, 0, 1]}\n", 10,
     ["load 'l'", "node"]),
    ("timefunc-kind", _sub("axis: [0, 1, 0]", "axis: [0, 1, 0], torque: {stpe: {value: 1}}"), 8,
     ["joint 'pivot'", "torque", "did you mean 'step'"]),
    ("timefunc-two-kinds",
     _sub("axis: [0, 1, 0]", "axis: [0, 1, 0], torque: {step: {value: 1}, ramp: {value: 1}}"),
     8, ["joint 'pivot'", "torque", "exactly one"]),
    ("timefunc-stop-before-start",
     _sub("axis: [0, 1, 0]", "axis: [0, 1, 0], torque: {step: {value: 1, start: 2, stop: 1}}"),
     8, ["joint 'pivot'", "torque.step.stop"]),
    ("timefunc-missing-value", _sub("axis: [0, 1, 0]", "axis: [0, 1, 0], torque: {ramp: {}}"),
     8, ["joint 'pivot'", "torque.ramp.value", "required"]),
    ("actuator-size", _sub("axis: [0, 1, 0]", "axis: [0, 1, 0], torque: [1, 2, 3]"), 8,
     ["joint 'pivot'", "torque", "component"]),
    ("control-unknown-field",
     _sub("axis: [0, 1, 0]", "axis: [0, 1, 0], control: {kp: 1, kdd: 2}"), 8,
     ["joint 'pivot'", "control.kdd", "did you mean 'kd'"]),
    ("negative-damping", _sub("axis: [0, 1, 0]", "axis: [0, 1, 0], damping: -1"), 8,
     ["joint 'pivot'", "damping"]),
    ("bushing-short-stiffness", BASE + "bushings:\n  mount: {a: ground, b: bob, stiffness: "
     "[1, 2, 3]}\n", 10, ["bushing 'mount'", "stiffness", "6 numbers"]),
    ("bushing-asymmetric-stiffness", BASE + "bushings:\n  mount:\n    a: ground\n    b: bob\n"
     "    stiffness: [" + ", ".join("[" + ", ".join("1" if c >= r else "0" for c in range(6))
                                    + "]" for r in range(6)) + "]\n", 13,
     ["bushing 'mount'", "'stiffness'", "symmetric"]),
    ("bushing-indefinite-damping", BASE + "bushings:\n  mount: {a: ground, b: bob, stiffness: 1,"
     " damping: [" + ", ".join("[" + ", ".join("1" if c != r else "0" for c in range(6)) + "]"
                                for r in range(6)) + "]}\n", 10,
     ["bushing 'mount'", "'damping'", "positive semi-definite"]),
    ("bushing-missing-stiffness", BASE + "bushings:\n  mount: {a: ground, b: bob}\n", 10,
     ["bushing 'mount'", "stiffness", "required"]),
    ("bushing-unknown-node", BASE + "bushings:\n  mount: {a: ground, b: bobb, stiffness: 1}\n",
     10, ["bushing 'mount'", "'b'", "did you mean 'bob'"]),
    ("simulation-type", BASE + "simulation: {t_end: 1, max_iter: 2.5}\n", 9,
     ["simulation", "max_iter", "integer"]),
    ("simulation-unknown", BASE + "simulation: {t_end: 1, stp: 0.1}\n", 9,
     ["simulation", "stp", "did you mean 'step'"]),
    ("alias", BASE.replace("gravity: [0, 0, -9.81]", "gravity: &g [0, 0, -9.81]"), 3,
     ["anchor", "not supported"]),
    ("billion-laughs", BOMB, 2, ["anchor"]),
    ("alias-only", BASE + "loads: *nothing\n", 9, ["alias"]),
    ("python-tag", _sub("name: pendulum", "name: !!python/object/apply:os.system ['echo hi']"), 2,
     ["model", "name"]),
    ("python-name-tag", _sub("name: pendulum", "name: !!python/name:os.system"), 2,
     ["model", "name"]),
    ("python-tag-in-flow", _sub("mass: 1.0", "mass: !!python/object/apply:os.getcwd []"), 6,
     ["node 'bob'", "mass"]),
    ("timestamp-name", _sub("name: pendulum", "name: 2001-12-14"), 2, ["model", "name"]),
    ("syntax-error", _sub("joints:", "joints: [1, 2"), None, ["syntax"]),
    ("bad-indentation", _sub("  bob:", "     bob:"), 6, ["syntax"]),
    ("two-documents", BASE + "---\nse3dyn: 1\n", 9, ["syntax", "single document"]),
    ("complex-key", BASE + "? [a, b]\n: 1\n", 9, ["model", "field names"]),
    ("non-utf8", b"se3dyn: 1\nname: caf\xe9\n", 2, ["UTF-8", "0xe9"]),
    ("control-char", "se3dyn: 1\nname: a\x00b\n", 2, ["syntax", "#x0000"]),
    ("deep-nesting", BASE + "simulation: " + "[" * 5000 + "]" * 5000 + "\n", 9,
     ["nested"]),
    ("deep-mapping-nesting", BASE + "simulation: " + "{a: " * 2000 + "1" + "}" * 2000 + "\n", 9,
     ["nested"]),
    ("huge-array", _sub("[1, 0, 0]", "[" + ", ".join(["0"] * 1_000_000) + "]"), 6,
     ["nodes.bob.position", "10000"]),
    ("huge-mapping", BASE + "loads: {" + ", ".join(f"l{i}: 1" for i in range(10_001)) + "}\n",
     9, ["loads", "10000"]),
    ("too-large-file", b"se3dyn: 1\n" + b"#" * (10 * 1024 * 1024), None, ["size", "bytes"]),
]

@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_malformed_file_gives_one_clear_error(case):
    _, text, line, parts = case
    with pytest.raises(ModelFileError) as ei:
        loads_model(text, filename="bad.yaml")
    msg = str(ei.value)
    assert msg.startswith("bad.yaml"), msg
    assert "\n" not in msg, msg
    assert "Traceback" not in msg
    if line is not None:
        assert f"bad.yaml, line {line}:" in msg, msg
        assert ei.value.line == line
    for p in parts:
        assert p in msg, (p, msg)
    assert isinstance(ei.value, sd.ModelError) and isinstance(ei.value, ValueError)
    assert ei.value.filename == "bad.yaml"


def test_errors_from_files_name_the_path(tmp_path):
    p = tmp_path / "model.yaml"
    p.write_text(_sub("mass: 1.0", "mass: -1.0"), encoding="utf-8")
    with pytest.raises(ModelFileError, match=re.escape(f"{p}, line 6: node 'bob'")):
        load_model(p)
    with pytest.raises(ModelFileError, match="readable"):
        load_model(tmp_path / "missing.yaml")
    big = tmp_path / "big.yaml"
    big.write_bytes(b"se3dyn: 1\n" + b"#" * (10 * 1024 * 1024))
    with pytest.raises(ModelFileError, match="size"):
        load_model(big)


# -------------------------------------------------------------------------------------------------
# 4b. mutation fuzzing of the slider-crank file: loads, or a ModelFileError; nothing else
# -------------------------------------------------------------------------------------------------
_SLIDER = yaml.safe_load(SLIDER_YAML.read_text(encoding="utf-8"))


def _paths(obj, prefix=()):
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += _paths(v, (*prefix, i))
    return out


_LEAVES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**30, 10**30),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
    st.sampled_from(["1", "2", "9", "hinge", "universal", "step", "position", "a", "b", ""]),
)
_VALUES = st.one_of(_LEAVES, st.lists(_LEAVES, max_size=7),
                    st.lists(st.lists(st.floats(-2, 2), min_size=3, max_size=3), max_size=4),
                    st.dictionaries(st.sampled_from(["value", "step", "sine", "kp", "x"]),
                                    _LEAVES, max_size=2))


def _mutate(data, doc):
    import copy

    doc = copy.deepcopy(doc)
    paths = [p for p in _paths(doc) if p]
    path = data.draw(st.sampled_from(paths))
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    key = path[-1]
    op = data.draw(st.sampled_from(["delete", "replace", "rename"]))
    if op == "delete":
        del parent[key]
    elif op == "replace":
        parent[key] = data.draw(_VALUES)
    elif isinstance(parent, dict):
        new = data.draw(st.one_of(st.text(max_size=8), st.sampled_from(
            ["mas", "positions", "axes", "A", "torque", "force", "node", "se3dyn", "2"])))
        parent = {(new if k == key else k): v for k, v in parent.items()}
        # rebuild in place
        holder = doc
        for k in path[:-2]:
            holder = holder[k]
        if len(path) == 1:
            doc = parent
        else:
            holder[path[-2]] = parent
    else:
        parent[key] = data.draw(_VALUES)
    return doc


@settings(max_examples=150, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_mutated_slider_crank_loads_or_fails_cleanly(data):
    doc = _mutate(data, _SLIDER)
    style = data.draw(st.sampled_from([None, False, True]))
    text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=style, allow_unicode=True)
    if data.draw(st.booleans()):  # duplicate one line (a duplicate key in block style)
        lines = text.splitlines(keepends=True)
        i = data.draw(st.integers(0, len(lines) - 1))
        lines.insert(i, lines[i])
        text = "".join(lines)
    try:
        model, cfg = loads_model(text, filename="fuzz.yaml")
    except ModelFileError as e:
        assert str(e).startswith("fuzz.yaml"), str(e)
    else:
        assert isinstance(model, sd.Model) and isinstance(cfg, dict)


@settings(max_examples=100, deadline=2000)
@given(st.binary(max_size=200) | st.text(max_size=200))
def test_random_input_fails_cleanly(blob):
    try:
        loads_model(blob, filename="rand.yaml")
    except ModelFileError as e:
        assert str(e).startswith("rand.yaml")


# -------------------------------------------------------------------------------------------------
# 5. callables cannot be written
# -------------------------------------------------------------------------------------------------
def _pendulum(**joint_kw):
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("ground", fixed=True)
    mb.node("bob", position=(1, 0, 0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    mb.node("tip", position=(2, 0, 0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    return mb


@pytest.mark.parametrize("what", ["torque", "control", "load", "universal"])
def test_callable_time_function_cannot_be_saved(what):
    mb = _pendulum()
    if what == "torque":
        mb.joint("pivot", "hinge", "ground", "bob", axis=(0, 1, 0), torque=lambda t: 0.1 * t)
        item, fld = "joint 'pivot'", "torque"
    elif what == "control":
        mb.joint("pivot", "hinge", "ground", "bob", axis=(0, 1, 0),
                 control=sd.PD(kp=1.0, target=math.sin))
        item, fld = "joint 'pivot'", "control.target"
    elif what == "load":
        mb.joint("pivot", "hinge", "ground", "bob", axis=(0, 1, 0))
        mb.load("wind", "bob", force=lambda t: (t, 0.0, 0.0))
        item, fld = "load 'wind'", "force"
    else:
        mb.joint("cardan", "universal", "ground", "bob", axes=[(1, 0, 0), (0, 1, 0)],
                 torque=lambda t: (t, -t))
        item, fld = "joint 'cardan'", "torque"
    mb.joint("weld", "rigid", "bob", "tip")
    model = mb.build()
    with pytest.raises(sd.ModelError) as ei:
        save_model(model)
    msg = str(ei.value)
    assert item in msg and f"'{fld}'" in msg and "callable" in msg, msg
    assert ei.value.item == item and ei.value.field == fld
