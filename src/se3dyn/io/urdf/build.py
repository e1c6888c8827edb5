"""A URDF robot as a :class:`~se3dyn.model.builder.ModelBuilder`: one node per link (at the link
frame), one se3dyn joint per URDF joint (at the joint frame, absolute coordinates), mimic tags
as exact couplings, loop closures as joints, visuals and the report of what was not mapped.
docs/urdf.md says what is mapped how."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from se3dyn.engine.system import combine_inertia
from se3dyn.errors import ModelError, Se3dynWarning
from se3dyn.io.urdf import meshes
from se3dyn.io.urdf.closure import close_loops, loop_residual
from se3dyn.io.urdf.geometry import plane_axes, pose_of, world_inertia
from se3dyn.io.urdf.loops import loops_argument, read_loop_tags
from se3dyn.io.urdf.parse import Joint, Robot, UrdfError, _Ctx, is_point_mass, read_robot
from se3dyn.io.urdf.tree import poses, tree_order, twists
from se3dyn.model.builder import ModelBuilder
from se3dyn.model.visuals import MESH_SUFFIXES

#: URDF joint types -> se3dyn joint types (a floating joint leaves its child a free node).
SE3DYN_TYPE = {"revolute": "hinge", "continuous": "hinge", "prismatic": "prismatic",
               "fixed": "rigid", "planar": "planar", "spherical": "spherical",
               "ball": "spherical"}
ONE_DOF = ("revolute", "continuous", "prismatic")
#: Largest gap (m, rad) between the two frames of a loop closure in the initial configuration.
LOOP_GAP = 1e-6


@dataclass(frozen=True)
class JointLimits:
    """A URDF joint's ``<limit>``: position range (rad or m; None for a continuous joint or
    when not given), largest speed (rad/s or m/s) and effort (N m or N). Kept, not enforced
    (joint stops: issue 33); ``effort`` is the saturation to give a PID law (``limit=``)."""

    lower: float | None
    upper: float | None
    velocity: float | None
    effort: float | None


@dataclass
class UrdfInfo:
    """What the import read beside the model: links, limits, friction, what was not mapped.

    Attributes
    ----------
    file : str
    root : str                      the root link (a fixed node unless ``floating_base``)
    joints : list of str            URDF joints with coordinates, parents first
    link_nodes : dict               link -> the node carrying it (itself, or the link it was
                                    merged into with ``fixed="merge"``)
    limits : dict                   joint -> :class:`JointLimits`
    friction : dict                 joint -> ``<dynamics friction>`` (not applied yet)
    couplings : dict                follower joint -> (leader, multiplier, offset) enforced
    ignored : list of str           tags nothing maps (path, count, where, why)
    notes : list of str             defaults applied, values kept but not applied, meshes
    """

    file: str
    root: str
    joints: list = field(default_factory=list)
    link_nodes: dict = field(default_factory=dict)
    limits: dict = field(default_factory=dict)
    friction: dict = field(default_factory=dict)
    couplings: dict = field(default_factory=dict)
    ignored: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    #: meshes found that the viewer does not read (format, mirroring scale): "link: file"
    undrawn: list = field(default_factory=list)
    #: links drawn with their collision mesh instead
    drawn_collision: list = field(default_factory=list)

    def report(self) -> str:
        """The import report: ignored tags and notes, one per line."""
        lines = [f"{self.file}: root link {self.root!r}, {len(self.link_nodes)} links, "
                 f"{len(self.joints)} joints with coordinates"]
        lines += ["  ignored: " + s for s in self.ignored]
        lines += ["  note: " + s for s in self.notes]
        return "\n".join(lines)


class UrdfBuilder(ModelBuilder):
    """The :class:`ModelBuilder` of an imported URDF (add to it as to any builder), with the
    import's :class:`UrdfInfo` as ``urdf`` (``mb.urdf.report()``, ``mb.urdf.limits``)."""

    urdf: UrdfInfo | None = None


