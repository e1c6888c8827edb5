"""In-memory results of a simulation, with accessors by node and joint name.

Writing files and plotting are separate layers; this module only holds arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from se3dyn.errors import ModelError, UnknownNameError, close_matches

if TYPE_CHECKING:
    from se3dyn.engine.system import System

__all__ = ["Results"]


def node_dofs(s, H: np.ndarray, arr: np.ndarray, i: int, frame: str) -> np.ndarray:
    """The 6 unknowns of node i in every row of ``arr`` (n, nq), shape (n, 6); ``frame=
    "inertial"`` rotates both parts by the node rotation of ``H`` (n, M, 4, 4) (Eq. (4));
    zeros for a clamped node."""
    _check_frame(frame)
    if s.node_fixed[i]:
        return np.zeros((len(arr), 6))
    d = s.node_dofadr[i]
    out = arr[:, d:d + 6].copy()
    return _rotate(H[:, i, :3, :3], out) if frame == "inertial" else out


def node_accelerations(s, H: np.ndarray, v: np.ndarray, vd: np.ndarray, i: int,
                       frame: str) -> np.ndarray:
    """Acceleration of node i in every row, shape (n, 6), from the frames H (n, M, 4, 4), the
    velocities v and their time derivatives vd (n, nq). ``frame="material"``: ``(dU/dt,
    dOmega/dt)``, the unknowns of Eq. (39); ``frame="inertial"``: the acceleration of the node's
    origin and the angular acceleration in the inertial frame, ``(R (dU/dt + Omega x U),
    R dOmega/dt)`` (the derivative of dx/dt = R U with dR/dt = R hat(Omega), Eqs. (3)-(4))."""
    a = node_dofs(s, H, vd, i, frame if frame != "inertial" else "material")  # (checks frame)
    if frame != "inertial":
        return a
    w = node_dofs(s, H, v, i, "material")
    return inertial_acceleration(H[:, i, :3, :3], w, a)


def inertial_acceleration(R: np.ndarray, w: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The inertial acceleration ``(R (dU/dt + Omega x U), R dOmega/dt)``, shape (n, 6), of a
    frame with rotation R (n, 3, 3), material velocity ``w = (U, Omega)`` (n, 6) and its time
    derivative ``a`` (n, 6): the acceleration of the frame's origin and the angular
    acceleration, both in the inertial frame (the derivative of dx/dt = R U with
    dR/dt = R hat(Omega), Eqs. (3)-(4))."""
    return _rotate(R, np.concatenate([_origin_acceleration(w, a), a[:, 3:]], axis=1))


