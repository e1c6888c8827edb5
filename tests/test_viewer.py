"""The viewer layer without a browser: the scene's geometry against the model's physics, the
frame encoding against its error bounds, the page's content, glTF structure, the command line.

Facts checked: the default body box has the body's mass and inertia; joint glyphs stay on the
joint axis and at the joint point seen from *both* nodes of the joint at every stored time (the
constraints hold, so the picture is consistent); a prismatic rail covers the relative travel;
ground symbols point against gravity at fixed nodes; links join node origins to joint points;
quantised frames decode within the stated bounds; the page embeds the results' times and
frames and loads nothing from outside; glTF carries one translation and one rotation channel per
moving node over the results' time range, with the node frames as key values.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import se3dyn as sd
from se3dyn.io.modelfile import load_model
from se3dyn.model.visuals import COLORS
from se3dyn.viewer import export_gltf, html_page
from se3dyn.viewer.encode import (
    ANGLE_BOUND,
    Blob,
    decode_frames,
    encode_frames,
    pack,
    quaternions,
    unpack,
)
from se3dyn.viewer.errors import ViewerError
from se3dyn.viewer.shapes import build_scene, equivalent_box, part_pose

ROOT = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------------------------------------
# fixtures: short runs of the paper's slider-crank (node form and body form) and a slider
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def crank():
    model = sd.examples.slider_crank()
    return model, sd.simulate(model, t_end=1.0, step=1e-2)


@pytest.fixture(scope="module")
def crank_bodies():
    model = sd.examples.slider_crank_bodies()
    return model, sd.simulate(model, t_end=1.0, step=1e-2)


def slider_model():
    """A block on a prismatic joint along (1, 1, 0)/sqrt 2 with a spring, released off its
    rest length: it oscillates along the axis."""
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81), name="slider")
    mb.node("base", position=(0, 0, 0), fixed=True)
    mb.node("block", position=(0.3, 0.3, 0.0), mass=1.0, inertia=(1e-2, 2e-2, 3e-2))
    mb.joint("rail", "prismatic", "base", "block", axis=np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0),
             stiffness=50.0,
             reference=0.2)
    return mb.build()


@pytest.fixture(scope="module")
def slider():
    model = slider_model()
    return model, sd.simulate(model, t_end=1.0, step=1e-2)


def _parts(scene, role=None, label=None):
    return [p for p in scene.parts if (role is None or p.role == role)
            and (label is None or p.label == label)]


# ---------------------------------------------------------------------------------------------
# 1. bodies: the equivalent box has the body's inertia
# ---------------------------------------------------------------------------------------------
def box_inertia(m, sides, Q):
    a2 = np.asarray(sides) ** 2
    J = m / 12.0 * np.diag([a2[1] + a2[2], a2[0] + a2[2], a2[0] + a2[1]])
    return Q @ J @ Q.T


def test_equivalent_box_has_the_inertia_it_was_made_from():
    rng = np.random.default_rng(7)
    for _ in range(50):
        m = rng.uniform(0.1, 10.0)
        sides = rng.uniform(0.2, 2.0, 3)
        Q = Rotation.random(random_state=rng).as_matrix()
        J = box_inertia(m, sides, Q)
        s, Q2 = equivalent_box(m, J)
        assert np.linalg.det(Q2) == pytest.approx(1.0)
        np.testing.assert_allclose(box_inertia(m, s, Q2), J, rtol=1e-10,
                                   atol=1e-12 * np.abs(J).max())
        np.testing.assert_allclose(np.sort(s), np.sort(sides), rtol=1e-9)


def test_slender_body_box_is_drawable():
    # a thin rod: J1 ~ 0 gives a zero side that is raised to MIN_ASPECT of the length
    from se3dyn.viewer.shapes import MIN_ASPECT

    s, _ = equivalent_box(1.0, np.diag([1e-12, 1 / 12, 1 / 12]))
    assert s.max() == pytest.approx(1.0, rel=1e-6)
    assert s.min() == pytest.approx(MIN_ASPECT * s.max())


def test_default_bodies_carry_the_node_inertia(crank):
    model, res = crank
    scene = build_scene(res, model)
    bodies = _parts(scene, "body")
    assert sorted(p.node for p in bodies) == sorted(
        i for i, n in enumerate(model.nodes) if n.mass > 0)
    for p in bodies:
        node = model.nodes[p.node]
        assert p.kind == "box"
        np.testing.assert_allclose(p.matrix[:3, 3], 0.0)  # centred on the node (mass centre)
        J = box_inertia(node.mass, p.scale, p.matrix[:3, :3])
        np.testing.assert_allclose(J, node.inertia, rtol=1e-9, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# 2. joints: glyphs on the joint axis and at the joint point, seen from both nodes
# ---------------------------------------------------------------------------------------------
def _joint_point_and_axis_through_a(model, res, joint):
    """The joint point and axis carried by node A at every stored time (inertial frame)."""
    names = res.system.node_names
    a = names.index(joint.node_a)
    nA = model.nodes[a]
    p0 = joint.at if joint.at is not None else model.node(joint.node_b).position
    R0 = nA.orientation
    A = np.asarray(joint.A).reshape(6, -1)
    axis0 = A[3:, 0] if np.linalg.norm(A[3:, 0]) > 0 else A[:3, 0]
    RA, xA = res.H[:, a, :3, :3], res.H[:, a, :3, 3]
    p = np.einsum("nij,j->ni", RA, R0.T @ (p0 - nA.position)) + xA
    ax = np.einsum("nij,j->ni", RA, R0.T @ axis0)
    return p, ax / np.linalg.norm(ax, axis=1, keepdims=True)


@pytest.mark.parametrize("which", ["crank", "crank_bodies"])
def test_hinge_and_sphere_glyphs_stay_on_the_joint_seen_from_node_a(which, request):
    model, res = request.getfixturevalue(which)
    scene = build_scene(res, model)
    checked = 0
    for j in model.joints:
        if j.type not in ("hinge", "spherical"):
            continue
        (glyph,) = _parts(scene, "joint", f"joint {j.name!r} ({j.type})")
        assert scene.node_names[glyph.node] == j.node_b  # the glyph moves with node B
        pose = part_pose(glyph, res.H[:, glyph.node])  # (n, 4, 4)
        p, ax = _joint_point_and_axis_through_a(model, res, j)
        # constraint violations are ~1e-12: the glyph is where node A says the joint is
        np.testing.assert_allclose(pose[:, :3, 3], p, atol=1e-9)
        if j.type == "hinge":
            z = pose[:, :3, 2] / np.linalg.norm(pose[:, :3, 2], axis=1, keepdims=True)
            np.testing.assert_allclose(z, ax, atol=1e-9)
            # at t0 it is the model's axis (inertial frame)
            a0 = np.asarray(j.params["axis"], dtype=float)
            np.testing.assert_allclose(z[0], a0 / np.linalg.norm(a0), atol=1e-12)
        checked += 1
    assert checked == 3


def test_prismatic_rail_on_a_covers_the_travel_of_b(slider):
    model, res = slider
    scene = build_scene(res, model)
    label = "joint 'rail' (prismatic)"
    rail, block = sorted(_parts(scene, "joint", label), key=lambda p: -p.scale[2])
    assert scene.node_names[rail.node] == "base" and scene.node_names[block.node] == "block"
    u = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    pose = part_pose(rail, res.H[:, rail.node])[0]
    np.testing.assert_allclose(pose[:3, 2] / np.linalg.norm(pose[:3, 2]), u, atol=1e-12)
    # every position of the block's joint point lies on the rail, within its length
    x = res.node_position("block")
    s = (x - pose[:3, 3]) @ u
    off_axis = (x - pose[:3, 3]) - np.outer(s, u)
    assert np.abs(off_axis).max() < 1e-9
    half = 0.5 * rail.scale[2]
    assert np.all(np.abs(s) <= half) and np.ptp(s) > 0.05  # it did move along the rail


def test_ground_symbols_point_against_gravity_from_fixed_nodes(crank):
    model, res = crank
    scene = build_scene(res, model)
    g = model.gravity / np.linalg.norm(model.gravity)
    np.testing.assert_allclose(scene.up, -g)
    fixed = [i for i, n in enumerate(model.nodes) if n.fixed]
    cones = [p for p in _parts(scene, "ground") if p.kind == "cone"]
    assert sorted(p.node for p in cones) == fixed
    for p in cones:
        pose = part_pose(p, res.H[0, p.node])
        apex = pose @ np.array([0.0, 0.0, 0.5, 1.0])
        np.testing.assert_allclose(apex[:3], res.H[0, p.node, :3, 3], atol=1e-12)
        np.testing.assert_allclose(pose[:3, 2] / np.linalg.norm(pose[:3, 2]), -g, atol=1e-12)


def test_links_join_node_origins_to_joint_points(crank_bodies):
    model, res = crank_bodies
    scene = build_scene(res, model)
    links = _parts(scene, "link")
    assert links
    points = [np.asarray(j.at) for j in model.joints]
    for p in links:
        pose = part_pose(p, res.H[0, p.node])
        ends = [pose @ np.array([0.0, 0.0, s, 1.0]) for s in (-0.5, 0.5)]
        np.testing.assert_allclose(ends[0][:3], res.H[0, p.node, :3, 3], atol=1e-12)
        assert min(np.linalg.norm(ends[1][:3] - q) for q in points) < 1e-12


def test_visuals_replace_the_default_body_and_keep_their_pose():
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("g", fixed=True)
    mb.node("arm", position=(0.25, 0, 0), mass=1.0, inertia=(1e-3, 5e-3, 5e-3))
    mb.joint("h", "hinge", "g", "arm", axis=(0, 1, 0), at=(0, 0, 0))
    mb.visual("rod", "arm", "cylinder", size=(0.02, 0.5), axis=(1, 0, 0), color="orange")
    mb.visual("tip", "arm", "sphere", size=0.04, offset=(0.25, 0, 0))
    model = mb.build()
    res = sd.simulate(model, t_end=0.3, step=1e-2)
    scene = build_scene(res, model)
    assert not _parts(scene, "body")
    rod, tip = _parts(scene, "visual")
    assert rod.color == COLORS["orange"]
    # the rod's axis is the arm direction, its end is at the pivot, at every time
    pose = part_pose(rod, res.H[:, rod.node])
    ends = pose @ np.array([0.0, 0.0, -0.5, 1.0])
    np.testing.assert_allclose(ends[:, :3], 0.0, atol=1e-9)
    tip_pose = part_pose(tip, res.H[:, tip.node])
    np.testing.assert_allclose(np.linalg.norm(tip_pose[:, :3, 3], axis=1), 0.5, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# 3. frame encoding
# ---------------------------------------------------------------------------------------------
def _frames(n=40, M=7, seed=3):
    rng = np.random.default_rng(seed)
    R = Rotation.random(n * M, random_state=rng).as_matrix().reshape(n, M, 3, 3)
    # special rotations: identity, half turns (w = 0), equal components
    R[0, 0] = np.eye(3)
    R[0, 1] = np.diag([1.0, -1.0, -1.0])
    R[0, 2] = Rotation.from_quat([0.5, 0.5, 0.5, 0.5]).as_matrix()
    R[0, 3] = Rotation.from_rotvec([0, 0, np.pi]).as_matrix()
    H = np.zeros((n, M, 4, 4))
    H[..., :3, :3] = R
    H[..., :3, 3] = rng.normal(size=(n, M, 3)) * np.array([1.0, 100.0, 1e-3])
    H[..., 3, 3] = 1.0
    H[:, 5, :3, 3] = 2.0  # a node that never moves
    return H


def test_quantised_frames_decode_within_the_stated_bounds():
    H = _frames()
    words, lo, hi = encode_frames(H)
    x, q = decode_frames(words, lo, hi)
    err = np.abs(x - H[..., :3, 3])
    assert np.all(err <= (hi - lo) / 131070 * (1 + 1e-9) + 1e-15)
    R = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(H.shape[:2] + (3, 3))
    ang = Rotation.from_matrix((np.swapaxes(R, -1, -2) @ H[..., :3, :3]).reshape(-1, 3, 3))
    assert ang.magnitude().max() <= ANGLE_BOUND


def test_packed_blocks_round_trip():
    words, _, _ = encode_frames(_frames())
    b = pack("f", words, delta=True)
    assert b.codec == "delta16+split+deflate"
    np.testing.assert_array_equal(unpack(b), words)
    m = np.arange(24, dtype=np.float32).reshape(2, 12)
    np.testing.assert_array_equal(unpack(pack("m", m)), m)


def test_quaternions_are_continuous_in_time():
    rv = np.linspace(0, 4 * np.pi, 200)[:, None] * np.array([0.0, 0.0, 1.0])
    R = Rotation.from_rotvec(rv).as_matrix()[:, None]
    q = quaternions(R)
    assert np.all(np.einsum("ni,ni->n", q[1:, 0], q[:-1, 0]) > 0)
    np.testing.assert_allclose(Rotation.from_quat(q[:, 0]).as_matrix(), R[:, 0], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# 4. the page
# ---------------------------------------------------------------------------------------------
class _Tags(HTMLParser):
    def __init__(self):
        super().__init__()
        self.scripts: dict[str, dict] = {}
        self.external: list[tuple] = []
        self._cur = None
        self._buf: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("src", "href", "srcset", "data", "action", "poster"):
            if a.get(key):
                self.external.append((tag, key, a[key]))
        if tag == "script":
            self._cur = a
            self._buf = []

    def handle_data(self, data):
        if self._cur is not None:
            self._buf.append(data)

    def handle_endtag(self, tag):
        if tag == "script" and self._cur is not None:
            if self._cur.get("id"):
                self.scripts[self._cur["id"]] = {**self._cur, "text": "".join(self._buf)}
            self._cur = None


def parse_page(text):
    p = _Tags()
    p.feed(text)
    return p


def blob_of(tags, name):
    s = tags.scripts[f"se3dyn-blob-{name}"]
    shape = tuple(int(x) for x in s["data-shape"].split(","))
    return unpack(Blob(name, s["data-dtype"], shape, s["data-codec"], s["text"].strip(), 0))


def test_page_embeds_the_results_and_nothing_external(crank):
    model, res = crank
    text = html_page(res)
    tags = parse_page(text)
    assert tags.external == []  # no src/href: nothing loaded from elsewhere
    meta = json.loads(tags.scripts["se3dyn-meta"]["text"])
    np.testing.assert_array_equal(meta["t"], res.t)
    assert meta["nodes"] == list(res.system.node_names)
    words, lo, hi = encode_frames(res.H)
    np.testing.assert_array_equal(blob_of(tags, "frames"), words)
    np.testing.assert_allclose(np.reshape(meta["lo"], (-1, 3)), lo)
    scene = build_scene(res, model)
    info = blob_of(tags, "part_info")
    assert info.shape == (len(scene.parts), 5)
    assert [p.node for p in scene.parts] == info[:, 0].tolist()
    mats = blob_of(tags, "part_matrix").reshape(-1, 3, 4)
    for p, m in zip(scene.parts, mats, strict=True):
        np.testing.assert_allclose(m, (p.matrix @ np.diag([*p.scale, 1.0]))[:3], rtol=1e-6,
                                   atol=1e-7)
    # embedded channels are the results' channels
    from se3dyn.results.channels import get_channel

    ch = blob_of(tags, "channels")
    names = meta["channels"]["names"]
    assert "joint/1/alpha/0" in names and meta["plot"] == "joint/1/alpha/0"
    k = names.index("joint/1/alpha/0")
    np.testing.assert_allclose(ch[k], get_channel(res, "joint/1/alpha/0"), rtol=1e-6)
    # the vendored libraries are inlined, and the loader links them
    for ident in ("se3dyn-lib-three-core", "se3dyn-lib-three-module",
                  "se3dyn-lib-orbit-controls"):
        assert len(tags.scripts[ident]["text"]) > 1000
    assert len(text) < 2_000_000


def test_vendored_three_is_the_recorded_version_with_its_licence():
    from se3dyn.viewer.html import STATIC, THREE_VERSION

    core = (STATIC / "three.core.js").read_text(encoding="utf-8")
    assert f"const REVISION = '{THREE_VERSION.split('.')[1]}'" in core
    assert "MIT License" in (STATIC / "LICENSE-three.txt").read_text(encoding="utf-8")
    # the import specifiers the page's loader rewrites exist
    assert "from './three.core.js'" in (STATIC / "three.module.js").read_text(encoding="utf-8")
    assert "from 'three'" in (STATIC / "OrbitControls.js").read_text(encoding="utf-8")
    app = (STATIC / "viewer.js").read_text(encoding="utf-8")
    assert app.count("from 'three'") == 1 and "</script" not in app


def test_channel_and_trace_choices_and_their_errors(crank):
    _, res = crank
    tags = parse_page(html_page(res, channels=["energy/*", "joint/1/alpha/0"], traces=["6"]))
    meta = json.loads(tags.scripts["se3dyn-meta"]["text"])
    assert meta["channels"]["names"][-1] == "joint/1/alpha/0"
    assert all(n.startswith("energy/") for n in meta["channels"]["names"][:-1])
    assert meta["traces"] == [res.system.node_names.index("6")]
    with pytest.raises(ViewerError, match=r"channel: field 'name'.*got 'joint/99/\*'"):
        html_page(res, channels=["joint/99/*"])
    with pytest.raises(ViewerError, match="trace: field 'node'.*did you mean '6'"):
        html_page(res, traces=["66"])


def test_page_of_a_results_file_uses_the_stored_model(tmp_path, crank):
    from se3dyn.io.h5 import ResultsWriter, read_results

    model, _ = crank
    path = tmp_path / "r.h5"
    with ResultsWriter(path, sd.compile_model(model)) as w:
        res = sd.simulate(model, t_end=0.2, step=1e-2, on_output=w.append)
        w.close(res.stats)
    back = read_results(path)
    a = build_scene(back)
    b = build_scene(res, model)
    def key(scene):
        return [(p.node, p.kind, p.role) for p in scene.parts]

    assert key(a) == key(b)
    for p, q in zip(a.parts, b.parts, strict=True):
        np.testing.assert_allclose(p.matrix, q.matrix, atol=1e-12)
    # without a usable model the nodes are still drawn, as points
    back.stats["model"] = ""
    pts = build_scene(back)
    assert pts.notes and {p.role for p in pts.parts} <= {"body", "ground"}


def test_chain_of_1000_links_with_1000_frames_fits_in_20_mb():
    """Worst case for the size: every frame a random pose and every channel random
    (incompressible), 1001 nodes."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from chain_scaling import chain
    finally:
        sys.path.pop(0)
    model = chain(1000)
    s = sd.compile_model(model)
    n, M = 1000, len(model.nodes)
    rng = np.random.default_rng(0)
    H = np.zeros((n, M, 4, 4))
    H[..., :3, :3] = Rotation.random(n * M, random_state=rng).as_matrix().reshape(n, M, 3, 3)
    H[..., :3, 3] = rng.uniform(-100, 100, size=(n, M, 3))
    H[..., 3, 3] = 1.0
    z = rng.normal(size=n)
    res = sd.Results(system=s, t=np.linspace(0, 1, n), H=H, v=rng.normal(size=(n, s.nq)),
                     vd=rng.normal(size=(n, s.nq)), lam=rng.normal(size=(n, s.nm)),
                     alpha=rng.normal(size=(n, s.nq)), kinetic=z, potential=z, spring=z,
                     work_actuators=z, work_loads=z, dissipation=z,
                     iterations=np.zeros(n, int), residual=z, constraint=z)
    text = html_page(res, model=model)
    assert len(text.encode()) <= 20_000_000
    tags = parse_page(text)
    info = blob_of(tags, "part_info")
    meta = json.loads(tags.scripts["se3dyn-meta"]["text"])
    # instanced drawing: thousands of parts share a handful of geometries
    assert len(info) > 3000 and len(meta["geometries"]) <= 5