# ---------------------------------------------------------------------------------------------
def load_urdf(path, *, floating_base: bool = False, package_dirs=(), mimic: str = "enforce",
              loops=None, q0: dict | None = None, v0: dict | None = None,
              fixed: str = "keep", gravity=(0.0, 0.0, -9.81),
              inertia: str = "refuse") -> UrdfBuilder:
    """Read a URDF file into a :class:`UrdfBuilder` (docs/urdf.md).

    Parameters
    ----------
    path : str or path
        The URDF file (XML; entity declarations refused).
    floating_base : bool
        The root link a free node (pose and twist from ``q0``/``v0`` under its link name);
        otherwise it is clamped (a fixed node: its own mass then has no effect, reported).
    package_dirs : path or sequence of paths
        Folders holding ROS packages for ``package://`` meshes (searched before
        ``ROS_PACKAGE_PATH`` and the folders above the URDF file).
    mimic : {"enforce", "ignore"}
        ``<mimic>`` as an exact coupling ``q_f = multiplier q_l + offset``, or dropped (said).
    loops : list of dict, or path, optional
        Loop closures beside those declared in the file (:mod:`se3dyn.io.urdf.loops`).
    q0, v0 : dict, optional
        Initial joint values and rates by URDF joint name (rad, m; a planar joint
        ``(u, v, theta)``, a floating joint a pose: 4x4 or ``(x, y, z, r, p, y)`` and a twist
        ``(v, w)`` of its child in the world frame). Under the root link's name: its pose
        (and, with ``floating_base``, its twist). Zero by default (URDF's ``<origin>``).
    fixed : {"keep", "merge"}
        Fixed joints as rigid joints, or their links merged into one body (masses, centres
        and inertias lumped exactly; the merged links' frames become markers).
    gravity : array_like (3,)
        URDF has none; ROS's z-up convention by default.
    inertia : {"refuse", "repair"}
        An inertia tensor no body can have (not positive definite, or principal moments
        breaking the triangle inequality ``J3 <= J1 + J2``: placeholders of real files) is
        refused naming the link, or made physical with the same principal axes (moments
        raised to 1e-3 of the largest, then the two smaller ones equally until the triangle
        inequality holds) and listed in the report.

    Returns
    -------
    UrdfBuilder
        Nodes named by links, joints by URDF joints (coordinates absolute, zero at
        ``<origin>``), couplings ``<follower>:mimic``; ``.urdf`` holds the report.
    """
    _check_option(str(path), "inertia", inertia, ("refuse", "repair"))
    robot = read_robot(path, read_loop_tags, repair_inertia=inertia == "repair")
    ctx = _Ctx(robot.file, {})
    _check_option(robot.file, "mimic", mimic, ("enforce", "ignore"))
    _check_option(robot.file, "fixed", fixed, ("keep", "merge"))
    root, order = tree_order(robot)
    info = UrdfInfo(robot.file, root, ignored=robot.ignored.lines())
    if robot.repaired:
        info.notes.append(f"{len(robot.repaired)} inertia tensors no body can have made "
                          "physical (inertia='repair'): " + "; ".join(robot.repaired))
    follow = _mimics(robot, order, mimic, info)
    all_loops = robot.loops + loops_argument(loops, ctx)
    q, Tw, tw = _initial_state(robot, order, root, q0, v0, follow, floating_base, all_loops,
                               info)
    group = _groups(robot, order, root, fixed == "merge", info)
    mb = UrdfBuilder(gravity, name=robot.name)
    mb.urdf = info
    _add_nodes(mb, robot, order, root, group, Tw, tw, floating_base)
    _add_joints(mb, robot, order, group, Tw, q)
    for f, (lead, r, o) in follow.items():
        _wrap(robot.file, mb.coupling, f"{f}:mimic", leader=lead, follower=f, ratio=r,
              offset=o)
    _add_loops(mb, robot, all_loops, group, Tw)
    _add_visuals(mb, robot, group, Tw, meshes.package_roots(package_dirs, str(path)),
                 str(path))
    _add_markers(mb, group, Tw)
    _keep(info, robot, order, group, fixed == "merge")
    _warn(info)
    return mb


def _initial_state(robot: Robot, order: list[Joint], root: str, q0, v0, follow: dict,
                   floating_base: bool, loops: list, info: UrdfInfo):
    """Joint values (name -> value, the loops closed), link poses and twists at t = 0."""
    q = _values(robot, order, root, q0, "q0", follow, floating_base)
    v = _values(robot, order, root, v0, "v0", follow, floating_base)
    T_root = q.pop(root, np.eye(4))
    moved = close_loops(order, root, T_root, q, loops, set(q0 or ()), follow)
    if moved:
        info.notes.append("q0 of " + ", ".join(moved) + " solved to close the loops (the "
                          "joints not given in q0)")
    Tw = poses(order, root, T_root, q)
    return q, Tw, twists(order, root, Tw, v, v.pop(root, np.zeros(6)))


