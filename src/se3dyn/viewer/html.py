"""The viewer page: one self-contained HTML file per result.

The page holds, inline:

* ``#se3dyn-meta``: JSON with the times, node names, position bounds, the geometries, labels,
  the embedded channel names and units, what to show first, and the markers and drives drawn
  (names; their shapes are parts, roles ``marker`` and ``drive``);
* ``#se3dyn-blob-NAME``: base64 of deflated typed arrays (:mod:`se3dyn.viewer.encode`):
  ``frames`` (quantised node frames, uint16 (n, M, 6)), ``part_matrix`` (float32 (P, 12): the
  first three rows of ``matrix @ diag(scale, 1)`` of every part), ``part_info`` (int32 (P, 5):
  node, geometry, colour 0xRRGGBB, role, label), ``channels`` (float32 (C, n)),
  ``mesh<k>_v`` (float32 (nv, 3)) / ``mesh<k>_f`` (uint32 (nf, 3)) per mesh file, and the
  beams' tubes (:class:`~se3dyn.viewer.shapes.Tube`, all beams in one mesh): ``tube_node``
  (int32 (V, 2)), ``tube_w`` (float32 (V,)), ``tube_p`` and ``tube_n`` (float32 (V, 6): the
  vertex and its normal in the frames of the two nodes), ``tube_rgb`` (uint8 (V, 3)) and
  ``tube_f`` (uint32 (F, 3));
* three.js (``three.core.js``, ``three.module.js``) and ``OrbitControls.js``, vendored from the
  npm package ``three`` (see ``static/README.md`` and ``static/LICENSE-three.txt``), deflated;
* the application module ``static/viewer.js`` and a small loader that inflates the libraries into
  ``blob:`` module URLs and imports them: nothing is fetched from the network.

Node positions and displacements are computed by the page from the frames; other channels are
embedded up to ``channel_budget`` bytes (float32), or as chosen with ``channels=``.
"""

from __future__ import annotations

import fnmatch
import html
import json
import os
import re
import zlib
from base64 import b64encode
from functools import lru_cache
from pathlib import Path

import numpy as np

from se3dyn.viewer.encode import encode_frames, pack
from se3dyn.viewer.errors import ViewerError
from se3dyn.viewer.shapes import ROLES, Scene, build_scene, rgb

__all__ = ["html_page", "write_html", "page_data", "THREE_VERSION", "STATIC"]

#: Version of the vendored three.js (npm package ``three``).
THREE_VERSION = "0.187.0"
STATIC = Path(__file__).parent / "static"
#: Default budget of embedded channels (bytes of float32 before compression).
CHANNEL_BUDGET = 4_000_000
#: The page stays below this size (bytes): the channel budget shrinks to fit beside the frames.
PAGE_LIMIT = 20_000_000
_PAGE_MARGIN = 800_000  # metadata, labels, page code
_LIBS = (("se3dyn-lib-three-core", "three.core.js"),
         ("se3dyn-lib-three-module", "three.module.js"),
         ("se3dyn-lib-orbit-controls", "OrbitControls.js"))
# channels in the order they are embedded when no pattern is given (positions and displacements
# are computed in the page from the frames)
_PRIORITY = ("energy/*", "solver/*", "drive/*", "joint/*/alpha/*", "joint/*/velocity/*",
             "joint/*/actuator/*", "joint/*/spring/*", "spring/*",
             "node/*/velocity/inertial/*", "node/*/velocity/material/*",
             "node/*/acceleration/*", "marker/*/position/*", "marker/*/accelerometer/*",
             "marker/*/gyroscope/*", "joint/*/multiplier/*", "node/*/rotation/*")
_DERIVED = ("node/*/position/*", "node/*/displacement/*")
# joint channels with one value per coordinate, whose unit follows the coordinate's
_PER_COORDINATE = ("alpha", "velocity", "torque", "actuator", "spring")


@lru_cache(maxsize=1)
def _libraries() -> str:
    """The vendored scripts as deflated base64 blocks (computed once per process)."""
    out = []
    for ident, fname in _LIBS:
        data = (STATIC / fname).read_bytes()
        text = b64encode(zlib.compress(data, 9)).decode("ascii")
        out.append(f'<script type="application/octet-stream" id="{ident}">{text}</script>')
    return "\n".join(out)


