"""Reading a URDF file into plain records (:class:`Robot`), every value checked where it is
read: an error is one line naming the file, the element and the field.

The XML is read by the standard library's expat parser through ``defusedxml``, which refuses
entity declarations (the "billion laughs" expansion, external entities) before anything is
expanded (docs/design.md, "URDF import", has the measurements behind the choice). Tags that
nothing maps are collected, by path, in :class:`Ignored` and reported once by the importer.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from se3dyn.errors import ModelError
from se3dyn.io.urdf.geometry import frame, rpy_matrix

#: The most links a URDF may have: the largest model se3dyn is tested with is the
#: 10^4-link chain (tests/test_determinism.py); beyond it the file is refused while it is read.
MAX_LINKS = 10_000
#: URDF joint types (the ROS specification) and the loop-closure types se3dyn accepts.
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
LOOP_TYPES = ("revolute", "continuous", "prismatic", "fixed", "spherical", "ball")
#: URIs that name Drake's URDF extensions whatever their prefix.
DRAKE_URIS = ("http://drake.mit.edu", "https://drake.mit.edu")


class UrdfError(ModelError):
    """A URDF file se3dyn cannot read: the message names the file, the element and the field."""


@dataclass
class Inertial:
    """``<inertial>``: mass (kg), the frame of the centre of mass in the link frame (4, 4)
    and the inertia tensor (3, 3) about the centre of mass in that frame."""

    mass: float
    T: np.ndarray
    inertia: np.ndarray


@dataclass
class Visual:
    """``<visual>``: a shape in the link frame (pose ``T`` (4, 4)); ``size`` as the viewer takes
    it (box sides, sphere radius, cylinder (radius, length), mesh scale); ``file`` as written."""

    name: str
    T: np.ndarray
    shape: str
    size: tuple
    file: str | None = None
    color: tuple | None = None


@dataclass
class Link:
    name: str
    inertial: Inertial | None
    visuals: list[Visual] = field(default_factory=list)
    #: ``<collision>`` meshes (no contact yet: drawn where a visual mesh cannot be)
    collisions: list[Visual] = field(default_factory=list)


@dataclass
class Joint:
    """``<joint>``: ``T`` the pose of the joint frame in the parent link frame (``<origin>``),
    ``axis`` a unit vector of the joint frame; ``limit`` the ``<limit>`` attributes given."""

    name: str
    type: str
    parent: str
    child: str
    T: np.ndarray
    axis: np.ndarray
    limit: dict = field(default_factory=dict)
    damping: float = 0.0
    friction: float = 0.0
    mimic: tuple | None = None  # (leader, multiplier, offset)


@dataclass
class Loop:
    """A loop closure: a joint of ``type`` between the frames ``T1`` on ``link1`` and ``T2`` on
    ``link2`` (each in its link's frame), which coincide when the loop is closed; ``axis`` in
    the frame on ``link1``."""

    name: str
    type: str
    link1: str
    T1: np.ndarray
    link2: str
    T2: np.ndarray
    axis: np.ndarray
    source: str


@dataclass
class Ignored:
    """What the file says and nothing maps: tag path -> the items holding it."""

    where: dict = field(default_factory=dict)

    def add(self, path: str, owner: str) -> None:
        self.where.setdefault(path, []).append(owner)

    def lines(self) -> list[str]:
        out = []
        for path, owners in self.where.items():
            shown = ", ".join(dict.fromkeys(owners))
            if len(shown) > 80:
                shown = shown[:77] + "..."
            reason = _REASONS.get(path.rsplit("/", 1)[-1], "not mapped")
            out.append(f"{path} x{len(owners)} ({shown}): {reason}")
        return out


_REASONS = {
    "<collision>": "collision geometry (no contact yet: issue 33)",
    "<gazebo>": "Gazebo simulator settings",
    "<transmission>": "ROS control transmissions (actuators are se3dyn's own: PD/PID, drives)",
    "<calibration>": "calibration reference positions",
    "<safety_controller>": "soft limits of the ROS safety controller",
    "<texture>": "textures (the viewer draws colours)",
}


@dataclass
class Robot:
    name: str
    links: dict[str, Link]
    joints: dict[str, Joint]
    loops: list[Loop]
    ignored: Ignored
    file: str
    #: the inertias made physical (``load_urdf(..., inertia="repair")``), one line each
    repaired: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------------------------
class _Ctx:
    """The file being read: its name for messages, the namespace prefixes it declares."""

    def __init__(self, file: str, prefixes: dict[str, str], repair: bool = False):
        self.file = file
        self.prefixes = prefixes  # uri -> prefix
        self.ignored = Ignored()
        #: inertias no body can have: repaired (and listed here) rather than refused
        self.repair = repair
        self.repaired: list[str] = []

    def fail(self, item: str, fld: str, expected: str, got=None, hint: str = ""):
        raise UrdfError(f"{self.file}: {item}", fld, expected, got, hint)

    def tag(self, el) -> str:
        """``local``, or ``prefix:local`` for a namespaced tag."""
        t = el.tag
        if not isinstance(t, str):
            return "#comment"
        if t.startswith("{"):
            uri, local = t[1:].split("}", 1)
            prefix = "drake" if uri in DRAKE_URIS else self.prefixes.get(uri, uri)
            return f"{prefix}:{local}"
        return t

    def floats(self, text, n: int, item: str, fld: str, default=None, bound=1e15
               ) -> np.ndarray:
        if text is None:
            if default is None:
                self.fail(item, fld, f"{n} numbers", None, "missing")
            return np.array(default, dtype=float)
        try:
            a = np.array([float(x) for x in str(text).split()], dtype=float)
        except ValueError:
            self.fail(item, fld, f"{n} numbers", text)
        if a.shape != (n,) or not np.all(np.isfinite(a)) or (
                bound is not None and np.any(np.abs(a) > bound)):
            self.fail(item, fld, f"{n} finite numbers" + (f" of magnitude at most {bound:g}"
                                                         if bound else ""), text)
        return a

    def number(self, el, attr: str, item: str, fld: str, default=None) -> float:
        v = None if el is None else el.get(attr)
        if v is None and default is not None:
            return float(default)
        return float(self.floats(v, 1, item, fld)[0])

    def name(self, el, kind: str, where: str) -> str:
        n = el.get("name")
        if not n or not n.isprintable() or len(n) > 200:
            self.fail(f"<{kind}> {where}", "name", "a non-empty printable name of at most 200 "
                      "characters", n)
        return n

    def unknown(self, el, known: tuple, path: str, owner: str) -> None:
        for ch in el:
            t = self.tag(ch)
            if t != "#comment" and t not in known:
                self.ignored.add(f"{path}/<{t}>", owner)


def origin(ctx: _Ctx, el, item: str, fld: str = "<origin>") -> np.ndarray:
    """The pose (4, 4) an ``<origin xyz rpy>`` child of ``el`` gives (identity if absent)."""
    o = el.find("origin") if el is not None else None
    if o is None:
        return np.eye(4)
    xyz = ctx.floats(o.get("xyz"), 3, item, f"{fld} xyz", default=(0.0, 0.0, 0.0))
    rpy = ctx.floats(o.get("rpy"), 3, item, f"{fld} rpy", default=(0.0, 0.0, 0.0))
    return frame(rpy_matrix(rpy), xyz)


# ---------------------------------------------------------------------------------------------
def read_xml(path: str):
    """Parse ``path`` with entity declarations refused; returns ``(root, {uri: prefix})``.
    Refuses files with more than :data:`MAX_LINKS` links while reading them."""
    import xml.etree.ElementTree as ET

    try:
        from defusedxml import DefusedXmlException
        from defusedxml.ElementTree import iterparse
    except ImportError:
        raise UrdfError("load_urdf", "defusedxml", "the package defusedxml (pip install "
                        "'se3dyn[urdf]'), which guards the XML parser", None) from None

    file = os.path.basename(str(path))
    prefixes, root, links = {}, None, 0
    try:
        for event, item in iterparse(str(path), events=("start-ns", "start")):
            if event == "start-ns":
                prefixes[item[1]] = item[0]
                continue
            if root is None:
                root = item
            elif item.tag == "link":
                links += 1
                if links > MAX_LINKS:
                    raise UrdfError(file, "<link>", f"at most {MAX_LINKS} links (the largest "
                                    "model se3dyn is tested with)", f"more than {MAX_LINKS}")
    except DefusedXmlException as exc:
        raise UrdfError(file, "<!ENTITY>", "a URDF without entity declarations (refused: "
                        "entity expansion can exhaust memory, external entities read other "
                        "files)", type(exc).__name__, str(exc)) from None
    except ET.ParseError as exc:
        raise UrdfError(file, "XML", "well-formed XML", str(exc)) from None
    except OSError as exc:
        raise UrdfError(file, "path", "a readable URDF file", str(path),
                        exc.strerror or str(exc)) from None
    return root, prefixes


def read_robot(path: str, extra=None, repair_inertia: bool = False) -> Robot:
    """Read ``path`` into a :class:`Robot` (links, joints, and the loop closures declared in
    it: ``extra(ctx, element, tag, loops) -> bool`` reads a top-level tag into ``loops``,
    :func:`se3dyn.io.urdf.loops.read_loop_tags`); ``repair_inertia``: inertia tensors no body
    can have made physical (:func:`physical_inertia`) and listed in ``Robot.repaired``."""
    root, prefixes = read_xml(path)
    ctx = _Ctx(os.path.basename(str(path)), prefixes, repair_inertia)
    if ctx.tag(root) != "robot":
        ctx.fail("root element", "tag", "<robot>", f"<{ctx.tag(root)}>")
    materials = _materials(ctx, root)
    links: dict[str, Link] = {}
    joints: dict[str, Joint] = {}
    loops: list[Loop] = []
    for el in root:
        t = ctx.tag(el)
        if t == "link":
            lk = _link(ctx, el, materials)
            if lk.name in links:
                ctx.fail(f"link {lk.name!r}", "name", "a unique link name", lk.name,
                         "defined twice")
            links[lk.name] = lk
        elif t == "joint":
            jt = _joint(ctx, el)
            if jt.name in joints:
                ctx.fail(f"joint {jt.name!r}", "name", "a unique joint name", jt.name,
                         "defined twice")
            joints[jt.name] = jt
        elif t == "material" or t == "#comment":
            continue
        elif extra is None or not extra(ctx, el, t, loops):
            ctx.ignored.add(f"<robot>/<{t}>", root.get("name") or "robot")
    return Robot(root.get("name") or "robot", links, joints, loops, ctx.ignored, ctx.file,
                 ctx.repaired)


def _materials(ctx: _Ctx, root) -> dict[str, tuple]:
    """Named ``<material>`` colours declared at the top level."""
    out = {}
    for m in root.findall("material"):
        c = _color(ctx, m, f"<material> {m.get('name')!r}")
        if m.get("name") and c is not None:
            out[m.get("name")] = c
    return out


def _color(ctx: _Ctx, mat, item: str):
    c = mat.find("color")
    if c is None:
        if mat.find("texture") is not None:
            ctx.ignored.add("<material>/<texture>", item)
        return None
    rgba = ctx.floats(c.get("rgba"), 4, item, "<color> rgba", default=(0.5, 0.5, 0.5, 1.0))
    return tuple(float(min(max(x, 0.0), 1.0)) for x in rgba[:3])


def _link(ctx: _Ctx, el, materials: dict) -> Link:
    name = ctx.name(el, "link", "")
    item = f"link {name!r}"
    ctx.unknown(el, ("inertial", "visual", "collision"), "<link>", name)
    collisions = []
    for i, c in enumerate(el.findall("collision")):
        ctx.ignored.add("<link>/<collision>", name)
        try:
            col = _visual(ctx, c, f"{item} <collision> {i}", materials, "<collision>")
        except UrdfError:
            col = None  # (only ever drawn; its element is in the report)
        if col is not None and col.shape == "mesh":
            collisions.append(col)
    inertials = el.findall("inertial")
    if len(inertials) > 1:
        ctx.fail(item, "<inertial>", "at most one <inertial>", len(inertials))
    inertial = _inertial(ctx, inertials[0], item) if inertials else None
    visuals = []
    for i, v in enumerate(el.findall("visual")):
        vis = _visual(ctx, v, f"{item} <visual> {i}", materials)
        if vis is not None:
            visuals.append(vis)
    return Link(name, inertial, visuals, collisions)


def _inertial(ctx: _Ctx, el, item: str) -> Inertial:
    """Mass >= 0 and an inertia tensor that a mass distribution can have (positive definite
    with mass, principal moments meeting the triangle inequality), checked here."""
    ctx.unknown(el, ("origin", "mass", "inertia"), "<inertial>", item)
    T = origin(ctx, el, item, "<inertial><origin>")
    m_el = el.find("mass")
    if m_el is None:
        ctx.fail(item, "<inertial><mass>", "a <mass value=...> element", None, "missing")
    m = ctx.number(m_el, "value", item, "<inertial><mass> value")
    if m < 0:
        ctx.fail(item, "<inertial><mass> value", "a non-negative mass (kg)", m)
    i_el = el.find("inertia")
    vals = {}
    for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
        vals[k] = ctx.number(i_el, k, item, f"<inertia> {k}", default=0.0)
    J = np.array([[vals["ixx"], vals["ixy"], vals["ixz"]],
                  [vals["ixy"], vals["iyy"], vals["iyz"]],
                  [vals["ixz"], vals["iyz"], vals["izz"]]])
    _check_inertia(ctx, item, m, J)
    return Inertial(m, T, J)


#: An inertia tensor whose entries are all below this (kg m^2) with a mass is a point mass
#: (1 g in a ball of 1 mm radius has 4e-10 kg m^2; real files write zeros or round-off).
POINT_MASS = 1e-12


def is_point_mass(inertial: Inertial | None) -> bool:
    """A mass with no rotational inertia (sensor frames of real URDFs): valid on a link
    fixed to another, which the importer then lumps into it."""
    return inertial is not None and inertial.mass > 0 and bool(np.all(inertial.inertia == 0))


def _check_inertia(ctx: _Ctx, item: str, m: float, J: np.ndarray) -> None:
    if m > 0 and np.abs(J).max() < POINT_MASS:
        J[:] = 0.0  # a point mass
        return
    if m == 0:
        if np.any(J != 0) and ctx.repair:
            J[:] = 0.0
            ctx.repaired.append(f"{item}: an inertia without mass dropped")
        elif np.any(J != 0):
            ctx.fail(item, "<inertia>", "no inertia on a link without mass (URDF mass 0)",
                     J.tolist(), "give the link its mass, or remove the inertia")
        return
    ev = np.linalg.eigvalsh(J)
    bad = ev[0] <= 0 or ev[2] > (ev[0] + ev[1]) * (1 + 1e-9)
    if bad and ctx.repair:
        J[:], new = physical_inertia(J)
        ctx.repaired.append(f"{item}: principal moments {_g(ev)} -> {_g(new)} kg m^2")
        return
    if ev[0] <= 0:
        ctx.fail(item, "<inertia>", "a positive-definite inertia tensor", J.tolist(),
                 f"principal moments {ev.tolist()}; load_urdf(..., inertia='repair') "
                 "makes such tensors physical and lists them")
    if bad:
        ctx.fail(item, "<inertia>", "principal moments satisfying the triangle inequality "
                 "J3 <= J1 + J2 of a real body", J.tolist(),
                 f"principal moments {ev.tolist()}: no mass distribution has them; "
                 "load_urdf(..., inertia='repair') makes such tensors physical and lists them")


def _g(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def physical_inertia(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nearest inertia tensor a body can have, with the same principal axes: principal
    moments raised to at least 1e-3 of the largest (a thin rod's ratio), then the two smaller
    ones raised equally until ``J3 <= J1 + J2`` (equality: a plate). Returns the tensor (3, 3)
    and its principal moments (3,)."""
    ev, V = np.linalg.eigh(0.5 * (J + J.T))
    top = max(float(ev[2]), 1e-300)
    ev = np.maximum(ev, 1e-3 * top)
    gap = ev[2] - ev[0] - ev[1]
    if gap > 0:
        ev[:2] += 0.5 * gap
    ev[2] = min(ev[2], ev[0] + ev[1])
    return (V * ev) @ V.T, ev


def _visual(ctx: _Ctx, el, item: str, materials: dict, tag: str = "<visual>"
            ) -> Visual | None:
    if tag == "<visual>":
        ctx.unknown(el, ("origin", "geometry", "material"), tag, item)
    T = origin(ctx, el, item, f"{tag}<origin>")
    g = el.find("geometry")
    shape = None if g is None else next((c for c in g if ctx.tag(c) != "#comment"), None)
    if shape is None:
        ctx.fail(item, "<geometry>", "a box, cylinder, sphere or mesh", None, "missing")
    color = None
    mat = el.find("material")
    if mat is not None:
        color = _color(ctx, mat, item)
        if color is None:
            color = materials.get(mat.get("name") or "")
    kind = ctx.tag(shape)
    name = el.get("name") or ""
    if kind == "box":
        return Visual(name, T, "box", tuple(ctx.floats(shape.get("size"), 3, item, "<box> size")),
                      color=color)
    if kind == "sphere":
        return Visual(name, T, "sphere", (ctx.number(shape, "radius", item, "<sphere> radius"),),
                      color=color)
    if kind in ("cylinder", "capsule"):
        return Visual(name, T, kind, (ctx.number(shape, "radius", item, f"<{kind}> radius"),
                                      ctx.number(shape, "length", item, f"<{kind}> length")),
                      color=color)
    if kind == "mesh":
        fname = shape.get("filename")
        if not fname:
            ctx.fail(item, "<mesh> filename", "a mesh file name", fname)
        scale = tuple(ctx.floats(shape.get("scale"), 3, item, "<mesh> scale",
                                 default=(1.0, 1.0, 1.0)))
        return Visual(name, T, "mesh", scale, fname, color)
    ctx.ignored.add(f"{tag}/<geometry>/<{kind}>", item)
    return None


def _joint(ctx: _Ctx, el) -> Joint:
    name = ctx.name(el, "joint", "")
    typ = el.get("type")
    item = f"joint {name!r} ({typ})"
    if typ not in JOINT_TYPES:
        ctx.fail(f"joint {name!r}", "type", "one of " + ", ".join(JOINT_TYPES), typ)
    ctx.unknown(el, ("origin", "parent", "child", "axis", "limit", "dynamics", "mimic",
                     "calibration", "safety_controller"), "<joint>", name)
    for t in ("calibration", "safety_controller"):
        if el.find(t) is not None:
            ctx.ignored.add(f"<joint>/<{t}>", name)
    ends = []
    for t in ("parent", "child"):
        e = el.find(t)
        if e is None or not e.get("link"):
            ctx.fail(item, f"<{t}> link", "the name of a link", None, "missing")
        ends.append(e.get("link"))
    T = origin(ctx, el, item)
    axis = ctx.floats(el.find("axis").get("xyz") if el.find("axis") is not None else None,
                      3, item, "<axis> xyz", default=(1.0, 0.0, 0.0))
    n = float(np.linalg.norm(axis))
    if typ not in ("fixed", "floating") and not n > 1e-12:
        ctx.fail(item, "<axis> xyz", "a non-zero axis", " ".join(f"{x:g}" for x in axis))
    axis = axis / n if n > 1e-12 else np.array([1.0, 0.0, 0.0])
    jt = Joint(name, typ, ends[0], ends[1], T, axis, _limit(ctx, el, item))
    dyn = el.find("dynamics")
    jt.damping = ctx.number(dyn, "damping", item, "<dynamics> damping", default=0.0)
    jt.friction = ctx.number(dyn, "friction", item, "<dynamics> friction", default=0.0)
    for fld, v in (("damping", jt.damping), ("friction", jt.friction)):
        if v < 0:
            ctx.fail(item, f"<dynamics> {fld}", "a non-negative number", v)
    mim = el.find("mimic")
    if mim is not None:
        if not mim.get("joint"):
            ctx.fail(item, "<mimic> joint", "the name of the joint it follows", None)
        jt.mimic = (mim.get("joint"), ctx.number(mim, "multiplier", item, "<mimic> multiplier",
                                                 default=1.0),
                    ctx.number(mim, "offset", item, "<mimic> offset", default=0.0))
    return jt


def _limit(ctx: _Ctx, el, item: str) -> dict:
    lim = el.find("limit")
    out = {}
    if lim is None:
        return out
    for k in ("lower", "upper", "effort", "velocity"):
        if lim.get(k) is not None:  # any finite number (+-1e16: "no limit" in some files)
            out[k] = float(ctx.floats(lim.get(k), 1, item, f"<limit> {k}", bound=None)[0])
    for k in ("effort", "velocity"):
        if out.get(k, 0.0) < 0:
            ctx.fail(item, f"<limit> {k}", "a non-negative number", out[k])
    if "lower" in out and "upper" in out and out["lower"] > out["upper"]:
        ctx.fail(item, "<limit> lower", f"at most upper = {out['upper']:g}", out["lower"])
    return out
