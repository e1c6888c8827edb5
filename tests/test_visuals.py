"""Visual shapes of nodes (``ModelBuilder.visual``, ``visuals:`` in model files).

Facts checked: visuals never change the motion (same results bit for bit with and without
them); they round-trip through model files and results files; an ``axis`` gives a rotation whose
third column is that axis; every bad input is one ModelError / ModelFileError naming the visual,
the field, what was expected and what came (with the file line).
"""

from __future__ import annotations

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.errors import ModelError
from se3dyn.io.modelfile import ModelFileError, json_schema, load_model, save_model
from se3dyn.model.visuals import COLORS, axis_rotation


def pendulum(with_visuals: bool) -> sd.Model:
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81), name="pendulum")
    mb.node("ground", fixed=True)
    mb.node("bob", position=(0.5, 0, 0), mass=1.0, inertia=(1e-3, 2e-2, 2e-2))
    mb.joint("hinge", "hinge", "ground", "bob", axis=(0, 1, 0), at=(0, 0, 0), damping=0.01)
    if with_visuals:
        mb.visual("rod", "bob", "cylinder", size=(0.01, 0.5), axis=(1, 0, 0),
                  offset=(-0.25, 0, 0), color="steel")
        mb.visual("ball", "bob", "sphere", size=0.05, color=(1.0, 0.5, 0.0))
        mb.visual("base", "ground", "box", size=(0.2, 0.2, 0.02), offset=(0, 0, -0.02))
        mb.visual("cap", "bob", "capsule", size=(0.02, 0.1), orientation=np.eye(3)[[1, 2, 0]].T)
        mb.visual("part", "bob", "mesh", file="meshes/part.stl", size=0.001)
    return mb.build()


def test_visuals_do_not_change_the_motion():
    a = sd.simulate(pendulum(False), t_end=0.5, step=1e-2)
    b = sd.simulate(pendulum(True), t_end=0.5, step=1e-2)
    np.testing.assert_array_equal(a.H, b.H)
    np.testing.assert_array_equal(a.v, b.v)