def _static_text(name: str) -> str:
    return (STATIC / name).read_text(encoding="utf-8")


def _json(obj) -> str:
    """JSON safe inside a <script> element."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def _units(res, names: list[str]) -> list[str]:
    """Units of channels (as :func:`se3dyn.results.channels.channel_unit`), the joint units computed
    once for all joint channels."""
    from se3dyn.results.channels import channel_unit, joint_units, unescape_name

    s = res.system
    per_dof = joint_units(s)
    k = np.asarray(s.joint_k, dtype=int)
    start = np.cumsum(k) - k
    out = []
    for c in names:
        parts = c.split("/")
        unit = channel_unit(c, res) if parts[0] == "drive" else channel_unit(c)
        if parts[0] == "joint" and len(parts) == 4 and parts[2] in _PER_COORDINATE:
            cols = [u for j in res._joints(unescape_name(parts[1]))
                    for u in per_dof[start[j]:start[j] + k[j]]]
            u = cols[int(parts[3])] if int(parts[3]) < len(cols) and cols[int(parts[3])] else ""
            if u:
                unit = {"alpha": u, "velocity": u + "/s"}.get(
                    parts[2], {"rad": "N m", "m": "N"}.get(u, unit))
        out.append(unit)
    return out


def _matcher(patterns):
    rx = re.compile("|".join(f"(?:{fnmatch.translate(p)})" for p in patterns))
    return lambda name: rx.match(name) is not None


def _channels(res, patterns, budget: int) -> tuple[list[str], list[str], np.ndarray, str]:
    from se3dyn.results.channels import get_channel, list_channels

    every = list_channels(res)
    is_derived = _matcher(_DERIVED)
    derived = [c for c in every if is_derived(c)]
    skip = set(derived) | {"time"}
    pool = [c for c in every if c not in skip]
    n = len(res.t)
    chosen: list[str] = []
    seen: set[str] = set()
    if patterns is not None:
        for pat in patterns:
            if any(ch in pat for ch in "*?["):
                m = _matcher([pat])
                hits = [c for c in pool if m(c)]
                known = bool(hits) or any(m(d) for d in derived)
            else:
                hits = [pat] if pat in pool else []
                known = bool(hits) or pat in derived
            if not known:
                import difflib

                close = difflib.get_close_matches(pat, every, n=1)
                raise ViewerError(f"channel: field 'name': expected a channel or pattern of the "
                                  f"results (see 'se3dyn channels'), got {pat!r}"
                                  + (f" (did you mean '{close[0]}'?)" if close else ""))
            for h in hits:
                if h not in seen:
                    seen.add(h)
                    chosen.append(h)
    else:
        cap = max(0, budget // max(4 * n, 1))
        for pat in _PRIORITY:
            m = _matcher([pat])
            for c in pool:
                if len(chosen) >= cap:
                    break
                if c not in seen and m(c):
                    seen.add(c)
                    chosen.append(c)
    data = np.zeros((len(chosen), n), dtype=np.float32)
    for k, c in enumerate(chosen):
        data[k] = np.asarray(get_channel(res, c), dtype=float)
    units = _units(res, chosen)
    left = len(pool) - len(chosen)
    note = ""
    if left > 0:
        note = (f"{len(chosen)} of {len(pool)} channels embedded (plus node positions and "
                f"displacements); others: se3dyn view --channel PATTERN")
    return chosen, units, data, note


def _default_plot(res, scene: Scene, names: list[str], data: np.ndarray) -> str | None:
    from se3dyn.results.channels import escape_name

    for d in scene.drives:  # a driven model: what its first drive supplies
        if d["channel"] in names:
            return d["channel"]
    for k, c in enumerate(names):
        if c.startswith("joint/") and "/alpha/" in c and np.ptp(data[k]) > 0:
            return c
    for i in scene.bodies:
        if not scene.node_fixed[i]:
            p = res.H[:, i, :3, 3]
            a = int(np.argmax(np.ptp(p, axis=0))) if len(p) else 2
            return f"node/{escape_name(scene.node_names[i])}/position/{'xyz'[a]}"
    return "energy/total" if "energy/total" in names else (names[0] if names else None)


def page_data(res, scene: Scene, *, channels=None, plot=None,
              channel_budget: int = CHANNEL_BUDGET, title=None) -> tuple[dict, list]:
    """The page's JSON metadata and its data blocks (:class:`~se3dyn.viewer.encode.Blob`)."""
    from se3dyn._version import __version__

    t = np.asarray(res.t, dtype=float)
    n, M = len(t), len(scene.node_names)
    if n == 0:
        raise ViewerError("results: field 't': expected at least one stored time, got none")
    words, lo, hi = encode_frames(res.H)
    blobs = [pack("frames", words, delta=True)]
    # parts
    keys: list[str] = []
    geoms: list[dict] = []
    labels: list[str] = []
    P = len(scene.parts)
    mats = np.zeros((P, 12), dtype=np.float32)
    info = np.zeros((P, 5), dtype=np.int32)
    for p, part in enumerate(scene.parts):
        key = part.geometry_key
        if key not in keys:
            keys.append(key)
            g: dict = {"key": key, "kind": part.kind}
            if part.kind == "capsule":
                g["params"] = [float(x) for x in part.params]
            if part.kind == "mesh":
                g["mesh"] = part.mesh
            geoms.append(g)
        if part.label not in labels:
            labels.append(part.label)
        A = part.matrix @ np.diag(np.append(np.asarray(part.scale, dtype=float), 1.0))
        mats[p] = A[:3].reshape(12)
        r, gg, b = rgb(part.color)
        info[p] = (part.node, keys.index(key), (r << 16) | (gg << 8) | b, ROLES.index(part.role),
                   labels.index(part.label))
    blobs += [pack("part_matrix", mats), pack("part_info", info)]
    tubes = scene.tubes
    if tubes:
        first = np.cumsum([0] + [len(tb.weight) for tb in tubes])
        rgbs = np.concatenate([np.tile(rgb(tb.color), (len(tb.weight), 1)) for tb in tubes])
        blobs += [
            pack("tube_node", np.concatenate([tb.nodes for tb in tubes]).astype(np.int32)),
            pack("tube_w", np.concatenate([tb.weight for tb in tubes]).astype(np.float32)),
            pack("tube_p", np.concatenate([tb.local.reshape(-1, 6) for tb in tubes])
                 .astype(np.float32)),
            pack("tube_n", np.concatenate([tb.normal.reshape(-1, 6) for tb in tubes])
                 .astype(np.float32)),
            pack("tube_rgb", rgbs.astype(np.uint8)),
            pack("tube_f", np.concatenate([tb.faces + f for tb, f in zip(tubes, first,
                                                                          strict=False)])
                 .astype(np.uint32))]
    for k, (V, F) in enumerate(scene.meshes):
        blobs += [pack(f"mesh{k}_v", np.asarray(V, dtype=np.float32)),
                  pack(f"mesh{k}_f", np.asarray(F, dtype=np.uint32))]
    # channels fill what the page limit leaves (base64 of incompressible float32 at worst)
    used = sum(len(b.text) for b in blobs) + len(_libraries()) + _PAGE_MARGIN
    budget = min(channel_budget, max(0, (PAGE_LIMIT - used) * 3 // 4))
    names, units, data, note = _channels(res, channels, budget)
    if len(names):
        blobs.append(pack("channels", data))
    if plot is None:
        plot = _default_plot(res, scene, names, data)
    colors: list[str | None] = [None] * M
    for part in scene.parts:
        if part.role in ("body", "visual") and colors[part.node] is None:
            colors[part.node] = part.color
    # bounds of the drawing: node positions over the run and the body sizes
    ext = max([float(np.max(np.abs(p.scale))) if p.kind != "capsule" else
               float(p.params[1] + 2.0 * p.params[0]) for p in scene.parts
               if p.role in ("body", "visual") and p.kind != "mesh"] + [2.0 * scene.glyph])
    blo, bhi = scene.lo - 0.5 * ext, scene.hi + 0.5 * ext
    path = (res.stats or {}).get("path")
    meta = {
        "format": 1,
        "title": title or (scene.model_name + (f" \u2014 {Path(path).name}" if path else "")),
        "se3dyn": __version__,
        "t": t.tolist(),
        "nodes": list(scene.node_names),
        "fixed": [bool(x) for x in scene.node_fixed],
        "lo": lo.reshape(-1).tolist(), "hi": hi.reshape(-1).tolist(),
        "up": scene.up.tolist(), "gravity": scene.gravity.tolist(), "glyph": scene.glyph,
        "bounds": {"lo": blo.tolist(), "hi": bhi.tolist()},
        "geometries": geoms, "roles": list(ROLES), "labels": labels,
        "meshes": len(scene.meshes),
        "tubes": [tb.label for tb in scene.tubes],
        "bodies": list(scene.bodies), "traces": list(scene.traces), "colors": colors,
        "channels": {"names": names, "units": units, "note": note},
        "plot": plot,
        "notes": list(scene.notes),
        "markers": [{"name": name, "node": i} for name, i in scene.markers],
        "drives": list(scene.drives),
        "counts": {"nodes": M, "joints": len(res.system.joint_names), "parts": P},
    }
    return meta, blobs


def html_page(res, *, model=None, model_path=None, channels=None, plot=None, traces=None,
              title=None, channel_budget: int = CHANNEL_BUDGET, mesh_dirs=()) -> str:
    """The viewer page of ``res`` (see :func:`write_html` for the parameters)."""
    scene = build_scene(res, model, model_path=model_path, mesh_dirs=mesh_dirs, traces=traces)
    meta, blobs = page_data(res, scene, channels=channels, plot=plot,
                            channel_budget=channel_budget, title=title)
    app = _static_text("viewer.js")
    if "</script" in app.lower():  # pragma: no cover - guards edits of viewer.js
        raise RuntimeError("viewer.js must not contain '</script'")
    blocks = "\n".join(f'<script type="application/octet-stream" {b.attrs()}>{b.text}</script>'
                       for b in blobs)
    page = _static_text("page.html")
    from se3dyn._version import __version__

    for token, value in (("@@SE3DYN_VERSION@@", html.escape(__version__)),
                         ("@@THREE_VERSION@@", THREE_VERSION),
                         ("@@TITLE@@", html.escape(meta["title"])),
                         ("@@META@@", _json(meta)), ("@@BLOBS@@", blocks),
                         ("@@LIBS@@", _libraries()), ("@@APP@@", app)):
        page = page.replace(token, value, 1)
    return page


def write_html(res, path, **kwargs) -> Path:
    """Write the self-contained viewer page of a result.

    Parameters
    ----------
    res : Results
        In memory, or read with :func:`se3dyn.io.h5.read_results`.
    path : path
        The HTML file to write.
    model : Model, optional
        The model to draw (default: the result's own, or the model stored in its file).
    model_path : path, optional
        Take the model (visuals, joints, inertias) from this model file instead; its node names
        must be the results'. Relative mesh files are looked up next to it.
    channels : list of str, optional
        Channels or shell-style patterns (``'joint/*/alpha/*'``) to embed for the plot (default:
        energies, solver, joint coordinates and velocities, node velocities, ... up to
        ``channel_budget`` bytes). Node positions and displacements are always available.
    plot : str, optional
        The channel plotted first (default: the first moving joint coordinate).
    traces : list of str, optional
        Nodes whose traces are offered first (default: the bodies if at most six, else the last).
    title : str, optional
    channel_budget : int
        Bytes (float32) of channels embedded when ``channels`` is not given.
    mesh_dirs : sequence of path
        More folders to look for relative mesh files in.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ViewerError
        Bad channel or trace names, missing mesh files, a model not matching the results.
    """
    page = html_page(res, **kwargs)
    p = Path(path)
    try:
        p.write_text(page, encoding="utf-8")
    except OSError as e:
        raise ViewerError(f"output: field 'path': expected a writable file, got {os.fspath(p)!r} "
                          f"({e.strerror})") from None
    return p