# ---------------------------------------------------------------------------------------------
# 5. glTF
# ---------------------------------------------------------------------------------------------
def _accessor(g, blob, idx):
    a = g.accessors[idx]
    v = g.bufferViews[a.bufferView]
    comps = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[a.type]
    dt = np.float32 if a.componentType == 5126 else np.uint32
    data = np.frombuffer(blob, dtype=dt, count=a.count * comps,
                         offset=v.byteOffset + (a.byteOffset or 0))
    return data.reshape(a.count, comps) if comps > 1 else data


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_gltf_animates_every_moving_node_over_the_results_times(tmp_path, crank_bodies, suffix):
    pygltflib = pytest.importorskip("pygltflib")
    model, res = crank_bodies
    path = export_gltf(res, tmp_path / f"m{suffix}", model=model)
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob() if suffix == ".glb" else None
    if blob is None:
        import base64

        blob = base64.b64decode(g.buffers[0].uri.split(",", 1)[1])
    assert g.asset.version == "2.0"
    (anim,) = g.animations
    names = list(res.system.node_names)
    moving = {n for n, f in zip(names, res.system.node_fixed, strict=True) if not f}
    targets: dict[str, set] = {}
    for ch in anim.channels:
        targets.setdefault(g.nodes[ch.target.node].name, set()).add(ch.target.path)
    assert set(targets) == moving
    assert all(v == {"translation", "rotation"} for v in targets.values())
    for ch in anim.channels:
        s = anim.samplers[ch.sampler]
        t = _accessor(g, blob, s.input)
        np.testing.assert_array_equal(t, res.t.astype(np.float32))
        assert g.accessors[s.input].min == [float(np.float32(res.t[0]))]
        assert g.accessors[s.input].max == [float(np.float32(res.t[-1]))]
        out = _accessor(g, blob, s.output)
        i = names.index(g.nodes[ch.target.node].name)
        if ch.target.path == "translation":
            np.testing.assert_allclose(out, res.H[:, i, :3, 3], atol=1e-6)
        else:
            R = Rotation.from_quat(out).as_matrix()
            np.testing.assert_allclose(R, res.H[:, i, :3, :3], atol=1e-6)
    # the root turns the model's up (-gravity = +z) onto glTF's +Y
    root = g.nodes[g.scenes[g.scene].nodes[0]]
    up = Rotation.from_quat(root.rotation).apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(up, [0.0, 1.0, 0.0], atol=1e-12)