def _check_option(file: str, fld: str, v, allowed: tuple) -> None:
    if v not in allowed:
        raise UrdfError(f"load_urdf({file})", fld, " or ".join(repr(a) for a in allowed), v)


def _wrap(src: str, fn, /, *args, **kwargs):
    """A builder call whose ModelError names the file ``src`` too."""
    try:
        return fn(*args, **kwargs)
    except UrdfError:
        raise
    except ModelError as exc:  # (arrays as lists: the message stays on one line)
        got = exc.got.tolist() if isinstance(exc.got, np.ndarray) else exc.got
        raise UrdfError(f"{src}: {exc.item}", exc.field, exc.expected, got) from None


# ---------------------------------------------------------------------------------------------
def _mimics(robot: Robot, order: list[Joint], mode: str, info: UrdfInfo) -> dict:
    """follower -> (leader, multiplier, offset), chains of mimics composed to their first
    leader; empty with ``mimic="ignore"`` (the dropped tags noted)."""
    raw = {j.name: j.mimic for j in order if j.mimic is not None}
    locked = [f for f, m in raw.items() if "fixed" in (
        robot.joints[f].type, getattr(robot.joints.get(m[0]), "type", None))]
    if locked:  # (reduced models lock joints and leave their tags)
        info.notes.append(f"<mimic> of {len(locked)} joints with a fixed joint on either side "
                          "dropped (nothing to couple): " + ", ".join(locked[:8]))
        raw = {f: m for f, m in raw.items() if f not in locked}
    if mode == "ignore":
        if raw:
            info.notes.append(f"<mimic> of {len(raw)} joints dropped (mimic='ignore'): "
                              + ", ".join(raw) + "; they move freely")
        return {}
    for f, (lead, _r, _o) in raw.items():
        item = f"{robot.file}: joint {f!r}"
        if lead not in robot.joints or lead == f:
            raise UrdfError(item, "<mimic> joint", "the name of another joint of the file",
                            lead)
        for name in (f, lead):
            if robot.joints[name].type not in ONE_DOF:
                raise UrdfError(item, "<mimic> joint", "revolute, continuous or prismatic "
                                "joints on both sides of a mimic",
                                f"{name!r} ({robot.joints[name].type})")
    out = {}
    for f in raw:
        lead, r, o = raw[f]
        seen = {f}
        while lead in raw:
            if lead in seen:
                raise UrdfError(f"{robot.file}: joint {f!r}", "<mimic> joint", "mimic tags "
                                "that lead back to a joint without one", lead, "a cycle")
            seen.add(lead)
            l2, r2, o2 = raw[lead]
            lead, r, o = l2, r * r2, r * o2 + o
        out[f] = (lead, r, o)
    info.couplings = dict(out)
    return out


def _values(robot: Robot, order: list[Joint], root: str, given, kind: str, follow: dict,
            floating_base: bool) -> dict:
    """Every joint's value (``q0``) or rate (``v0``), defaults zero; the root's pose or
    twist under ``root`` when given; followers of mimics from their leaders."""
    f = robot.file
    given = {} if given is None else given
    if not isinstance(given, dict):
        raise UrdfError(f"load_urdf({f})", kind, "a dict {joint name: value}", given)
    movable = {j.name: j for j in order if j.type != "fixed"}
    out = {}
    for key, val in given.items():
        if key in movable:
            out[key] = _value(f, movable[key], val, kind)
        elif key == root and (kind == "q0" or floating_base):
            out[key] = _root_value(f, root, val, kind)
        else:
            raise UrdfError(f"load_urdf({f})", f"{kind}[{key!r}]", "a joint with coordinates"
                            + (" or the root link" if kind == "q0" or floating_base else ""),
                            key, "valid: " + ", ".join(list(movable)[:12]) + (
                                " ..." if len(movable) > 12 else ""))
    for name, j in movable.items():
        out.setdefault(name, _value(f, j, None, kind))
    for fol, (lead, r, o) in follow.items():
        want = r * out[lead] + (o if kind == "q0" else 0.0)
        if fol in given and abs(out[fol] - want) > 1e-12 * (1.0 + abs(want)):
            raise UrdfError(f"load_urdf({f})", f"{kind}[{fol!r}]", f"{want!r} = "
                            f"{r:g} x {kind}[{lead!r}]" + (f" + {o:g}" if kind == "q0" else "")
                            + " (its <mimic>)", out[fol], "leave it out: it follows")
        out[fol] = want
    return out


