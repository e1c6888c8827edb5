"""Model description: frozen, named specs built by :class:`ModelBuilder` and validated on build.

A model is what the user describes, with names, not numbers: nodes (frames with optional mass and
inertia, Sec. 2 and 6), kinematic joints between two nodes (``H_B = H_A H_J``, Eq. (7), or, with
an attachment point ``at``, ``H_B X_B = H_A X_A H_J``) with their force elements (springs
Eq. (62), dampers Eq. (64), actuators Eq. (66), PD control laws), nodal loads (Eq. (66)),
point spring-dampers, geometrically exact beams (chains of SE(3) beam elements between nodes,
:meth:`ModelBuilder.beam`, :mod:`se3dyn.elements.beam`) and gravity.
:func:`se3dyn.engine.system.compile_model` turns it into arrays.

Initial configuration (Sec. 5.2): node frames are ``H(R0, x0)`` with ``R0`` the identity unless
an ``orientation`` is given; joint transformations start at ``H_J0 = H_A0^-1 H_B0`` so that the
constraints hold exactly; joint axes are given in the inertial frame of the initial configuration
and expressed in the material frame of node B by the compiler.

Joint offsets. A joint given an attachment point ``at = p`` (inertial frame, initial
configuration) connects constant attachment frames of its nodes instead of the node frames: with
``P = H(I, p)``, ``X_A = H_A0^-1 P`` and ``X_B = H_B0^-1 P`` (4 x 4, constant), the joint imposes
``H_B X_B = H_A X_A H_J`` (Eq. (7) between the attachment frames), ``H_J0 = I``, and its axes
(inertial frame, initial configuration) are already expressed in the attachment frame of B. A rigid
body with several joints then needs a single node; without ``at`` a joint is exactly the paper's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from se3dyn.errors import ModelError, UnknownNameError, close_matches
from se3dyn.model.joint_types import is_abelian
from se3dyn.model.sensors import parse_sensor
from se3dyn.model.timefunc import TimeFunction, as_timefunc

if TYPE_CHECKING:
    from se3dyn.model.visuals import VisualSpec


@dataclass(frozen=True)
class PD:
    """PD control law on the relative coordinates of an abelian joint.

    The actuator force is ``tau = -kp (alpha - target(t)) - kd (alpha_dot - target_rate(t))``
    (a spring-damper with a moving reference, Eqs. (62), (64), (66)); ``target_rate`` defaults to
    the time derivative of ``target``.

    Parameters
    ----------
    kp, kd : float or array_like, shape (k,)
        Proportional and derivative gains (>= 0).
    target : number, array (k,), TimeFunction or callable of t
        Target relative coordinates alpha_ref(t).
    target_rate : same, optional
        Target rates; derivative of ``target`` if omitted.
    """

    kp: Any
    kd: Any = 0.0
    target: Any = 0.0
    target_rate: Any = None

    def __post_init__(self):
        # the checks joint(control=...) makes that need no joint (its k checks the lengths)
        for fld in ("kp", "kd"):
            v = getattr(self, fld)
            _kvec(v, int(np.size(v)) if isinstance(v, list | tuple | np.ndarray) else 1,
                  "PD", fld, nonneg=True)
        as_timefunc(self.target, "PD", "target")
        if self.target_rate is not None:
            as_timefunc(self.target_rate, "PD", "target_rate")


@dataclass(frozen=True)
class PID:
    """PID control law on the relative coordinates of an abelian joint, with saturation and
    anti-windup.

    ``tau = sat(-kp e - ki z - kd (alpha_dot - target_rate(t)))``, ``e = alpha - target(t)``,
    ``z = int e dt`` (zero at the start of a run), ``sat`` clipping to ``[-limit, limit]``. The
    integral is a state of the run, integrated inside every step's Newton iterations by the
    trapezoidal rule (second order, like the rest of the step; ``_core/elements/
    joint_force.hpp``); while the output is saturated and integrating would push it further,
    the integral holds (conditional integration: no windup).

    Parameters
    ----------
    kp, ki, kd : float or array_like, shape (k,)
        Proportional (N m/rad or N/m), integral (per second) and derivative gains (>= 0).
    target : number, array (k,), TimeFunction or callable of t
        Target relative coordinates alpha_ref(t).
    target_rate : same, optional
        Target rates; derivative of ``target`` if omitted.
    limit : float or array_like (k,), optional
        Largest magnitude of the law's force or torque (> 0); None: no saturation.
    sample_time : float, optional
        A sampled (digital) controller: the law is evaluated at the times ``k sample_time``
        only, from the state there, and its output held until the next (zero-order hold),
        with the integral summed as ``I_k = I_(k-1) + sample_time e_k``. The step of a run
        must divide it (fixed steps). None: the continuous law.
    gear : float, optional
        The law drives a motor behind a gear of ratio ``gear`` (motor turns per joint turn):
        the law's output and ``limit`` are the motor's torque, the joint receives ``gear``
        times it (so the gains act as ``gear`` times larger on the joint).
    rotor_inertia : float, optional
        The motor's rotor inertia; the joint's coordinates carry ``gear^2 rotor_inertia`` of
        it (its reflected inertia, added to the joint's ``armature``).
    sensor : str or sequence of str, optional
        A sampled law (``sample_time`` required) may measure a sensor instead of the joint's
        coordinate: ``e = s - target(t)``, ``e' = s' - target_rate(t)`` with ``s`` one of the
        results channels ``marker/<m>/position/x|y|z``, ``marker/<a>/distance/<b>`` or
        ``joint/<j>/alpha/<i>`` (:mod:`se3dyn.model.sensors`), evaluated by the compiled
        kernel at the sample times; one name per coordinate of the joint (a single name for
        a one-coordinate joint). None: the joint's own coordinates.
    """

    kp: Any
    ki: Any = 0.0
    kd: Any = 0.0
    target: Any = 0.0
    target_rate: Any = None
    limit: Any = None
    sample_time: Any = None
    gear: Any = 1.0
    rotor_inertia: Any = 0.0
    sensor: Any = None

    def __post_init__(self):
        for fld in ("kp", "ki", "kd"):
            v = getattr(self, fld)
            _kvec(v, int(np.size(v)) if isinstance(v, list | tuple | np.ndarray) else 1,
                  "PID", fld, nonneg=True)
        if self.limit is not None:
            v = self.limit
            _limits(v, int(np.size(v)) if isinstance(v, list | tuple | np.ndarray) else 1,
                    "PID", "limit")
        for fld, lo in (("gear", None), ("rotor_inertia", 0.0)):
            v = getattr(self, fld)
            if (isinstance(v, bool) or not isinstance(v, int | float | np.floating)
                    or not math.isfinite(v) or (lo is None and v == 0) or (lo is not None
                                                                          and v < lo)):
                raise ModelError("PID", fld, "a nonzero finite number" if lo is None else
                                 "a non-negative finite number", v)
        if self.sample_time is not None:
            ts = self.sample_time
            if (isinstance(ts, bool) or not isinstance(ts, int | float | np.floating)
                    or not (math.isfinite(ts) and ts > 0)):
                raise ModelError("PID", "sample_time", "a positive time in s (or None: a "
                                 "continuous law)", ts)
        as_timefunc(self.target, "PID", "target")
        if self.target_rate is not None:
            as_timefunc(self.target_rate, "PID", "target_rate")
        if self.sensor is not None:
            sensor_names(self.sensor, "PID", "sensor")
            if self.sample_time is None:
                raise ModelError("PID", "sensor", "a sampled law (sample_time=...) to read a "
                                 "sensor: a continuous law on a sensor is not built (its "
                                 "tangent would couple the joint to the sensor's bodies)",
                                 self.sensor)


def sensor_names(v: Any, item: str, fld: str) -> tuple[str, ...]:
    """A PID law's ``sensor``: a channel name or a sequence of them, as a tuple, each checked
    for its form (:func:`se3dyn.model.sensors.parse_sensor`)."""
    names = (v,) if isinstance(v, str) else tuple(v) if isinstance(v, list | tuple) else None
    if not names:
        raise ModelError(item, fld, "a sensor channel name or a list of them", v)
    for name in names:
        parse_sensor(name, item, fld)
    return names


@dataclass(frozen=True)
class Law:
    """An actuator law of the user's on an abelian joint's coordinates: ``tau = fn(t, q, v)``
    (q, v: the joint's k coordinates and rates, absolute; tau (k,) along them).

    Written in Python, it is called from the compiled time loop once per Newton iteration
    (the engine's callback, with the GIL), with its tangents ``d tau / d q`` and
    ``d tau / d v`` from ``jacobian(t, q, v) -> (k x k, k x k)`` or by central differences of
    ``fn`` (4 k more calls: steps ``1e-7 max(1, |x|)``), so Newton keeps its speed. Its
    cost is Python's: docs/control.md. ``torque=lambda t, q, v: ...`` makes one.
    """

    fn: Any = field(compare=False)
    jacobian: Any = field(default=None, compare=False)

    def __post_init__(self):
        if not callable(self.fn):
            raise ModelError("Law", "fn", "a callable fn(t, q, v)", self.fn)
        if self.jacobian is not None and not callable(self.jacobian):
            raise ModelError("Law", "jacobian", "a callable jacobian(t, q, v) or None",
                             self.jacobian)


def state_law(v: Any) -> Law | None:
    """``v`` as a :class:`Law` when it is one or a callable of three positional arguments
    (t, q, v); None otherwise (a time function, a number, ...)."""
    if isinstance(v, Law):
        return v
    if isinstance(v, TimeFunction) or not callable(v):
        return None
    import inspect

    try:
        params = list(inspect.signature(v).parameters.values())
    except (TypeError, ValueError):
        return None
    pos = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
           and p.default is p.empty]
    return Law(v) if len(pos) == 3 else None


@dataclass(frozen=True)
class NodeSpec:
    """A node: a frame in SE(3) (Eq. (1)) with optional rigid-body inertia at it (Eq. (49)).

    Attributes
    ----------
    name : str
    position : ndarray, shape (3,)
        Initial position in the inertial frame.
    orientation : ndarray, shape (3, 3)
        Initial rotation R0 (columns: material axes in the inertial frame); identity by default.
    mass : float
    inertia : ndarray, shape (3, 3)
        Inertia tensor about the node in the inertial frame of the initial configuration
        (``R0_principal J' R0_principal^T``, Sec. 6).
    fixed : bool
        Clamped node (no unknowns).
    velocity : ndarray, shape (6,)
        Initial velocity ``(U, Omega)`` in the *inertial* frame (converted on compile).
    com : ndarray, shape (3,), or None
        Centre of mass as a point in the inertial frame of the initial configuration (the
        convention of ``at``); None: at the node. ``inertia`` is about the centre of mass.
    """

    name: str
    position: np.ndarray
    orientation: np.ndarray
    mass: float
    inertia: np.ndarray
    fixed: bool
    velocity: np.ndarray
    com: np.ndarray | None = None


@dataclass(frozen=True)
class JointSpec:
    """A kinematic joint ``H_B = H_A H_J`` with ``H_J`` in the subgroup spanned by A (Eqs. 7-9),
    or ``H_B X_B = H_A X_A H_J`` between attachment frames when ``at`` is given.

    Attributes
    ----------
    name, type, node_a, node_b : str
    params : dict
        Type parameters as given (axis, axes, normal, pitch, A).
    A : ndarray, shape (6, k)
        Subalgebra basis in the inertial frame of the initial configuration (Table 1).
    stiffness, reference, damping : ndarray, shape (k,)
        Spring K (Eq. (62)) with reference alpha0, damper C (Eq. (64)).
    actuator : TimeFunction or None
        Actuator force/torque tau(t) (Eq. (66)), k components.
    control : PD, PID or None
        Control law, normalised: gains arrays (k,), target and target_rate TimeFunctions;
        a PID's limit an array (k,) (inf: no saturation).
    composite : str or None
        Name of the composite joint (e.g. a universal joint) this joint belongs to.
    initial : ndarray, shape (k,) or None
        Values of the relative coordinates in the initial configuration (abelian joints):
        coordinates, spring references and PD targets are then absolute; None: zero (they
        count from the initial configuration).
    at : ndarray, shape (3,), or None
        Attachment point in the inertial frame of the initial configuration: the joint connects
        the frames ``X_A = H_A0^-1 H(I, at)`` and ``X_B = H_B0^-1 H(I, at)`` rigidly attached to
        nodes A and B (see the module docstring). None: the node frames themselves (Eq. (7)).
    """

    name: str
    type: str
    node_a: str
    node_b: str
    params: dict
    A: np.ndarray
    stiffness: np.ndarray
    reference: np.ndarray
    damping: np.ndarray
    actuator: TimeFunction | None
    control: PD | PID | None
    composite: str | None = None
    at: np.ndarray | None = None
    initial: np.ndarray | None = None
    #: Internal (never given by users): the compiled joint of a condensed model
    #: (:mod:`se3dyn.dynamics.condense`), ``(X_A, X_B, H_J0, A)`` with the attachment frames
    #: (4, 4) on its
    #: nodes, the initial joint transformation and A (6, k) in the attachment frame of node B.
    frames: tuple | None = None
    #: (k,) inertia on the joint's coordinates (reflected rotor inertia), or None
    armature: np.ndarray | None = None
    #: an actuator law of the user's on the joint's coordinates, f(t, q, v), or None
    law: Law | None = None

    @property
    def k(self) -> int:
        return self.A.shape[1]

    @property
    def abelian(self) -> bool:
        return is_abelian(self.A)


@dataclass(frozen=True)
class LoadSpec:
    """External load on a body (Eq. (66)): a force and a torque, each a TimeFunction of 3
    components or None, given in the inertial or the body frame, the force applied at the point
    ``at`` (inertial frame, initial configuration; None: the node)."""

    name: str
    node: str
    force: TimeFunction | None
    torque: TimeFunction | None
    at: np.ndarray | None = None
    force_frame: str = "inertial"
    torque_frame: str = "body"


@dataclass(frozen=True)
class SpringDamperSpec:
    """A spring-damper between two points attached to two nodes: force
    ``stiffness (L - length) + damping dL/dt`` along the line of the points.

    Attributes
    ----------
    name, node_a, node_b : str
    at_a, at_b : ndarray (3,)
        The points in the inertial frame of the initial configuration.
    stiffness, damping : float
        N/m and N s/m (>= 0).
    length : float
        Free length L0 (m, >= 0).
    """

    name: str
    node_a: str
    node_b: str
    at_a: np.ndarray
    at_b: np.ndarray
    stiffness: float
    damping: float
    length: float


@dataclass(frozen=True)
class BushingSpec:
    """A bushing: stiffness and damping on the relative motion of two frames attached to two
    nodes at the point ``at``, ``d = log(H_a'^-1 H_b')`` (see :mod:`se3dyn.elements.bushing`).

    Attributes
    ----------
    name, node_a, node_b : str
    at : ndarray (3,)
        The bushing point in the inertial frame of the initial configuration: the origin of the
        frame attached to node a at t0 (and of the one attached to node b, without
        ``deformation``).
    stiffness, damping : ndarray (6, 6)
        Symmetric positive semi-definite K and D on ``(d_U, d_Omega)``, translation first, in
        the axes of the attached frames: N/m, N/rad, N m/rad (K); N s/m, N s/rad, N m s/rad (D).
    orientation : ndarray (3, 3)
        Rotation of the frame attached to node a at t0 (columns: the bushing axes in the
        inertial frame); the identity by default.
    deformation : ndarray (6,)
        Relative motion d at t0 (a preloaded bushing): the frame attached to node b is
        ``H(orientation, at) exp(deformation)`` at t0; zero by default.
    """

    name: str
    node_a: str
    node_b: str
    at: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    orientation: np.ndarray = field(default_factory=lambda: np.eye(3))
    deformation: np.ndarray = field(default_factory=lambda: np.zeros(6))


@dataclass(frozen=True)
class BeamSpec:
    """A geometrically exact beam on SE(3): a chain of two-node elements between its nodes
    (element ``e`` joins ``nodes[e]`` and ``nodes[e + 1]``), see :mod:`se3dyn.elements.beam`.

    Attributes
    ----------
    name : str
    nodes : tuple of str, length n + 1
        The nodes along the beam (the first and last given by the user, the others created by
        the builder and named ``f"{name}/{i}"``).
    reference : ndarray, shape (n + 1, 4, 4)
        Stress-free section frames (inertial frame): axis 1 along the beam, axes 2 and 3 the
        principal axes of the section.
    offsets : ndarray, shape (n + 1, 4, 4)
        Constant section frames in the material frames of the nodes, ``X_i = H_i0^-1 H_ref,i``
        (the identity for the nodes the builder creates).
    stiffness : ndarray, shape (6, 6)
        Section stiffness (translation first): ``diag(EA, GA2, GA3, GJ, EI2, EI3)``.
    damping : ndarray, shape (6, 6)
        Section damping on the strain rates (``f = K eps + D deps/dt``).
    mass_per_length : float
        kg/m.
    rotary_inertia : ndarray, shape (3,)
        Rotary inertia of the section per unit length about axes 1, 2, 3 (kg m).
    """

    name: str
    nodes: tuple[str, ...]
    reference: np.ndarray
    offsets: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    mass_per_length: float
    rotary_inertia: np.ndarray

    @property
    def elements(self) -> int:
        return len(self.nodes) - 1


@dataclass(frozen=True)
class MarkerSpec:
    """A marker: a frame fixed on a node, an output only (never part of the compiled system).

    The marker frame is ``H_m = H X`` (``H`` the node frame, Eq. (1)), with the constant offset
    ``X`` in the node's material frame; its kinematics and the sensors on it (accelerometer,
    gyroscope) are accessors of :class:`~se3dyn.results.results.Results`.

    Attributes
    ----------
    name, node : str
    X : ndarray, shape (4, 4)
        Offset of the marker frame in the material frame of the node: origin ``X[:3, 3]``,
        axes the columns of ``X[:3, :3]``.
    at, offset : ndarray (3,) or None
        As given to :meth:`ModelBuilder.marker` (kept to write the model file back): the origin
        as a point in the inertial frame of the initial configuration, or in the node's material
        frame; both None: at the node.
    orientation : ndarray (3, 3) or None
        As given: the marker axes in the inertial frame of the initial configuration; None: the
        node's axes.
    """

    name: str
    node: str
    X: np.ndarray
    at: np.ndarray | None = None
    offset: np.ndarray | None = None
    orientation: np.ndarray | None = None


@dataclass(frozen=True)
class DriveSpec:
    """Prescribed motion of joint coordinates (a rheonomic driver, issue 30).

    Each driven coordinate of an abelian joint follows a function of time: its position
    ``alpha(t) = f(t)`` (absolute coordinates, as :attr:`JointSpec.initial` counts them), or its
    rate ``v(t) = g(t)`` with the position integrated by the time loop. The coordinate stays an
    unknown of the step whose value the driver sets (:mod:`se3dyn.engine.system`); the force or
    torque the driver supplies is the residual of its equation of motion (Eq. (36)), an exact
    output (:meth:`se3dyn.results.results.Results.drive_effort`).

    Attributes
    ----------
    name, joint : str
        The driver and the joint as given (a composite joint such as a universal joint too).
    position, velocity : dict[int, TimeFunction]
        As given, by coordinate index of ``joint``.
    targets : tuple of (str, int, str)
        Per driven coordinate, in order of the coordinate index: the joint it belongs to (a
        part of a composite joint), its index there, and ``"position"`` or ``"velocity"``.
    functions : tuple of TimeFunction
        The function of each target.
    """

    name: str
    joint: str
    position: dict
    velocity: dict
    targets: tuple
    functions: tuple


@dataclass(frozen=True)
class CouplingSpec:
    """An exact linear coupling of two joint coordinates, ``alpha_b = ratio alpha_a + offset``
    (gears, racks, belts, URDF ``<mimic>``; :meth:`se3dyn.ModelBuilder.coupling`).

    Attributes
    ----------
    name : str
    leader, follower : tuple (joint as given, coordinate index, compiled joint, index there)
    ratio, offset : float
    """

    name: str
    leader: tuple
    follower: tuple
    ratio: float
    offset: float


@dataclass(frozen=True)
class Model:
    """A validated, immutable model. Build it with :class:`ModelBuilder`."""

    nodes: tuple[NodeSpec, ...]
    joints: tuple[JointSpec, ...]
    loads: tuple[LoadSpec, ...] = ()
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    composites: dict = field(default_factory=dict)
    name: str = "model"
    springs: tuple[SpringDamperSpec, ...] = ()
    #: shapes drawn by the viewer (never used by the physics), see :mod:`se3dyn.model.visuals`
    visuals: tuple[VisualSpec, ...] = ()
    beams: tuple[BeamSpec, ...] = ()
    bushings: tuple[BushingSpec, ...] = ()
    #: frames fixed on nodes, read by the results (never used by the physics)
    markers: tuple[MarkerSpec, ...] = ()
    #: prescribed motion of joint coordinates
    drives: tuple[DriveSpec, ...] = ()
    #: exact couplings of joint coordinates
    couplings: tuple[CouplingSpec, ...] = ()
    #: collision shapes on nodes (:mod:`se3dyn.model.contact`)
    collisions: tuple = ()
    #: pairs of shapes with their own material, or disabled
    contact_pairs: tuple = ()

    def __post_init__(self):
        # immutable for good: the arrays of every spec are read-only (a model compiles once,
        # :func:`se3dyn.engine.system.system_of`, so a change in place would go unseen)
        _read_only(self.gravity)
        for spec in (*self.nodes, *self.joints, *self.loads, *self.springs, *self.beams,
                     *self.bushings, *self.visuals, *self.markers, *self.collisions):
            for value in vars(spec).values():
                _read_only(value)

    def __getstate__(self) -> dict:
        # the compiled system kept with the model (system_of) is not part of the model
        return {k: v for k, v in self.__dict__.items() if k != "_system"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    def node(self, name: str) -> NodeSpec:
        """The node called ``name`` (:class:`~se3dyn.errors.UnknownNameError`, a KeyError,
        listing valid names otherwise)."""
        for n in self.nodes:
            if n.name == name:
                return n
        raise UnknownNameError(_unknown("node", name, [n.name for n in self.nodes]))

    def joint(self, name: str) -> JointSpec:
        """The joint called ``name``."""
        for j in self.joints:
            if j.name == name:
                return j
        raise UnknownNameError(_unknown("joint", name, [j.name for j in self.joints]))

    def drive(self, name: str) -> DriveSpec:
        """The driver called ``name``."""
        for dr in self.drives:
            if dr.name == name:
                return dr
        raise UnknownNameError(_unknown("drive", name, [dr.name for dr in self.drives]))

    def marker(self, name: str) -> MarkerSpec:
        """The marker called ``name``."""
        for mk in self.markers:
            if mk.name == name:
                return mk
        raise UnknownNameError(_unknown("marker", name, [mk.name for mk in self.markers]))

    @property
    def node_names(self) -> list[str]:
        return [n.name for n in self.nodes]

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]


def _read_only(value) -> None:
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif isinstance(value, tuple):
        for v in value:
            _read_only(v)


#: Largest magnitude accepted for a number of a model (positions, lengths, masses, stiffnesses,
#: pitches, reference values, velocities): beyond it products and squares overflow.
MAX_ABS = 1e15
#: Largest ratio of a body's inertia about its node (``m |com - position|^2``) to its smallest
#: principal moment about the centre of mass: beyond, the rotation about the centre of mass
#: keeps fewer than 6 of the 16 digits of the mass matrix, and the rank analysis of ``check``
#: (relative tolerance 1e-10) counts it as a motion without inertia.
INERTIA_RANGE = 1e10
#: Longest accepted name (nodes, joints, loads, springs, visuals, the model).
MAX_NAME = 200


def _check_name(kind: str, name: Any) -> str:
    """A name must be printable text (stored in HDF5 and YAML files): no control characters,
    no lone surrogates, at most MAX_NAME characters."""
    if not isinstance(name, str) or not name:
        raise ModelError(kind, "name", "a non-empty string", name)
    if not name.isprintable() or len(name) > MAX_NAME:
        raise ModelError(kind, "name", f"printable text of at most {MAX_NAME} characters (no "
                         "control characters, no lone surrogates)", name)
    return name


def _bounded(a: np.ndarray, item: str, fld: str, v: Any) -> np.ndarray:
    if np.any(np.abs(a) > MAX_ABS):
        raise ModelError(item, fld, f"values of magnitude at most {MAX_ABS:g}", v,
                         "larger values overflow in the computation")
    return a


def _unknown(kind: str, name: str, valid: list[str]) -> str:
    close = close_matches(str(name), valid, n=1)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    shown = ", ".join(repr(v) for v in valid[:20]) + (" ..." if len(valid) > 20 else "")
    return f"unknown {kind} {name!r}{hint} (valid: {shown})"


def _vec(v: Any, n: int, item: str, fld: str, *, allow_none: bool = False) -> np.ndarray | None:
    if v is None and allow_none:
        return None
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, fld, f"{n} numbers", v) from None
    if a.shape != (n,):
        raise ModelError(item, fld, f"{n} numbers", v)
    if not np.all(np.isfinite(a)):
        raise ModelError(item, fld, f"{n} finite numbers", v)
    return _bounded(a, item, fld, v)


def _k_array(v: Any, k: int, item: str, fld: str, expected: str) -> np.ndarray:
    """``v`` as an array (k,): one number for all k, or k numbers (ModelError otherwise)."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, fld, expected, v) from None
    if a.ndim == 0:
        a = np.full(k, float(a))
    if a.shape != (k,):
        raise ModelError(item, fld, expected, v)
    return a


def _kvec(v: Any, k: int, item: str, fld: str, *, nonneg: bool = False) -> np.ndarray:
    a = _k_array(v, k, item, fld, f"a number or {k} numbers (one per relative coordinate)")
    if not np.all(np.isfinite(a)):
        raise ModelError(item, fld, "finite numbers", v)
    if nonneg and np.any(a < 0):
        raise ModelError(item, fld, "non-negative values", v)
    return _bounded(a, item, fld, v)


def _limits(v: Any, k: int, item: str, fld: str) -> np.ndarray:
    """Output limits (k,) of a control law: positive numbers, inf for none."""
    expected = f"a positive number or {k} (inf: no limit)"
    a = _k_array(v, k, item, fld, expected)
    if np.any(np.isnan(a)) or np.any(a <= 0):
        raise ModelError(item, fld, expected, v)
    return a


def _sym6(v: Any, item: str, fld: str) -> np.ndarray:
    """A symmetric positive semi-definite 6 x 6 matrix from one number (all six diagonal
    values), 6 diagonal values or a 6 x 6 matrix."""
    expected = ("a non-negative number, 6 non-negative diagonal values or a symmetric positive "
                "semi-definite 6 x 6 matrix")
    try:
        if isinstance(v, bool | str | bytes) or v is None:
            raise TypeError(v)
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, fld, expected, v) from None
    if a.shape not in ((), (6,), (6, 6)):
        raise ModelError(item, fld, expected, v, f"got an array of shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ModelError(item, fld, "finite values (" + expected + ")", v)
    _bounded(a, item, fld, v)
    if a.ndim < 2:
        if np.any(a < 0):
            raise ModelError(item, fld, "non-negative diagonal values", v,
                             "a negative stiffness or damping creates energy")
        return np.diag(np.broadcast_to(a, (6,))).astype(float)
    tol = 1e-12 * max(1.0, float(np.abs(a).max()))
    if np.abs(a - a.T).max() > tol:
        i, j = np.unravel_index(int(np.argmax(np.abs(a - a.T))), a.shape)
        raise ModelError(item, fld, "a symmetric 6 x 6 matrix", v,
                         f"entries [{i}][{j}] = {a[i, j]:g} and [{j}][{i}] = {a[j, i]:g} differ")
    a = 0.5 * (a + a.T)
    ev = np.linalg.eigvalsh(a)
    if ev[0] < -1e-12 * max(1.0, float(np.abs(ev).max())):
        raise ModelError(item, fld, "a positive semi-definite 6 x 6 matrix", v,
                         f"eigenvalue {ev[0]:g} < 0: the element would create energy")
    return a


def _rotation(v: Any, item: str, fld: str) -> np.ndarray:
    try:
        R = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, fld, "a 3x3 rotation matrix", v) from None
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ModelError(item, fld, "a 3x3 rotation matrix", v)
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0:
        raise ModelError(item, fld, "an orthonormal matrix with determinant +1 (a rotation)", R)
    return R
