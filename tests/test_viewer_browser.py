"""The viewer page in a real browser: headless Chromium (Debian's ``chromium``) driven through
the DevTools protocol over a pipe (``tests/_browser.py``; no browser is downloaded).

Facts checked: the page draws a non-blank picture, logs no console error and requests nothing
but its own file and the blob: URLs it makes; ``#t=SECONDS`` opens it paused at that time; the
pictures at two times differ where a body moved and agree pixel for pixel where nodes are fixed
(positions projected with the page's own camera); the frames decoded by the page's JavaScript
equal the results within the quantisation bounds; moving the scrubber moves time and changes the
picture; the notebook frame (``sd.show(result)``) renders too.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import se3dyn as sd
from _browser import Browser, find_chromium
from se3dyn.viewer import write_html
from se3dyn.viewer.encode import ANGLE_BOUND

pytestmark = pytest.mark.skipif(
    find_chromium() is None,
    reason="chromium is not installed (apt-get install chromium; .ci/run installs it)")

W, H = 1000, 700


@pytest.fixture(scope="module")
def browser():
    with Browser(W, H) as b:
        yield b


def pendulum():
    """A bob on a hinge about y through the origin, released horizontal, and a fixed post."""
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81), name="pendulum")
    mb.node("pivot", position=(0, 0, 0), fixed=True)
    mb.node("post", position=(0.9, 0.0, 0.6), fixed=True)
    mb.node("bob", position=(0.5, 0, 0), mass=1.0, inertia=(1e-3, 1e-2, 1e-2))
    mb.joint("hinge", "hinge", "pivot", "bob", axis=(0, 1, 0), at=(0, 0, 0))
    mb.visual("post", "post", "box", size=0.12, color="#2ca02c")
    mb.visual("ball", "bob", "sphere", size=0.07, color="#1f77b4")
    return mb.build()


@pytest.fixture(scope="module")
def pendulum_page(tmp_path_factory):
    model = pendulum()
    res = sd.simulate(model, t_end=0.6, step=1e-2)
    path = tmp_path_factory.mktemp("page") / "pendulum.html"
    write_html(res, path)
    return res, path


@pytest.fixture(scope="module")
def crank_page(tmp_path_factory):
    model = sd.examples.slider_crank()
    res = sd.simulate(model, t_end=1.0, step=1e-2)
    path = tmp_path_factory.mktemp("page") / "slider_crank.html"
    write_html(res, path)
    return res, path


def url(path: Path, t: float | None = None) -> str:
    u = path.resolve().as_uri()
    return u if t is None else f"{u}#t={t}"


def region(img: np.ndarray, xy, r: int = 4) -> np.ndarray:
    x, y = (int(round(c)) for c in xy)
    return img[y - r:y + r + 1, x - r:x + r + 1].astype(int)


def on_canvas(b: Browser, xy) -> bool:
    return b.evaluate(f"document.elementFromPoint({xy[0]}, {xy[1]}) === "
                      "document.querySelector('#stage canvas')")


def assert_clean(b: Browser) -> None:
    assert b.errors() == [], b.errors()
    foreign = [u for u in b.requests if not u.startswith(("file:", "blob:", "data:", "about:"))]
    assert foreign == []


# ---------------------------------------------------------------------------------------------
def test_console_errors_would_be_seen(browser):
    """The harness itself: a page that logs an error is caught (so 'no errors' means none)."""
    browser.open("data:text/html,<script>console.error('boom')</script><p>x",
                 ready="document.body !== null")
    assert any("boom" in e["text"] for e in browser.errors())
    browser.log.clear()


def test_page_renders_a_picture_without_errors_or_network(browser, crank_page):
    res, path = crank_page
    browser.log.clear()
    browser.requests.clear()
    browser.open(url(path, 0.5))
    img = browser.screenshot()
    stage = img[:H - 46]
    background = np.array([244, 245, 247])
    drawn = np.any(np.abs(stage.astype(int) - background) > 12, axis=-1)
    assert drawn.mean() > 0.04  # panels, grid and the mechanism (inertia boxes: outlines)
    colours = len(np.unique(stage.reshape(-1, 3), axis=0))
    assert colours > 200  # shaded solids, not a flat fill
    # the mechanism is drawn where the camera sees the node positions
    x = res.H[50, :, :3, 3]
    pts = [browser.evaluate(f"se3dyn.project({p[0]}, {p[1]}, {p[2]})") for p in x]
    hits = sum(bool(drawn[int(y), int(xx)]) for xx, y in pts if 0 <= y < H - 46 and 0 <= xx < W)
    assert hits >= len(pts) - 1
    assert_clean(browser)


def test_time_in_the_address_opens_paused_at_that_time(browser, crank_page):
    _, path = crank_page
    browser.open(url(path, 0.35))
    assert browser.evaluate("se3dyn.time()") == pytest.approx(0.35)
    assert browser.evaluate("se3dyn.state.playing") is False
    assert browser.evaluate("document.getElementById('time').textContent") == "t = 0.350 s"
    time.sleep(0.3)
    assert browser.evaluate("se3dyn.time()") == pytest.approx(0.35)
    # a new hash on the open page jumps there too
    browser.evaluate("location.hash = '#t=0.8'")
    browser.wait_for("Math.abs(se3dyn.time() - 0.8) < 1e-12", timeout=10)
    assert_clean(browser)


def test_page_decodes_the_results_frames(browser, crank_page):
    res, path = crank_page
    browser.open(url(path, 0))
    n, M = res.H.shape[:2]
    span = np.ptp(res.H[:, :, :3, 3], axis=0)  # (M, 3)
    for k in (0, n // 3, n - 1):
        got = np.array(browser.evaluate(
            f"Array.from({{length: {M}}}, (_, i) => se3dyn.nodePosition(i, {k}))"))
        # quantisation (span / 131070) plus float32 storage in the page
        tol = span / 131070 + 1e-6 * (1 + np.abs(res.H[k, :, :3, 3]))
        assert np.all(np.abs(got - res.H[k, :, :3, 3]) <= tol)
        q = np.array(browser.evaluate(
            f"Array.from({{length: {M}}}, (_, i) => se3dyn.nodeQuaternion(i, {k}))"))
        ang = (Rotation.from_quat(q).inv() * Rotation.from_matrix(res.H[k, :, :3, :3]))
        assert ang.magnitude().max() <= ANGLE_BOUND + 1e-6


def test_two_times_differ_where_bodies_moved_and_agree_where_nodes_are_fixed(
        browser, pendulum_page):
    res, path = pendulum_page
    names = res.system.node_names
    bob0 = res.H[0, names.index("bob"), :3, 3]
    bob1 = res.H[-1, names.index("bob"), :3, 3]
    assert np.linalg.norm(bob1 - bob0) > 0.3  # the bob did swing away
    browser.open(url(path, 0))
    img0 = browser.screenshot()
    project = lambda p: browser.evaluate(f"se3dyn.project({p[0]}, {p[1]}, {p[2]})")  # noqa: E731
    glyph = browser.evaluate("se3dyn.meta.glyph")
    plate = (0.9, 0.0, 0.6 - 2.2 * glyph)  # the ground symbol under the fixed post
    at_bob0, at_bob1, at_post, at_plate = (project(p) for p in (bob0, bob1, (0.9, 0.0, 0.6),
                                                                plate))
    for xy in (at_bob0, at_bob1, at_post, at_plate):
        assert on_canvas(browser, xy)
    browser.open(url(path, float(res.t[-1])))
    assert project(bob0) == pytest.approx(at_bob0)  # same camera
    img1 = browser.screenshot()
    # where the bob was (and went), the pictures differ
    assert np.abs(region(img0, at_bob0) - region(img1, at_bob0)).mean() > 25
    assert np.abs(region(img0, at_bob1) - region(img1, at_bob1)).mean() > 25
    # at the fixed post and its ground symbol they are the same, pixel for pixel
    assert np.abs(region(img0, at_post) - region(img1, at_post)).max() <= 2
    assert np.abs(region(img0, at_plate, 2) - region(img1, at_plate, 2)).max() <= 2
    assert np.abs(region(img0, at_plate, 2) - [244, 245, 247]).mean() > 40  # drawn, not empty
    # the post is drawn there, in its colour (green dominates)
    r, g, b = region(img0, at_post, 2).reshape(-1, 3).mean(axis=0)
    assert g > r + 30 and g > b + 10
    assert_clean(browser)


def test_moving_the_scrubber_changes_the_frame(browser, pendulum_page):
    res, path = pendulum_page
    browser.open(url(path, 0))
    before = browser.screenshot()
    rect = json.loads(browser.evaluate(
        "JSON.stringify(document.getElementById('scrub').getBoundingClientRect())"))
    frame0 = browser.evaluate("document.getElementById('frame').textContent")
    browser.click(rect["left"] + 0.75 * rect["width"], rect["top"] + rect["height"] / 2)
    browser.frames()
    t0, t1 = float(res.t[0]), float(res.t[-1])
    t = browser.evaluate("se3dyn.time()")
    assert t == pytest.approx(t0 + 0.75 * (t1 - t0), abs=0.05 * (t1 - t0))
    assert browser.evaluate("document.getElementById('frame').textContent") != frame0
    after = browser.screenshot()
    bob0 = res.H[0, res.system.node_names.index("bob"), :3, 3]
    at_bob0 = browser.evaluate(f"se3dyn.project({bob0[0]}, {bob0[1]}, {bob0[2]})")
    assert np.abs(region(before, at_bob0) - region(after, at_bob0)).mean() > 25
    # the plot's time cursor moved with it
    prect = json.loads(browser.evaluate(
        "JSON.stringify(document.getElementById('plot-canvas').getBoundingClientRect())"))
    y0, y1 = int(prect["top"]), int(prect["bottom"])
    x0, x1 = int(prect["left"]), int(prect["right"])
    assert np.abs(before[y0:y1, x0:x1].astype(int) - after[y0:y1, x0:x1]).max() > 50
    # the paused time is in the address, for sharing
    assert browser.evaluate("location.hash").startswith("#t=0.4")
    assert_clean(browser)


def test_playing_advances_time_and_toggles_redraw(browser, pendulum_page):
    res, path = pendulum_page
    browser.open(url(path))  # no time in the address: it plays
    start = browser.evaluate("se3dyn.time()")
    # (the 0.6-s run loops: "time > start + 0.05" could never hold once start was past 0.55 s,
    # as it was when a loaded machine drew the first frames late; a change of time is playing)
    browser.wait_for(f"se3dyn.time() !== {start}", timeout=60)
    assert browser.evaluate("se3dyn.state.playing") is True
    browser.evaluate("se3dyn.pause(), se3dyn.setTime(0.3)")
    browser.frames()
    plain = browser.screenshot()
    for box in ("show-frames", "show-traces"):
        browser.evaluate(f"document.getElementById('{box}').click()")
        browser.frames()
        shown = browser.screenshot()
        assert np.abs(shown.astype(int) - plain).max() > 50, box
        plain = shown
    assert_clean(browser)


def test_hover_names_a_body_and_a_click_toggles_its_trace(browser, pendulum_page):
    res, path = pendulum_page
    browser.open(url(path, 0))
    bob = res.H[0, res.system.node_names.index("bob"), :3, 3]
    x, y = browser.evaluate(f"se3dyn.project({bob[0]}, {bob[1]}, {bob[2]})")
    assert browser.evaluate("[...se3dyn.state.traces].map(i => se3dyn.meta.nodes[i])") == ["bob"]
    browser.call("Input.dispatchMouseEvent", session=True, type="mouseMoved", x=x, y=y,
                 button="none")
    browser.wait_for("!document.getElementById('tooltip').hidden", timeout=10)
    assert browser.evaluate("document.getElementById('tooltip').textContent") == \
        "visual 'ball' (sphere) on node 'bob'"
    browser.click(x, y)
    browser.frames()
    assert browser.evaluate("se3dyn.state.traces.size") == 0
    assert browser.evaluate("document.getElementById('show-traces').checked") is True
    browser.click(x, y)
    assert browser.evaluate("[...se3dyn.state.traces].map(i => se3dyn.meta.nodes[i])") == ["bob"]
    assert_clean(browser)


def test_notebook_frame_renders(browser, pendulum_page, tmp_path):
    res, _ = pendulum_page
    page = tmp_path / "notebook.html"
    page.write_text("<!doctype html><html><body>" + sd.show(res, height=500)._repr_html_()
                    + "</body></html>", encoding="utf-8")
    browser.open(page.as_uri(), ready="(() => { const f = document.querySelector('iframe'); "
                 "return f && f.contentDocument && "
                 "f.contentDocument.documentElement.dataset.ready === '1'; })()")
    assert_clean(browser)


def test_chain_of_1000_links_loads_and_plays(browser, tmp_path):
    """The scale case: 1000 links, 1000 stored times (synthetic swinging motion)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        from chain_scaling import chain
    finally:
        sys.path.pop(0)
    model = chain(1000)
    s = sd.compile_model(model)
    n, M = 1000, len(model.nodes)
    t = np.linspace(0.0, 1.0, n)
    # every link turns about y by its own angle: a travelling wave down the chain
    ang = 0.6 * np.sin(2 * np.pi * (t[:, None] - np.arange(M)[None, :] / 200.0))
    Hs = np.zeros((n, M, 4, 4))
    Hs[..., :3, :3] = Rotation.from_rotvec(
        np.stack([np.zeros_like(ang), ang, np.zeros_like(ang)], axis=-1).reshape(-1, 3)
    ).as_matrix().reshape(n, M, 3, 3)
    x0 = np.array([nd.position for nd in model.nodes])
    Hs[..., :3, 3] = x0[None] + np.stack([np.zeros_like(ang), np.zeros_like(ang),
                                           0.05 * ang], axis=-1)
    Hs[..., 3, 3] = 1.0
    z = np.zeros(n)
    res = sd.Results(system=s, t=t, H=Hs, v=np.zeros((n, s.nq)), vd=np.zeros((n, s.nq)),
                     lam=np.zeros((n, s.nm)), alpha=np.zeros((n, s.nq)), kinetic=z, potential=z,
                     spring=z, work_actuators=z, work_loads=z, dissipation=z,
                     iterations=np.zeros(n, int), residual=z, constraint=z)
    path = write_html(res, tmp_path / "chain.html", model=model)
    assert path.stat().st_size <= 20_000_000
    start = time.monotonic()
    browser.open(url(path, 0.5), timeout=90)
    loaded = time.monotonic() - start
    assert loaded < 60
    img = browser.screenshot()
    assert len(np.unique(img[:H - 46].reshape(-1, 3), axis=0)) > 100
    # the page's own work per frame (interpolating 1001 frames, 4000 instance matrices) is a
    # few ms; the drawing itself is the graphics card's (software GL in this test, so it is
    # only required to finish)
    per_frame = browser.evaluate("""(() => {
        const t0 = performance.now();
        for (let k = 0; k < 20; k++) se3dyn.setTime(0.2 + 0.01 * k);
        return (performance.now() - t0) / 20; })()""")
    assert per_frame < 50
    browser.frames()
    assert_clean(browser)