def _value(file: str, j: Joint, val, kind: str):
    item = f"load_urdf({file})"

    def fail(expected, got):
        raise UrdfError(item, f"{kind}[{j.name!r}]", expected, got)

    if j.type == "floating":
        if kind == "q0":
            return np.eye(4) if val is None else pose_of(val, item, kind, fail)
        return np.zeros(6) if val is None else _numbers(val, 6, fail, "a twist (v, w)")
    if j.type == "planar":
        return np.zeros(3) if val is None else _numbers(val, 3, fail, "(u, v, theta)")
    return 0.0 if val is None else float(_numbers(val, 1, fail, "a number")[0])


def _root_value(file: str, root: str, val, kind: str):
    def fail(expected, got):
        raise UrdfError(f"load_urdf({file})", f"{kind}[{root!r}] (the root link)", expected,
                        got)

    if kind == "q0":
        return pose_of(val, file, kind, fail)
    return _numbers(val, 6, fail, "a twist (v, w) in the world frame")


def _numbers(val, n: int, fail, expected: str) -> np.ndarray:
    try:
        a = np.atleast_1d(np.asarray(val, dtype=float))
    except (TypeError, ValueError):
        fail(expected, val)
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        fail(expected + f" ({n} finite numbers)", val)
    return a


def _groups(robot: Robot, order: list[Joint], root: str, merge: bool, info: UrdfInfo
            ) -> dict[str, str]:
    """link -> the link whose node carries it: merged through fixed joints (all with
    ``merge``, point masses always), or itself."""
    g, points = {root: root}, []
    for j in order:
        point = j.type == "fixed" and is_point_mass(robot.links[j.child].inertial)
        g[j.child] = g[j.parent] if (merge or point) and j.type == "fixed" else j.child
        if point and not merge:
            points.append(j.child)
    if points:
        info.notes.append(f"{len(points)} point masses (no inertia) on fixed joints lumped into "
                          "their parents, their frames kept as markers: " + ", ".join(points[:8])
                          + (" ..." if len(points) > 8 else ""))
    return g


# ---------------------------------------------------------------------------------------------
def _add_nodes(mb, robot: Robot, order, root: str, group: dict, Tw: dict, tw: dict,
               floating_base: bool) -> None:
    """One node per group of links, at its first link's frame, with the group's mass,
    centre of mass and inertia (world frame, parallel-axis rule over rotated frames)."""
    for link in [root] + [j.child for j in order]:
        if group[link] != link:
            continue
        M, J, c = _lumped(robot, [k for k in group if group[k] == link], Tw)
        fixed = link == root and not floating_base
        if M > 0 and not fixed and np.linalg.eigvalsh(J)[0] <= 0:
            raise UrdfError(f"{robot.file}: link {link!r}", "<inertia>", "a positive-definite "
                            "inertia (a point mass alone has none: on a moving joint, or as "
                            "a floating base, give it the inertia of its shape)", J.tolist())
        if fixed and M > 0:
            mb.urdf.notes.append(f"root link {link!r}: its mass ({M:g} kg) is carried by the "
                                 "ground (a fixed base; floating_base=True moves it)")
            M, J, c = 0.0, None, None
        T = Tw[link]
        kw = {} if fixed else {"velocity": tw[link][:3], "angular_velocity": tw[link][3:]}
        _wrap(robot.file, mb.node, link, T[:3, 3], orientation=T[:3, :3], mass=M,
              inertia=J if M > 0 else None, com=c if M > 0 else None, fixed=fixed, **kw)
        mb.urdf.link_nodes.update({k: link for k in group if group[k] == link})


def _lumped(robot: Robot, links: list[str], Tw: dict):
    """Mass, inertia about the centre of mass and the centre (world frame) of ``links``."""
    parts = [(robot.links[k].inertial, Tw[k]) for k in links]
    parts = [(i, T) for i, T in parts if i is not None and i.mass > 0]
    if not parts:
        return 0.0, None, None
    cs, Js = zip(*(world_inertia(T, i.T, i.inertia) for i, T in parts), strict=True)
    return combine_inertia(np.array([i.mass for i, _ in parts]), np.array(cs), np.array(Js))


