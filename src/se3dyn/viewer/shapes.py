"""What the viewer draws: solids attached to nodes, built from the model and its results.

A :class:`Scene` is a list of :class:`Part` objects, each a unit solid (box, sphere, cylinder,
cone, capsule or mesh) placed rigidly in the material frame of one node: at time t its pose in
the inertial frame is ``H_node(t) @ part.matrix @ diag(part.scale, 1)``. The page
(:mod:`se3dyn.viewer.html`) and the glTF exporter (:mod:`se3dyn.viewer.gltf`) both draw scenes.

Unit solids (shared by the page and the glTF exporter), in the part's own frame:

* ``box``: the cube [-1/2, 1/2]^3 (scale = side lengths);
* ``sphere``: radius 1 (scale = radii);
* ``cylinder``: radius 1, height 1 along z, centred (scale = (r, r, length));
* ``cone``: base of radius 1 at z = -1/2, apex at z = +1/2 (scale = (r, r, height));
* ``capsule``: radius ``params[0]``, hemisphere centres at z = -/+ ``params[1] / 2``, scale 1;
* ``mesh``: the vertices of ``scene.meshes[part.mesh]`` (scale = the visual's scales).

Default picture (nodes without ``visuals``):

* **bodies**: a node with mass is drawn as the *equivalent box* of its inertia
  (:func:`equivalent_box`): the homogeneous box with the node's mass whose inertia tensor about
  its centre is the node's, centred on the node and aligned with the principal axes;
* **joints**, at the joint point (the attachment point ``at``, or node B for a joint between
  node frames) and on the joint's axes (columns of A, Table 1): hinge, screw: a short cylinder
  on the axis; prismatic: a rail on node A covering the relative travel seen in the results and
  a block on node B; cylindrical: the rail and a sleeve; spherical, general: a ball; planar: a
  plate on A normal to the plane and a puck on B; rigid: nothing but the links. Glyphs move with
  node B (the rail and the plate with node A); their axes are the joint axes expressed in that
  node's material frame, so they stay on the joint axis as the mechanism moves;
* **links**: a thin rod from each node to each joint point it carries (the body's arms);
* **ground**: a pyramid on a plate under every fixed node, pointing against gravity;
* **markers** (``ModelBuilder.marker``): an axis triad on the marker frame (x red, y green,
  z blue, as the node frames) and a small dot at its origin, moving with the marker's node;
* **drives** (``ModelBuilder.drive``): an orange collar around each driven coordinate's axis
  at the joint point, on the joint's node A (the motor's housing), so a driven joint stands
  out from the free ones; the page lists the drives and plots their efforts;
* **beams**: a :class:`Tube` per beam, drawn by default (the model's ``visuals`` do not replace
  it): the element's centre line with an elliptic section whose area and second moments are the
  beam's (:func:`beam_section`), skinned on the beam's nodes (see :class:`Tube`);
* the gravity direction (drawn by the page in its axes inset).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from se3dyn.viewer.errors import ViewerError

__all__ = ["Part", "Scene", "Tube", "ViewerError", "build_scene", "equivalent_box", "PALETTE",
           "resolve_model", "beam_section", "beam_tube", "tube_vertices"]

#: Body colours, in order of the bodies (colour-blind friendly, no greys).
PALETTE = ("#4e79a7", "#f28e2b", "#59a14f", "#e15759", "#76b7b2", "#edc948", "#b07aa1",
           "#ff9da7", "#9c755f")
JOINT_COLOR = "#3b4252"
LINK_COLOR = "#a3a9b3"
GROUND_COLOR = "#6b6f76"
POINT_COLOR = "#7a7f87"
#: Smallest side of a default body box relative to its largest (flat or slender bodies).
MIN_ASPECT = 0.08
ROLES = ("body", "visual", "joint", "link", "ground", "marker", "drive")
#: Marker triads: the colours of the x, y, z axes (those of the page's node frames), the dot.
MARKER_AXES = ("#d62728", "#2ca02c", "#1f77b4")
MARKER_COLOR = "#22262c"
#: Collar of a driven joint coordinate.
DRIVE_COLOR = "#e4572e"
#: Beam colour (steel blue-grey, apart from the body palette).
BEAM_COLOR = "#8a96a3"
#: Points on the outline of a beam's section, and section rings per element.
TUBE_SIDES, TUBE_RINGS = 16, 4




@dataclass(frozen=True)
class Part:
    """One solid moving rigidly with a node.

    Attributes
    ----------
    node : int
        Index of the node in ``scene.node_names``.
    kind : str
        ``box``, ``sphere``, ``cylinder``, ``cone``, ``capsule`` or ``mesh`` (see the module).
    matrix : ndarray, shape (4, 4)
        Rigid pose of the solid in the material frame of the node.
    scale : ndarray, shape (3,)
        Scales of the unit solid along its own axes.
    color : str
        ``"#rrggbb"``.
    role : str
        ``body``, ``visual``, ``joint``, ``link``, ``ground``, ``marker`` or ``drive`` (what
        the page toggles).
    label : str
        What it shows, e.g. ``"joint '1' (hinge)"``.
    params : tuple of float
        Capsule: (radius, length).
    mesh : int
        Index into ``scene.meshes`` for ``kind == "mesh"``, else -1.
    """

    node: int
    kind: str
    matrix: np.ndarray
    scale: np.ndarray
    color: str
    role: str
    label: str
    params: tuple = ()
    mesh: int = -1

    @property
    def geometry_key(self) -> str:
        """Solids with the same key share one geometry (and one instanced mesh on the page)."""
        if self.kind == "capsule":
            return "capsule:" + ":".join(f"{p:.9g}" for p in self.params)
        if self.kind == "mesh":
            return f"mesh:{self.mesh}"
        return self.kind


@dataclass(frozen=True)
class Tube:
    """A deformable tube along a beam, skinned on the beam's nodes.

    Vertex ``v`` follows the frames of two nodes ``nodes[v]`` (those of its element) by linear
    blend skinning: at time t its inertial position is

        (1 - w_v) H_a(t) p_v,a + w_v H_b(t) p_v,b,        (a, b) = nodes[v],

    with ``p`` the vertex in the material frames of the two nodes in the initial configuration
    (so both terms agree at t0) and ``w`` the vertex's arc parameter along the element, 0 at
    node a and 1 at node b. The normals blend alike (then normalised). The page and glTF
    (a ``skin`` with the nodes as joints) draw the same mesh.

    Attributes
    ----------
    label : str
    color : str
        ``"#rrggbb"``.
    nodes : ndarray of int, shape (V, 2)
        Indices into ``scene.node_names``.
    weight : ndarray, shape (V,)
        Weight of the second node.
    local : ndarray, shape (V, 2, 3)
        The vertex in the material frames of the two nodes.
    normal : ndarray, shape (V, 2, 3)
        Its unit normal in the same frames.
    bind : ndarray, shape (V, 3)
        The vertex in the inertial frame, initial configuration.
    bind_normal : ndarray, shape (V, 3)
        Its unit normal there.
    faces : ndarray of int, shape (F, 3)
        Triangles (counter-clockwise seen from outside).
    frames0 : ndarray, shape (M, 4, 4)
        The initial node frames that ``local`` refers to (``bind = H0 local``).
    """

    label: str
    color: str
    nodes: np.ndarray
    weight: np.ndarray
    local: np.ndarray
    normal: np.ndarray
    bind: np.ndarray
    bind_normal: np.ndarray
    faces: np.ndarray
    frames0: np.ndarray


@dataclass
class Scene:
    """Everything the viewer draws, besides the motion itself.

    Attributes
    ----------
    node_names : tuple of str, (M,)
    node_fixed : ndarray of bool, (M,)
    parts : list of Part
    meshes : list of (ndarray (nv, 3) float, ndarray (nf, 3) int)
        Vertices and triangles of the mesh files, in the file's units.
    gravity : ndarray, shape (3,)
    up : ndarray, shape (3,)
        Unit vector against gravity (e_z without gravity).
    glyph : float
        Size of the joint glyphs (m): the scale of frames, traces and symbols.
    tubes : list of Tube
        The beams.
    bodies : list of int
        Nodes drawn as bodies (default boxes or visuals), in order.
    traces : list of int
        Nodes whose traces the page offers first.
    lo, hi : ndarray, shape (3,)
        Bounds of every node position over the whole motion.
    model_name : str
    notes : list of str
        Remarks shown by the page (e.g. no model stored).
    markers : list of (str, int)
        The markers drawn: name and node index.
    drives : list of dict
        The drives drawn: ``name``, ``joint`` (as given), ``kind`` (``"position"``,
        ``"velocity"`` or both joined by ``+``) and ``channel``, the effort channel plotted.
    """

    node_names: tuple
    node_fixed: np.ndarray
    parts: list = field(default_factory=list)
    tubes: list = field(default_factory=list)
    meshes: list = field(default_factory=list)
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    glyph: float = 0.05
    bodies: list = field(default_factory=list)
    traces: list = field(default_factory=list)
    lo: np.ndarray = field(default_factory=lambda: np.zeros(3))
    hi: np.ndarray = field(default_factory=lambda: np.zeros(3))
    model_name: str = "model"
    notes: list = field(default_factory=list)
    markers: list = field(default_factory=list)
    drives: list = field(default_factory=list)


# ---------------------------------------------------------------------------------------------
def equivalent_box(mass: float, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The homogeneous box of mass ``mass`` whose inertia about its centre is ``inertia``.

    With principal moments ``J1, J2, J3`` (eigenvalues, ascending) and principal axes ``Q``
    (columns), a box of sides ``(a, b, c)`` along them has ``J1 = m (b^2 + c^2) / 12`` and so
    on, hence ``a^2 = 6 (J2 + J3 - J1) / m`` and cyclically.

    Parameters
    ----------
    mass : float
        > 0.
    inertia : ndarray, shape (3, 3)
        Symmetric positive-definite inertia tensor about the centre, in any frame.

    Returns
    -------
    sides : ndarray, shape (3,)
        Side lengths along the columns of ``axes``. A side that the triangle inequality of the
        moments makes zero or imaginary (a lamina, a rod) is raised to ``MIN_ASPECT`` times the
        largest side, so the box is drawable (its inertia then differs in that direction).
    axes : ndarray, shape (3, 3)
        Rotation (det +1) whose columns are the principal axes in the frame of ``inertia``.
    """
    J = 0.5 * (np.asarray(inertia, dtype=float) + np.asarray(inertia, dtype=float).T)
    w, Q = np.linalg.eigh(J)
    if np.linalg.det(Q) < 0:
        Q[:, 2] = -Q[:, 2]
    tr = w.sum()
    sq = 6.0 * (tr - 2.0 * w) / mass  # a^2 = 6 (J2 + J3 - J1) / m
    sides = np.sqrt(np.clip(sq, 0.0, None))
    floor = MIN_ASPECT * sides.max()
    sides = np.maximum(sides, floor)
    return sides, Q