def test_gltf_opens_in_another_reader(tmp_path, crank):
    trimesh = pytest.importorskip("trimesh")
    model, res = crank
    path = export_gltf(res, tmp_path / "m.glb", model=model)
    scene = trimesh.load(str(path))
    assert len(scene.geometry) > 0
    # bounds (in glTF's Y-up frame) contain the node positions at t0 (z up -> y up)
    x = res.H[0, :, :3, 3]
    y_up = np.column_stack([x[:, 0], x[:, 2], -x[:, 1]])
    lo, hi = scene.bounds
    assert np.all(y_up >= lo - 1e-6) and np.all(y_up <= hi + 1e-6)


# ---------------------------------------------------------------------------------------------
# 6. mesh visuals
# ---------------------------------------------------------------------------------------------
def test_mesh_visual_from_stl_and_obj_files(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box(extents=(0.4, 0.1, 0.05))
    box.export(tmp_path / "link.stl")
    trimesh.creation.icosphere(subdivisions=1, radius=0.05).export(tmp_path / "ball.obj")
    text = f"""se3dyn: 1
gravity: [0, 0, -9.81]
nodes:
  g: {{fixed: true}}
  arm: {{position: [0.2, 0, 0], mass: 1, inertia: [1.0e-3, 1.0e-2, 1.0e-2]}}
joints:
  h: {{type: hinge, a: g, b: arm, axis: [0, 1, 0], at: [0, 0, 0]}}
visuals:
  link: {{node: arm, shape: mesh, file: link.stl, color: steel}}
  ball: {{node: arm, shape: mesh, file: {tmp_path / 'ball.obj'}, size: 2, offset: [0.2, 0, 0]}}
simulation: {{t_end: 0.1, step: 0.01}}
"""
    (tmp_path / "arm.yaml").write_text(text)
    model, settings = load_model(tmp_path / "arm.yaml")
    res = sd.simulate(model, **settings)
    scene = build_scene(res, model, model_path=tmp_path / "arm.yaml")
    assert len(scene.meshes) == 2
    V, F = scene.meshes[0]
    np.testing.assert_allclose(V.max(axis=0) - V.min(axis=0), [0.4, 0.1, 0.05], atol=1e-9)
    tags = parse_page(html_page(res, model=model, model_path=tmp_path / "arm.yaml"))
    assert blob_of(tags, "mesh0_f").shape == F.shape
    export_gltf(res, tmp_path / "arm.glb", model=model, model_path=tmp_path / "arm.yaml")
    # a missing mesh file is one clear error naming the visual and the file
    (tmp_path / "link.stl").unlink()
    with pytest.raises(ViewerError, match=r"visual 'link' \(mesh\): field 'file'.*'link.stl'"):
        build_scene(res, model, model_path=tmp_path / "arm.yaml")


# ---------------------------------------------------------------------------------------------
# 7. command line and notebook
# ---------------------------------------------------------------------------------------------
def _cli(*args, cwd=None):
    exe = Path(sys.executable).parent / "se3dyn"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "se3dyn.cli"]
    p = subprocess.run(cmd + [str(a) for a in args], capture_output=True, text=True, cwd=cwd,
                       timeout=300)
    assert "Traceback" not in p.stderr, p.stderr
    return p