def test_visuals_round_trip_through_a_model_file(tmp_path):
    m = pendulum(True)
    text = save_model(m)
    m2, _ = load_model(text)
    assert [v.name for v in m2.visuals] == [v.name for v in m.visuals]
    for a, b in zip(m.visuals, m2.visuals, strict=True):
        assert (a.node, a.shape, a.color, a.file) == (b.node, b.shape, b.color, b.file)
        for f in ("size", "offset", "orientation"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert save_model(m2) == text


def test_visuals_travel_in_results_files(tmp_path):
    from se3dyn.io.h5 import ResultsWriter, read_results
    from se3dyn.viewer.shapes import resolve_model

    m = pendulum(True)
    with ResultsWriter(tmp_path / "r.h5", sd.compile_model(m)) as w:
        res = sd.simulate(m, t_end=0.05, step=1e-2, on_output=w.append)
        w.close(res.stats)
    back = read_results(tmp_path / "r.h5")
    model = resolve_model(back)
    assert [v.name for v in model.visuals] == ["rod", "ball", "base", "cap", "part"]


def test_axis_gives_a_rotation_with_that_third_column():
    rng = np.random.default_rng(1)
    axes = [*rng.normal(size=(20, 3)), (0, 0, 1), (0, 0, -1), (1e-9, 0, -1)]
    for a in axes:
        R = axis_rotation(np.asarray(a, dtype=float))
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(R[:, 2], np.asarray(a) / np.linalg.norm(a), atol=1e-12)


def test_colours_are_normalised():
    mb = sd.ModelBuilder()
    mb.node("n", mass=1, inertia=(1, 1, 1))
    mb.visual("a", "n", "sphere", size=1, color="RED")
    mb.visual("b", "n", "sphere", size=1, color="#AbC")
    mb.visual("c", "n", "sphere", size=1, color=(0, 1, 0.5))
    m = mb.build()
    assert [v.color for v in m.visuals] == [COLORS["red"], "#aabbcc", "#00ff80"]


@pytest.mark.parametrize("kwargs, field, expected", [
    (dict(shape="cube", size=1), "shape", "one of box, sphere"),
    (dict(shape="box", size=(1, 2)), "size", "3 side lengths"),
    (dict(shape="sphere", size=-1), "size", "a radius > 0"),
    (dict(shape="cylinder", size=1), "size", "(radius, length) > 0"),
    (dict(shape="box"), "size", "3 side lengths"),
    (dict(shape="box", size=1, color="#12"), "color", "'#rrggbb'"),
    (dict(shape="box", size=1, color=(2, 0, 0)), "color", "3 numbers in [0, 1]"),
    (dict(shape="box", size=1, offset=(1, 2)), "offset", "3 numbers"),
    (dict(shape="box", size=1, axis=(0, 0, 0)), "axis", "a non-zero direction"),
    (dict(shape="box", size=1, axis=(0, 0, 1), orientation=np.eye(3)), "axis", "not both"),
    (dict(shape="box", size=1, orientation=2 * np.eye(3)), "orientation", "rotation matrix"),
    (dict(shape="mesh"), "file", "a mesh file name"),
    (dict(shape="mesh", file="part.png"), "file", "ending in .stl"),
    (dict(shape="box", size=1, file="part.stl"), "file", "only a 'mesh' shape"),
])
def test_bad_visuals_name_the_item_field_expected_and_got(kwargs, field, expected):
    mb = sd.ModelBuilder()
    mb.node("n", mass=1, inertia=(1, 1, 1))
    shape = kwargs.pop("shape")
    with pytest.raises(ModelError) as e:
        mb.visual("v", "n", shape, **kwargs)
    assert e.value.item.startswith("visual 'v'") and e.value.field == field
    assert expected in e.value.expected
    assert "got" in str(e.value) and "\n" not in str(e.value)


def test_visual_on_an_unknown_node_or_twice():
    mb = sd.ModelBuilder()
    mb.node("node1", mass=1, inertia=(1, 1, 1))
    with pytest.raises(ModelError, match="field 'node'.*did you mean 'node1'"):
        mb.visual("v", "node2", "sphere", size=1)
    mb.visual("v", "node1", "sphere", size=1)
    with pytest.raises(ModelError, match="a unique visual name"):
        mb.visual("v", "node1", "sphere", size=1)


BASE = """se3dyn: 1
nodes:
  a: {mass: 1, inertia: [1, 1, 1]}
visuals:
  v: {node: a, shape: box, size: 0.1}
"""


@pytest.mark.parametrize("line, field, fragment", [
    ("  v: {node: b, shape: box, size: 0.1}", "node", "unknown node 'b'"),
    ("  v: {node: a, shape: cube, size: 0.1}", "shape", "one of box, sphere"),
    ("  v: {node: a, shape: spher, size: 0.1}", "shape", "did you mean 'sphere'"),
    ("  v: {node: a, shape: box, size: [1, 2]}", "size", "3 side lengths"),
    ("  v: {node: a, shape: box, size: 0.1, colour: red}", "colour", "did you mean 'color'"),
    ("  v: {node: a, shape: box, size: 0.1, color: 7}", "color", "a colour"),
    ("  v: {node: a, shape: box, size: 0.1, color: [1, 2, 3]}", "color", "3 numbers in [0, 1]"),
    ("  v: {node: a, shape: box, size: 0.1, offset: [1, 2]}", "offset", "3 numbers"),
    ("  v: {node: a, shape: mesh, file: part.png}", "file", "ending in .stl"),
])
def test_bad_visuals_in_files_name_the_line(line, field, fragment):
    text = BASE.replace("  v: {node: a, shape: box, size: 0.1}", line)
    with pytest.raises(ModelFileError) as e:
        load_model(text)
    msg = str(e.value)
    assert e.value.line == 5, msg
    assert f"field '{field}'" in msg and "visual 'v'" in msg and fragment in msg, msg


def test_schema_knows_visuals():
    schema = json_schema()
    assert "visuals" in schema["properties"]
    vis = schema["$defs"]["visual"]
    assert vis["required"] == ["node", "shape"]
    assert vis["properties"]["shape"]["enum"] == ["box", "sphere", "cylinder", "capsule", "mesh"]
    jsonschema = pytest.importorskip("jsonschema")
    import yaml

    jsonschema.validate(yaml.safe_load(save_model(pendulum(True))), schema)
