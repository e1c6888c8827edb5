"""Sensors a control law reads (``PID(sensor=...)``): results channel names that the compiled
kernel can evaluate from a state, parsed and checked against a model.

A sampled PID law (``sample_time``) may measure, instead of its joint's own coordinate, one of

* ``marker/<m>/position/x|y|z``: an inertial component of a marker's origin ``x + R p``
  (its rate ``R (U + Omega x p)``: the node's material velocities, Eq. (4));
* ``marker/<a>/distance/<b>``: the distance ``|p_b - p_a|`` of two markers (its rate
  ``(p_b - p_a) . (p_b' - p_a') / |p_b - p_a|``);
* ``joint/<j>/alpha/<i>``: the coordinate ``i`` of another (or the same) joint, and its rate.

These are the names of the same quantities as results channels (``se3dyn.results.channels``),
so what a law reads is what a run plots.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from se3dyn.errors import ModelError

if TYPE_CHECKING:
    from se3dyn.model.specs import Model

#: the channel forms a control law can read, for messages
FORMS = ("marker/<m>/position/x|y|z", "marker/<a>/distance/<b>", "joint/<j>/alpha/<i>")
_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class SensorRef:
    """A parsed sensor channel.

    Attributes
    ----------
    kind : str
        ``"position"``, ``"distance"`` or ``"coordinate"``.
    names : tuple of str
        The marker (position), the two markers (distance) or the joint (coordinate).
    index : int
        The inertial axis (position) or the joint coordinate; 0 for a distance.
    channel : str
        The name as given.
    """

    kind: str
    names: tuple[str, ...]
    index: int
    channel: str


def parse_sensor(channel: object, item: str, fld: str) -> SensorRef:
    """The :class:`SensorRef` of a channel name (syntax only; see :func:`check_sensor`).

    Raises
    ------
    ModelError
        Not one of :data:`FORMS`.
    """
    parts = channel.split("/") if isinstance(channel, str) else []
    if len(parts) == 4 and all(parts):
        head, name, qty, last = parts
        if head == "marker" and qty == "position" and last in _AXES:
            return SensorRef("position", (name,), _AXES[last], channel)
        if head == "marker" and qty == "distance":
            return SensorRef("distance", (name, last), 0, channel)
        if head == "joint" and qty == "alpha" and last.isdigit():
            return SensorRef("coordinate", (name,), int(last), channel)
    raise ModelError(item, fld, "a sensor channel " + " or ".join(FORMS), channel)


def check_sensor(ref: SensorRef, model: Model, item: str, fld: str) -> None:
    """Check that the markers or the joint (and its coordinate) of ``ref`` exist in ``model``.

    Raises
    ------
    ModelError
        Naming the channel and what it names that the model does not have.
    """
    if ref.kind == "coordinate":
        names = [j.name for j in model.joints]
        if ref.names[0] not in names:
            raise ModelError(item, fld, f"a joint of the model in {ref.channel!r}",
                             ref.names[0], hint=_listing("joints", names))
        k = model.joints[names.index(ref.names[0])].k
        if ref.index >= k:
            raise ModelError(item, fld, f"a coordinate index below {k} (joint "
                             f"{ref.names[0]!r} has {k} coordinates)", ref.channel)
        return
    markers = [m.name for m in model.markers]
    for name in ref.names:
        if name not in markers:
            raise ModelError(item, fld, f"a marker of the model in {ref.channel!r}", name,
                             hint=_listing("markers", markers))
    if ref.kind == "distance" and ref.names[0] == ref.names[1]:
        raise ModelError(item, fld, "the distance of two different markers", ref.channel)


def _listing(kind: str, names: list[str]) -> str:
    shown = ", ".join(names[:8]) + (" ..." if len(names) > 8 else "")
    return f"the model's {kind}: {shown}" if names else f"the model has no {kind}"