def _add_joints(mb, robot: Robot, order: list[Joint], group: dict, Tw: dict, q: dict) -> None:
    """The se3dyn joint of every URDF joint (fixed ones inside a merged group excepted)."""
    for j in order:
        if group[j.child] != j.child:
            continue
        if j.type == "floating":
            mb.urdf.notes.append(f"floating joint {j.name!r}: link {j.child!r} is a free "
                                 "node (no se3dyn joint)")
            continue
        Tj = Tw[j.parent] @ j.T
        a = Tj[:3, :3] @ j.axis
        kw = {"at": Tj[:3, 3]}
        if j.type in ONE_DOF:
            kw.update(axis=a, initial=q[j.name], damping=j.damping or None)
            mb.urdf.joints.append(j.name)
        elif j.type == "planar":
            kw.update(normal=a, axes=(Tj[:3, :3] @ plane_axes(j.axis).T).T)
            mb.urdf.joints.append(j.name)
        _wrap(robot.file, mb.joint, j.name, SE3DYN_TYPE[j.type], group[j.parent], j.child,
              **kw)


def _add_loops(mb, robot: Robot, loops: list, group: dict, Tw: dict) -> None:
    """Each loop closure an se3dyn joint at its frame on link1, after checking that its two
    frames coincide in the initial configuration."""
    for lp in loops:
        item = f"{robot.file}: loop {lp.name!r} ({lp.source})"
        for fld, link in (("link1", lp.link1), ("link2", lp.link2)):
            if link not in robot.links:
                raise UrdfError(item, fld, "the name of a link of the file", link)
        _loop_gap(item, lp, Tw)
        F1 = Tw[lp.link1] @ lp.T1
        na, nb = group[lp.link1], group[lp.link2]
        if na == nb:
            raise UrdfError(item, "link2", "a link on another body than link1", lp.link2,
                            f"both are on node {na!r}")
        typ = SE3DYN_TYPE[lp.type]
        kw = {"at": F1[:3, 3]}
        if typ in ("hinge", "prismatic"):
            kw["axis"] = F1[:3, :3] @ lp.axis
        _wrap(robot.file, mb.joint, lp.name, typ, na, nb, **kw)
        mb.urdf.notes.append(f"loop closure {lp.name!r} ({lp.source}, {lp.type}) between "
                             f"{lp.link1!r} and {lp.link2!r}: an exact {typ} joint")


def _loop_gap(item: str, lp, Tw: dict) -> None:
    """Refuse a loop whose frames do not meet at the initial configuration (q0)."""
    r = loop_residual(lp, Tw)
    gap, turn = float(np.linalg.norm(r[:3])), float(np.linalg.norm(r[3:]))
    if gap > LOOP_GAP or turn > LOOP_GAP:
        raise UrdfError(item, "link2", f"frames that meet in the initial configuration "
                        f"(within {LOOP_GAP:g} m and rad)", f"{gap:.3g} m apart, axes "
                        f"{turn:.3g} rad apart", "the joints not given in q0 could not close "
                        "it: give q0 values that do")


# ---------------------------------------------------------------------------------------------
def _add_visuals(mb, robot: Robot, group: dict, Tw: dict, roots: list, path: str) -> None:
    """The links' ``<visual>`` shapes on their nodes; a mesh not found or not readable by
    the viewer is noted (named with the paths tried), never an error."""
    for link, lk in robot.links.items():
        node = group[link]
        for i, v in enumerate(lk.visuals):
            T = np.linalg.inv(Tw[node]) @ Tw[link] @ v.T
            kw = {"offset": T[:3, 3], "orientation": T[:3, :3], "color": v.color}
            if v.shape == "mesh":
                file = _mesh_file(mb.urdf, link, v, roots, path)
                if file is None:
                    v, file = _collision_mesh(mb.urdf, lk, roots, path)
                    if file is None:
                        continue
                    T = np.linalg.inv(Tw[node]) @ Tw[link] @ v.T
                    kw.update(offset=T[:3, 3], orientation=T[:3, :3])
                kw.update(size=v.size, file=file)
            else:
                kw["size"] = v.size
            _wrap(robot.file, mb.visual, f"{link}:visual:{i}", node, v.shape, **kw)