def beam_section(stiffness: np.ndarray) -> tuple[float, float]:
    """Semi-axes of the solid ellipse with a beam section's area and second moments.

    An ellipse with semi-axes ``a2`` (along section axis 2) and ``a3`` (axis 3) has
    ``A = pi a2 a3``, ``I2 = A a3^2 / 4`` and ``I3 = A a2^2 / 4``; with the section stiffness
    ``diag(EA, GA2, GA3, GJ, EI2, EI3)`` of one material, ``I2 / A = EI2 / EA``. A solid circle
    of radius r gives ``a2 = a3 = r`` exactly; other shapes an ellipse of the same bending
    proportions.

    Parameters
    ----------
    stiffness : ndarray, shape (6, 6)
        Section stiffness (translation first), :attr:`se3dyn.model.specs.BeamSpec.stiffness`.

    Returns
    -------
    a2, a3 : float
        Semi-axes (m).
    """
    K = np.diag(np.asarray(stiffness, dtype=float))
    return 2.0 * float(np.sqrt(K[5] / K[0])), 2.0 * float(np.sqrt(K[4] / K[0]))


def beam_tube(spec, idx: dict, H0: np.ndarray, color: str = "") -> Tube:
    """The :class:`Tube` of a beam in its stress-free configuration.

    Each element ``e`` (frames ``F_e``, ``F_e+1`` of ``spec.reference``) gets ``TUBE_RINGS + 1``
    section rings at the frames of the element's own interpolation ``F_e exp(s d0)``, ``d0 =
    log(F_e^-1 F_e+1)`` (:mod:`se3dyn.elements.beam`), ``s`` in [0, 1]; each ring is the
    ellipse of :func:`beam_section` in the section plane (axes 2 and 3), ``TUBE_SIDES`` points
    (beams of more than 100 elements: the two end rings and 8 points).

    Parameters
    ----------
    spec : BeamSpec
    idx : dict
        Node name -> index into the scene's nodes.
    H0 : ndarray, shape (M, 4, 4)
        Initial node frames (inertial), the frames the local coordinates refer to.
    color : str, optional
        ``"#rrggbb"`` (default :data:`BEAM_COLOR`).

    Returns
    -------
    Tube
    """
    from se3dyn import lie

    a2, a3 = beam_section(spec.stiffness)
    F = np.asarray(spec.reference, dtype=float)
    fine = len(F) - 1 <= 100  # long beams: fewer facets (the page stays light to draw)
    sides, rings = (TUBE_SIDES, TUBE_RINGS) if fine else (8, 1)
    th = 2.0 * np.pi * np.arange(sides) / sides
    ring = np.stack([np.zeros_like(th), a2 * np.cos(th), a3 * np.sin(th)], axis=1)  # (S, 3)
    rn = np.stack([np.zeros_like(th), np.cos(th) / a2, np.sin(th) / a3], axis=1)
    rn /= np.linalg.norm(rn, axis=1, keepdims=True)
    s = np.arange(rings + 1) / rings
    nodes, weight, bind, nrm, faces = [], [], [], [], []
    per = (rings + 1) * sides
    S = sides
    for e in range(len(F) - 1):
        d0 = lie.log_se3(lie.inverse(F[e]) @ F[e + 1])
        Fs = F[e] @ lie.exp_se3(s[:, None] * d0)  # (R, 4, 4)
        bind.append((np.einsum("rij,kj->rki", Fs[:, :3, :3], ring)
                     + Fs[:, None, :3, 3]).reshape(-1, 3))
        nrm.append(np.einsum("rij,kj->rki", Fs[:, :3, :3], rn).reshape(-1, 3))
        weight.append(np.repeat(s, S))
        nodes.append(np.tile([idx[spec.nodes[e]], idx[spec.nodes[e + 1]]], (per, 1)))
        r, k = np.meshgrid(np.arange(rings), np.arange(S), indexing="ij")
        v0 = e * per + r * S + k
        v1 = e * per + r * S + (k + 1) % S
        faces.append(np.concatenate([np.stack([v0, v1 + S, v0 + S], -1).reshape(-1, 3),
                                     np.stack([v0, v1, v1 + S], -1).reshape(-1, 3)]))
    nodes_ = np.concatenate(nodes).astype(np.int64)
    bind_ = np.concatenate(bind)
    nrm_ = np.concatenate(nrm)
    Hn = np.asarray(H0, dtype=float)[nodes_]  # (V, 2, 4, 4)
    local = np.einsum("vnji,vnj->vni", Hn[..., :3, :3], bind_[:, None, :] - Hn[..., :3, 3])
    normal = np.einsum("vnji,vj->vni", Hn[..., :3, :3], nrm_)
    return Tube(f"beam {spec.name!r} ({len(F) - 1} elements, section {2 * a2:.3g} x "
                f"{2 * a3:.3g} m)", color or BEAM_COLOR, nodes_, np.concatenate(weight),
                local, normal, bind_, nrm_, np.concatenate(faces).astype(np.int64),
                np.asarray(H0, dtype=float))


