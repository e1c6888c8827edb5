"""Loop closures: URDF describes a tree, so a closed loop is declared beside it and becomes an
exact se3dyn joint between two links.

Accepted, all giving a :class:`~se3dyn.io.urdf.parse.Loop` (the frames on both links, which
coincide when the loop is closed):

* Isaac Sim's ``<loop_joint name= type=>`` with ``<link1 link= xyz= rpy=/>`` and
  ``<link2 .../>`` (types ``spherical``, ``fixed``, ``revolute``, ``prismatic``; an optional
  ``<axis xyz=/>`` in the frame on link1, URDF's default ``1 0 0`` otherwise);
* Drake's ``<drake:ball_constraint>`` (``drake:ball_constraint_body_A name=``,
  ``..._body_B``, ``..._p_AP value=``, ``..._p_BQ``): a spherical joint at the points;
* se3dyn's ``<se3dyn:loop>`` (any namespace URI bound to the prefix ``se3dyn``), written as
  Isaac's tag, with every type of :data:`~se3dyn.io.urdf.parse.LOOP_TYPES`;
* the ``loops=`` argument of :func:`~se3dyn.io.urdf.load_urdf`: a list of dicts, or a YAML
  or JSON side file with a ``loops:`` list, each entry as the tag:
  ``{name, type, link1: {link, xyz, rpy}, link2: {link, xyz, rpy}, axis}``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from se3dyn.io.urdf.geometry import frame, rpy_matrix
from se3dyn.io.urdf.parse import LOOP_TYPES, Loop, UrdfError


def read_loop_tags(ctx, el, tag: str, loops: list) -> bool:
    """Add the loop closure ``el`` declares to ``loops``; False if it is no loop tag."""
    if tag in ("loop_joint", "se3dyn:loop"):
        loops.append(_two_sided(ctx, el, tag))
        return True
    if tag == "drake:ball_constraint":
        loops.append(_drake_ball(ctx, el, len(loops)))
        return True
    return False


def _two_sided(ctx, el, tag: str) -> Loop:
    name = ctx.name(el, tag, "")
    typ = el.get("type")
    item = f"<{tag}> {name!r}"
    if typ not in LOOP_TYPES:
        ctx.fail(item, "type", "one of " + ", ".join(LOOP_TYPES), typ)
    ends = []
    for side in ("link1", "link2"):
        e = el.find(side)
        if e is None or not e.get("link"):
            ctx.fail(item, f"<{side}> link", "the name of a link", None, "missing")
        xyz = ctx.floats(e.get("xyz"), 3, item, f"<{side}> xyz", default=(0.0, 0.0, 0.0))
        rpy = ctx.floats(e.get("rpy"), 3, item, f"<{side}> rpy", default=(0.0, 0.0, 0.0))
        ends += [e.get("link"), frame(rpy_matrix(rpy), xyz)]
    ax = el.find("axis")
    axis = ctx.floats(None if ax is None else ax.get("xyz"), 3, item, "<axis> xyz",
                      default=(1.0, 0.0, 0.0))
    return Loop(name, typ, *ends, _unit(axis, lambda: ctx.fail(item, "<axis> xyz", "a non-zero "
                                                               "axis", axis.tolist())),
                f"<{tag}>")


def _drake_ball(ctx, el, i: int) -> Loop:
    item = f"<drake:ball_constraint> {i}"
    parts = {}
    for ch in el:
        t = ctx.tag(ch)
        if t.startswith("drake:ball_constraint_"):
            parts[t[len("drake:ball_constraint_"):]] = ch
    vals = {}
    for key in ("body_A", "body_B"):
        ch = parts.get(key)
        v = None if ch is None else (ch.get("name") or (ch.text or "").strip())
        if not v:
            ctx.fail(item, f"drake:ball_constraint_{key}", "the name of a link", None)
        vals[key] = v
    for key in ("p_AP", "p_BQ"):
        ch = parts.get(key)
        txt = None if ch is None else (ch.get("value") or ch.text)
        vals[key] = ctx.floats(txt, 3, item, f"drake:ball_constraint_{key}")
    name = f"ball:{vals['body_A']}:{vals['body_B']}"
    return Loop(name, "spherical", vals["body_A"], frame(np.eye(3), vals["p_AP"]),
                vals["body_B"], frame(np.eye(3), vals["p_BQ"]), np.array([1.0, 0.0, 0.0]),
                "<drake:ball_constraint>")


def _unit(a: np.ndarray, fail) -> np.ndarray:
    n = float(np.linalg.norm(a))
    if not n > 1e-12:
        fail()
    return a / n


# ---------------------------------------------------------------------------------------------
def loops_argument(loops, ctx) -> list[Loop]:
    """The ``loops=`` argument: None, a list of dicts, or a YAML/JSON side file."""
    if loops is None:
        return []
    where = "loops"
    if isinstance(loops, str | os.PathLike):
        where = os.path.basename(str(loops))
        loops = _side_file(Path(loops))
    if not isinstance(loops, list | tuple):
        raise UrdfError(where, "loops", "a list of loop closures (dicts) or a side file with "
                        "a 'loops:' list", type(loops).__name__)
    return [_loop_dict(ctx, d, i, where) for i, d in enumerate(loops)]


def _side_file(path: Path):
    import yaml

    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UrdfError(path.name, "loops", "a readable side file", str(path),
                        exc.strerror or str(exc)) from None
    except yaml.YAMLError as exc:
        raise UrdfError(path.name, "loops", "YAML or JSON", str(exc).splitlines()[0]) from None
    if not isinstance(data, dict) or "loops" not in data:
        raise UrdfError(path.name, "loops", "a mapping with a 'loops:' list",
                        type(data).__name__)
    return data["loops"]


def _loop_dict(ctx, d, i: int, where: str) -> Loop:
    item = f"loop {i}"
    if not isinstance(d, dict):
        raise UrdfError(where, item, "a dict {name, type, link1, link2, axis}", d)
    unknown = set(d) - {"name", "type", "link1", "link2", "axis"}
    if unknown:
        raise UrdfError(where, f"{item} {sorted(unknown)[0]!r}", "one of name, type, link1, "
                        "link2, axis", sorted(unknown)[0])
    name, typ = d.get("name"), d.get("type")
    if not isinstance(name, str) or not name:
        raise UrdfError(where, f"{item} name", "a non-empty name", name)
    if typ not in LOOP_TYPES:
        raise UrdfError(where, f"loop {name!r} type", "one of " + ", ".join(LOOP_TYPES), typ)
    ends = []
    for side in ("link1", "link2"):
        e = d.get(side)
        if isinstance(e, str):
            e = {"link": e}
        if not isinstance(e, dict) or not isinstance(e.get("link"), str):
            raise UrdfError(where, f"loop {name!r} {side}", "a link name or {link, xyz, rpy}", e)
        xyz = ctx.floats(" ".join(map(str, e.get("xyz", (0, 0, 0)))), 3, f"loop {name!r}",
                         f"{side} xyz")
        rpy = ctx.floats(" ".join(map(str, e.get("rpy", (0, 0, 0)))), 3, f"loop {name!r}",
                         f"{side} rpy")
        ends += [e["link"], frame(rpy_matrix(rpy), xyz)]
    axis = ctx.floats(" ".join(map(str, d.get("axis", (1, 0, 0)))), 3, f"loop {name!r}", "axis")
    return Loop(name, typ, *ends, _unit(axis, lambda: ctx.fail(
        f"loop {name!r}", "axis", "a non-zero axis", axis.tolist())), where)