@pytest.fixture(scope="module")
def results_file(tmp_path_factory, crank):
    from se3dyn.io.h5 import ResultsWriter

    model, _ = crank
    path = tmp_path_factory.mktemp("view") / "crank.h5"
    with ResultsWriter(path, sd.compile_model(model)) as w:
        res = sd.simulate(model, t_end=0.3, step=1e-2, on_output=w.append)
        w.close(res.stats)
    return path


def test_cli_view_and_export_gltf(results_file, tmp_path):
    p = _cli("view", results_file, "-o", tmp_path / "v.html")
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "v.html").stat().st_size > 100_000
    p = _cli("export", results_file, "--gltf", tmp_path / "v.glb")
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "v.glb").read_bytes()[:4] == b"glTF"


@pytest.mark.parametrize("args, message", [
    (["view", "{res}", "-o", "{tmp}/x.html", "--channel", "node/99/*"], "channel: field 'name'"),
    (["view", "{res}", "-o", "{tmp}/x.html", "--trace", "nope"], "trace: field 'node'"),
    (["view", "{res}", "-o", "{tmp}/none/x.html"], "output: field 'path'"),
    (["view", "{tmp}/missing.h5"], "no such results file"),
    (["view", "{res}", "-o", "{tmp}/x.html", "--model", "{root}/examples/a01_simple_pendulum.yaml"],
     "field 'nodes': expected the 9 nodes of the results"),
    (["export", "{res}", "--gltf", "{tmp}/x.png"], "expected a file name ending in .glb"),
    (["export", "{res}", "--gltf", "{tmp}/x.glb", "time"], "give no channels"),
])
def test_cli_bad_input_is_one_line_and_exit_2(results_file, tmp_path, args, message):
    fill = {"res": results_file, "tmp": tmp_path, "root": ROOT}
    p = _cli(*[a.format(**fill) for a in args])
    assert p.returncode == 2
    assert message in p.stderr and p.stderr.strip().count("\n") == 0, p.stderr


