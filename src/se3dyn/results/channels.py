"""Stable channel names over a :class:`~se3dyn.results.results.Results` (in memory or read
from a file).

A channel is one scalar time history, shape (n,), named by a path (see ``docs/results-file.md``)::

    time
    node/<node>/position/x|y|z                      m
    node/<node>/displacement/x|y|z                  m   (position minus the first row)
    node/<node>/rotation/R11 .. R33                 -   (rotation matrix entries)
    node/<node>/velocity/material|inertial/x|y|z|wx|wy|wz        m/s, rad/s
    node/<node>/acceleration/material|inertial/x|y|z|wx|wy|wz    m/s^2, rad/s^2
    joint/<joint>/alpha/<i>                         rad or m (per coordinate)
    joint/<joint>/velocity/<i>                      rad/s or m/s
    joint/<joint>/multiplier/<i>                    N (i mod 6 < 3), N m (otherwise)
    joint/<joint>/reaction/joint|inertial/fx|fy|fz|mx|my|mz    N, N m  (wrench on body B)
    joint/<joint>/torque/<i>                        N m or N (per coordinate)
    joint/<joint>/actuator/<i>                      N m or N (actuator + PD law, per coordinate)
    joint/<joint>/spring/<i>                        N m or N (spring + damper, per coordinate)
    drive/<drive>/effort                            N m or N (a drive of one coordinate)
    drive/<drive>/effort/<i>                        N m or N (per driven coordinate, several)
    drive/<drive>/power                             W   (sum of effort * rate)
    spring/<spring>/force|length|rate               N, m, m/s (point spring-damper)
    coupling/<coupling>/force                       N m or N (on the follower's coordinate)
    contact/<pair>/force|point|normal/x|y|z         N, m, - (pair "a%2Fb": shapes a, b; the
    contact/<pair>/normal_force|penetration         N, m   force on b; runs in memory)
    marker/<marker>/position/x|y|z                  m
    marker/<marker>/rotation/R11 .. R33             -   (marker axes in the inertial frame)
    marker/<marker>/velocity/material|inertial/x|y|z|wx|wy|wz      m/s, rad/s
    marker/<marker>/acceleration/material|inertial/x|y|z|wx|wy|wz  m/s^2, rad/s^2
    marker/<marker>/accelerometer/x|y|z             m/s^2   (specific force, marker axes)
    marker/<marker>/gyroscope/x|y|z                 rad/s   (angular velocity, marker axes)
    marker/<a>/distance/<b>                         m       (|p_b - p_a|, a listed before b)
    marker/<a>/distance_rate/<b>                    m/s     (its time derivative)
    beam/<beam>/<e>/force/N|V2|V3|T|M2|M3           N, N m  (section forces of element e)
    beam/<beam>/<e>/strain/e1|g2|g3|k1|k2|k3        -, 1/m  (eps - eps0, section frame)
    beam/<beam>/<e>/energy                          J       (elastic energy of element e)
    energy/kinetic|potential|spring|total|balance|work_actuators|work_loads|dissipation   J
    solver/iterations|residual|constraint           -

Markers (``ModelBuilder.marker``, ``markers:`` in model files) are frames fixed on nodes; their
channels are :meth:`Results.marker_velocity`, :meth:`Results.accelerometer` and the others
(material = the marker's own axes); the distance between two markers is listed once per pair,
under the marker that comes first in the model, and read in either order. Results read from a
file take them from the model stored in it.

Joint sensors (:meth:`Results.joint_reaction`, :meth:`Results.joint_torque`) come from the
multipliers: the reaction wrench of the joint on its body B about the joint point (components
in the joint frame or the inertial frame) and the generalized force of the joint's force
elements along its coordinates. The inertial components and the torque need the joint's
attachment frame and axes: results read from a file list them only when the file stores its
model.

Force sensors (:meth:`Results.actuator_effort`, :meth:`Results.spring_force`,
:meth:`Results.spring_damper_force`): the generalized force of a joint's actuator and PD law
(positive along increasing coordinates) and of its spring and damper (positive when stretched),
listed for the joints that have them, evaluated by the compiled kernels; the axial force of a
point spring-damper (tension positive), its length and rate. They need the model: results read
from a file list them when the file stores its model.

Drivers (``ModelBuilder.drive``) give the force or torque they supply
(:meth:`Results.drive_effort`: exact, from the residual of the driven coordinates' equations of
motion) and its power; results read from a file list them when the file stores its model.

Escaping: a node, joint, marker, drive or spring name is written with ``%`` replaced by
``%25`` and ``/`` by ``%2F`` (in this order), so ``node/a%2Fb/position/x`` is the x position
of node ``a/b``.
Composite joints (e.g. a universal joint) are listed under their own name, with the
coordinates of their parts side by side as :meth:`Results.joint_coordinates` gives them.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np

from se3dyn.errors import UnknownNameError, close_matches
from se3dyn.results.forces import PARTS, has_part
from se3dyn.results.results import marker_specs, model_system

if TYPE_CHECKING:
    from se3dyn.results.results import Results

__all__ = ["list_channels", "get_channel", "channel_unit", "escape_name", "unescape_name",
           "joint_units"]

_AXES = ("x", "y", "z", "wx", "wy", "wz")
_ENERGY = ("kinetic", "potential", "spring", "total", "balance", "work_actuators",
           "work_loads", "dissipation")
_SOLVER = ("iterations", "residual", "constraint")
_ROT = tuple(f"R{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3))
_SENSORS = ("accelerometer", "gyroscope")
_PAIR = ("distance", "distance_rate")
_WRENCH = ("fx", "fy", "fz", "mx", "my", "mz")
_SPRING = {"force": "N", "length": "m", "rate": "m/s"}
_BEAM = {"force": ("N", "V2", "V3", "T", "M2", "M3"),
         "strain": ("e1", "g2", "g3", "k1", "k2", "k3")}


def escape_name(name: str) -> str:
    """A node or joint name as it appears in a channel name (``%`` -> ``%25``, ``/`` -> ``%2F``)."""
    return str(name).replace("%", "%25").replace("/", "%2F")


def unescape_name(text: str) -> str:
    """Inverse of :func:`escape_name`."""
    return re.sub(r"%(25|2[Ff])", lambda m: "%" if m.group(1) == "25" else "/", text)


def _joint_entries(res: Results) -> list[str]:
    """Joint names as listed: composites by their own name, other joints except their parts."""
    s = res.system
    comp = dict(s.composites)
    parts = {p for ps in comp.values() for p in ps}
    names = [n for n in s.joint_names if n not in parts]
    return names + [c for c in comp if c not in names]


def _joint_size(res: Results, name: str) -> tuple[int, int]:
    """(number of coordinates, number of multipliers) of a joint or composite."""
    s = res.system
    ids = res._joints(name)
    return int(sum(int(s.joint_k[j]) for j in ids)), 6 * len(ids)


def _beam_system(res: Results):
    """The compiled system that holds the beams of ``res`` (:func:`model_system`: in-memory
    results carry theirs, a results file's layout compiles the model stored in the file), or
    None when it has no beams."""
    s = model_system(res.system)
    return s if s is not None and len(s.beams) else None


def list_channels(res: Results) -> list[str]:
    """Every channel name of ``res``, in a stable order."""
    s = res.system
    geom = model_system(s) is not None
    out = ["time"]
    for name in s.node_names:
        e = f"node/{escape_name(name)}"
        out += [f"{e}/position/{a}" for a in _AXES[:3]]
        out += [f"{e}/displacement/{a}" for a in _AXES[:3]]
        out += [f"{e}/rotation/{r}" for r in _ROT]
        for q in ("velocity", "acceleration"):
            for frame in ("material", "inertial"):
                out += [f"{e}/{q}/{frame}/{a}" for a in _AXES]
    for name in _joint_entries(res):
        e = f"joint/{escape_name(name)}"
        k, nmult = _joint_size(res, name)
        out += [f"{e}/alpha/{c}" for c in range(k)]
        out += [f"{e}/velocity/{c}" for c in range(k)]
        out += [f"{e}/multiplier/{c}" for c in range(nmult)]
        for frame in ("joint", "inertial") if geom else ("joint",):
            out += [f"{e}/reaction/{frame}/{c}" for c in _WRENCH]
        if geom:
            out += [f"{e}/torque/{c}" for c in range(k)]
            for part in _joint_parts(res, name):
                out += [f"{e}/{part}/{c}" for c in range(k)]
    for name, count in _drive_entries(res):
        e = f"drive/{escape_name(name)}"
        out += [f"{e}/effort"] if count == 1 else [f"{e}/effort/{c}" for c in range(count)]
        out.append(f"{e}/power")
    for name in _spring_entries(res):
        out += [f"spring/{escape_name(name)}/{q}" for q in _SPRING]
    out += [f"coupling/{escape_name(n)}/force" for n in _coupling_names(res)]
    if getattr(res, "contact_rows", None) is not None:
        for n in res.contact_pairs():
            e = f"contact/{escape_name(n)}"
            out += [f"{e}/{q}/{c}" for q in ("force", "point", "normal") for c in "xyz"]
            out += [f"{e}/normal_force", f"{e}/penetration"]
    mks = [escape_name(mk.name) for mk in marker_specs(s)]
    for i, mk in enumerate(mks):
        out += _marker_entries(f"marker/{mk}")
        out += [f"marker/{mk}/{q}/{other}" for other in mks[i + 1:] for q in _PAIR]
    bsys = _beam_system(res)
    for b in getattr(bsys, "beams", ()):
        e = f"beam/{escape_name(b['beam'])}/{b['index']}"
        for q, comps in _BEAM.items():
            out += [f"{e}/{q}/{c}" for c in comps]
        out.append(f"{e}/energy")
    out += [f"energy/{x}" for x in _ENERGY]
    out += [f"solver/{x}" for x in _SOLVER]
    return out


def _joint_parts(res: Results, name: str) -> tuple[str, ...]:
    """The parts of force elements (``"actuator"``, ``"spring"``) that a joint or composite has
    in the model behind ``res`` (none without the model)."""
    s = model_system(res.system)
    if s is None:
        return ()
    joints = s.model.joints
    ids = res._joints(name)
    return tuple(p for p in PARTS if any(has_part(joints[j], p) for j in ids))


def _spring_entries(res: Results) -> list[str]:
    """The names of the point spring-dampers of the model behind ``res``."""
    s = model_system(res.system)
    return [sp.name for sp in getattr(getattr(s, "model", None), "springs", ())]


def _drive_entries(res: Results) -> list[tuple[str, int]]:
    """(name, number of driven coordinates) of every drive of the model behind ``res``."""
    s = model_system(res.system)
    return [(d.name, len(d.targets)) for d in getattr(getattr(s, "model", None), "drives", ())]


def _coupling_names(res: Results) -> list[str]:
    """The couplings of the model behind ``res``."""
    s = model_system(res.system)
    return [c.name for c in getattr(getattr(s, "model", None), "couplings", ())]


def _contact_channel(res: Results, name: str, parts: list[str]) -> np.ndarray:
    """A ``contact/<pair>/...`` channel (Results.contact_*)."""
    pair = unescape_name(parts[1])
    if pair not in res.contact_pairs():
        raise _unknown(res, name, f"no contact pair {pair!r}")
    if len(parts) == 3 and parts[2] in ("normal_force", "penetration"):
        f = res.contact_normal_force if parts[2] == "normal_force" else res.contact_penetration
        return f(pair)
    if len(parts) == 4 and parts[2] in ("force", "point", "normal") and parts[3] in "xyz":
        f = {"force": res.contact_force, "point": res.contact_point,
             "normal": res.contact_normal}[parts[2]]
        return f(pair)[:, "xyz".index(parts[3])]
    raise _unknown(res, name)


def _drive_channel(res: Results, name: str, parts: list[str]) -> np.ndarray:
    """A ``drive/...`` channel (effort per coordinate, or power)."""
    drive = unescape_name(parts[1])
    count = dict(_drive_entries(res)).get(drive)
    if count is None:
        raise _unknown(res, name, f"no drive {drive!r}")
    eff = res.drive_effort(drive)
    if parts[2] == "power" and len(parts) == 3:
        s = model_system(res.system)
        rate = np.asarray(res.v, dtype=float)[:, s.drive_dof[s.drive_of == [
            d.name for d in s.model.drives].index(drive)]]
        return np.sum(eff * rate, axis=1)
    if parts[2] == "effort" and len(parts) == 3 and count == 1:
        return eff[:, 0]
    if parts[2] == "effort" and len(parts) == 4:
        return eff[:, _index(res, name, parts[3], count)]
    raise _unknown(res, name)


def _drive_unit(res: Results | None, parts: list[str]) -> str:
    """"N m" or "N" by the driven coordinate's unit (both without ``res``)."""
    s = model_system(res.system) if res is not None else None
    if s is None or len(parts) < 3:
        return "N m | N"
    names = [d.name for d in s.model.drives]
    drive = unescape_name(parts[1])
    if drive not in names:
        return "N m | N"
    dofs = s.drive_dof[s.drive_of == names.index(drive)]
    c = int(parts[3]) if len(parts) == 4 and parts[3].isdigit() else 0
    if c >= len(dofs):
        return "N m | N"
    start = int(np.flatnonzero(s.dof_is_joint)[0]) if np.any(s.dof_is_joint) else 0
    unit = joint_units(s)[int(dofs[c]) - start]
    return {"rad": "N m", "m": "N"}.get(unit, "N m | N")


def _marker_entries(e: str) -> list[str]:
    out = [f"{e}/position/{a}" for a in _AXES[:3]]
    out += [f"{e}/rotation/{r}" for r in _ROT]
    for q in ("velocity", "acceleration"):
        for frame in ("material", "inertial"):
            out += [f"{e}/{q}/{frame}/{a}" for a in _AXES]
    out += [f"{e}/{q}/{a}" for q in _SENSORS for a in _AXES[:3]]
    return out


def _marker_channel(res: Results, name: str, parts: list[str]) -> np.ndarray:
    marker = unescape_name(parts[1])
    names = [mk.name for mk in marker_specs(res.system)]
    if marker not in names:
        raise _unknown(res, name, f"no marker {marker!r}")
    q, rest = parts[2], parts[3:]
    if q in _PAIR and len(rest) == 1:
        other = unescape_name(rest[0])
        if other not in names:
            raise _unknown(res, name, f"no marker {other!r}")
        f = res.marker_distance if q == "distance" else res.marker_distance_rate
        return f(marker, other)
    if q == "position" and rest in [[a] for a in _AXES[:3]]:
        return res.marker_position(marker)[:, _AXES.index(rest[0])]
    if q == "rotation" and len(rest) == 1 and rest[0] in _ROT:
        return res.marker_rotation(marker)[:, int(rest[0][1]) - 1, int(rest[0][2]) - 1]
    if (q in ("velocity", "acceleration") and len(rest) == 2
            and rest[0] in ("material", "inertial") and rest[1] in _AXES):
        f = res.marker_velocity if q == "velocity" else res.marker_acceleration
        return f(marker, frame=rest[0])[:, _AXES.index(rest[1])]
    if q in _SENSORS and rest in [[a] for a in _AXES[:3]]:
        return getattr(res, q)(marker)[:, _AXES.index(rest[0])]
    raise _unknown(res, name)


def _beam_channel(res: Results, name: str, parts: list[str]) -> np.ndarray:
    from se3dyn.elements.beam import section_forces

    s = _beam_system(res)
    beam = unescape_name(parts[1])
    els = [i for i, b in enumerate(getattr(s, "beams", ())) if b["beam"] == beam]
    if not els:
        raise _unknown(res, name, f"no beam {beam!r}")
    e = _index(res, name, parts[2], len(els))
    if parts[3:] == ["energy"]:
        q, c = "energy", None
    elif len(parts) == 5 and parts[3] in _BEAM and parts[4] in _BEAM[parts[3]]:
        q, c = parts[3], _BEAM[parts[3]].index(parts[4])
    else:
        raise _unknown(res, name)
    out = section_forces(s, np.asarray(res.H), vq=np.asarray(res.v))
    x = out[q][:, els[e]]
    return (x if c is None else x[:, c]).copy()


def _unknown(res: Results, name: str, why: str = "") -> UnknownNameError:
    valid = list_channels(res)
    close = close_matches(str(name), valid, n=3, cutoff=0.5)
    msg = f"unknown channel {name!r}"
    if why:
        msg += f" ({why})"
    if close:
        msg += "; did you mean " + ", ".join(repr(c) for c in close) + "?"
    else:
        msg += "; valid names look like " + ", ".join(repr(c) for c in valid[1:4]) + ", ..."
    return UnknownNameError(msg)


def _index(res: Results, name: str, text: str, size: int) -> int:
    if not re.fullmatch(r"\d+", text) or int(text) >= size:
        raise _unknown(res, name, f"component must be 0..{size - 1}" if size else
                       "this joint has no such component")
    return int(text)


def get_channel(res: Results, name: str) -> np.ndarray:
    """The time history ``(n,)`` of channel ``name`` (see :func:`list_channels`).

    Raises
    ------
    KeyError
        Unknown channel, with close valid names as suggestions.
    """
    parts = str(name).split("/")
    try:
        if parts == ["time"]:
            return np.asarray(res.t, dtype=float).copy()
        if len(parts) == 2 and parts[0] == "energy" and parts[1] in _ENERGY:
            key = {"total": "total_energy", "balance": "energy_balance"}.get(parts[1], parts[1])
            return np.asarray(getattr(res, key), dtype=float).copy()
        if len(parts) == 2 and parts[0] == "solver" and parts[1] in _SOLVER:
            return np.asarray(getattr(res, parts[1])).copy()
        if len(parts) >= 4 and parts[0] == "node":
            node = unescape_name(parts[1])
            if node not in res.system.node_names:
                raise _unknown(res, name, f"no node {node!r}")
            q, rest = parts[2], parts[3:]
            if q in ("position", "displacement") and len(rest) == 1 and rest[0] in _AXES[:3]:
                p = res.node_position(node)[:, _AXES.index(rest[0])]
                return p - p[0] if q == "displacement" and len(p) else p
            if q == "rotation" and len(rest) == 1 and rest[0] in _ROT:
                i, j = int(rest[0][1]) - 1, int(rest[0][2]) - 1
                return res.node_rotation(node)[:, i, j]
            if (q in ("velocity", "acceleration") and len(rest) == 2
                    and rest[0] in ("material", "inertial") and rest[1] in _AXES):
                f = res.node_velocity if q == "velocity" else res.node_acceleration
                return f(node, frame=rest[0])[:, _AXES.index(rest[1])]
        if len(parts) == 3 and parts[0] == "spring" and parts[2] in _SPRING:
            spring = unescape_name(parts[1])
            if spring not in _spring_entries(res):
                raise _unknown(res, name, f"no spring-damper {spring!r}")
            f = {"force": res.spring_damper_force, "length": res.spring_damper_length,
                 "rate": res.spring_damper_rate}[parts[2]]
            return f(spring)
        if parts[0] == "contact" and len(parts) in (3, 4):
            return _contact_channel(res, name, parts)
        if parts[0] == "coupling" and len(parts) == 3 and parts[2] == "force":
            cpl = unescape_name(parts[1])
            if cpl not in _coupling_names(res):
                raise _unknown(res, name, f"no coupling {cpl!r}")
            return res.coupling_force(cpl)
        if len(parts) in (3, 4) and parts[0] == "drive":
            return np.array(_drive_channel(res, name, parts), dtype=float)
        if len(parts) in (4, 5) and parts[0] == "marker":
            return np.array(_marker_channel(res, name, parts), dtype=float)
        if len(parts) in (4, 5) and parts[0] == "beam":
            return _beam_channel(res, name, parts)
        if len(parts) in (4, 5) and parts[0] == "joint":
            joint = unescape_name(parts[1])
            try:
                k, nmult = _joint_size(res, joint)
            except KeyError:
                raise _unknown(res, name, f"no joint {joint!r}") from None
            if parts[2] in ("alpha", "velocity") and len(parts) == 4:
                c = _index(res, name, parts[3], k)
                f = res.joint_coordinates if parts[2] == "alpha" else res.joint_velocities
                return f(joint)[:, c]
            if parts[2] == "multiplier" and len(parts) == 4:
                c = _index(res, name, parts[3], nmult)
                return res.joint_multipliers(joint)[:, c]
            if (parts[2] == "reaction" and len(parts) == 5 and parts[3] in ("joint", "inertial")
                    and parts[4] in _WRENCH):
                return res.joint_reaction(joint, frame=parts[3])[:, _WRENCH.index(parts[4])]
            if parts[2] == "torque" and len(parts) == 4:
                c = _index(res, name, parts[3], k)
                return res.joint_torque(joint)[:, c]
            if parts[2] in PARTS and len(parts) == 4:
                if parts[2] not in _joint_parts(res, joint):
                    raise _unknown(res, name, f"joint {joint!r} has no {parts[2]}")
                c = _index(res, name, parts[3], k)
                f = res.actuator_effort if parts[2] == "actuator" else res.spring_force
                return f(joint)[:, c]
    except (ValueError, IndexError) as e:
        raise _unknown(res, name, str(e)) from None
    raise _unknown(res, name)


def channel_unit(name: str, res: Results | None = None) -> str:
    """Unit of a channel for axis labels: "m", "m/s", "m/s^2", "rad", "rad/s", "rad/s^2", "J",
    "N", "N m", "W", "s", or "" (counts, dimensionless). Joint coordinates are "rad" or "m" when
    ``res`` is given (from the joint axes), otherwise "rad | m"; joint torques, actuator efforts
    and spring forces "N m" or "N" likewise (otherwise "N m | N")."""
    parts = str(name).split("/")
    if parts == ["time"]:
        return "s"
    if parts[0] == "energy":
        return "J"
    if parts[0] == "solver":
        return ""
    if parts[0] == "spring" and len(parts) == 3:
        return _SPRING.get(parts[2], "")
    if parts[0] == "coupling" and len(parts) == 3:
        return "N m | N"
    if parts[0] == "contact" and len(parts) >= 3:
        return {"force": "N", "normal_force": "N", "point": "m", "penetration": "m"}.get(
            parts[2], "")
    if parts[0] == "drive" and len(parts) >= 3:
        return "W" if parts[2] == "power" else _drive_unit(res, parts)
    if parts[0] == "marker" and len(parts) >= 4:
        if parts[2] in _PAIR:
            return "m" if parts[2] == "distance" else "m/s"
        if parts[2] == "accelerometer":
            return "m/s^2"
        if parts[2] == "gyroscope":
            return "rad/s"
    if parts[0] in ("node", "marker") and len(parts) >= 4:
        q, last = parts[2], parts[-1]
        if q in ("position", "displacement"):
            return "m"
        if q == "rotation":
            return ""
        rot = last.startswith("w")
        if q == "velocity":
            return "rad/s" if rot else "m/s"
        if q == "acceleration":
            return "rad/s^2" if rot else "m/s^2"
    if parts[0] == "beam" and len(parts) >= 4:
        if parts[3] == "energy":
            return "J"
        last = parts[-1]
        if parts[3] == "force":
            return "N m" if last in ("T", "M2", "M3") else "N"
        if parts[3] == "strain":
            return "1/m" if last.startswith("k") else ""
    if parts[0] == "joint" and len(parts) == 5 and parts[2] == "reaction":
        return "N" if parts[4].startswith("f") else "N m"
    if parts[0] == "joint" and len(parts) == 4:
        q = parts[2]
        if q in ("torque", *PARTS):
            unit = "rad | m"
            if res is not None and parts[3].isdigit():
                unit = _joint_unit(res, unescape_name(parts[1]), int(parts[3])) or unit
            return " | ".join({"rad": "N m", "m": "N"}[u] for u in unit.split(" | "))
        if q == "multiplier":
            return "N" if parts[3].isdigit() and int(parts[3]) % 6 < 3 else "N m"
        unit = "rad | m"
        if res is not None and parts[3].isdigit():
            unit = _joint_unit(res, unescape_name(parts[1]), int(parts[3])) or unit
        if q == "velocity":
            return " | ".join(u + "/s" for u in unit.split(" | "))
        return unit
    return ""


def _joint_unit(res: Results, joint: str, c: int) -> str:
    try:
        ids = res._joints(joint)
    except KeyError:
        return ""
    s = res.system
    units = joint_units(s)
    k = np.asarray(s.joint_k, dtype=int)
    start = np.cumsum(k) - k
    cols = [u for j in ids for u in units[start[j]:start[j] + k[j]]]
    return cols[c] if c < len(cols) else ""


def joint_units(system) -> tuple[str, ...]:
    """"rad" (rotation) or "m" (translation) per joint unknown, joints in order ("" when unknown).

    Uses ``system.joint_units`` (a layout read from a file) or the joint bases A of
    ``system.model``: a coordinate whose column of A has a rotation part is an angle.
    """
    if hasattr(system, "joint_units"):
        return tuple(system.joint_units)
    out: list[str] = []
    model = getattr(system, "model", None)
    for jj, k in enumerate(system.joint_k):
        A = None
        if model is not None:
            A = np.asarray(model.joints[jj].A, dtype=float).reshape(6, -1)
        for c in range(int(k)):
            out.append("" if A is None or A.shape[1] <= c
                       else ("rad" if np.any(A[3:, c] != 0.0) else "m"))
    return tuple(out)
