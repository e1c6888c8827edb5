"""Visual shapes of nodes: what a picture of the model draws, kept apart from the physics.

A :class:`VisualSpec` attaches a shape to a node (``ModelBuilder.visual``, the ``visuals:``
section of a model file). It never enters the equations: :func:`se3dyn.engine.system.compile_model`
ignores it and only the viewer (:mod:`se3dyn.viewer`) reads it. Without visuals the viewer draws
a default picture from the masses, inertias and joints (see :mod:`se3dyn.viewer.shapes`).

Frames. A shape is placed in the *material frame of its node*: the shape's own frame is
``H_node(t) @ H(orientation, offset)``; at t0 a node without an initial ``orientation`` has its
material axes along the inertial axes, so ``offset`` and ``axis`` are then simply inertial
directions of the initial configuration.

Shapes and their ``size`` (SI units, metres), in the shape's own frame:

========== =========================== ==================================================
shape      size                        geometry
========== =========================== ==================================================
box        (a, b, c) or a              side lengths along x, y, z (a cube for one number)
sphere     r                           radius
cylinder   (r, length)                 radius, length along z (centred on the origin)
capsule    (r, length)                 radius, distance between the two hemisphere centres,
                                       along z (total length ``length + 2 r``)
mesh       s or (sx, sy, sz), def. 1   scale of the mesh file's coordinates (STL, OBJ, glTF)
========== =========================== ==================================================
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from se3dyn.errors import ModelError, close_matches

__all__ = ["VisualSpec", "SHAPES", "MESH_SUFFIXES", "COLORS", "make_visual", "visual_to_dict",
           "axis_rotation"]

#: Shapes and the number of ``size`` values stored (after expanding a single number).
SHAPES: dict[str, int] = {"box": 3, "sphere": 1, "cylinder": 2, "capsule": 2, "mesh": 3}
#: Mesh file types the viewer reads (through trimesh).
MESH_SUFFIXES = (".stl", ".obj", ".gltf", ".glb")
#: Colour names accepted besides ``#rrggbb`` and three numbers in [0, 1].
COLORS: dict[str, str] = {
    "black": "#000000", "white": "#ffffff", "grey": "#808080", "gray": "#808080",
    "lightgrey": "#d3d3d3", "darkgrey": "#404040", "red": "#d62728", "green": "#2ca02c",
    "blue": "#1f77b4", "orange": "#ff7f0e", "purple": "#9467bd", "brown": "#8c564b",
    "pink": "#e377c2", "olive": "#bcbd22", "cyan": "#17becf", "yellow": "#ffd700",
    "steel": "#4682b4", "gold": "#daa520", "silver": "#c0c0c0",
}
_SIZE_TEXT = {
    "box": "3 side lengths (a, b, c) > 0, or one (a cube)",
    "sphere": "a radius > 0",
    "cylinder": "(radius, length) > 0",
    "capsule": "(radius, length) > 0 (length between the hemisphere centres)",
    "mesh": "a scale > 0 or 3 scales (sx, sy, sz)",
}


@dataclass(frozen=True)
class VisualSpec:
    """A shape drawn with a node (pictures only; no mass, no contact).

    Attributes
    ----------
    name, node, shape : str
        Unique visual name, the node it moves with, one of :data:`SHAPES`.
    size : ndarray, shape (SHAPES[shape],)
        Box (a, b, c); sphere (r,); cylinder and capsule (r, length); mesh scales (3,).
    color : str or None
        ``"#rrggbb"``; None: the viewer's palette colour of the node.
    offset : ndarray, shape (3,)
        Origin of the shape in the material frame of the node (m).
    orientation : ndarray, shape (3, 3)
        Rotation of the shape's frame in the material frame of the node (columns: the shape's
        axes); for a cylinder or capsule its third column is the shape's axis.
    file : str or None
        Mesh file (``shape="mesh"`` only), as given; a relative path is looked up by the viewer
        next to the model file.
    """

    name: str
    node: str
    shape: str
    size: np.ndarray
    color: str | None
    offset: np.ndarray
    orientation: np.ndarray
    file: str | None = None


def _arc(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation taking unit b to unit a (b . a > -1/2, well conditioned)."""
    v = np.cross(b, a)
    V = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + V + V @ V / (1.0 + float(b @ a))


def axis_rotation(axis: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) whose third column is the direction ``axis`` (3,): the shortest arc from
    e_z to it; for axes in the lower half-space, a half turn about x followed by the shortest arc
    from -e_z (so that the formula never divides by a small ``1 + cos``)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    ez = np.array([0.0, 0.0, 1.0])
    if a[2] >= 0.0:
        return _arc(ez, a)
    return _arc(-ez, a) @ np.diag([1.0, -1.0, -1.0])