def tube_vertices(tube: Tube, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and unit normals of a tube's vertices for node frames ``H``.

    Parameters
    ----------
    tube : Tube
    H : ndarray, shape (..., M, 4, 4)
        Node frames (inertial), e.g. ``Results.H`` or one row of it.

    Returns
    -------
    positions, normals : ndarray, shape (..., V, 3)
    """
    H = np.asarray(H, dtype=float)
    Hv = H[..., tube.nodes, :, :]  # (..., V, 2, 4, 4)
    p = np.einsum("...vnij,vnj->...vni", Hv[..., :3, :3], tube.local) + Hv[..., :3, 3]
    q = np.einsum("...vnij,vnj->...vni", Hv[..., :3, :3], tube.normal)
    w = np.stack([1.0 - tube.weight, tube.weight], axis=-1)[..., None]  # (V, 2, 1)
    pos = np.sum(w * p, axis=-2)
    nrm = np.sum(w * q, axis=-2)
    return pos, nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)


def _frame(R: np.ndarray | None = None, p: np.ndarray | None = None) -> np.ndarray:
    H = np.eye(4)
    if R is not None:
        H[:3, :3] = R
    if p is not None:
        H[:3, 3] = p
    return H


def _axis_frame(p: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Pose whose z axis is ``axis`` (unit) and origin ``p``."""
    from se3dyn.model.visuals import axis_rotation

    return _frame(axis_rotation(axis), p)


def _hexrgb(color: str) -> tuple[int, int, int]:
    return int(color[1:3], 16), int(color[3:5], 16), int(color[5:7], 16)


# ---------------------------------------------------------------------------------------------
def resolve_model(res, model=None, model_path: str | os.PathLike | None = None):
    """The :class:`~se3dyn.model.specs.Model` to draw ``res`` with, or None.

    Order: ``model`` given; a model file ``model_path``; the model of an in-memory result
    (``res.system.model``); the model text stored in a results file (``res.stats["model"]``).
    A model whose node names differ from the results' raises :class:`ViewerError` when given
    explicitly and is ignored (None) when found in the results.
    """
    names = tuple(res.system.node_names)
    explicit = model is not None or model_path is not None
    if model is None and model_path is not None:
        from se3dyn.errors import ModelError
        from se3dyn.io.modelfile import load_model

        try:
            model, _ = load_model(Path(model_path))
        except ModelError as e:
            raise ViewerError(str(e)) from None
    if model is None:
        model = getattr(res.system, "model", None)
    if model is None:
        text = (res.stats or {}).get("model") or ""
        if text.strip():
            from se3dyn.errors import ModelError
            from se3dyn.io.modelfile import loads_model

            try:
                model, _ = loads_model(text, filename="<model stored in the results file>")
            except ModelError:
                model = None
    if model is None:
        return None
    got = tuple(n.name for n in model.nodes)
    if got != names:
        if explicit:
            missing = [n for n in names if n not in got][:3]
            raise ViewerError(
                f"model '{model.name}': field 'nodes': expected the {len(names)} nodes of the "
                f"results in their order, got {len(got)} nodes"
                + (f" (missing {', '.join(repr(m) for m in missing)})" if missing else ""))
        return None
    return model


def build_scene(res, model=None, *, model_path=None, mesh_dirs=(), traces=None) -> Scene:
    """The scene of ``res``: visuals of the model, or the default picture (module docstring).

    Parameters
    ----------
    res : Results
        In memory or read from a file (:func:`se3dyn.io.h5.read_results`).
    model : Model, optional
        The model to draw (default: see :func:`resolve_model`).
    model_path : path, optional
        A model file to take the model (and the folder of relative mesh files) from.
    mesh_dirs : sequence of path
        Extra folders where relative mesh file names are looked up.
    traces : sequence of str, optional
        Node names whose traces the page shows first (default: the bodies if at most six,
        else the last body).

    Raises
    ------
    ViewerError
        Unknown trace node, missing or unreadable mesh file, explicit model not matching.
    """
    model = resolve_model(res, model, model_path)
    names = tuple(res.system.node_names)
    M = len(names)
    fixed = np.asarray(res.system.node_fixed, dtype=bool)
    pos = res.H[:, :, :3, 3]
    lo = pos.min(axis=(0, 1)) if pos.size else np.zeros(3)
    hi = pos.max(axis=(0, 1)) if pos.size else np.zeros(3)
    grav = np.zeros(3) if model is None else np.asarray(model.gravity, dtype=float)
    up = -grav / np.linalg.norm(grav) if np.linalg.norm(grav) > 0 else np.array([0.0, 0, 1])
    scene = Scene(names, fixed, gravity=grav, up=up, lo=lo, hi=hi,
                  model_name=(model.name if model is not None else
                              Path(str((res.stats or {}).get("path") or "results")).stem))
    diag = float(np.linalg.norm(hi - lo))
    if model is None:
        scene.notes.append("no model with the results: nodes drawn as points")
        _points_only(scene, diag)
    else:
        dirs = [Path(model_path).parent] if model_path is not None else []
        path = (res.stats or {}).get("path")
        if path:
            dirs += [Path(path).parent, Path(path).parent.parent]
        dirs += [Path(d) for d in mesh_dirs] + [Path.cwd()]
        _from_model(scene, res, model, diag, dirs)
    if traces is None:
        bodies = [i for i in scene.bodies if not fixed[i]] or [i for i in range(M)
                                                               if not fixed[i]]
        scene.traces = list(bodies) if len(bodies) <= 6 else list(bodies[-1:])
    else:
        idx = []
        for name in traces:
            if name not in names:
                import difflib

                close = difflib.get_close_matches(str(name), names, n=1)
                raise ViewerError(f"trace: field 'node': expected a node of the results, got "
                                  f"{name!r}" + (f" (did you mean '{close[0]}'?)" if close
                                                 else ""))
            idx.append(names.index(name))
        scene.traces = idx
    return scene


def _glyph_size(sizes: list[float], diag: float) -> float:
    """Joint glyph radius: 12 % of the median body size, at most 5 % of the scene."""
    if sizes:
        g = 0.12 * float(np.median(sizes))
        return min(g, 0.05 * diag) if diag > 0 else g
    return 0.02 * diag if diag > 0 else 0.05


def _points_only(scene: Scene, diag: float) -> None:
    g = _glyph_size([], diag)
    scene.glyph = g
    for i in range(len(scene.node_names)):
        if scene.node_fixed[i]:
            _ground(scene, i, g)
        else:
            scene.parts.append(Part(i, "sphere", np.eye(4), np.full(3, g), POINT_COLOR, "body",
                                    f"node {scene.node_names[i]!r}"))
            scene.bodies.append(i)


def _ground(scene: Scene, i: int, g: float, R0: np.ndarray | None = None) -> None:
    """Pyramid (apex at the node) on a plate, against gravity, in node i's material frame."""
    up = scene.up if R0 is None else R0.T @ scene.up
    label = f"node {scene.node_names[i]!r} (fixed)"
    h = 2.0 * g
    scene.parts.append(Part(i, "cone", _axis_frame(-0.5 * h * up, up), np.array([1.4 * g,
                            1.4 * g, h]), GROUND_COLOR, "ground", label))
    scene.parts.append(Part(i, "box", _axis_frame(-(h + 0.2 * g) * up, up),
                            np.array([4.0 * g, 4.0 * g, 0.4 * g]), GROUND_COLOR, "ground", label))


def _visual_extent(v) -> float:
    s = np.asarray(v.size, dtype=float)
    if v.shape == "box":
        return float(s.max())
    if v.shape == "sphere":
        return float(2 * s[0])
    if v.shape in ("cylinder", "capsule"):
        return float(max(2 * s[0], s[1]))
    return 0.0


def _from_model(scene: Scene, res, model, diag: float, dirs: list[Path]) -> None:
    names = scene.node_names
    idx = {n: i for i, n in enumerate(names)}
    nodes = model.nodes
    R0 = np.array([n.orientation for n in nodes])
    x0 = np.array([n.position for n in nodes])
    with_visuals = {v.node for v in model.visuals}

    # bodies: equivalent boxes of the inertia (material frame at t0: R0^T J R0)
    sizes: list[float] = []
    boxes = []
    for i, n in enumerate(nodes):
        if n.mass > 0 and n.name not in with_visuals:
            sides, Q = equivalent_box(n.mass, R0[i].T @ n.inertia @ R0[i])
            boxes.append((i, sides, Q))
            sizes.append(float(sides.max()))
    sizes += [e for e in (_visual_extent(v) for v in model.visuals) if e > 0]
    g = _glyph_size(sizes, diag)
    scene.glyph = g
    colors: dict[int, str] = {}
    order = sorted({b[0] for b in boxes} | {idx[v.node] for v in model.visuals})
    for k, i in enumerate(order):
        colors[i] = PALETTE[k % len(PALETTE)]
    scene.bodies = order
    for i, sides, Q in boxes:
        scene.parts.append(Part(i, "box", _frame(Q), sides, colors[i], "body",
                                f"node {names[i]!r} (m = {nodes[i].mass:g} kg)"))
    mesh_index: dict[str, int] = {}
    for v in model.visuals:
        i = idx[v.node]
        H = _frame(v.orientation, v.offset)
        color = v.color or colors[i]
        label = f"visual {v.name!r} ({v.shape}) on node {v.node!r}"
        s = np.asarray(v.size, dtype=float)
        if v.shape == "box":
            scene.parts.append(Part(i, "box", H, s.copy(), color, "visual", label))
        elif v.shape == "sphere":
            scene.parts.append(Part(i, "sphere", H, np.full(3, s[0]), color, "visual", label))
        elif v.shape == "cylinder":
            scene.parts.append(Part(i, "cylinder", H, np.array([s[0], s[0], s[1]]), color,
                                    "visual", label))
        elif v.shape == "capsule":
            scene.parts.append(Part(i, "capsule", H, np.ones(3), color, "visual", label,
                                    params=(float(s[0]), float(s[1]))))
        else:
            from se3dyn.viewer.meshes import load_mesh

            key = v.file
            if key not in mesh_index:
                mesh_index[key] = len(scene.meshes)
                scene.meshes.append(load_mesh(v.file, dirs, f"visual {v.name!r} (mesh)"))
            scene.parts.append(Part(i, "mesh", H, s.copy(), color, "visual", label,
                                    mesh=mesh_index[key]))

    # beams: tubes skinned on their nodes (initial node frames H0 of the model)
    H0 = np.broadcast_to(np.eye(4), (len(nodes), 4, 4)).copy()
    H0[:, :3, :3], H0[:, :3, 3] = R0, x0
    for b in model.beams:
        scene.tubes.append(beam_tube(b, idx, H0))

    # fixed nodes
    for i, n in enumerate(nodes):
        if n.fixed:
            _ground(scene, i, g, R0[i])

    # joints: glyphs and links
    H = res.H
    links: set[tuple] = set()
    for j in model.joints:
        a, b = idx[j.node_a], idx[j.node_b]
        p0 = np.asarray(j.at, dtype=float) if j.at is not None else x0[b].copy()
        label = f"joint {(j.composite or j.name)!r} ({j.type})"
        for i in (a, b):
            d = R0[i].T @ (p0 - x0[i])  # joint point in the material frame of node i
            L = float(np.linalg.norm(d))
            key = (i, *np.round(d / max(g, 1e-300), 6))
            if L > 0.1 * g and key not in links:
                links.add(key)
                scene.parts.append(Part(i, "cylinder", _axis_frame(0.5 * d, d / L),
                                        np.array([0.3 * g, 0.3 * g, L]), LINK_COLOR, "link",
                                        f"link of node {names[i]!r} to {label}"))
        _joint_glyph(scene, j, a, b, p0, R0, x0, H, g, label)
    _markers(scene, model, idx, g)
    _drives(scene, model, idx, R0, x0, g)


def _markers(scene: Scene, model, idx: dict, g: float) -> None:
    """An axis triad and a dot per marker (module docstring), in its node's material frame:
    the marker's offset ``X`` (:class:`~se3dyn.model.specs.MarkerSpec`) is that pose."""
    size = 2.5 * g
    for mk in model.markers:
        i = idx[mk.node]
        X = np.asarray(mk.X, dtype=float)
        c = X[:3, 3]
        label = f"marker {mk.name!r} on node {mk.node!r}"
        scene.parts.append(Part(i, "sphere", _frame(None, c), np.full(3, 0.3 * g), MARKER_COLOR,
                                "marker", label))
        for a in range(3):
            e = X[:3, a]
            scene.parts.append(Part(i, "cylinder", _axis_frame(c + 0.5 * size * e, e),
                                    np.array([0.1 * g, 0.1 * g, size]), MARKER_AXES[a],
                                    "marker", label))
        scene.markers.append((mk.name, i))


def _drives(scene: Scene, model, idx: dict, R0, x0, g: float) -> None:
    """A collar per driven coordinate (module docstring): around the coordinate's axis (its
    rotation axis, else its direction of translation; a column of the joint's A, Table 1) at
    the joint point, on node A."""
    from se3dyn.results.channels import escape_name

    joints = {j.name: j for j in model.joints}
    for dr in model.drives:
        label = f"drive {dr.name!r} on joint {dr.joint!r}"
        for jname, c, _kind in dr.targets:
            j = joints[jname]
            a, b = idx[j.node_a], idx[j.node_b]
            p0 = np.asarray(j.at, dtype=float) if j.at is not None else x0[b]
            col = np.asarray(j.A, dtype=float).reshape(6, -1)[:, c]
            axis = col[3:] if np.linalg.norm(col[3:]) > 0 else col[:3]
            axis = R0[a].T @ (axis / np.linalg.norm(axis))
            scene.parts.append(Part(a, "cylinder", _axis_frame(R0[a].T @ (p0 - x0[a]), axis),
                                    np.array([1.6 * g, 1.6 * g, 1.2 * g]), DRIVE_COLOR, "drive",
                                    label))
        kinds = "+".join(sorted({k for _, _, k in dr.targets}))
        effort = f"drive/{escape_name(dr.name)}/effort" + ("" if len(dr.targets) == 1 else "/0")
        scene.drives.append({"name": dr.name, "joint": dr.joint, "kind": kinds,
                             "channel": effort})


def _joint_glyph(scene, j, a, b, p0, R0, x0, H, g, label) -> None:
    A = np.asarray(j.A, dtype=float).reshape(6, -1)
    t = j.type

    def on(i, p, axis):  # pose on node i: origin at p, z along axis (inertial, t0)
        return _axis_frame(R0[i].T @ (p - x0[i]), R0[i].T @ axis / np.linalg.norm(axis))

    def add(i, kind, Hloc, scale):
        scene.parts.append(Part(i, kind, Hloc, np.asarray(scale, dtype=float), JOINT_COLOR,
                                "joint", label))

    if t in ("hinge", "screw"):
        add(b, "cylinder", on(b, p0, A[3:, 0]), (g, g, 3.0 * g))
        if t == "screw":
            add(a, "cylinder", on(a, p0, A[3:, 0]), (0.35 * g, 0.35 * g, 6.0 * g))
    elif t in ("prismatic", "cylindrical"):
        c = 0 if np.linalg.norm(A[:3, 0]) > 0 else 1
        u = A[:3, c] / np.linalg.norm(A[:3, c])
        s_lo, s_hi = _travel(H, a, b, p0, u, R0, x0)
        mid = p0 + 0.5 * (s_lo + s_hi) * u
        add(a, "box", on(a, mid, u), (0.6 * g, 0.6 * g, (s_hi - s_lo) + 4.0 * g))
        if t == "prismatic":
            add(b, "box", on(b, p0, u), (1.6 * g, 1.6 * g, 2.4 * g))
        else:
            add(b, "cylinder", on(b, p0, u), (g, g, 2.4 * g))
    elif t == "planar":
        nrm = A[3:, int(np.argmax(np.linalg.norm(A[3:], axis=0)))]  # the rotation column
        add(a, "box", on(a, p0, nrm), (8.0 * g, 8.0 * g, 0.25 * g))
        add(b, "cylinder", on(b, p0 + 0.4 * g * nrm / np.linalg.norm(nrm), nrm),
            (1.2 * g, 1.2 * g, 0.5 * g))
    elif t in ("spherical", "general"):
        add(b, "sphere", _frame(None, R0[b].T @ (p0 - x0[b])), np.full(3, 1.2 * g))
    # rigid: links only


def _travel(H, a, b, p0, u, R0, x0) -> tuple[float, float]:
    """Range of the joint point of B along the unit axis u, seen from node A over the results
    (inertial quantities at t0): ``s(t) = u_A . (H_A^-1 H_B p_B - p_A)`` in A's frame."""
    pb = R0[b].T @ (p0 - x0[b])          # joint point on B, B's frame
    pa = R0[a].T @ (p0 - x0[a])          # joint point on A, A's frame
    ua = R0[a].T @ u
    Ra, xa = H[:, a, :3, :3], H[:, a, :3, 3]
    Rb, xb = H[:, b, :3, :3], H[:, b, :3, 3]
    world = np.einsum("nij,j->ni", Rb, pb) + xb
    in_a = np.einsum("nji,nj->ni", Ra, world - xa)
    s = (in_a - pa) @ ua
    return (float(s.min()), float(s.max())) if len(s) else (0.0, 0.0)


def part_pose(part: Part, H_node: np.ndarray) -> np.ndarray:
    """Inertial pose of a part for node frames ``H_node`` (..., 4, 4): ``H @ matrix @
    diag(scale, 1)``, shape (..., 4, 4)."""
    S = np.diag(np.append(np.asarray(part.scale, dtype=float), 1.0))
    return np.asarray(H_node) @ part.matrix @ S


def rgb(color: str) -> tuple[int, int, int]:
    """``"#rrggbb"`` as three integers 0..255."""
    return _hexrgb(color)