def test_view_without_output_opens_the_browser(results_file, monkeypatch):
    from se3dyn.cli import commands as cli

    opened = []
    monkeypatch.setattr("webbrowser.open", lambda url, *a, **k: opened.append(url) or True)
    assert cli.main(["view", str(results_file)]) == 0
    (url,) = opened
    assert url.startswith("file://") and url.endswith(".html")
    path = Path(re.sub("^file://", "", url))
    try:
        assert path.stat().st_size > 100_000
    finally:
        path.unlink()


def test_results_show_is_an_inline_frame(crank):
    _, res = crank
    v = sd.show(res, height=400)
    html = v._repr_html_()
    assert html.startswith("<iframe srcdoc=") and "height:400px" in html
    assert "&lt;script" in html and "<script" not in html  # the page is escaped into srcdoc


def test_the_core_never_imports_the_viewer():
    code = ("import sys, se3dyn, se3dyn.io.modelfile, se3dyn.io.h5, se3dyn.cli.commands; "
            "m = sorted(k for k in sys.modules if k.startswith(('se3dyn.viewer', 'trimesh', "
            "'pygltflib'))); print(m); assert not m")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr


# ---------------------------------------------------------------------------------------------
# 7. beams: a tube along the centre line, following the nodes' frames, with the section
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def flexible():
    model, _ = load_model(Path(__file__).parent.parent / "examples" / "slider_crank_flexible.yaml")
    return model, sd.simulate(model, t_end=0.4, step=5e-3)