def _color(item: str, color: Any) -> str | None:
    expected = ("'#rrggbb', '#rgb', a colour name (" + ", ".join(sorted(COLORS)) +
                ") or 3 numbers in [0, 1]")
    if color is None:
        return None
    if isinstance(color, str):
        c = color.strip().lower()
        if c in COLORS:
            return COLORS[c]
        if re.fullmatch(r"#[0-9a-f]{6}", c):
            return c
        if re.fullmatch(r"#[0-9a-f]{3}", c):
            return "#" + "".join(ch * 2 for ch in c[1:])
        raise ModelError(item, "color", expected, color)
    try:
        rgb = np.asarray(color, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, "color", expected, color) from None
    if rgb.shape != (3,) or not np.all(np.isfinite(rgb)) or rgb.min() < 0 or rgb.max() > 1:
        raise ModelError(item, "color", expected, color)
    return "#" + "".join(f"{round(255 * x):02x}" for x in rgb)


def _vec3(item: str, fld: str, v: Any) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, fld, "3 numbers", v) from None
    if a.shape != (3,):
        raise ModelError(item, fld, "3 numbers", v)
    if not np.all(np.isfinite(a)):
        raise ModelError(item, fld, "3 finite numbers", v)
    return a


def _shown(v: Any) -> Any:
    """An array argument as a nested list, so error messages stay on one line."""
    try:
        return np.asarray(v, dtype=float).tolist()
    except (TypeError, ValueError):
        return v


def make_visual(name: str, node: str, shape: str, *, size: Any = None, color: Any = None,
                offset: Any = None, orientation: Any = None, axis: Any = None,
                file: Any = None) -> VisualSpec:
    """Validate the arguments of ``ModelBuilder.visual`` and return the :class:`VisualSpec`
    (the node's existence is checked by the builder). Errors name the visual and the field."""
    if not isinstance(name, str) or not name:
        raise ModelError("visual", "name", "a non-empty string", name)
    if shape not in SHAPES:
        close = close_matches(str(shape), list(SHAPES), n=1)
        raise ModelError(f"visual {name!r}", "shape", "one of " + ", ".join(SHAPES), shape,
                         f"did you mean '{close[0]}'?" if close else "")
    item = f"visual {name!r} ({shape})"
    n = SHAPES[shape]
    if size is None:
        if shape != "mesh":
            raise ModelError(item, "size", _SIZE_TEXT[shape], None, "a size is required")
        sz = np.ones(3)
    else:
        try:
            sz = np.atleast_1d(np.asarray(size, dtype=float))
        except (TypeError, ValueError):
            raise ModelError(item, "size", _SIZE_TEXT[shape], size) from None
        if sz.ndim != 1 or not np.all(np.isfinite(sz)) or np.any(sz <= 0):
            raise ModelError(item, "size", _SIZE_TEXT[shape], _shown(size))
        if len(sz) == 1 and shape in ("box", "mesh"):
            sz = np.repeat(sz, 3)
        if len(sz) != n:
            raise ModelError(item, "size", _SIZE_TEXT[shape], size)
    off = np.zeros(3) if offset is None else _vec3(item, "offset", offset)
    if orientation is not None and axis is not None:
        raise ModelError(item, "axis", "either 'axis' or 'orientation', not both", axis)
    if axis is not None:
        a = _vec3(item, "axis", axis)
        if not np.linalg.norm(a) > 0:
            raise ModelError(item, "axis", "a non-zero direction", axis)
        R = axis_rotation(a)
    elif orientation is not None:
        try:
            R = np.asarray(orientation, dtype=float)
        except (TypeError, ValueError):
            raise ModelError(item, "orientation", "a 3x3 rotation matrix", orientation) from None
        if (R.shape != (3, 3) or not np.all(np.isfinite(R))
                or np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0):
            raise ModelError(item, "orientation", "a 3x3 rotation matrix (orthonormal, det +1)",
                             _shown(orientation))
    else:
        R = np.eye(3)
    fname = None
    if shape == "mesh":
        if not isinstance(file, str) or not file.strip():
            raise ModelError(item, "file", "a mesh file name (" + ", ".join(MESH_SUFFIXES) + ")",
                             file)
        if not file.lower().endswith(MESH_SUFFIXES):
            raise ModelError(item, "file", "a mesh file name ending in " +
                             ", ".join(MESH_SUFFIXES), file)
        fname = file
    elif file is not None:
        raise ModelError(item, "file", "no file (only a 'mesh' shape reads a file)", file)
    return VisualSpec(name, node, shape, sz, _color(item, color), off, R, fname)


def visual_to_dict(v: VisualSpec) -> dict:
    """The model-file mapping of a visual (inverse of loading its ``visuals:`` entry)."""
    d: dict[str, Any] = {"node": v.node, "shape": v.shape}
    size = [float(x) for x in v.size]
    if v.shape in ("box", "mesh") and len(set(size)) == 1:
        size = size[:1]
    if not (v.shape == "mesh" and size == [1.0]):
        d["size"] = size[0] if len(size) == 1 else size
    if v.color is not None:
        d["color"] = v.color
    if np.any(v.offset != 0):
        d["offset"] = [float(x) for x in v.offset]
    if not np.array_equal(v.orientation, np.eye(3)):
        d["orientation"] = v.orientation.astype(float).tolist()
    if v.file is not None:
        d["file"] = v.file
    return d