def _origin_acceleration(w: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The acceleration of a frame's origin in the frame's own axes, ``dU/dt + Omega x U``
    (n, 3), from its material velocity ``w`` and ``a = dw/dt`` (n, 6)."""
    return a[:, :3] + np.cross(w[:, 3:], w[:, :3])


def marker_specs(system) -> tuple:
    """The markers (:class:`~se3dyn.model.specs.MarkerSpec`) of the model of ``system``: a
    compiled System's ``model.markers``, or the ``markers`` of a layout read from a file."""
    mk = getattr(system, "markers", None)
    if mk is None:
        mk = getattr(getattr(system, "model", None), "markers", ())
    return tuple(mk or ())


def model_system(system):
    """The compiled System behind results: ``system`` itself when it is one (it carries its
    model), else the ``stored_system`` of a layout read from a file (the model stored in the
    file, compiled there by the io layer); None when there is none. The joint sensors take the
    joints' node B, attachment frames and axes from it, the beam channels its beams."""
    if getattr(system, "model", None) is not None and hasattr(system, "joint_XB"):
        return system
    return getattr(system, "stored_system", None)


def _to_marker(X: np.ndarray, w: np.ndarray) -> np.ndarray:
    """A twist of the node frame (material, (n, 6)) as the twist of the marker frame ``H X``
    in its own material frame, ``Ad(X^-1) w`` (n, 6): ``(Rx^T (U + Omega x c), Rx^T Omega)``
    with ``X = H(Rx, c)`` constant (so it maps accelerations the same way)."""
    Rx, c = X[:3, :3], X[:3, 3]
    lin = w[:, :3] + np.cross(w[:, 3:], c)
    return np.concatenate([lin @ Rx, w[:, 3:] @ Rx], axis=1)


def _unknown(kind: str, name, valid, empty: str = "") -> UnknownNameError:
    """The error for an unknown node, joint or marker name: a hint and the valid names."""
    close = close_matches(str(name), list(valid), n=1)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    shown = ", ".join(valid) if len(valid) or not empty else empty
    return UnknownNameError(f"unknown {kind} {name!r}{hint} (valid: {shown})")


def _check_frame(frame: str) -> None:
    if frame not in ("material", "inertial"):
        raise ModelError("results", "frame", "'material' or 'inertial'", frame)


def _rotate(R: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Both parts of twists w (n, 6) rotated by R (n, 3, 3)."""
    return np.concatenate([np.einsum("nij,nj->ni", R, w[:, :3]),
                           np.einsum("nij,nj->ni", R, w[:, 3:])], axis=1)


@dataclass
class Results:
    """Time histories of a simulation (one row per stored step, the initial state included).

    Attributes
    ----------
    system : System
        Or any object with the layout attributes the accessors use: ``node_names``,
        ``node_fixed``, ``node_dofadr``, ``joint_names``, ``joint_k``, ``joint_dofadr``,
        ``joint_multadr``, ``composites`` (so results read from a file need no model).
    t : ndarray (n,)
    H : ndarray (n, M, 4, 4)        node frames
    v, vd : ndarray (n, nq)         velocities and accelerations (material frame, Eq. (4))
    lam : ndarray (n, nm)           multipliers
    alpha : ndarray (n, nq)         relative coordinates (joint unknowns; Eq. (60))
    kinetic, potential, spring : ndarray (n,)   energies (Eq. (47), gravity, Eq. (62))
    work_actuators, work_loads, dissipation : ndarray (n,)   accumulated works
    iterations : ndarray (n,) int   Newton iterations of the step ending at t (0 at t0)
    residual, constraint : ndarray (n,)   final relative residual and constraint violation
    stats : dict                    steps, total iterations, wall time, settings

    Markers of the model (:meth:`~se3dyn.model.builder.ModelBuilder.marker`) are read through
    :meth:`marker_frame`, :meth:`marker_velocity`, :meth:`marker_acceleration`,
    :meth:`accelerometer` and :meth:`gyroscope`; they need ``system.model.markers`` (a
    compiled System) or ``system.markers`` and ``system.gravity`` (a layout read from a file).

    Joint and force sensors (:meth:`joint_reaction`, :meth:`joint_torque`,
    :meth:`actuator_effort`, :meth:`spring_force`, :meth:`drive_effort`,
    :meth:`spring_damper_force`) need the model: a compiled System, or a results file that
    stores it (:func:`model_system`).
    """

    system: System
    t: np.ndarray
    H: np.ndarray
    v: np.ndarray
    vd: np.ndarray
    lam: np.ndarray
    alpha: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    spring: np.ndarray
    work_actuators: np.ndarray
    work_loads: np.ndarray
    dissipation: np.ndarray
    iterations: np.ndarray
    residual: np.ndarray
    constraint: np.ndarray
    stats: dict = field(default_factory=dict)
    #: (n, 19 npairs) the contact pairs' states and outputs of the rows (runs in memory only;
    #: :meth:`contact_force` and the other contact_* methods read them)
    contact_rows: np.ndarray | None = None

    # ------------------------------------------------------------------------------------------
    def _node(self, name: str) -> int:
        names = self.system.node_names
        if isinstance(name, str) and name in names:
            return names.index(name)
        raise _unknown("node", name, names)

    def _joints(self, name: str) -> list[int]:
        s = self.system
        comp = s.composites
        names = list(s.joint_names)
        if not isinstance(name, str):
            name = repr(name)  # never a valid name: reported below with the valid ones
        if name in comp:
            return [names.index(n) for n in comp[name]]
        if name in names:
            return [names.index(name)]
        raise _unknown("joint", name, [n for n in names if ":" not in n] + list(comp))

    def node_position(self, name: str) -> np.ndarray:
        """Position of a node in the inertial frame, shape (n, 3)."""
        return self.H[:, self._node(name), :3, 3].copy()

    def node_rotation(self, name: str) -> np.ndarray:
        """Rotation matrix of a node (material axes in the inertial frame), shape (n, 3, 3)."""
        return self.H[:, self._node(name), :3, :3].copy()

    def node_frame(self, name: str) -> np.ndarray:
        """Homogeneous frame of a node, shape (n, 4, 4)."""
        return self.H[:, self._node(name)].copy()

    def _node_dof(self, name: str, arr: np.ndarray, frame: str) -> np.ndarray:
        return node_dofs(self.system, self.H, arr, self._node(name), frame)

    def node_velocity(self, name: str, frame: str = "material") -> np.ndarray:
        """Velocity ``(U, Omega)`` of a node, shape (n, 6).

        ``frame="material"``: the unknowns of Eq. (4); ``frame="inertial"``: ``(R v_U, R v_Omega)``
        (the time derivative of the position and the spatial angular velocity).
        """
        return self._node_dof(name, self.v, frame)

    def node_acceleration(self, name: str, frame: str = "material") -> np.ndarray:
        """Acceleration of a node, shape (n, 6): ``frame="material"`` the time derivative of the
        material velocity ``(dU/dt, dOmega/dt)``; ``frame="inertial"`` the acceleration of the
        node's origin and the angular acceleration in the inertial frame (see
        :func:`node_accelerations`)."""
        return node_accelerations(self.system, self.H, self.v, self.vd, self._node(name), frame)

    def _joint_cols(self, name: str, arr: np.ndarray) -> np.ndarray:
        s = self.system
        cols = [arr[:, s.joint_dofadr[j]:s.joint_dofadr[j] + s.joint_k[j]]
                for j in self._joints(name) if s.joint_k[j]]
        return np.concatenate(cols, axis=1) if cols else np.zeros((len(self.t), 0))

    def joint_coordinates(self, name: str) -> np.ndarray:
        """Relative coordinates alpha of a joint (Eq. (60)), unwrapped, shape (n, k).

        For a composite joint (universal), the coordinates of its parts side by side.
        """
        return self._joint_cols(name, self.alpha)

    def joint_velocities(self, name: str) -> np.ndarray:
        """Relative velocities v_j of a joint (Eq. (61)), shape (n, k)."""
        return self._joint_cols(name, self.v)

    def joint_multipliers(self, name: str) -> np.ndarray:
        """Lagrange multipliers of a joint, shape (n, 6) (n, 6 * parts for a composite).

        They are the constraint forces and moments on node B in its material frame, with
        the sign of Eq. (36) (``Phi_q^T lambda`` on the left-hand side); for a joint with an
        attachment point (``at``), in the attachment frame ``H_B X_B`` of node B (origin at the
        joint, axes those of the inertial frame at t0 carried along with node B); the wrench on
        node B in its own material frame is then ``PB^T lambda`` (``PB = Ad(X_B^-1)``).
        """
        s = self.system
        return np.concatenate([self.lam[:, s.joint_multadr[j]:s.joint_multadr[j] + 6]
                               for j in self._joints(name)], axis=1)

    # ------------------------------------------------------------------------------------------
    # Joint sensors: reaction wrench and transmitted generalized force, from the multipliers
    def _joint_geometry(self, j: int):
        """(node B index, X_B (4, 4), A (6, k)) of joint j, from :func:`model_system`."""
        ms = model_system(self.system)
        if ms is None:
            raise ModelError("results", "joint", "results with their model (a compiled System, "
                             "or a results file that stores its model) for the joint's "
                             "attachment frame and axes", self.system.joint_names[j])
        A = np.asarray(ms.model.joints[j].A, dtype=float).reshape(6, -1)
        return int(ms.joint_b[j]), np.asarray(ms.joint_XB[j], dtype=float), A

    def joint_reaction(self, name: str, frame: str = "joint", part: str = "total"
                       ) -> np.ndarray:
        """Reaction wrench of a joint on its body B, shape (n, 6): ``(force, moment)``.

        Exact from the multipliers (no dummy body): by Eq. (36) with the gradient of Eq. (58)
        (column ``-I`` for node B), the multipliers ``lambda`` of the joint are the force and
        moment the joint applies to node B, in the joint frame ``H_B X_B`` (the attachment
        frame for a joint with ``at``, node B's own frame otherwise; Eqs. (55)-(57)). The
        moment is about the origin of that frame: the joint point ``at`` (node B's origin
        without ``at``). The body A receives the opposite wrench about the same point.

        Parameters
        ----------
        name : str
            Joint name; for a composite joint (universal) the reaction on its body B (that of
            its last part).
        frame : {"joint", "inertial"}
            ``"joint"``: components in the axes of ``H_B X_B`` (those of the inertial frame at
            t0 carried along with node B for a joint with ``at``); ``"inertial"``: the same
            force and moment (same point) in the inertial axes, ``R_B R_XB`` applied to both.
        part : {"total", "constraint"}
            ``"total"``: everything the joint transmits to B, its force elements (springs,
            dampers, actuators, PD laws) included: what a six-axis load cell between the joint
            and body B reads; its components along the joint's free directions are
            :meth:`joint_torque` (``A^T lambda``). ``"constraint"``: the part that does no work
            on the joint's motion, ``lambda - A^+T A^T lambda`` (``A^+`` the pseudo-inverse of
            the joint basis A of Eq. (9)): e.g. zero moment about a hinge's axis.

        Returns
        -------
        ndarray (n, 6)
            ``(fx, fy, fz, mx, my, mz)`` in N and N m.
        """
        if frame not in ("joint", "inertial"):
            raise ModelError("results", "frame", "'joint' or 'inertial'", frame)
        if part not in ("total", "constraint"):
            raise ModelError("results", "part", "'total' or 'constraint'", part)
        j = self._joints(name)[-1]
        s = self.system
        a = s.joint_multadr[j]
        w = np.array(self.lam[:, a:a + 6], dtype=float)
        if frame == "joint" and (part == "total" or not s.joint_k[j]):
            return w
        b, XB, A = self._joint_geometry(j)
        if part == "constraint" and s.joint_k[j]:
            A = A[:, :s.joint_k[j]]
            w -= (w @ A) @ np.linalg.pinv(A)
        return w if frame == "joint" else _rotate(self.H[:, b, :3, :3] @ XB[:3, :3], w)

    def joint_torque(self, name: str) -> np.ndarray:
        """Generalized force along the joint's own coordinates, shape (n, k): what a torque (or
        force) sensor in the joint measures, the sum of its springs, dampers, actuators and PD
        laws acting on body B in the sense of increasing coordinates (N m for an angle, N for
        a translation).

        The joint frame carries no inertia, so its rows of Eq. (36) read ``A^T lambda +
        g_int,j = 0`` (column ``A`` of Eq. (58)): the force elements' generalized force
        ``-g_int,j`` (Eqs. (62), (64), (66)) is ``A^T lambda``, exact from the stored
        multipliers to the Newton tolerance of the step. For a composite joint, the values of
        its parts side by side (as :meth:`joint_coordinates`); zero columns for a joint
        without coordinates (k = 0).
        """
        s = self.system
        cols = []
        for j in self._joints(name):
            if not s.joint_k[j]:
                continue
            _, _, A = self._joint_geometry(j)
            a = s.joint_multadr[j]
            cols.append(np.asarray(self.lam[:, a:a + 6], dtype=float) @ A[:, :s.joint_k[j]])
        return np.concatenate(cols, axis=1) if cols else np.zeros((len(self.t), 0))

    def drive_effort(self, name: str) -> np.ndarray:
        """Force or torque a driver supplies to its coordinates, shape (n, c) for its c driven
        coordinates (in order of the coordinate index): N m for an angle, N for a translation,
        positive in the sense of increasing coordinate, as an actuator's.

        Exact: a driven coordinate's row of the equations of motion (Eq. (36)) holds with the
        driver's force added, so the force is that row's residual at the stored state (the
        joint's ``A^T lambda`` and its force elements: springs, dampers, actuators, PD laws),
        evaluated by the compiled element kernels. ``effort * rate`` is the driver's power,
        which the energy balance counts with the actuators' (``work_act``).
        """
        s = model_system(self.system)
        drives = getattr(getattr(s, "model", None), "drives", ())
        names = [d.name for d in drives]
        if name not in names:
            raise _unknown("drive", name, names, "none: the model has no drives")
        return self._prescribed_rows(s)[:, :len(s.drive_dof)][
            :, s.drive_of == names.index(name)].copy()

    def coupling_force(self, name: str) -> np.ndarray:
        """Force or torque a coupling (``ModelBuilder.coupling``) applies to its follower's
        coordinate, shape (n,): N m for an angle, N for a translation, positive along it; the
        leader receives ``-ratio`` times it (an ideal coupling does no work).

        Exact, as :meth:`drive_effort`: the residual of the follower's equation of motion
        (Eq. (36)) at the stored state, without the coupling."""
        s = model_system(self.system)
        cpl = getattr(getattr(s, "model", None), "couplings", ())
        names = [c.name for c in cpl]
        if name not in names:
            raise _unknown("coupling", name, names, "none: the model has no couplings")
        return self._prescribed_rows(s)[:, len(s.drive_dof) + names.index(name)].copy()

    def _prescribed_rows(self, s) -> np.ndarray:
        """The residual rows (n, nd + ncpl) of the driven coordinates and the couplings'
        followers at the stored rows, computed once (the compiled kernels)."""
        cache = self.__dict__.setdefault("_drive_r", {})
        if id(s) not in cache:
            from se3dyn.engine.system import joint_frames, residual_rows

            H = np.asarray(self.H, float)
            r = residual_rows(s, np.asarray(self.t, float), H, joint_frames(s, H), self.alpha,
                              self.v, self.vd, self.lam)
            cache.clear()
            cache[id(s)] = r[:, np.concatenate([s.drive_dof, s.cpl_follow])]
        return cache[id(s)]

    # ------------------------------------------------------------------------------------------
    # Force sensors: the parts of the joints' force elements, point spring-dampers
    def _force_rows(self, part: str, name: str) -> np.ndarray:
        """The residual of the joints' force elements of ``part`` at the stored rows, (n, nq)
        (:func:`se3dyn.results.forces.joint_force_rows`), computed once per part."""
        from se3dyn.results.forces import joint_force_rows

        self._joints(name)  # an unknown joint is reported first
        s = model_system(self.system)
        if s is None:
            raise ModelError("results", "joint", "results with their model (a compiled System, "
                             "or a results file that stores its model) for the joint's force "
                             "elements", name)
        cache = self.__dict__.setdefault("_force_r", {})
        key = (id(s), part)
        if key not in cache:
            rows = joint_force_rows(s, part, self.t, self.H, self.alpha, self.v, self.vd)
            if part == "actuator":
                rows = -rows  # (the residual holds -tau: the effort is positive along alpha)
                self._pid_efforts(s, rows, name)
            cache[key] = rows
        return cache[key]

    def _pid_efforts(self, s, rows: np.ndarray, name: str) -> None:
        """The efforts of the PID-controlled joints into ``rows`` (n, nq), in place: their
        integral state is not in the stored rows, so from the joint coordinates' equations of
        motion (Eq. (36)), ``A^T lambda + spring + J_a dv/dt`` (:mod:`se3dyn.results.forces`)."""
        from se3dyn.results.forces import pid_joints

        pids = pid_joints(s.model)
        if not pids:
            return
        spring = self._force_rows("spring", name)
        Ja = np.asarray(getattr(s, "dof_armature", np.zeros(s.nq)), dtype=float)
        for j in pids:
            d, k = int(s.joint_dofadr[j]), int(s.joint_k[j])
            rows[:, d:d + k] = (self.joint_torque(s.joint_names[j]) + spring[:, d:d + k]
                                + Ja[d:d + k] * np.asarray(self.vd, float)[:, d:d + k])

    def actuator_effort(self, name: str) -> np.ndarray:
        """Generalized force that a joint's actuator (``actuator=``, Eq. (66): a time function
        or a law ``f(t, q, v)``) and control law (``control=``: PD or PID) apply along its
        coordinates, shape (n, k): ``tau(t) - kp
        (alpha - target(t)) - kd (v - target_rate(t))`` (a PID law: ``- ki z`` more, saturated),
        N m for an angle and N for a translation, positive in the sense of increasing
        coordinates (as :meth:`drive_effort`); a PID law behind a gear: what the joint
        receives, gear times the motor's torque.

        Exact: evaluated by the compiled element kernel at the stored rows (the time
        functions at the rows' times), see :mod:`se3dyn.results.forces`; under a PID law, whose
        integral state the rows do not hold, from the joint's equation of motion (``A^T lambda
        + spring + J_a dv/dt``, to the Newton tolerance of the step). ``sum(effort * v)``
        is the actuators' power, whose time integral is ``work_actuators`` (with the drives').
        Zero columns for a joint without actuator or PD law; for a composite joint its parts'
        values side by side (as :meth:`joint_coordinates`).
        """
        return self._joint_cols(name, self._force_rows("actuator", name))

    def spring_force(self, name: str) -> np.ndarray:
        """Generalized force of a joint's spring and damper (``stiffness=``, ``damping=``,
        Eqs. (62), (64)), shape (n, k): ``K (alpha - reference) + C v`` on an abelian joint,
        positive when the spring is stretched beyond its reference (it then pulls the
        coordinate back: the force on body B along increasing coordinates is minus this, as a
        point spring-damper's tension, :meth:`spring_damper_force`). On a non-abelian joint
        (spherical, planar) the spring acts on the log coordinates, ``T_A(alpha)^-T K (alpha -
        reference) + C v``, the kernel's generalized force on the joint's unknowns.

        Exact: evaluated by the compiled element kernel at the stored rows (see
        :mod:`se3dyn.results.forces`). Without drives on the joint, ``joint_torque =
        actuator_effort - spring_force - J_a dv/dt`` (``J_a`` the joint's armature, if any).
        Zero columns for a joint without spring or damper.
        """
        return self._joint_cols(name, self._force_rows("spring", name))

    def _spring_damper(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(length, rate, force) of a point spring-damper, each (n,), computed once."""
        from se3dyn.results.forces import point_spring

        s = model_system(self.system)
        specs = getattr(getattr(s, "model", None), "springs", ())
        names = [sp.name for sp in specs]
        if name not in names:
            raise _unknown("spring-damper", name, names,
                           "none: the model has no spring-dampers (or its results file stores "
                           "no model)")
        cache = self.__dict__.setdefault("_spring_d", {})
        key = (id(s), name)
        if key not in cache:
            a, b, ca, cb, k, d, L0 = s.springs[names.index(name)]
            H = np.asarray(self.H, dtype=float)
            wa, wb = (node_dofs(self.system, H, self.v, i, "material") for i in (a, b))
            cache[key] = point_spring(H[:, a], wa, ca, H[:, b], wb, cb, k, d, L0)
        return cache[key]

    def spring_damper_force(self, name: str) -> np.ndarray:
        """Axial force of a point spring-damper (``ModelBuilder.spring_damper``), shape (n,) (N):
        ``stiffness (L - length) + damping dL/dt``, tension positive (the spring then pulls its
        two points towards each other)."""
        return self._spring_damper(name)[2].copy()

    def spring_damper_length(self, name: str) -> np.ndarray:
        """Distance ``L`` between the two points of a point spring-damper, shape (n,) (m)."""
        return self._spring_damper(name)[0].copy()

    def spring_damper_rate(self, name: str) -> np.ndarray:
        """Time derivative ``dL/dt`` of :meth:`spring_damper_length`, shape (n,) (m/s), from the
        exact velocities of the two points (positive when they move apart)."""
        return self._spring_damper(name)[1].copy()

    # ------------------------------------------------------------------------------------------
    # Contacts (se3dyn.elements.contact): the kernel's outputs at the rows, stored by the run
    def contact_pairs(self) -> list[str]:
        """The names ``"a/b"`` of the contact pairs (shape a: the plane, or the first sphere)."""
        return [p.name for p in getattr(self.system, "contacts", ())]

    def _contact(self, name: str, lo: int, hi: int) -> np.ndarray:
        names = self.contact_pairs()
        if name not in names:
            raise _unknown("contact pair", name, names, "none: the model has no contact pairs")
        if self.contact_rows is None:
            raise ModelError("results", "contact pair", "results of a run in memory (the "
                             "contact outputs are not stored in results files yet)", name)
        k = 19 * names.index(name)
        return self.contact_rows[:, k + lo:k + hi].copy()

    def contact_force(self, name: str) -> np.ndarray:
        """Force on the pair's shape b (its opposite on shape a), inertial frame, (n, 3) (N):
        the normal force along :meth:`contact_normal` and the friction, at
        :meth:`contact_point`; zero while apart."""
        return self._contact(name, 10, 13)

    def contact_normal_force(self, name: str) -> np.ndarray:
        """The normal force ``k delta^{3/2} (1 + c delta'/v_in)`` (n,) (N), >= 0."""
        return self._contact(name, 9, 10)[:, 0]

    def contact_point(self, name: str) -> np.ndarray:
        """The contact point (the middle of the overlap), inertial frame, (n, 3) (m)."""
        return self._contact(name, 13, 16)

    def contact_normal(self, name: str) -> np.ndarray:
        """The unit normal from shape a into shape b, inertial frame, (n, 3)."""
        return self._contact(name, 16, 19)

    def contact_penetration(self, name: str) -> np.ndarray:
        """The penetration ``delta`` (n,) (m): negative, the gap while apart."""
        return self._contact(name, 6, 7)[:, 0]

    # ------------------------------------------------------------------------------------------
    # Markers and sensors: frames fixed on nodes (ModelBuilder.marker), H_m = H X
    def _marker(self, name: str):
        """(spec, node index) of a marker; UnknownNameError listing the valid names."""
        specs = marker_specs(self.system)
        for mk in specs:
            if mk.name == name:
                return mk, self._node(mk.node)
        raise _unknown("marker", name, [mk.name for mk in specs],
                       "none: the model has no markers")

    def _marker_twists(self, name: str, *arrs: np.ndarray):
        """Marker frame (n, 4, 4), then the node twists of each of ``arrs`` (v, vd) as twists
        of the marker frame (n, 6)."""
        mk, i = self._marker(name)
        X = np.asarray(mk.X, dtype=float)
        return (self.H[:, i] @ X, *(_to_marker(X, node_dofs(self.system, self.H, arr, i,
                                                             "material")) for arr in arrs))

    def marker_frame(self, name: str) -> np.ndarray:
        """Homogeneous frame ``H_m = H X`` of a marker (inertial frame), shape (n, 4, 4)."""
        mk, i = self._marker(name)
        return self.H[:, i] @ np.asarray(mk.X, dtype=float)

    def marker_position(self, name: str) -> np.ndarray:
        """Position of a marker's origin in the inertial frame, shape (n, 3)."""
        return self.marker_frame(name)[:, :3, 3].copy()

    def marker_rotation(self, name: str) -> np.ndarray:
        """Rotation of a marker (its axes in the inertial frame), shape (n, 3, 3)."""
        return self.marker_frame(name)[:, :3, :3].copy()

    def marker_velocity(self, name: str, frame: str = "material") -> np.ndarray:
        """Velocity ``(U, Omega)`` of a marker frame, shape (n, 6).

        ``frame="material"``: in the marker's own axes (Eq. (4) for the marker frame,
        ``Ad(X^-1) v`` of its node); ``frame="inertial"``: ``(R_m U, R_m Omega)``, the time
        derivative of the marker's position and the angular velocity in the inertial frame.
        Zeros on a fixed node.
        """
        _check_frame(frame)
        Hm, w = self._marker_twists(name, self.v)
        return w if frame == "material" else _rotate(Hm[:, :3, :3], w)

    def marker_acceleration(self, name: str, frame: str = "material") -> np.ndarray:
        """Acceleration of a marker frame, shape (n, 6).

        ``frame="material"``: the time derivative of the material velocity of the marker,
        ``(dU/dt, dOmega/dt)`` (the node-level convention of :meth:`node_acceleration`);
        ``frame="inertial"``: the acceleration of the marker's origin (tangential, centripetal
        and Coriolis terms included: ``R (dU/dt + Omega x U)``) and the angular acceleration,
        in the inertial frame (:func:`inertial_acceleration`).
        """
        _check_frame(frame)
        if frame == "material":
            return self._marker_twists(name, self.vd)[1]
        Hm, w, a = self._marker_twists(name, self.v, self.vd)
        return inertial_acceleration(Hm[:, :3, :3], w, a)

    def accelerometer(self, name: str) -> np.ndarray:
        """Specific force at a marker in the marker's axes, as a real accelerometer reports
        it, shape (n, 3) (m/s^2): ``R_m^T (a - g)``, with ``a`` the inertial acceleration of
        the marker's origin and ``g`` the model's gravity.

        Sign convention: an accelerometer at rest reads ``-g`` in its own axes, i.e. +9.81
        along the upward vertical for gravity ``(0, 0, -9.81)``; in free fall it reads zero.
        """
        Hm, w, a = self._marker_twists(name, self.v, self.vd)
        g = np.asarray(self.system.gravity, dtype=float)
        return _origin_acceleration(w, a) - np.einsum("nji,j->ni", Hm[:, :3, :3], g)

    def gyroscope(self, name: str) -> np.ndarray:
        """Angular velocity of a marker in the marker's own axes (a rate gyroscope), shape
        (n, 3) (rad/s): ``R_m^T omega``, ``omega`` the inertial angular velocity."""
        return self.marker_velocity(name, "material")[:, 3:].copy()

    def marker_distance(self, a: str, b: str) -> np.ndarray:
        """Distance between the origins of two markers, shape (n,) (m): ``|p_b - p_a|``."""
        return np.linalg.norm(self.marker_position(b) - self.marker_position(a), axis=1)

    def marker_distance_rate(self, a: str, b: str) -> np.ndarray:
        """Time derivative of :meth:`marker_distance`, shape (n,) (m/s): ``(p_b - p_a) .
        (dp_b/dt - dp_a/dt) / |p_b - p_a|``, from the exact marker velocities (positive when
        the markers move apart); zero where the two origins coincide (the rate is undefined)."""
        d = self.marker_position(b) - self.marker_position(a)
        dv = (self.marker_velocity(b, "inertial")[:, :3]
              - self.marker_velocity(a, "inertial")[:, :3])
        dist = np.linalg.norm(d, axis=1)
        num = np.einsum("ni,ni->n", d, dv)
        return np.divide(num, dist, out=np.zeros_like(num), where=dist > 0)

    @property
    def total_energy(self) -> np.ndarray:
        """Kinetic + gravity potential + spring energy, shape (n,)."""
        return self.kinetic + self.potential + self.spring

    @property
    def energy_balance(self) -> np.ndarray:
        """``E - W_actuators - W_loads + dissipation``, constant for the exact solution, (n,)."""
        return self.total_energy - self.work_actuators - self.work_loads + self.dissipation

    def __len__(self) -> int:
        return len(self.t)

    def show(self, *args, **kwargs):
        """Moved: ``sd.show(result)`` (:func:`se3dyn.viewer.show`) shows the 3D viewer inline in
        a Jupyter notebook. Results sit below the viewer in the layers (docs/design.md), so
        they do not open it themselves."""
        raise AttributeError("Results.show() is now se3dyn.show(result) (import se3dyn as sd; "
                             "sd.show(result, height=520)): the viewer is a layer above the "
                             "results")


def _get_lam(self) -> np.ndarray:
    fill = self.__dict__.get("_lam_fill")
    if fill is not None:  # computed when first asked for (se3dyn.dynamics.condense)
        self.__dict__["_lam_fill"] = None
        fill(self)
    return self.__dict__["_lam"]


def _set_lam(self, value) -> None:
    self.__dict__["_lam"] = value
    self.__dict__["_lam_fill"] = None


#: ``lam`` (n, nm): a stored array, or one with columns computed on first access (the
#: multipliers of rigid joints condensed for the time loop, :mod:`se3dyn.dynamics.condense`):
#: ``results.defer_multipliers(fill)`` registers ``fill(results)``, which completes
#: ``results.__dict__["_lam"]`` in place.
Results.lam = property(_get_lam, _set_lam, doc="multipliers (n, nm)")


def _defer(self, fill) -> None:
    self.__dict__["_lam_fill"] = fill


Results.defer_multipliers = _defer