@pytest.fixture(scope="module")
def flexible_page(tmp_path_factory):
    from se3dyn.io.modelfile import load_model

    model, _ = load_model(Path(__file__).resolve().parents[1] / "examples"
                          / "slider_crank_flexible.yaml")
    res = sd.simulate(model, t_end=0.4, step=5e-3)
    path = tmp_path_factory.mktemp("page") / "slider_crank_flexible.html"
    write_html(res, path)
    return model, res, path


def test_the_flexible_connecting_rod_is_drawn_with_its_section(browser, flexible_page):
    """examples/slider_crank_flexible.yaml: the beam (d = 28 mm) is drawn where its nodes are,
    as wide as its section seen from the camera, and nowhere beside it; the page's tube
    vertices are the Python scene's skinning of the results' frames."""
    model, res, path = flexible_page
    names = list(res.system.node_names)
    k = 60  # t = 0.3 s, a stored time
    browser.open(url(path, float(res.t[k])))
    img = browser.screenshot()
    background = np.array([244, 245, 247])
    project = lambda p: np.array(browser.evaluate(  # noqa: E731
        f"se3dyn.project({p[0]}, {p[1]}, {p[2]})"))
    x = {nm: res.H[k, names.index(nm), :3, 3] for nm in ("rod/1", "rod/2", "rod/3")}
    for nm, p in x.items():  # interior beam nodes: no body, glyph or link there, only the rod
        xy = project(p)
        assert on_canvas(browser, xy), nm
        rgb = region(img, xy, 1).reshape(-1, 3).mean(axis=0)
        assert np.abs(rgb - background).max() > 40, (nm, rgb)
        assert rgb[2] >= rgb[0] - 5, (nm, rgb)  # the rod's steel blue-grey, not the orange crank
    # across the rod at its midpoint: drawn over the projected diameter, background beyond
    a, b, c = project(x["rod/1"]), project(x["rod/2"]), project(x["rod/3"])
    d = (c - a) / np.linalg.norm(c - a)
    nrm = np.array([-d[1], d[0]])  # screen normal of the rod
    u = (x["rod/3"] - x["rod/1"]) / np.linalg.norm(x["rod/3"] - x["rod/1"])
    e1 = np.cross(u, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    ang = np.linspace(0, np.pi, 37)
    width = max(abs((project(x["rod/2"] + 0.014 * (np.cos(t) * e1 + np.sin(t) * e2)) - b) @ nrm)
                for t in ang) * 2
    assert width > 6  # pixels: the 28 mm rod is resolved
    s = np.arange(-3 * width, 3 * width + 1, 0.5)
    pts = np.rint(b[None, :] + s[:, None] * nrm[None, :]).astype(int)
    drawn = np.abs(img[pts[:, 1], pts[:, 0]].astype(int) - background).max(axis=1) > 25
    covered = np.ptp(s[drawn]) if drawn.any() else 0.0
    assert covered == pytest.approx(width, rel=0.3)
    # the page's tube is the scene's, skinned on the decoded frames
    from se3dyn.viewer.shapes import build_scene, tube_vertices

    (tube,) = build_scene(res).tubes
    want, _ = tube_vertices(tube, res.H[k])
    got = np.array(browser.evaluate("se3dyn.tubePositions()")).reshape(-1, 3)
    span = np.ptp(res.H[:, :, :3, 3], axis=0).max()
    assert np.abs(got - want).max() < span / 131070 + 0.014 * 2 * ANGLE_BOUND + 1e-6
    assert_clean(browser)


def _seg_dist(p, a, b):
    """Distance of the point p from the segment a-b (screen pixels)."""
    ab = b - a
    t = np.clip((p - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(a + t * ab - p))


def test_default_inertia_box_is_an_outline_while_links_are_drawn(browser, crank_page):
    """The slider-crank without visuals: the connecting rod's equivalent inertia box (Table 3 on
    the inertial axes, lying across the mechanism) is drawn as its 12 edges while the joints and
    links are shown: inside its outline the picture is the background; hiding the links draws
    the solid box there, in the body's colour."""
    from itertools import product

    from se3dyn.viewer.shapes import build_scene, part_pose

    res, path = crank_page
    k = 50
    browser.open(url(path, float(res.t[k])))
    scene = build_scene(res)
    names = list(res.system.node_names)
    (box,) = [p for p in scene.parts if p.role == "body" and p.node == names.index("6")]
    P = part_pose(box, res.H[k, box.node])
    project = lambda x: np.array(browser.evaluate(  # noqa: E731
        f"se3dyn.project({x[0]}, {x[1]}, {x[2]})"))
    corners = [P[:3, :3] @ (np.array(c) - 0.5) + P[:3, 3] for c in product((0, 1), repeat=3)]
    sc = [project(c) for c in corners]
    edges = [(a, b) for a in range(8) for b in range(8) if a < b and bin(a ^ b).count("1") == 1]
    # the drawn segments that are not the box: links and joints, between the node positions
    x = res.H[k, :, :3, 3]
    others = [(project(x[i]), project(x[j])) for i in range(len(x)) for j in range(len(x))
              if i < j and np.linalg.norm(x[i] - x[j]) > 0]
    best = None
    for u, v, w in product(np.linspace(0.2, 0.8, 7), repeat=3):
        q = project(P[:3, :3] @ (np.array([u, v, w]) - 0.5) + P[:3, 3])
        d = min([_seg_dist(q, sc[a], sc[b]) for a, b in edges]
                + [_seg_dist(q, a, b) - 25 for a, b in others])
        if best is None or d > best[0]:
            best = (d, q)
    d, q = best
    assert d > 8 and on_canvas(browser, q)
    outlined = browser.screenshot()
    inside = region(outlined, q, 2).reshape(-1, 3).mean(axis=0)
    assert np.abs(inside - [244, 245, 247]).max() < 30, inside  # empty inside the outline
    # an edge of the outline is drawn, in a colour of its own (not the background)
    a, b = edges[0]
    mid = 0.5 * (sc[a] + sc[b])
    line = [np.abs(region(outlined, mid + t * (sc[b] - sc[a]), 1).astype(int)
                   - [244, 245, 247]).max() for t in np.linspace(-0.3, 0.3, 7)]
    assert max(line) > 40
    browser.evaluate("document.getElementById('show-joints').click()")
    browser.frames()
    solid = browser.screenshot()
    r, g, bl = region(solid, q, 2).reshape(-1, 3).mean(axis=0)
    assert np.abs(np.array([r, g, bl]) - [244, 245, 247]).max() > 60  # the solid box is there
    want = np.array([int(box.color[i:i + 2], 16) for i in (1, 3, 5)])
    assert np.argmax([r, g, bl]) == np.argmax(want)  # in the body's dominant colour
    browser.evaluate("document.getElementById('show-joints').click()")
    assert_clean(browser)


def test_markers_and_drives_are_drawn_listed_and_plotted(browser, tmp_path):
    # the driven slider-crank of tests/test_viewer.py: a marker triad on the connecting rod,
    # an orange collar on the driven crank, the drive listed and its effort plotted
    from test_viewer import driven_crank_model

    model = driven_crank_model()
    res = sd.simulate(model, t_end=0.5, step=1e-2)
    path = tmp_path / "driven.html"
    write_html(res, path)
    browser.log.clear()
    browser.open(url(path, 0.3))
    assert browser.evaluate("se3dyn.markers.map(m => m.name)") == ["rod_mid", "base"]
    assert browser.evaluate("se3dyn.partsOfRole('marker')") == 8
    assert browser.evaluate("se3dyn.partsOfRole('drive')") == 1
    assert browser.evaluate("se3dyn.plotted()") == "drive/motor/effort"
    assert browser.evaluate("document.getElementById('marker-list').textContent") == \
        "rod_mid, base"
    link = "document.querySelector('#drives a.drive')"
    assert browser.evaluate(f"{link}.textContent") == "motor"
    # another channel, then the drive's name plots its effort again
    assert browser.evaluate("se3dyn.selectChannel('energy/total')") is True
    browser.evaluate(f"{link}.click()")
    assert browser.evaluate("se3dyn.plotted()") == "drive/motor/effort"
    assert browser.evaluate("document.getElementById('plot-msg').textContent") == ""
    # the marker is drawn where the camera sees it: hiding the markers changes the picture there
    browser.frames()
    shown = browser.screenshot()
    k = int(np.argmin(np.abs(res.t - 0.3)))
    p = res.marker_position("rod_mid")[k]
    xy = browser.evaluate(f"se3dyn.project({p[0]}, {p[1]}, {p[2]})")
    assert on_canvas(browser, xy)
    browser.evaluate("document.getElementById('show-markers').click()")
    browser.frames()
    assert browser.evaluate("se3dyn.partsOfRole('marker')") == 0
    hidden = browser.screenshot()
    assert np.abs(region(shown, xy, 6) - region(hidden, xy, 6)).max() > 50
    assert_clean(browser)