def _rings_at_nodes(tube, pos):
    """Vertices of the rings that sit exactly on a node (weight 0 or 1): node -> (..., k, 3)."""
    out = {}
    for side in (0, 1):
        on = tube.weight == side
        for i in np.unique(tube.nodes[on, side]):
            out.setdefault(int(i), []).append(pos[..., on & (tube.nodes[:, side] == i), :])
    return {i: np.concatenate(v, axis=-2) for i, v in out.items()}


def test_beam_tube_has_the_section_and_follows_the_nodes(flexible):
    """The connecting rod (d = 28 mm, 4 elements) is drawn: at every stored time the tube's
    rings at the beam nodes are circles of radius 14 mm centred on the node and normal to its
    section axis 1 (the beam's own frames), i.e. the tube follows the computed motion."""
    from se3dyn.viewer.shapes import tube_vertices

    model, res = flexible
    scene = build_scene(res)
    (tube,) = scene.tubes
    names = list(res.system.node_names)
    beam = model.beams[0]
    assert sorted(names[i] for i in np.unique(tube.nodes)) == sorted(beam.nodes)
    pos, nrm = tube_vertices(tube, res.H)  # (n, V, 3)
    rings = _rings_at_nodes(tube, pos)
    assert set(rings) == {names.index(b) for b in beam.nodes}
    for i, ring in rings.items():
        x = res.H[:, i, :3, 3]  # (n, 3)
        X = beam.offsets[beam.nodes.index(names[i])]
        axis1 = np.einsum("nij,j->ni", res.H[:, i, :3, :3], X[:3, 0])  # section axis 1
        r = ring - x[:, None, :]
        np.testing.assert_allclose(np.linalg.norm(r, axis=-1), 0.014, rtol=1e-9)
        np.testing.assert_allclose(np.einsum("nkj,nj->nk", r, axis1), 0.0, atol=1e-12)
        np.testing.assert_allclose(r.mean(axis=1), 0.0, atol=1e-12)
    # normals point outwards, unit
    w = np.stack([1 - tube.weight, tube.weight], -1)[:, :, None]  # (V, 2, 1)
    cen = np.sum(w * res.H[:, :, :3, 3][:, tube.nodes], axis=-2)  # (n, V, 3)
    assert np.all(np.einsum("...j,...j->...", nrm, pos - cen) > 0)
    # in the initial configuration the tube is the straight rod from node 5 to node 7
    x5, x7 = model.nodes[names.index("5")].position, model.nodes[names.index("7")].position
    u = (x7 - x5) / np.linalg.norm(x7 - x5)
    off = tube.bind - x5
    radial = off - np.outer(off @ u, u)
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), 0.014, rtol=1e-9)
    assert off @ u == pytest.approx(np.clip(off @ u, 0, np.linalg.norm(x7 - x5)), abs=1e-12)