def _mesh_file(info: UrdfInfo, link: str, v, roots: list, path: str) -> str | None:
    found, tried = meshes.resolve(v.file, path, roots)
    if found is None:
        shown = ", ".join(str(p) for p in tried[:4]) + (" ..." if len(tried) > 4 else "")
        info.notes.append(f"link {link!r}: visual mesh {v.file!r} not found (tried {shown}); "
                          "not drawn")
        return None
    if found.suffix.lower() not in MESH_SUFFIXES or min(v.size) <= 0:
        info.undrawn.append(f"{link}: {found.name}")
        return None
    return str(found)


def _collision_mesh(info: UrdfInfo, lk, roots: list, path: str):
    """The first ``<collision>`` mesh of the link the viewer reads, drawn instead of a visual
    mesh it cannot (noted); ``(None, None)`` if none."""
    for c in lk.collisions:
        found, _ = meshes.resolve(c.file, path, roots)
        if found is not None and found.suffix.lower() in MESH_SUFFIXES and min(c.size) > 0:
            info.drawn_collision.append(lk.name)
            return c, str(found)
    return None, None


def _add_markers(mb, group: dict, Tw: dict) -> None:
    """The frame of every link merged into another's node, as a marker named by the link."""
    for link, node in group.items():
        if node != link:
            T = Tw[link]
            mb.marker(link, node, at=T[:3, 3], orientation=T[:3, :3])


def _keep(info: UrdfInfo, robot: Robot, order: list[Joint], group: dict, merge: bool) -> None:
    """Limits and friction kept on ``info``; what was read and not applied noted."""
    for j in order:
        lim = j.limit
        if lim and j.type != "fixed":
            pos = j.type != "continuous"
            info.limits[j.name] = JointLimits(lim.get("lower") if pos else None,
                                              lim.get("upper") if pos else None,
                                              lim.get("velocity"), lim.get("effort"))
        if j.friction > 0:
            info.friction[j.name] = j.friction
        if j.damping > 0 and j.type not in ONE_DOF:
            info.notes.append(f"joint {j.name!r} ({j.type}): <dynamics damping> not applied "
                              "(applied on revolute, continuous and prismatic joints)")
    if info.limits:
        info.notes.append(f"<limit> of {len(info.limits)} joints kept (mb.urdf.limits), not "
                          "enforced: joint stops are issue 33")
    if info.friction:
        info.notes.append(f"<dynamics friction> of {len(info.friction)} joints kept "
                          "(mb.urdf.friction), not applied: joint friction is issue 33")
    if info.undrawn:
        info.notes.append(f"{len(info.undrawn)} visual meshes not drawn (the viewer reads "
                          + ", ".join(MESH_SUFFIXES) + " with positive scales): "
                          + ", ".join(info.undrawn[:4]) + (" ..." if len(info.undrawn) > 4
                                                           else ""))
    if info.drawn_collision:
        info.notes.append(f"{len(info.drawn_collision)} links drawn with their <collision> "
                          "mesh instead: " + ", ".join(info.drawn_collision[:6])
                          + (" ..." if len(info.drawn_collision) > 6 else ""))
    bare = [k for k, lk in robot.links.items() if lk.inertial is None]
    if bare:
        info.notes.append(f"{len(bare)} links without <inertial> have no mass (URDF's "
                          "default): " + ", ".join(bare[:8]) + (" ..." if len(bare) > 8 else ""))
    merged = [k for k, n in group.items() if n != k]
    if merged and merge:
        info.notes.append(f"{len(merged)} links merged through fixed joints (fixed='merge'), "
                          "their frames kept as markers: " + ", ".join(merged[:8])
                          + (" ..." if len(merged) > 8 else ""))


def _warn(info: UrdfInfo) -> None:
    """One warning with what was ignored, what was kept but not applied, and what was
    changed (inertias made physical)."""
    said = info.ignored + [n for n in info.notes
                           if "not " in n or "dropped" in n or "made physical" in n]
    if said:
        warnings.warn(Se3dynWarning(
            f"{info.file}: not mapped: " + "; ".join(said) + " (mb.urdf.report())"),
            stacklevel=3)


__all__ = ["load_urdf", "UrdfBuilder", "UrdfInfo", "JointLimits"]
