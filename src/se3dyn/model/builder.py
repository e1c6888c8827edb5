"""The mutable :class:`ModelBuilder`: nodes, joints (with their springs, dampers, actuators and PD
laws), loads, spring-dampers, bushings and beams added by name and validated as they are added;
``build()`` gives the frozen :class:`~se3dyn.model.specs.Model`. The conventions (initial
configuration, attachment offsets) are in :mod:`se3dyn.model.specs`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from se3dyn.errors import ModelError, close_matches
from se3dyn.model.contact import SHAPES, CollisionSpec, ContactMaterial, ContactPairSpec
from se3dyn.model.joint_types import JOINT_SYNONYMS, JOINT_TYPES, is_abelian, unit_vector
from se3dyn.model.sensors import check_sensor, parse_sensor
from se3dyn.model.specs import (
    INERTIA_RANGE,
    MAX_ABS,
    PD,
    PID,
    BeamSpec,
    BushingSpec,
    CouplingSpec,
    DriveSpec,
    JointSpec,
    LoadSpec,
    MarkerSpec,
    Model,
    NodeSpec,
    SpringDamperSpec,
    _bounded,
    _check_name,
    _kvec,
    _limits,
    _rotation,
    _sym6,
    _unknown,
    _vec,
    sensor_names,
    state_law,
)
from se3dyn.model.timefunc import Component, as_timefunc
from se3dyn.model.visuals import VisualSpec, make_visual


class ModelBuilder:
    """Mutable builder of a :class:`Model` (the Python front door).

    Parameters
    ----------
    gravity : array_like, shape (3,)
        Gravity acceleration in the inertial frame, e.g. ``(0, 0, -9.81)``.
    name : str
        Model name (used in results and files).

    Examples
    --------
    >>> import se3dyn as sd
    >>> mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    >>> mb.node("ground", position=(0, 0, 0), fixed=True)
    >>> mb.node("bob", position=(1, 0, 0), mass=1.0, inertia=(1e-3, 1e-3, 1e-3))
    >>> mb.joint("pivot", "spherical", "ground", "bob")  # doctest: +SKIP
    """

    def __init__(self, gravity: Any = (0.0, 0.0, 0.0), name: str = "model"):
        self._gravity = _vec(gravity, 3, "model", "gravity")
        self._name = _check_name("model", name)
        self._nodes: dict[str, NodeSpec] = {}
        self._joints: dict[str, JointSpec] = {}
        self._loads: dict[str, LoadSpec] = {}
        self._springs: dict[str, SpringDamperSpec] = {}
        self._bushings: dict[str, BushingSpec] = {}
        self._composites: dict[str, tuple[str, ...]] = {}
        self._visuals: dict[str, VisualSpec] = {}
        self._beams: dict[str, BeamSpec] = {}
        self._markers: dict[str, MarkerSpec] = {}
        self._drives: dict[str, DriveSpec] = {}
        self._couplings: dict[str, CouplingSpec] = {}
        self._collisions: dict[str, CollisionSpec] = {}
        self._contact_pairs: dict[frozenset, ContactPairSpec] = {}

    @classmethod
    def from_model(cls, model: Model) -> ModelBuilder:
        """A builder holding everything of a built ``model`` (its validated specs as they are),
        to add to it: drives to an example, markers to a model read from a file, bodies to an
        imported robot. ``from_model(m).build()`` has the very specs of ``m``.

        Examples
        --------
        >>> mb = sd.ModelBuilder.from_model(sd.examples.slider_crank())  # doctest: +SKIP
        >>> mb.drive("motor", "1", velocity=2 * math.pi)  # doctest: +SKIP
        """
        if not isinstance(model, Model):
            raise ModelError("ModelBuilder.from_model", "model", "a Model (ModelBuilder.build())",
                             type(model).__name__)
        mb = cls(model.gravity, model.name)
        for attr, specs in (("_nodes", model.nodes), ("_joints", model.joints),
                            ("_loads", model.loads), ("_springs", model.springs),
                            ("_bushings", model.bushings), ("_visuals", model.visuals),
                            ("_beams", model.beams), ("_markers", model.markers),
                            ("_drives", model.drives), ("_couplings", model.couplings),
                            ("_collisions", model.collisions)):
            getattr(mb, attr).update((sp.name, sp) for sp in specs)
        mb._contact_pairs.update((frozenset((p.a, p.b)), p) for p in model.contact_pairs)
        mb._composites.update(model.composites)
        return mb

    # -----------------------------------------------------------------------------------------
    def node(self, name: str, position: Any = (0.0, 0.0, 0.0), *, orientation: Any = None,
             mass: float = 0.0, inertia: Any = None, principal_axes: Any = None,
             fixed: bool = False, velocity: Any = None, angular_velocity: Any = None,
             velocity_frame: str = "inertial", com: Any = None) -> None:
        """Add a node.

        Parameters
        ----------
        name : str
            Unique node name.
        position : array_like, shape (3,)
            Initial position in the inertial frame (Table 2).
        orientation : array_like, shape (3, 3), optional
            Initial rotation R0 of the node frame (identity by default, as the paper proposes).
        mass : float
            Mass (kg), >= 0. A node with mass needs a positive-definite inertia.
        inertia : array_like, shape (3,) or (3, 3), optional
            Principal moments ``(J1, J2, J3)`` about ``principal_axes`` (identity by default),
            or a full symmetric tensor in the inertial frame of the initial configuration (Sec. 6).
        principal_axes : array_like, shape (3, 3), optional
            Rotation ``R0_I`` whose columns are the principal axes (Sec. 6, ``J = R0 J' R0^T``).
        fixed : bool
            Clamped node (boundary condition); must carry no mass.
        velocity, angular_velocity : array_like, shape (3,), optional
            Initial linear and angular velocity.
        velocity_frame : {"inertial", "material"}
            Frame in which the initial velocities are given.
        com : array_like, shape (3,), optional
            Centre of mass as a point in the inertial frame of the initial configuration (the
            convention of ``at``), when the node is not at it (e.g. at a joint or at the fixed
            point of a top); ``inertia`` is then about the centre of mass. The constant
            material mass matrix about the node and its gyroscopic terms generalise Eqs.
            (47)-(53). At most ``sqrt(INERTIA_RANGE J_min / m)`` from the node
            (:data:`INERTIA_RANGE`).
        """
        _check_name("node", name)
        item = f"node {name!r}"
        if name in self._nodes:
            raise ModelError(item, "name", "a unique node name", name, "defined twice")
        x = _vec(position, 3, item, "position")
        R0 = np.eye(3) if orientation is None else _rotation(orientation, item, "orientation")
        try:
            if isinstance(mass, bool | str):
                raise TypeError(mass)
            m = float(mass)
        except (TypeError, ValueError):
            raise ModelError(item, "mass", "a non-negative number (kg)", mass) from None
        if not math.isfinite(m) or m < 0 or m > MAX_ABS:
            raise ModelError(item, "mass", f"a non-negative finite number (kg) <= {MAX_ABS:g}",
                             mass)
        if not isinstance(fixed, bool | np.bool_):
            raise ModelError(item, "fixed", "True or False", fixed)
        J = self._inertia(item, m, inertia, principal_axes)
        if fixed and (m > 0 or np.any(J != 0)):
            raise ModelError(item, "mass", "no mass or inertia on a fixed node", m,
                             "a clamped node does not move; put the body on a free node")
        if velocity_frame not in ("inertial", "material"):
            raise ModelError(item, "velocity_frame", "'inertial' or 'material'", velocity_frame)
        vU = np.zeros(3) if velocity is None else _vec(velocity, 3, item, "velocity")
        vO = (np.zeros(3) if angular_velocity is None
              else _vec(angular_velocity, 3, item, "angular_velocity"))
        if fixed and (np.any(vU != 0) or np.any(vO != 0)):
            raise ModelError(item, "velocity", "zero velocity for a fixed node", (vU, vO))
        if velocity_frame == "material":
            vU, vO = R0 @ vU, R0 @ vO
        c = None
        if com is not None:
            c = _vec(com, 3, item, "com")
            if m == 0:
                raise ModelError(item, "com", "a centre of mass only on a node with mass", com,
                                 "give the node a mass and an inertia")
            d2 = float(np.sum((c - x) ** 2))
            jmin = float(np.linalg.eigvalsh(J)[0])
            if m * d2 > INERTIA_RANGE * jmin:
                reach = math.sqrt(INERTIA_RANGE * jmin / m)
                raise ModelError(item, "com", f"a centre of mass within {reach:.3g} m of the "
                                 f"node (its inertia about the node, m |c - x|^2 = "
                                 f"{m * d2:.3g} kg m^2, at most {INERTIA_RANGE:.0e} times the "
                                 f"smallest moment about the centre of mass, {jmin:.3g})", com,
                                 "beyond, the rotation about the centre of mass is lost in the "
                                 "round-off: place the node on the body")
        self._nodes[name] = NodeSpec(name, x, R0, m, J, bool(fixed), np.concatenate([vU, vO]),
                                     c)

    @staticmethod
    def _inertia(item: str, m: float, inertia: Any, axes: Any) -> np.ndarray:
        if inertia is None:
            if m > 0:
                raise ModelError(item, "inertia", "a positive-definite inertia for a node with "
                                 "mass", None, "give principal values (J1, J2, J3)")
            return np.zeros((3, 3))
        try:
            Jin = np.asarray(inertia, dtype=float)
        except (TypeError, ValueError):
            raise ModelError(item, "inertia", "3 principal values or a 3x3 tensor",
                             inertia) from None
        if not np.all(np.isfinite(Jin)):
            raise ModelError(item, "inertia", "finite values", inertia)
        _bounded(Jin, item, "inertia", inertia)
        if Jin.shape == (3,):
            Rp = np.eye(3) if axes is None else _rotation(axes, item, "principal_axes")
            J = Rp @ np.diag(Jin) @ Rp.T
            J = 0.5 * (J + J.T)  # exactly symmetric, like a given tensor
        elif Jin.shape == (3, 3):
            if axes is not None:
                raise ModelError(item, "principal_axes", "no principal axes with a full tensor",
                                 axes)
            if np.abs(Jin - Jin.T).max() > 1e-12 * max(1.0, np.abs(Jin).max()):
                raise ModelError(item, "inertia", "a symmetric 3x3 tensor", Jin)
            J = 0.5 * (Jin + Jin.T)
        else:
            raise ModelError(item, "inertia", "3 principal values or a 3x3 tensor", inertia)
        if m == 0 and np.any(J != 0):
            raise ModelError(item, "inertia", "no inertia on a node without mass", inertia,
                             "give the node a mass")
        if m > 0:
            ev = np.linalg.eigvalsh(J)
            if ev.min() <= 0:
                raise ModelError(item, "inertia", "a positive-definite inertia", inertia,
                                 f"eigenvalues {ev}")
            # a real mass distribution: each principal moment at most the sum of the other two
            if ev[2] > (ev[0] + ev[1]) * (1 + 1e-9):
                raise ModelError(item, "inertia", "principal moments satisfying the triangle "
                                 "inequality J3 <= J1 + J2 of a real body", inertia,
                                 f"principal moments {ev}: no mass distribution has them")
        return J

    # -----------------------------------------------------------------------------------------
    def joint(self, name: str, type: str, node_a: str, node_b: str, *, axis: Any = None,
              axes: Any = None, normal: Any = None, pitch: Any = None, A: Any = None,
              stiffness: Any = None, reference: Any = None, damping: Any = None,
              actuator: Any = None, torque: Any = None, force: Any = None,
              control: PD | PID | None = None, at: Any = None,
              initial: Any = None, armature: Any = None) -> None:
        """Add a kinematic joint ``H_B = H_A H_J`` (Eq. (7)) between nodes A and B, or between
        frames attached to them at the point ``at``.

        Parameters
        ----------
        name : str
            Unique joint name.
        type : str
            One of ``rigid, hinge, prismatic, cylindrical, spherical, planar, screw, general,
            universal`` (Table 1).
        node_a, node_b : str
            Node names (A and B of Eq. (7)).
        axis : array_like, shape (3,)
            Unit axis (hinge, prismatic, cylindrical, screw), inertial frame, initial config.
        axes : array_like, shape (3, 3) / (2, 3)
            Spherical: three orthonormal rotation axes (identity default). Planar: two in-plane
            axes. Universal: the two hinge axes (first on A's side, second on B's side).
        normal : array_like, shape (3,)
            Planar joint: plane normal.
        pitch : float
            Screw joint: translation per radian (m/rad).
        A : array_like, shape (6, k)
            General joint: subalgebra basis, columns ``(e_U, e_Omega)``.
        stiffness, reference : float or array_like, shape (k,)
            Spring on the relative coordinates, Eq. (62): ``K (alpha - reference)``.
        damping : float or array_like, shape (k,)
            Damper on the relative velocities, Eq. (64): ``C v_j``.
        actuator : number, array (k,), TimeFunction or callable of t
            Actuator force/torque tau(t) on the relative coordinates (Eq. (66)). ``torque`` and
            ``force`` are aliases, for readability.
        control : PD or PID, optional
            PD or PID control law on the relative coordinates (abelian joints only).
        at : array_like, shape (3,), optional
            Where the joint sits: a point in the inertial frame of the initial configuration.
            The joint then connects two frames rigidly attached to nodes A and B, both at ``at``
            with the inertial orientation at t0: ``X_A = H_A0^-1 P``, ``X_B = H_B0^-1 P`` with
            ``P = H(I, at)`` (constant 4 x 4 offsets), and imposes ``H_B X_B = H_A X_A H_J``
            (Eq. (7) between the attachment frames; constraints ``vect((H_B X_B)^-1 H_A X_A
            H_J)``, Eq. (55)), ``H_J0 = I``. The nodes may be anywhere (e.g. at the mass
            centres), so a rigid body with several joints needs one node. Without ``at`` the
            joint acts between the node frames, as in the paper (``X_A = X_B = I``). A
            universal joint puts both hinges and its cross at ``at``.
        armature : float or array_like (k,), optional
            Abelian joints: inertia added to the joint's own coordinates (kg m^2 for an angle,
            kg for a translation), the reflected inertia ``N^2 J_rotor`` of a motor's rotor
            behind a gear of ratio N (MuJoCo's ``armature``): the kinetic energy
            ``1/2 armature v^2`` and the force ``armature * v_dot`` on the coordinate.
        initial : float or array_like (k,), optional
            Abelian joints (hinge, prismatic, cylindrical, screw, universal): the values of
            the relative coordinates in the initial configuration, e.g. a hinge that starts at
            an absolute angle of 30 degrees: ``initial=math.radians(30)``. Coordinates
            (results, Eq. (60)), spring references and PD targets are then absolute; the
            configuration itself is the one the nodes give. By default the coordinates count
            from the initial configuration (zero there).
        """
        jt_keys = sorted(list(JOINT_TYPES) + ["universal"])
        _check_name("joint", name)
        if isinstance(type, str):
            type = JOINT_SYNONYMS.get(type, type)  # revolute -> hinge, ball -> spherical, ...
        if not isinstance(type, str) or type not in jt_keys:
            close = close_matches(str(type), jt_keys + list(JOINT_SYNONYMS), n=1)
            hint = ""
            if close:
                c = close[0]
                hint = (f"did you mean '{c}' (se3dyn's '{JOINT_SYNONYMS[c]}')?"
                        if c in JOINT_SYNONYMS else f"did you mean '{c}'?")
            raise ModelError(f"joint {name!r}", "type", "one of " + ", ".join(jt_keys)
                             + " (or a synonym: " + ", ".join(
                                 f"{k} = {v}" for k, v in JOINT_SYNONYMS.items()) + ")", type,
                             hint)
        item = f"joint {name!r} ({type})"
        if name in self._joints or name in self._composites:
            raise ModelError(item, "name", "a unique joint name", name, "defined twice")
        for fld, nd in (("node_a", node_a), ("node_b", node_b)):
            if not isinstance(nd, str) or nd not in self._nodes:
                raise ModelError(item, fld, "the name of a node defined before the joint", nd,
                                 _unknown("node", nd, list(self._nodes)))
        if node_a == node_b:
            raise ModelError(item, "node_b", "a node other than node_a", node_b,
                             "a joint between a node and itself")
        acts = [(k, v) for k, v in (("actuator", actuator), ("torque", torque), ("force", force))
                if v is not None]
        if len(acts) > 1:
            raise ModelError(item, acts[1][0], "only one of actuator/torque/force", acts[1][1])
        act_field, act = acts[0] if acts else ("actuator", None)
        law = state_law(act)
        if law is not None and type == "universal":
            raise ModelError(item, act_field, "a function of t (a law f(t, q, v) on the hinges of "
                             "a universal joint: give each hinge its own joint)", act)
        p = _vec(at, 3, item, "at", allow_none=True)
        if type == "universal":
            self._universal(name, node_a, node_b, axes, stiffness, reference, damping,
                            act_field, act, control, p, initial, armature)
            return
        given = {"axis": axis, "axes": axes, "normal": normal, "pitch": pitch, "A": A}
        jt = JOINT_TYPES[type]
        for key, val in given.items():
            if val is not None and key not in jt.params:
                raise ModelError(item, key, "parameters " + (", ".join(jt.params) or "none"),
                                 val, f"a {type} joint takes no '{key}'")
        params = {key: given[key] for key in jt.params}
        for key in ("axis", "normal", "pitch", "A"):
            if key in params and params[key] is None:
                raise ModelError(item, key, f"a value (required for a {type} joint)", None)
        A_ = jt.make_A(item, **params)
        self._add_joint(name, type, node_a, node_b, params, A_, stiffness, reference, damping,
                        act_field, None if law else act, control, at=p, initial=initial,
                        armature=armature, law=law)

    def _add_joint(self, name, type, node_a, node_b, params, A_, stiffness, reference, damping,
                   act_field, act, control, composite=None, at=None, initial=None,
                   armature=None, law=None):
        item = f"joint {name!r} ({type})"
        if name in self._joints:
            raise ModelError(f"joint {composite!r}" if composite else item, "name",
                             "a joint name not used yet", name,
                             f"joint {name!r} exists already" + (
                                 f"; the parts of composite joint {composite!r} are named "
                                 f"'{composite}:1' and '{composite}:2'" if composite else ""))
        k = A_.shape[1]
        K = np.zeros(k) if stiffness is None else _kvec(stiffness, k, item, "stiffness",
                                                           nonneg=True)
        a0 = np.zeros(k) if reference is None else _kvec(reference, k, item, "reference")
        C = np.zeros(k) if damping is None else _kvec(damping, k, item, "damping", nonneg=True)
        if k == 0:
            for fld, v in (("stiffness", stiffness), ("damping", damping), (act_field, act),
                           ("control", control)):
                if v is not None:
                    raise ModelError(item, fld, "nothing: a rigid joint has no relative "
                                     "coordinates", v)
        tau = None if act is None else as_timefunc(act, item, act_field, k)
        pd = None
        if control is not None:
            if not isinstance(control, PD | PID):
                raise ModelError(item, "control", "an se3dyn.PD(kp, kd, target) or "
                                 "se3dyn.PID(kp, ki, kd, target) law", control)
            if not is_abelian(A_):
                raise ModelError(item, "control", "an abelian joint (hinge, prismatic, "
                                 "cylindrical, screw) for a control law on relative coordinates",
                                 type)
            pd = _control_law(control, k, item)
        init = None
        if initial is not None:
            if k == 0 or not is_abelian(A_):
                raise ModelError(item, "initial", "an abelian joint (hinge, prismatic, "
                                 "cylindrical, screw, universal): its coordinates add up",
                                 type, "the coordinates of this joint are log coordinates of "
                                 "its relative motion, zero in the initial configuration")
            init = _kvec(initial, k, item, "initial")
        arm = None
        if armature is not None:
            if not is_abelian(A_):
                raise ModelError(item, "armature", "an abelian joint (its coordinates' rates are "
                                 "the rotor's)", type)
            arm = _kvec(armature, k, item, "armature", nonneg=True)
        if law is not None:
            _check_law(law, k, A_, item, act_field, init)
        self._joints[name] = JointSpec(name, type, node_a, node_b, params, A_, K, a0, C, tau, pd,
                                       composite, None if at is None else at.copy(), init,
                                       armature=arm, law=law)

    def _universal(self, name, node_a, node_b, axes, stiffness, reference, damping, act_field,
                   act, control, at=None, initial=None, armature=None):
        item = f"joint {name!r} (universal)"
        try:
            ax = np.asarray(axes, dtype=float)
        except (TypeError, ValueError):
            ax = None
        if axes is None or ax is None or ax.shape != (2, 3):
            raise ModelError(item, "axes", "two orthogonal unit axes (shape (2, 3))", axes)
        a1 = unit_vector(ax[0], item, "axes[0]")
        a2 = unit_vector(ax[1], item, "axes[1]")
        if abs(a1 @ a2) > 1e-9:
            raise ModelError(item, "axes", "two orthogonal axes (a cardan cross)", axes)
        cross = f"{name}:cross"
        if cross in self._nodes:
            raise ModelError(item, "name", "a name whose ':cross' node is free", cross)
        # the cross sits at the centre of the universal joint: node B, or the attachment point
        centre = self._nodes[node_b].position if at is None else at
        self._nodes[cross] = NodeSpec(cross, centre.copy(), np.eye(3), 0.0,
                                      np.zeros((3, 3)), False, np.zeros(6))

        def part(v, i, fld):
            if v is None:
                return None
            a = _kvec(v, 2, item, fld)
            return a[i]

        tau = None if act is None else as_timefunc(act, item, act_field, 2)
        sub = []
        for i, (na, nb, a) in enumerate(((node_a, cross, a1), (cross, node_b, a2))):
            sname = f"{name}:{i + 1}"
            A_ = JOINT_TYPES["hinge"].make_A(item, axis=a)
            sub_act = None if tau is None else Component(tau, i)
            sub_pd = None
            if control is not None:
                tgt = Component(as_timefunc(control.target, item, "control.target", 2), i)
                rate = None if control.target_rate is None else Component(
                    as_timefunc(control.target_rate, item, "control.target_rate", 2), i)
                if isinstance(control, PID):
                    lim = None if control.limit is None else part(control.limit, i,
                                                                  "control.limit")
                    sens = None if control.sensor is None else sensor_names(
                        control.sensor, item, "control.sensor")
                    sub_pd = PID(part(control.kp, i, "control.kp"),
                                 part(control.ki, i, "control.ki"),
                                 part(control.kd, i, "control.kd"), tgt, rate, lim,
                                 control.sample_time, control.gear, control.rotor_inertia,
                                 None if sens is None else _universal_sensor(sens, i,
                                                                             item))
                else:
                    sub_pd = PD(part(control.kp, i, "control.kp"),
                                part(control.kd, i, "control.kd"), tgt, rate)
            self._add_joint(sname, "hinge", na, nb, {"axis": a}, A_, part(stiffness, i,
                            "stiffness"), part(reference, i, "reference"),
                            part(damping, i, "damping"), act_field, sub_act, sub_pd,
                            composite=name, at=at, initial=part(initial, i, "initial"),
                            armature=part(armature, i, "armature"))
            sub.append(sname)
        self._composites[name] = tuple(sub)

    # -----------------------------------------------------------------------------------------
    def load(self, name: str, node: str, *, force: Any = None, torque: Any = None,
             at: Any = None, force_frame: str = "inertial", torque_frame: str = "body"
             ) -> None:
        """Add an external load on a body (Eq. (66)), at a point of it.

        Parameters
        ----------
        name : str
            Unique load name.
        node : str
            Loaded node.
        force : array (3,), TimeFunction or callable of t, optional
            Force, in the inertial frame by default (its tangent term, Eq. (67), is included).
        torque : array (3,), TimeFunction or callable of t, optional
            Torque, in the body (material) frame of the node by default.
        at : array_like (3,), optional
            Point of application of the force, in the inertial frame of the initial
            configuration (it moves with the body); the node by default.
        force_frame, torque_frame : {"inertial", "body"}
            Frames of the force and of the torque: ``"inertial"`` keeps its direction in
            space, ``"body"`` turns with the body (a follower load).
        """
        _check_name("load", name)
        item = f"load {name!r}"
        if not isinstance(node, str):
            raise ModelError(item, "node", "the name of a defined node", node)
        if name in self._loads:
            raise ModelError(item, "name", "a unique load name", name, "defined twice")
        if node not in self._nodes:
            raise ModelError(item, "node", "the name of a defined node", node,
                             _unknown("node", node, list(self._nodes)))
        if self._nodes[node].fixed:
            raise ModelError(item, "node", "a free node (a load on a clamped node does nothing)",
                             node)
        if force is None and torque is None:
            raise ModelError(item, "force", "a force and/or a torque", None)
        f = None if force is None else as_timefunc(force, item, "force", 3)
        m = None if torque is None else as_timefunc(torque, item, "torque", 3)
        for fld, val in (("force_frame", force_frame), ("torque_frame", torque_frame)):
            if val not in ("inertial", "body"):
                raise ModelError(item, fld, "'inertial' or 'body'", val)
        p = None if at is None else _vec(at, 3, item, "at")
        self._loads[name] = LoadSpec(name, node, f, m, p, force_frame, torque_frame)

    def _two_nodes(self, kind: str, what: str, existing: dict, name: Any, node_a: Any,
                   node_b: Any, one_free: bool = True) -> str:
        """The checks of an element between two nodes: a unique valid name, two defined and
        distinct nodes, not both fixed (``one_free``). Returns the item of its error
        messages."""
        _check_name(kind, name)
        item = f"{kind} {name!r}"
        if name in existing:
            raise ModelError(item, "name", f"a unique {what} name", name, "defined twice")
        for fld, nd in (("node_a", node_a), ("node_b", node_b)):
            if not isinstance(nd, str) or nd not in self._nodes:
                raise ModelError(item, fld, "the name of a defined node", nd,
                                 _unknown("node", nd, list(self._nodes))
                                 if isinstance(nd, str) else None)
        if node_a == node_b:
            raise ModelError(item, "node_b", "a node other than node_a", node_b)
        if one_free and self._nodes[node_a].fixed and self._nodes[node_b].fixed:
            raise ModelError(item, "node_b", "at least one free node", node_b,
                             "both nodes are fixed: the element does nothing")
        return item

    # -----------------------------------------------------------------------------------------
    def spring_damper(self, name: str, node_a: str, node_b: str, *, at_a: Any = None,
                      at_b: Any = None, stiffness: Any, damping: Any = 0.0,
                      length: Any = None) -> None:
        """Add a spring-damper between two points attached to two nodes.

        The force ``stiffness (L - length) + damping dL/dt`` acts along the line of the points
        (``L`` their distance), pulling them together when positive.

        Parameters
        ----------
        name : str
            Unique name.
        node_a, node_b : str
            The nodes the points are attached to (either may be fixed, not both).
        at_a, at_b : array_like (3,), optional
            The points in the inertial frame of the initial configuration (they move with
            their nodes); the node positions by default.
        stiffness : float
            N/m, >= 0.
        damping : float
            N s/m, >= 0.
        length : float, optional
            Absolute free length (m); the initial distance of the points by default.
        """
        item = self._two_nodes("spring_damper", "spring-damper", self._springs, name, node_a,
                               node_b)
        pa = self._nodes[node_a].position if at_a is None else _vec(at_a, 3, item, "at_a")
        pb = self._nodes[node_b].position if at_b is None else _vec(at_b, 3, item, "at_b")
        vals = {}
        for fld, val in (("stiffness", stiffness), ("damping", damping)):
            try:
                x = float(val)
            except (TypeError, ValueError):
                raise ModelError(item, fld, "a non-negative number", val) from None
            if isinstance(val, bool) or not math.isfinite(x) or x < 0 or x > MAX_ABS:
                raise ModelError(item, fld, f"a non-negative finite number <= {MAX_ABS:g}", val)
            vals[fld] = x
        L0 = float(np.linalg.norm(pb - pa))
        if L0 == 0:
            raise ModelError(item, "at_b", "a point apart from at_a (the line of the force is "
                             "undefined for coinciding points)", pb)
        if length is not None:
            try:
                L = float(length)
            except (TypeError, ValueError):
                raise ModelError(item, "length", "a non-negative length (m)", length) from None
            if isinstance(length, bool) or not math.isfinite(L) or L < 0 or L > MAX_ABS:
                raise ModelError(item, "length", f"a non-negative finite length (m) <= "
                                 f"{MAX_ABS:g}", length)
            L0 = L
        self._springs[name] = SpringDamperSpec(name, node_a, node_b, pa, pb,
                                               vals["stiffness"], vals["damping"], L0)

    # -----------------------------------------------------------------------------------------
    def collision(self, name: str, node: str, shape: str, *, size: Any = None, at: Any = None,
                  normal: Any = None, material: ContactMaterial | None = None,
                  exclude: Any = (), length: Any = None, axis: Any = None) -> None:
        """Add a collision shape on a node (compliant contact, docs/contact.md).

        Parameters
        ----------
        name : str
            Unique shape name.
        node : str
            The node it moves with: fixed, or with mass.
        shape : {"sphere", "plane", "capsule"}
            A sphere, the half-space below a plane (its outward side up), or a capsule (the
            points within ``size`` of a segment).
        size : float
            Radius of a sphere or a capsule (m), > 0; not used by a plane.
        at : array_like (3,), optional
            Centre of a sphere or a capsule, or a point of a plane, in the inertial frame of the
            initial configuration; the node's position by default.
        normal : array_like (3,), optional
            Outward normal of a plane (inertial frame, initial configuration); +z by default.
        length, axis :
            A capsule's segment: its length (m, > 0) and direction (inertial frame, initial
            configuration; +z by default).
        material : ContactMaterial, optional
            The shape's contact law (``ContactMaterial()`` by default).
        exclude : sequence of str
            Shapes or nodes this shape never touches.

        Every sphere touches every plane and sphere on another node (pair rule:
        :mod:`se3dyn.model.contact`); :meth:`contact_pair` sets a pair's material or disables it.
        """
        item = f"collision {_check_name('collision', name)!r} ({shape})"
        if name in self._collisions:
            raise ModelError(item, "name", "a new collision name", name, "already used")
        if node not in self._nodes:
            raise ModelError(item, "node", "an existing node", node, _did_you_mean(
                node, list(self._nodes)))
        nd = self._nodes[node]
        if not nd.fixed and nd.mass <= 0:
            raise ModelError(item, "node", "a fixed node or a node with mass", node,
                             "a contact force on a massless node has no inertia to act on")
        if shape not in SHAPES:
            raise ModelError(item, "shape", f"one of {', '.join(SHAPES)}", shape)
        r = 0.0
        if shape != "plane":
            try:
                r = float(size)
            except (TypeError, ValueError):
                raise ModelError(item, "size", "a positive radius (m)", size) from None
            if isinstance(size, bool) or not math.isfinite(r) or r <= 0 or r > MAX_ABS:
                raise ModelError(item, "size", "a positive finite radius (m)", size)
        p = nd.position if at is None else _vec(at, 3, item, "at")
        fld, given = ("axis", axis) if shape == "capsule" else ("normal", normal)
        nrm = np.array([0.0, 0.0, 1.0]) if given is None else _vec(given, 3, item, fld)
        if shape != "sphere":
            ln = float(np.linalg.norm(nrm))
            if ln == 0:
                raise ModelError(item, fld, "a non-zero 3-vector", given)
            if abs(ln - 1.0) > 1e-15:  # (a unit vector stays as given: files round-trip)
                nrm = nrm / ln
        seg = 0.0
        if shape == "capsule":
            try:
                seg = float(length)
            except (TypeError, ValueError):
                raise ModelError(item, "length", "a positive length (m)", length) from None
            if isinstance(length, bool) or not math.isfinite(seg) or seg <= 0 or seg > MAX_ABS:
                raise ModelError(item, "length", "a positive finite length (m)", length)
        if material is None:
            material = ContactMaterial()
        if isinstance(material, dict):  # (model files, or a dict of ContactMaterial's fields)
            try:
                material = ContactMaterial(**material)
            except ModelError as exc:
                raise ModelError(item, f"material.{exc.field}", exc.expected, exc.got) from None
            except TypeError as exc:
                raise ModelError(item, "material", "the fields of se3dyn.ContactMaterial",
                                 str(exc)) from None
        if not isinstance(material, ContactMaterial):
            raise ModelError(item, "material", "an se3dyn.ContactMaterial",
                             type(material).__name__)
        if isinstance(exclude, str):
            exclude = (exclude,)
        self._collisions[name] = CollisionSpec(name, node, shape, r, np.array(p, float),
                                               np.array(nrm, float), material,
                                               tuple(str(x) for x in exclude), seg)

    def contact_pair(self, shape_a: str, shape_b: str, *,
                     material: ContactMaterial | None = None, enabled: bool = True) -> None:
        """Give the pair of two shapes its own material, or disable it (``enabled=False``)."""
        item = f"contact pair {shape_a!r}/{shape_b!r}"
        for fld, nm in (("shape_a", shape_a), ("shape_b", shape_b)):
            if nm not in self._collisions:
                raise ModelError(item, fld, "an existing collision shape", nm,
                                 _did_you_mean(nm, list(self._collisions)))
        if material is not None and not isinstance(material, ContactMaterial):
            raise ModelError(item, "material", "an se3dyn.ContactMaterial",
                             type(material).__name__)
        self._contact_pairs[frozenset((shape_a, shape_b))] = ContactPairSpec(
            shape_a, shape_b, material, bool(enabled))

    # -----------------------------------------------------------------------------------------
    def beam(self, name: str, node_a: str, node_b: str, *, elements: int | None = None,
             EA: Any, GA: Any, GJ: Any, EI: Any, mass_per_length: Any = 0.0,
             rotary_inertia: Any = None, damping: Any = 0.0, axis2: Any = None,
             frames: Any = None, initial_velocity: str = "rest") -> None:
        """Add a geometrically exact beam between two existing nodes, meshed into two-node SE(3)
        elements (Sonneville, Cardona & Bruls, Comput. Methods Appl. Mech. Engrg. 268 (2014)
        451-474, doi:10.1016/j.cma.2013.10.008; see :mod:`se3dyn.elements.beam`).

        The builder creates the intermediate nodes ``f"{name}/1"`` ... ``f"{name}/{n-1}"``
        (their frames are the section frames: axis 1 along the beam). Joints, springs and loads
        attach to any of them. The end nodes keep their own frames: the beam acts on section
        frames rigidly attached to them.

        Parameters
        ----------
        name : str
            Unique beam name.
        node_a, node_b : str
            The existing end nodes (either may be fixed, not both).
        elements : int, optional
            Number of elements n (>= 1); 1 by default, or the number of ``frames`` minus one.
        EA, GJ : float
            Axial and torsional stiffness (N, N m^2), > 0.
        GA, EI : float or (float, float)
            Shear stiffness along section axes 2, 3 (N) and bending stiffness about them
            (N m^2): one number for an isotropic section, or a pair. See
            :mod:`se3dyn.model.sections` for the values of common sections.
        mass_per_length : float
            kg/m, >= 0; lumped: each element puts half its mass and rotary inertia on each of
            its nodes.
        rotary_inertia : array_like (3,), optional
            Rotary inertia of the section per unit length about axes 1, 2, 3 (kg m), positive
            when ``mass_per_length > 0`` (``density * (I2 + I3, I2, I3)``).
        damping : float or array_like (6,)
            Damping on the strain rates, ``f = K eps + D deps/dt``: a number beta (s) for the
            stiffness-proportional ``D = beta K``, or the diagonal of D (6 numbers, >= 0).
        axis2 : array_like (3,), optional
            Straight beam: direction of section axis 2 (orthogonalised against the beam axis);
            by default ``z x axis1`` (horizontal; the global y axis for a vertical beam).
        frames : array_like (n + 1, 4, 4), optional
            A curved or pre-twisted beam: its stress-free section frames, node A to node B
            (homogeneous 4 x 4, inertial frame, axis 1 along the beam); the first and last
            positions must be those of node_a and node_b. Consecutive frames must be less
            than pi apart in rotation. Replaces the straight segment and ``axis2``.
        initial_velocity : {"rest", "rigid"}
            Initial velocity of the intermediate nodes: at rest, or moving rigidly with node_a
            (``v = v_a + w_a x (x - x_a)``, ``w = w_a``, inertial frame); the end nodes keep
            theirs.
        """
        # (both ends may be fixed: a clamped-clamped beam has free nodes in between)
        item = self._two_nodes("beam", "beam", self._beams, name, node_a, node_b,
                               one_free=False)
        na, nb = self._nodes[node_a], self._nodes[node_b]
        if elements is not None and (not isinstance(elements, int | np.integer)
                                     or isinstance(elements, bool) or elements < 1
                                     or elements > 100000):
            raise ModelError(item, "elements", "an integer >= 1", elements)
        Kd, Dd, mpl, rot = _beam_section(item, EA, GA, GJ, EI, mass_per_length, rotary_inertia,
                                         damping)
        if frames is None:
            n = 1 if elements is None else int(elements)
            F = _straight_frames(item, na, nb, node_b, n, axis2)
        else:
            F, n = _given_frames(item, na, nb, frames, elements, axis2)
        _check_frame_steps(item, F, n)
        names = [node_a] + [f"{name}/{i}" for i in range(1, n)] + [node_b]
        for nm_ in names[1:-1]:
            _check_name("node", nm_)
            if nm_ in self._nodes:
                raise ModelError(item, "name", f"a name whose intermediate node {nm_!r} is "
                                 "free", name, "a node of that name exists")
        if initial_velocity not in ("rest", "rigid"):
            raise ModelError(item, "initial_velocity", "'rest' or 'rigid'", initial_velocity)
        if na.fixed and nb.fixed and n == 1:
            raise ModelError(item, "node_b", "at least one free node", node_b,
                             "both nodes are fixed: the element does nothing")
        X = _end_offsets(na, nb, F, n)
        for i in range(1, n):
            vel = np.zeros(6)
            if initial_velocity == "rigid":
                wa = na.velocity[3:]
                vel = np.concatenate([na.velocity[:3] + np.cross(wa, F[i, :3, 3] - na.position),
                                      wa])
            self._nodes[names[i]] = NodeSpec(names[i], F[i, :3, 3].copy(), F[i, :3, :3].copy(),
                                             0.0, np.zeros((3, 3)), False, vel)
        self._beams[name] = BeamSpec(name, tuple(names), F, X, np.diag(Kd), np.diag(Dd), mpl,
                                     rot)

    # -----------------------------------------------------------------------------------------
    def bushing(self, name: str, node_a: str, node_b: str, *, at: Any = None, stiffness: Any,
                damping: Any = 0.0, orientation: Any = None, deformation: Any = None) -> None:
        """Add a bushing: 6 x 6 stiffness and damping on the relative motion of two frames
        attached to two nodes.

        Both frames sit at the point ``at`` with the inertial orientation in the initial
        configuration (``X = H0^-1 H(I, at)`` on each node, the convention of joints with
        ``at``; ``H(orientation, at)`` with an ``orientation``) and move with their nodes;
        their relative motion is the twist ``d = log(H_a'^-1 H_b')`` (6,), translation first,
        zero initially (``deformation`` otherwise). The bushing stores the energy
        ``d^T K d / 2`` and dissipates ``d_dot^T D d_dot``, with ``d_dot = T(d)^-1 w`` the rate
        of the log coordinates (Eqs. (26)-(27)), ``w`` the relative velocity of the frames: the
        wrench ``T(d)^-T (K d + D d_dot)`` acts on frame b', its opposite on frame a'. The
        relative rotation angle must stay below pi (principal logarithm).

        Examples
        --------
        >>> mb.bushing("mount", "ground", "engine", at=(0.3, 0.2, 0.0),
        ...            stiffness=(2e5, 2e5, 3e5, 1e3, 1e3, 1e3), damping=200.0)  # doctest: +SKIP

        Parameters
        ----------
        name : str
            Unique name.
        node_a, node_b : str
            The nodes the frames are attached to (either may be fixed, not both).
        at : array_like (3,), optional
            The bushing point in the inertial frame of the initial configuration; the position
            of ``node_b`` by default.
        stiffness : float, array_like (6,) or (6, 6)
            K on ``(d_U, d_Omega)`` in the axes of the attached frames (the inertial axes at
            t0, or the columns of ``orientation``): six diagonal values
            ``(kx, ky, kz, krx, kry, krz)`` (N/m, N m/rad), one value for all six, or a
            symmetric positive semi-definite 6 x 6 matrix (coupling blocks in N/rad).
        damping : float, array_like (6,) or (6, 6)
            D on ``d_dot``, same forms (N s/m, N m s/rad); zero by default.
        orientation : array_like (3, 3), optional
            Rotation of the bushing frame at t0: its columns are the bushing axes in the
            inertial frame (the identity by default).
        deformation : array_like (6,), optional
            Relative motion d at t0, in the bushing axes (a preloaded bushing; rotation angle
            below pi): the frame attached to node b starts at ``H(orientation, at)
            exp(deformation)``, the one attached to node a at ``H(orientation, at)``. Zero by
            default: the bushing starts unloaded.
        """
        item = self._two_nodes("bushing", "bushing", self._bushings, name, node_a, node_b)
        p = self._nodes[node_b].position.copy() if at is None else _vec(at, 3, item, "at")
        K = _sym6(stiffness, item, "stiffness")
        D = _sym6(damping, item, "damping")
        R = np.eye(3) if orientation is None else _rotation(orientation, item, "orientation")
        d0 = np.zeros(6) if deformation is None else _vec(deformation, 6, item, "deformation")
        if np.linalg.norm(d0[3:]) >= math.pi:
            raise ModelError(item, "deformation", "a rotation part of norm below pi (the "
                             "principal logarithm)", deformation)
        self._bushings[name] = BushingSpec(name, node_a, node_b, p, K, D, R, d0)

    # -----------------------------------------------------------------------------------------
    def visual(self, name: str, node: str, shape: str, *, size: Any = None, color: Any = None,
               offset: Any = None, orientation: Any = None, axis: Any = None,
               file: Any = None) -> None:
        """Draw a shape with a node (pictures only: no mass, no effect on the motion).

        Parameters
        ----------
        name : str
            Unique visual name.
        node : str
            The node the shape moves with (a node may carry several shapes). A node with
            visuals is drawn by them instead of the viewer's default solid.
        shape : {"box", "sphere", "cylinder", "capsule", "mesh"}
        size : float or array_like
            box: side lengths (3,) or one number; sphere: radius; cylinder and capsule:
            (radius, length) along the shape's z axis; mesh: scale, one or 3 numbers (default 1).
        color : str or array_like, shape (3,), optional
            ``"#rrggbb"``, a colour name or RGB in [0, 1]; default: a palette colour.
        offset : array_like, shape (3,), optional
            Origin of the shape in the material frame of the node (m).
        orientation : array_like, shape (3, 3), optional
            Rotation of the shape in the material frame of the node (columns: its axes).
        axis : array_like, shape (3,), optional
            Instead of ``orientation``: the direction of the shape's z axis (cylinder, capsule).
        file : str, optional
            Mesh file (STL, OBJ, glTF/GLB) for ``shape="mesh"``; a relative path is looked up
            next to the model file when viewed.
        """
        _check_name("visual", name)
        if not isinstance(node, str):
            raise ModelError(f"visual {name!r}", "node", "the name of a defined node", node)
        v = make_visual(name, node, shape, size=size, color=color, offset=offset,
                        orientation=orientation, axis=axis, file=file)
        if name in self._visuals:
            raise ModelError(f"visual {name!r}", "name", "a unique visual name", name,
                             "defined twice")
        if node not in self._nodes:
            raise ModelError(f"visual {name!r} ({shape})", "node", "the name of a defined node",
                             node, _unknown("node", node, list(self._nodes)))
        self._visuals[name] = v

    # -----------------------------------------------------------------------------------------
    def marker(self, name: str, node: str, *, at: Any = None, offset: Any = None,
               orientation: Any = None) -> None:
        """Add a marker: a frame fixed on a node, where the results read positions,
        velocities, accelerations and an IMU (outputs only: no effect on the motion).

        Parameters
        ----------
        name : str
            Unique marker name.
        node : str
            The node (body) the marker moves with; a fixed node is allowed.
        at : array_like (3,), optional
            Origin of the marker as a point in the inertial frame of the initial configuration
            (the convention of joints' ``at``).
        offset : array_like (3,), optional
            Instead of ``at``: the origin in the material frame of the node (m). Neither: the
            marker's origin is the node.
        orientation : array_like (3, 3), optional
            Rotation of the marker in the initial configuration (columns: its axes in the
            inertial frame); the node's orientation by default.

        Examples
        --------
        >>> mb.marker("imu", "body", at=(0.1, 0, 0.05))  # doctest: +SKIP
        >>> r.accelerometer("imu")  # (n, 3) specific force in the marker frame  # doctest: +SKIP
        """
        _check_name("marker", name)
        item = f"marker {name!r}"
        if name in self._markers:
            raise ModelError(item, "name", "a unique marker name", name, "defined twice")
        if not isinstance(node, str) or node not in self._nodes:
            raise ModelError(item, "node", "the name of a defined node", node,
                             _unknown("node", node, list(self._nodes))
                             if isinstance(node, str) else None)
        if at is not None and offset is not None:
            raise ModelError(item, "offset", "either 'at' or 'offset', not both", offset,
                             "'at' is a point in the inertial frame, 'offset' the same point "
                             "in the node's material frame")
        p = None if at is None else _vec(at, 3, item, "at")
        c = None if offset is None else _vec(offset, 3, item, "offset")
        Rm = None if orientation is None else _rotation(orientation, item, "orientation")
        X = marker_offset(self._nodes[node], p, c, Rm)
        self._markers[name] = MarkerSpec(name, node, X, p, c, Rm)

    # -----------------------------------------------------------------------------------------
    def drive(self, name: str, joint: str, *, position: Any = None,
              velocity: Any = None) -> None:
        """Prescribe the motion of coordinates of an abelian joint (a rheonomic driver).

        A driven coordinate follows the given function of time exactly at every step, beside
        the free motion of the rest of the model; the force or torque the driver supplies is an
        output (:meth:`Results.drive_effort`, channel ``drive/<name>/effort``), exact at every
        step: the residual of the coordinate's equation of motion (Eq. (36)) at the converged
        state. A joint may have some coordinates driven by motion and the others by forces
        (springs, actuators, PD laws: "motion provided, force computed" per coordinate).

        Parameters
        ----------
        name : str
            Unique driver name.
        joint : str
            An abelian joint defined before (hinge, prismatic, cylindrical, screw, universal,
            or a general joint with an abelian subalgebra).
        position : number, TimeFunction, callable of t, or dict {index: ...}
            The coordinate's value ``alpha(t)`` (absolute: zero in the initial configuration,
            or the joint's ``initial`` value there). A dict by coordinate index for a joint
            with several coordinates.
        velocity : as ``position``
            The coordinate's rate ``v(t)``; the position is integrated by the time loop. Only
            coordinates not given a position.

        Notes
        -----
        At the start of a run the driver must agree with the model: ``f(t0)`` with the joint's
        initial coordinate (an error says by how much and how to fix it otherwise); the
        initial velocities are made consistent with ``f'(t0)`` (or ``g(t0)``) like given node
        velocities, with a report of what changed (``initial_velocities``).

        Examples
        --------
        >>> mb.drive("motor", joint="crank", velocity=2 * math.pi)  # doctest: +SKIP
        >>> mb.drive("lift", joint="slide", position=sd.Ramp(0.2, duration=2.0))  # doctest: +SKIP
        """
        _check_name("drive", name)
        item = f"drive {name!r}"
        if name in self._drives:
            raise ModelError(item, "name", "a unique drive name", name, "defined twice")
        parts = self._drive_parts(item, joint)
        given = {}
        for fld, val in (("position", position), ("velocity", velocity)):
            given[fld] = self._drive_functions(item, fld, val, len(parts))
        if not given["position"] and not given["velocity"]:
            raise ModelError(item, "position", "a position or a velocity to prescribe", None)
        both = sorted(set(given["position"]) & set(given["velocity"]))
        if both:
            raise ModelError(item, "velocity", "coordinates not given a position", both,
                             f"coordinate {both[0]} has both a position and a velocity")
        taken = {t[:2]: f"drive {d.name!r}" for d in self._drives.values() for t in d.targets}
        taken.update({c.follower[2:]: f"coupling {c.name!r}" for c in self._couplings.values()})
        targets, functions = [], []
        for i in sorted(set(given["position"]) | set(given["velocity"])):
            kind = "position" if i in given["position"] else "velocity"
            tgt = (parts[i][0], parts[i][1], kind)
            self._no_pid(item, kind, parts[i][0])
            if tgt[:2] in taken:
                raise ModelError(item, kind, "a coordinate no other drive prescribes",
                                 f"coordinate {i} of joint {joint!r}",
                                 f"{taken[tgt[:2]]} prescribes it already")
            targets.append(tgt)
            functions.append(given[kind][i])
        self._drives[name] = DriveSpec(name, joint, given["position"], given["velocity"],
                                       tuple(targets), tuple(functions))

    def coupling(self, name: str, *, leader: str, follower: str, ratio: float = 1.0,
                 offset: float = 0.0, leader_coordinate: int = 0,
                 follower_coordinate: int = 0) -> None:
        """Couple two joint coordinates exactly: ``alpha_follower = ratio alpha_leader +
        offset`` (a gear pair: ``ratio = -z_leader / z_follower``; a rack and pinion: the
        pinion's radius; a belt; URDF ``<mimic>``).

        The follower's coordinate is not an unknown of the step: it moves with the leader's,
        position, rate and acceleration, at every step (the follower's equation of motion is
        added to the leader's, as the coupling's virtual work says). The force or torque the
        coupling applies to the follower is an exact output (:meth:`Results.coupling_force`,
        channel ``coupling/<name>/force``); the leader receives ``-ratio`` times it. An ideal
        coupling does no work.

        Parameters
        ----------
        name : str
            Unique coupling name.
        leader, follower : str
            Abelian joints defined before (a universal joint's coordinates by index).
        ratio, offset : float
            ``alpha_follower = ratio alpha_leader + offset`` (absolute coordinates: zero in
            the initial configuration, or the joints' ``initial`` values there).
        leader_coordinate, follower_coordinate : int
            The coordinates of joints with several.
        """
        _check_name("coupling", name)
        item = f"coupling {name!r}"
        if name in self._couplings:
            raise ModelError(item, "name", "a unique coupling name", name, "defined twice")
        ends = []
        for fld, joint, i in (("leader", leader, leader_coordinate),
                              ("follower", follower, follower_coordinate)):
            parts = self._drive_parts(item, joint, fld)
            if isinstance(i, bool) or not isinstance(i, int | np.integer) or not (
                    0 <= i < len(parts)):
                raise ModelError(item, f"{fld}_coordinate",
                                 f"a coordinate index 0 to {len(parts) - 1}", i)
            ends.append((joint, int(i), *parts[int(i)]))
        if ends[0][2:] == ends[1][2:]:
            raise ModelError(item, "follower", "a coordinate other than the leader's",
                             follower)
        self._no_pid(item, "follower", ends[1][2])
        for fld, v in (("ratio", ratio), ("offset", offset)):
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating) or not \
                    math.isfinite(v) or abs(v) > MAX_ABS:
                raise ModelError(item, fld, "a finite number", v)
        if ratio == 0:
            raise ModelError(item, "ratio", "a nonzero ratio", ratio)
        taken = {t[:2]: f"drive {d.name!r}" for d in self._drives.values() for t in d.targets}
        taken.update({c.follower[2:]: f"coupling {c.name!r}" for c in self._couplings.values()})
        if ends[1][2:] in taken:
            raise ModelError(item, "follower", "a coordinate nothing else prescribes",
                             f"coordinate {ends[1][1]} of joint {ends[1][0]!r}",
                             f"{taken[ends[1][2:]]} prescribes it already")
        if any(c.leader[2:] == ends[1][2:] for c in self._couplings.values()) or \
                ends[0][2:] in taken and taken[ends[0][2:]].startswith("coupling"):
            raise ModelError(item, "leader", "couplings that do not chain (a follower leading "
                             "another coupling, or a leader that follows one)", leader)
        self._couplings[name] = CouplingSpec(name, ends[0], ends[1], float(ratio),
                                             float(offset))

    def _drive_parts(self, item: str, joint: Any, fld: str = "joint") -> list[tuple[str, int]]:
        """The (joint, index) of every coordinate of a driven (or coupled) joint (the hinges of
        a universal joint), checking it exists and is abelian."""
        names = list(self._joints) + list(self._composites)
        if not isinstance(joint, str) or joint not in names:
            what = item.split()[0]
            raise ModelError(item, fld, f"the name of a joint defined before the {what}",
                             joint, _unknown("joint", joint, names)
                             if isinstance(joint, str) else None)
        if joint in self._composites:
            return [(p, 0) for p in self._composites[joint]]
        js = self._joints[joint]
        if js.k == 0 or not is_abelian(js.A):
            raise ModelError(item, fld, "an abelian joint with coordinates (hinge, "
                             "prismatic, cylindrical, screw, universal)",
                             f"{joint!r} ({js.type})",
                             "a rigid joint has no coordinate" if js.k == 0 else
                             "its coordinates are log coordinates, which do not add up")
        return [(joint, i) for i in range(js.k)]

    def _no_pid(self, item: str, fld: str, joint: str) -> None:
        """A driven coordinate or a coupling's follower takes no PID law: its motion is given,
        the law would only add to the drive's effort or the coupling's force, which the
        results then could not tell (the law's integral is not in the stored rows)."""
        if hasattr(self._joints[joint].control, "ki"):
            raise ModelError(item, fld, "a coordinate without a PID law", f"joint {joint!r}",
                             "its motion is given here; control another coordinate, or drive "
                             "it without the law")

    @staticmethod
    def _drive_functions(item: str, fld: str, val: Any, k: int) -> dict:
        """``{index: TimeFunction}`` of a drive's ``position`` or ``velocity``."""
        if val is None:
            return {}
        if not isinstance(val, dict):
            if k != 1:
                raise ModelError(item, fld, f"a dict {{coordinate index: function}} (the joint "
                                 f"has {k} coordinates)", val)
            val = {0: val}
        out = {}
        for i, f in val.items():
            if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i < k:
                raise ModelError(item, fld, f"coordinate indices 0 to {k - 1}", i)
            tf = as_timefunc(f, item, f"{fld}[{i}]", size=1)
            if np.asarray(tf(0.0)).size != 1:
                raise ModelError(item, f"{fld}[{i}]", "a scalar function of t", tf(0.0))
            out[int(i)] = tf
        return out

    # -----------------------------------------------------------------------------------------
    def build(self) -> Model:
        """Validate the whole model and return the immutable :class:`Model`."""
        if not self._nodes:
            raise ModelError("model", "nodes", "at least one node", 0)
        attached = {n: 0 for n in self._nodes}
        for j in self._joints.values():
            attached[j.node_a] += 1
            attached[j.node_b] += 1
        for b in self._beams.values():
            for nd in b.nodes:
                attached[nd] += 1
        loaded = {ld.node for ld in self._loads.values()}
        for n in self._nodes.values():
            if not n.fixed and n.mass == 0 and attached[n.name] == 0:
                raise ModelError(f"node {n.name!r}", "mass",
                                 "a mass, or a joint or beam attaching it", 0.0,
                                 "a free massless node with no joint has no equation of motion"
                                 + (" (a load alone is not enough)" if n.name in loaded
                                    else ""))
        model = Model(tuple(self._nodes.values()), tuple(self._joints.values()),
                      tuple(self._loads.values()), self._gravity.copy(), dict(self._composites),
                      self._name, tuple(self._springs.values()),
                      visuals=tuple(self._visuals.values()),
                      bushings=tuple(self._bushings.values()),
                      beams=tuple(self._beams.values()), markers=tuple(self._markers.values()),
                      drives=tuple(self._drives.values()),
                      couplings=tuple(self._couplings.values()),
                      collisions=tuple(self._collisions.values()),
                      contact_pairs=tuple(self._contact_pairs.values()))
        _check_sensors(model)
        return model


def _did_you_mean(word: str, names: list) -> str:
    m = close_matches(str(word), names)
    return f"did you mean {m[0]!r}?" if m else f"known: {', '.join(names[:10]) or 'none'}"


def _check_law(law, k: int, A_: np.ndarray, item: str, fld: str, init) -> None:
    """A law of the user's must suit an abelian joint and give k finite forces at the start
    (t = 0, the initial coordinates, zero rates)."""
    if not is_abelian(A_):
        raise ModelError(item, fld, "an abelian joint for a law f(t, q, v) on its coordinates",
                         "a non-abelian joint")
    q = np.zeros(k) if init is None else np.array(init, dtype=float)
    try:
        f = np.asarray(law.fn(0.0, q, np.zeros(k)), dtype=float)
    except Exception as exc:  # user code: anything
        raise ModelError(item, fld, "a law f(t, q, v) that can be evaluated at t = 0",
                         f"{type(exc).__name__}: {exc}") from None
    if f.size not in (1, k) or not np.all(np.isfinite(f)):
        raise ModelError(item, fld, f"a law f(t, q, v) giving {k} finite value(s)", f)


def _control_law(control: PD | PID, k: int, item: str) -> PD | PID:
    """A joint's control law normalised to k coordinates: gains arrays (k,), targets time
    functions, a PID's limit an array (k,) (inf: none)."""
    kp = _kvec(control.kp, k, item, "control.kp", nonneg=True)
    kd = _kvec(control.kd, k, item, "control.kd", nonneg=True)
    tgt = as_timefunc(control.target, item, "control.target", k)
    rate = (None if control.target_rate is None
            else as_timefunc(control.target_rate, item, "control.target_rate", k))
    if isinstance(control, PD):
        return PD(kp, kd, tgt, rate)
    ki = _kvec(control.ki, k, item, "control.ki", nonneg=True)
    lim = (np.full(k, np.inf) if control.limit is None
           else _limits(control.limit, k, item, "control.limit"))
    ts = None if control.sample_time is None else float(control.sample_time)
    sensor = None
    if control.sensor is not None:
        sensor = sensor_names(control.sensor, item, "control.sensor")
        if len(sensor) != k:
            raise ModelError(item, "control.sensor", f"{k} sensor channel name(s), one per "
                             "coordinate of the joint", control.sensor)
    return PID(kp, ki, kd, tgt, rate, lim, ts, float(control.gear),
               float(control.rotor_inertia), sensor)


def _universal_sensor(sens: tuple[str, ...], i: int, item: str) -> str:
    """The sensor of hinge ``i`` of a universal joint's law (one name per hinge)."""
    if len(sens) != 2:
        raise ModelError(item, "control.sensor", "2 sensor channel names, one per hinge of "
                         "the universal joint", sens)
    return sens[i]


def _check_sensors(model: Model) -> None:
    """The sensors read by sampled PID laws name markers and joint coordinates of the model."""
    for j in model.joints:
        for name in getattr(j.control, "sensor", None) or ():
            check_sensor(parse_sensor(name, f"joint {j.name!r}", "control.sensor"), model,
                         f"joint {j.name!r}", "control.sensor")


def marker_offset(node: NodeSpec, at: np.ndarray | None, offset: np.ndarray | None,
                  orientation: np.ndarray | None) -> np.ndarray:
    """The constant frame X (4, 4) of a marker in the material frame of ``node`` (its initial
    frame ``H(R0, x0)``): origin ``R0^T (at - x0)``, or ``offset``, or the node; axes
    ``R0^T orientation`` or the node's."""
    X = np.eye(4)
    if at is not None:
        X[:3, 3] = node.orientation.T @ (at - node.position)
    elif offset is not None:
        X[:3, 3] = offset
    if orientation is not None:
        X[:3, :3] = node.orientation.T @ orientation
    return X


# ---------------------------------------------------------------------------------------------
# ModelBuilder.beam: validation of the section, the reference frames and the end offsets
def _beam_numbers(item: str, fld: str, v: Any, sizes: tuple, what: str,
                  positive: bool) -> np.ndarray:
    """v as an array of one of ``sizes`` (a single number fills the first size)."""
    try:
        if isinstance(v, bool | str):
            raise TypeError(v)
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, fld, what, v) from None
    if a.ndim == 0 and sizes[0] > 1:
        a = np.full(sizes[0], float(a))
    ok = ((a.ndim == 0 and sizes[0] == 1)
          or (a.ndim == 1 and a.shape[0] in sizes and a.shape[0] > 1))
    if (not ok or not np.all(np.isfinite(a)) or np.any(np.abs(a) > MAX_ABS)
            or np.any(a <= 0 if positive else a < 0)):
        raise ModelError(item, fld, what, v)
    return a


def _beam_section(item: str, EA: Any, GA: Any, GJ: Any, EI: Any, mass_per_length: Any,
                  rotary_inertia: Any, damping: Any) -> tuple:
    """The checked section of a beam: the diagonals of K and D (6,), the mass per length and
    the rotary inertia (3,)."""
    ea = float(_beam_numbers(item, "EA", EA, (1,), "a positive number (N)", True))
    gj = float(_beam_numbers(item, "GJ", GJ, (1,), "a positive number (N m^2)", True))
    ga = _beam_numbers(item, "GA", GA, (2,), "a positive number or a pair (GA2, GA3) (N)", True)
    ei = _beam_numbers(item, "EI", EI, (2,), "a positive number or a pair (EI2, EI3) (N m^2)",
                       True)
    Kd = np.array([ea, ga[0], ga[1], gj, ei[0], ei[1]])
    mpl, rot = _beam_mass(item, mass_per_length, rotary_inertia)
    Dd = _beam_numbers(item, "damping", damping, (1, 6), "a non-negative number beta (s, "
                       "D = beta K) or the 6 non-negative diagonal entries of D", False)
    Dd = Dd * Kd if Dd.ndim == 0 else Dd
    return Kd, Dd, mpl, rot


def _beam_mass(item: str, mass_per_length: Any, rotary_inertia: Any) -> tuple[float,
                                                                               np.ndarray]:
    """The checked mass per length and rotary inertia (3,) of a beam's section."""
    try:
        mpl = float(mass_per_length)
    except (TypeError, ValueError):
        raise ModelError(item, "mass_per_length", "a non-negative number (kg/m)",
                         mass_per_length) from None
    if (isinstance(mass_per_length, bool) or not math.isfinite(mpl) or mpl < 0
            or mpl > MAX_ABS):
        raise ModelError(item, "mass_per_length", "a non-negative number (kg/m)",
                         mass_per_length)
    rot = (np.zeros(3) if rotary_inertia is None
           else _beam_numbers(item, "rotary_inertia", rotary_inertia, (3,), "three "
                              "non-negative values (kg m) about section axes 1, 2, 3", False))
    if mpl > 0 and np.any(rot <= 0):
        raise ModelError(item, "rotary_inertia", "three positive values (kg m) for a beam "
                         "with mass", rotary_inertia, "density * (I2 + I3, I2, I3); the "
                         "helpers of se3dyn.model.sections give them")
    if mpl == 0 and np.any(rot != 0):
        raise ModelError(item, "rotary_inertia", "no rotary inertia without a mass",
                         rotary_inertia, "give mass_per_length")
    if rot[0] > (rot[1] + rot[2]) * (1 + 1e-9) or rot[1] > (rot[0] + rot[2]) * (1 + 1e-9) \
            or rot[2] > (rot[0] + rot[1]) * (1 + 1e-9):
        raise ModelError(item, "rotary_inertia", "moments satisfying the triangle "
                         "inequality (as density * (I2 + I3, I2, I3) does)", rotary_inertia)
    return mpl, rot


def _straight_frames(item: str, na: NodeSpec, nb: NodeSpec, node_b: str, n: int,
                     axis2: Any) -> np.ndarray:
    """The section frames (n + 1, 4, 4) of a straight beam from node a to node b."""
    xa, xb = na.position, nb.position
    Lc = float(np.linalg.norm(xb - xa))
    if Lc == 0:
        raise ModelError(item, "node_b", "a node at another position than node_a",
                         node_b, "the beam has zero length")
    e1 = (xb - xa) / Lc
    if axis2 is None:
        a2 = np.cross([0.0, 0.0, 1.0], e1)
        if np.linalg.norm(a2) < 1e-6:
            a2 = np.array([0.0, 1.0, 0.0])
    else:
        a2 = _vec(axis2, 3, item, "axis2")
    a2 = a2 - (a2 @ e1) * e1
    if np.linalg.norm(a2) < 1e-9 * max(1.0, float(np.linalg.norm(a2 + e1))):
        raise ModelError(item, "axis2", "a direction not parallel to the beam", axis2)
    e2 = a2 / np.linalg.norm(a2)
    R = np.column_stack([e1, e2, np.cross(e1, e2)])
    F = np.broadcast_to(np.eye(4), (n + 1, 4, 4)).copy()
    F[:, :3, :3] = R
    F[:, :3, 3] = xa + np.linspace(0.0, 1.0, n + 1)[:, None] * (xb - xa)
    return F


def _given_frames(item: str, na: NodeSpec, nb: NodeSpec, frames: Any, elements: Any,
                  axis2: Any) -> tuple[np.ndarray, int]:
    """The checked section frames (n + 1, 4, 4) of a curved or pre-twisted beam, and n."""
    if axis2 is not None:
        raise ModelError(item, "axis2", "no axis2 with frames (the frames give the "
                         "section axes)", axis2)
    try:
        F = np.array(frames, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(item, "frames", "an array of 4x4 frames, shape (n + 1, 4, 4)",
                         frames) from None
    if F.ndim != 3 or F.shape[1:] != (4, 4) or len(F) < 2 or not np.all(np.isfinite(F)):
        raise ModelError(item, "frames", "an array of 4x4 frames, shape (n + 1, 4, 4)",
                         frames)
    n = len(F) - 1
    if elements is not None and elements != n:
        raise ModelError(item, "elements", f"{n} (the number of frames minus one) or "
                         "nothing", elements)
    for i in range(n + 1):
        _rotation(F[i, :3, :3], item, f"frames[{i}]")
        if np.any(F[i, 3] != [0, 0, 0, 1]):
            raise ModelError(item, f"frames[{i}]", "a homogeneous frame (last row "
                             "0, 0, 0, 1)", F[i])
    scale = max(1.0, float(np.abs(F[:, :3, 3]).max()))
    for i, nd in ((0, na), (n, nb)):
        if np.linalg.norm(F[i, :3, 3] - nd.position) > 1e-9 * scale:
            raise ModelError(item, f"frames[{i}]", f"a frame at the position of node "
                             f"{nd.name!r} {nd.position.tolist()}", F[i, :3, 3])
    return F, n


def _check_frame_steps(item: str, F: np.ndarray, n: int) -> None:
    """Refuse consecutive section frames 0.95 pi or more apart in rotation, or at one
    position."""
    from se3dyn import lie
    for i in range(n):
        d0 = lie.log_se3(lie.inverse(F[i]) @ F[i + 1])
        ang = float(np.linalg.norm(d0[3:]))
        if ang >= 0.95 * math.pi:
            raise ModelError(item, "frames", "consecutive frames less than 0.95 pi apart "
                             "in rotation", f"{ang:.4g} rad between frames {i} and {i + 1}",
                             "use more elements")
        if np.linalg.norm(d0[:3]) == 0:
            raise ModelError(item, "frames", "consecutive frames at distinct positions",
                             f"element {i} has zero length")


def _end_offsets(na: NodeSpec, nb: NodeSpec, F: np.ndarray, n: int) -> np.ndarray:
    """The section offsets ``X = H0^-1 F`` (n + 1, 4, 4) of the beam's nodes: the end nodes
    keep their own frames, sitting on the beam ends; the identity for the others."""
    from se3dyn import lie
    X = np.broadcast_to(np.eye(4), (n + 1, 4, 4)).copy()
    for i, nd in ((0, na), (n, nb)):
        H0 = np.eye(4)
        H0[:3, :3], H0[:3, 3] = nd.orientation, nd.position
        X[i] = lie.inverse(H0) @ F[i]
        X[i, :3, 3] = 0.0  # the node sits on the beam end
    return X