def test_beam_section_is_the_ellipse_of_the_section_moments():
    from se3dyn.model.sections import rectangle
    from se3dyn.viewer.shapes import beam_section

    sec = rectangle(0.02, 0.06, E=70e9, nu=0.3, density=2700.0)  # width along 2, height along 3
    a2, a3 = beam_section(np.diag([sec["EA"], *sec["GA"], sec["GJ"], *sec["EI"]]))
    A, I2, I3 = 0.02 * 0.06, 0.02 * 0.06 ** 3 / 12, 0.06 * 0.02 ** 3 / 12
    # the solid ellipse with semi-axes a2, a3: I2 = A a3^2 / 4, I3 = A a2^2 / 4
    assert a3 ** 2 / 4 == pytest.approx(I2 / A) and a2 ** 2 / 4 == pytest.approx(I3 / A)
    assert a3 / a2 == pytest.approx(3.0)  # the height / width of the rectangle


def test_beam_in_the_page_and_in_gltf_skinned_on_its_nodes(tmp_path, flexible):
    """The page carries the tube; glTF carries it as a skin on the beam's nodes: skinning it as
    any glTF reader does (joint matrices from the animation, inverse bind matrices, weights)
    puts the rings on the nodes with the section's radius at a later stored time too."""
    pygltflib = pytest.importorskip("pygltflib")
    model, res = flexible
    meta = json.loads(re.search(r'id="se3dyn-meta"[^>]*>(.*?)</script>',
                                html_page(res), re.S).group(1))
    assert meta["tubes"] and "rod" in meta["tubes"][0]
    path = export_gltf(res, tmp_path / "flex.glb")
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()
    (skin,) = g.skins
    names = list(res.system.node_names)
    assert sorted(g.nodes[j].name for j in skin.joints) == sorted(model.beams[0].nodes)
    (mesh_node,) = [nd for nd in g.nodes if nd.skin is not None]
    prim = g.meshes[mesh_node.mesh].primitives[0]

    def acc(i, dt, comps):
        a = g.accessors[i]
        v = g.bufferViews[a.bufferView]
        return np.frombuffer(blob, dtype=dt, count=a.count * comps,
                             offset=v.byteOffset + (a.byteOffset or 0)).reshape(a.count, comps)

    bind = acc(prim.attributes.POSITION, np.float32, 3).astype(float)
    joints = acc(prim.attributes.JOINTS_0, np.uint16, 4)
    weights = acc(prim.attributes.WEIGHTS_0, np.float32, 4).astype(float)
    ibm = acc(skin.inverseBindMatrices, np.float32, 16).reshape(-1, 4, 4).transpose(0, 2, 1)
    k = len(res.t) - 1
    anim = g.animations[0]
    T = {}
    for ch in anim.channels:
        out = acc(anim.samplers[ch.sampler].output, np.float32,
                  3 if ch.target.path == "translation" else 4)[k]
        T.setdefault(ch.target.node, {})[ch.target.path] = out.astype(float)
    J = []
    for j in skin.joints:  # joint globals in the model's frame (the root rotation cancels out)
        Hj = np.eye(4)
        tr = T.get(j, {"translation": g.nodes[j].translation, "rotation": g.nodes[j].rotation})
        Hj[:3, :3] = Rotation.from_quat(tr["rotation"]).as_matrix()
        Hj[:3, 3] = tr["translation"]
        J.append(Hj)
    M = np.array(J) @ ibm
    b4 = np.column_stack([bind, np.ones(len(bind))])
    skinned = np.einsum("vc,vcij,vj->vi", weights, M[joints], b4)[:, :3]
    for jj, j in enumerate(skin.joints):
        sel = np.any((weights[:, :2] == 1.0) & (joints[:, :2] == jj), axis=1)
        assert sel.sum() >= 16
        i = names.index(g.nodes[j].name)
        r = skinned[sel] - res.H[k, i, :3, 3]
        np.testing.assert_allclose(np.linalg.norm(r, axis=1), 0.014, rtol=2e-4)
        np.testing.assert_allclose(r.mean(axis=0), 0.0, atol=1e-5)


def test_demo_model_visuals_lie_on_its_links_at_every_stored_time():
    """examples/slider_crank.yaml draws its crank, rod and slider: the crank cylinder ends at
    hinge (1) and joint (4), the rod capsule's tips at the rod's joint points (nodes 5 and 7),
    the slider box is centred on node 8, at every stored time (the shapes move with the
    bodies as the joints do)."""
    model, settings = load_model(Path(__file__).parent.parent / "examples" / "slider_crank.yaml")
    res = sd.simulate(model, t_end=0.5, step=1e-2)
    names = list(res.system.node_names)
    parts = {p.label.split("'")[1]: p for p in build_scene(res).parts if p.role == "visual"}
    assert set(parts) == {"crank", "rod", "slider"}
    x = res.H[:, :, :3, 3]

    def ends(part, half):
        P = part_pose(part, res.H[:, part.node])  # (n, 4, 4)
        return [np.einsum("nij,j->ni", P, [0, 0, s * half, 1])[:, :3] for s in (-1, 1)]

    crank = parts["crank"]
    lo, hi = ends(crank, 0.5)
    for e, node in ((lo, "2"), (hi, "4")):
        np.testing.assert_allclose(e, x[:, names.index(node)], atol=1e-9)
    rod = parts["rod"]
    r, length = rod.params
    a, b = ends(rod, 0.5 * length + r)  # the capsule's tips
    np.testing.assert_allclose(a, x[:, names.index("5")], atol=1e-9)
    np.testing.assert_allclose(b, x[:, names.index("7")], atol=1e-9)
    c = part_pose(parts["slider"], res.H[:, parts["slider"].node])[:, :3, 3]
    np.testing.assert_allclose(c, x[:, names.index("8")], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# 8. markers and drives (issue 30): triads moving with their nodes, collars on driven joints,
#    the drive's effort in the plot panel
# ---------------------------------------------------------------------------------------------
def driven_crank_model():
    """The paper's slider-crank with its crank driven up to 2 pi rad/s from rest, a marker on
    the connecting rod (rotated, off its node) and one on the ground."""
    mb = sd.ModelBuilder.from_model(sd.examples.slider_crank())
    mb.drive("motor", "1", velocity=sd.Ramp(2 * np.pi, 0.0, 0.2))
    R = Rotation.from_rotvec([0.3, -0.5, 0.8]).as_matrix()
    mb.marker("rod_mid", "6", offset=(0.05, 0.02, -0.01), orientation=R)
    mb.marker("base", "1")
    return mb.build()


@pytest.fixture(scope="module")
def driven_crank():
    model = driven_crank_model()
    return model, sd.simulate(model, t_end=0.5, step=1e-2)


def test_marker_triads_move_with_their_nodes(driven_crank):
    model, res = driven_crank
    scene = build_scene(res)
    assert scene.markers == [("rod_mid", 5), ("base", 0)]
    for name, i in scene.markers:
        parts = _parts(scene, "marker", f"marker {name!r} on node {model.marker(name).node!r}")
        assert len(parts) == 4 and {p.node for p in parts} == {i}
        dot = next(p for p in parts if p.kind == "sphere")
        axes = [p for p in parts if p.kind == "cylinder"]
        Hm = res.marker_frame(name)
        for k in (0, len(res) // 2, len(res) - 1):
            # the dot at the marker's origin, each arm along one marker axis, from the origin
            np.testing.assert_allclose(part_pose(dot, res.H[k, i])[:3, 3], Hm[k, :3, 3],
                                       atol=1e-12)
            for a, p in enumerate(axes):
                P = part_pose(p, res.H[k, i])
                arm = P[:3, 2] / np.linalg.norm(P[:3, 2])  # the cylinder's length axis
                np.testing.assert_allclose(arm, Hm[k, :3, a], atol=1e-12)
                start = P[:3, 3] - 0.5 * P[:3, 2]
                np.testing.assert_allclose(start, Hm[k, :3, 3], atol=1e-12)


def test_driven_joint_has_a_collar_on_its_axis_and_the_page_plots_its_effort(driven_crank,
                                                                             tmp_path):
    from se3dyn.results.channels import get_channel

    model, res = driven_crank
    scene = build_scene(res)
    collar = _parts(scene, "drive")
    assert [p.label for p in collar] == ["drive 'motor' on joint '1'"]
    # on node A of the hinge (the ground), centred on the joint point, along the hinge axis
    j = model.joint("1")
    c = collar[0]
    assert c.node == 0 and c.kind == "cylinder"
    P = part_pose(c, res.H[-1, 0])
    np.testing.assert_allclose(P[:3, 3], model.node(j.node_b).position, atol=1e-12)
    axis = P[:3, 2] / np.linalg.norm(P[:3, 2])
    assert abs(axis @ j.A[3:, 0]) == pytest.approx(1.0)
    assert scene.drives == [{"name": "motor", "joint": "1", "kind": "velocity",
                             "channel": "drive/motor/effort"}]
    tags = parse_page(html_page(res))
    meta = json.loads(tags.scripts["se3dyn-meta"]["text"])
    assert meta["markers"] == [{"name": "rod_mid", "node": 5}, {"name": "base", "node": 0}]
    assert meta["drives"] == scene.drives
    # the drive's effort is embedded and plotted first, in N m, with its values
    names = meta["channels"]["names"]
    assert meta["plot"] == "drive/motor/effort"
    k = names.index("drive/motor/effort")
    assert meta["channels"]["units"][k] == "N m"
    effort = get_channel(res, "drive/motor/effort")
    assert np.ptp(effort) > 0
    np.testing.assert_allclose(blob_of(tags, "channels")[k], effort, rtol=1e-6,
                               atol=1e-6 * np.abs(effort).max())
    assert "marker/rod_mid/accelerometer/x" in names and "drive/motor/power" in names
    assert {"marker 'rod_mid' on node '6'", "drive 'motor' on joint '1'"} <= set(meta["labels"])
    roles = blob_of(tags, "part_info")[:, 3]
    assert (roles == meta["roles"].index("marker")).sum() == 8
    assert (roles == meta["roles"].index("drive")).sum() == 1
    # the glTF file carries them too
    export_gltf(res, tmp_path / "driven.glb")
    import pygltflib

    g = pygltflib.GLTF2().load(str(tmp_path / "driven.glb"))
    assert sum(n.name == "drive 'motor' on joint '1'" for n in g.nodes) == 1
    assert sum((n.name or "").startswith("marker 'rod_mid'") for n in g.nodes) == 4


def test_models_without_markers_or_drives_keep_their_page(crank):
    _, res = crank
    meta = json.loads(parse_page(html_page(res)).scripts["se3dyn-meta"]["text"])
    assert meta["markers"] == [] and meta["drives"] == []
    assert meta["plot"] == "joint/1/alpha/0"
