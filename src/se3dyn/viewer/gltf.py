"""Animated glTF 2.0 export of results (``se3dyn export RESULTS --gltf FILE.glb``).

The file holds the scene of :func:`se3dyn.viewer.shapes.build_scene` (visuals or the default
picture) and one animation, ``motion``:

* a root node ``se3dyn`` turning the model's "up" (against gravity, else e_z) onto glTF's +Y;
* per model node a glTF node of the same name whose translation and rotation are the node frame
  ``H = (R, x)``; its children carry the solids (meshes) at their fixed poses in the node's
  material frame (translation, rotation and scale of ``part.matrix @ diag(scale, 1)``);
* per beam a skinned mesh (:class:`~se3dyn.viewer.shapes.Tube`): the tube in the initial
  configuration, a ``skin`` whose joints are the beam's glTF nodes with the inverse initial
  node frames as inverse bind matrices, and per vertex the two nodes of its element with the
  weights ``1 - w``, ``w``: any glTF viewer bends it as the page does;
* per moving (non-fixed) node two channels, ``translation`` (x) and ``rotation`` (the unit
  quaternion of R, ``(x, y, z, w)``, sign-continuous in time), LINEAR, sampled at the stored
  times of the results (one shared input accessor, ``min``/``max`` = first and last time).

Written with pygltflib (``pip install 'se3dyn[view]'``); ``.glb`` is binary, ``.gltf`` JSON with
the buffer embedded as a data URI. Units are metres and seconds, as glTF's.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from se3dyn.viewer.encode import quaternions
from se3dyn.viewer.errors import ViewerError
from se3dyn.viewer.shapes import Scene, build_scene, rgb

__all__ = ["export_gltf", "unit_solid"]

_FLOAT, _UINT, _USHORT = 5126, 5125, 5123  # glTF component types
_ARRAY, _ELEMENTS = 34962, 34963  # buffer view targets
_ROLE_PBR = {"body": (0.05, 0.55), "visual": (0.05, 0.55), "joint": (0.35, 0.35),
             "link": (0.1, 0.6), "ground": (0.0, 0.9), "marker": (0.0, 0.5),
             "drive": (0.2, 0.4)}  # metallic, roughness


def unit_solid(kind: str, params=(), mesh=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangles of a unit solid of :mod:`se3dyn.viewer.shapes` (same conventions as the page).

    Returns
    -------
    positions, normals : ndarray, shape (nv, 3), float32
        Flat-shaded (one vertex per triangle corner) except spheres and capsules (smooth).
    indices : ndarray, shape (nf * 3,), uint32
    """
    import trimesh

    smooth = kind in ("sphere", "capsule")
    if kind == "box":
        m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    elif kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    elif kind == "cylinder":
        m = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=28)
    elif kind == "cone":
        m = trimesh.creation.cone(radius=1.0, height=1.0, sections=4)
        m.apply_translation((0.0, 0.0, -0.5))
    elif kind == "capsule":
        m = trimesh.creation.capsule(height=float(params[1]), radius=float(params[0]),
                                     count=[24, 24])
    elif kind == "mesh":
        V, F = mesh
        m = trimesh.Trimesh(vertices=V, faces=F, process=False)
    else:  # pragma: no cover - the scene makes only the kinds above
        raise ValueError(f"unknown solid {kind!r}")
    V = np.asarray(m.vertices, dtype=float)
    F = np.asarray(m.faces, dtype=np.int64)
    if smooth:
        N = np.asarray(m.vertex_normals, dtype=float)
        return V.astype(np.float32), N.astype(np.float32), F.reshape(-1).astype(np.uint32)
    P = V[F].reshape(-1, 3)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    ln = np.linalg.norm(fn, axis=1, keepdims=True)
    fn = np.where(ln > 0, fn / np.where(ln > 0, ln, 1.0), np.array([0.0, 0.0, 1.0]))
    N = np.repeat(fn, 3, axis=0)
    return P.astype(np.float32), N.astype(np.float32), np.arange(len(P), dtype=np.uint32)


def _shortest_arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) rotating unit vector a onto unit vector b."""
    c = float(np.dot(a, b))
    if c < -1.0 + 1e-12:  # half turn about any axis normal to a
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return np.array([*axis, 0.0])
    q = np.array([*np.cross(a, b), 1.0 + c])
    return q / np.linalg.norm(q)


class _Buffer:
    """One binary buffer with 4-byte aligned views and accessors."""

    def __init__(self, gltf):
        self.g = gltf
        self.chunks: list[bytes] = []
        self.size = 0

    def accessor(self, arr: np.ndarray, type_: str, *, target=None, minmax=False) -> int:
        import pygltflib as G

        data = np.ascontiguousarray(arr)
        raw = data.tobytes()
        pad = (-self.size) % 4
        if pad:
            self.chunks.append(b"\0" * pad)
            self.size += pad
        self.g.bufferViews.append(G.BufferView(buffer=0, byteOffset=self.size,
                                               byteLength=len(raw), target=target))
        self.chunks.append(raw)
        self.size += len(raw)
        comp = {np.dtype(np.uint32): _UINT, np.dtype(np.uint16): _USHORT}.get(data.dtype, _FLOAT)
        count = data.shape[0]
        acc = G.Accessor(bufferView=len(self.g.bufferViews) - 1, componentType=comp, count=count,
                         type=type_)
        if minmax:
            flat = data.reshape(count, -1)
            acc.min = [float(x) for x in flat.min(axis=0)]
            acc.max = [float(x) for x in flat.max(axis=0)]
        self.g.accessors.append(acc)
        return len(self.g.accessors) - 1

    def blob(self) -> bytes:
        return b"".join(self.chunks)


def _trs(part) -> tuple[list, list, list]:
    from scipy.spatial.transform import Rotation

    R = part.matrix[:3, :3]
    q = Rotation.from_matrix(R).as_quat()
    return ([float(x) for x in part.matrix[:3, 3]], [float(x) for x in q],
            [float(x) for x in part.scale])


def _linear(color: str) -> list[float]:
    """glTF base colour (linear RGB, alpha 1) of an sRGB ``"#rrggbb"``."""
    srgb = np.array(rgb(color)) / 255.0
    lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    return [*(float(x) for x in lin), 1.0]


def _tubes(g, buf: _Buffer, scene: Scene, node_ids: list[int]) -> None:
    """The beams as skinned meshes (module docstring), children of the root node."""
    import pygltflib as G

    for tb in scene.tubes:
        used = np.unique(tb.nodes)
        joint = np.searchsorted(used, tb.nodes)  # (V, 2) indices into the skin's joints
        J4 = np.zeros((len(joint), 4), dtype=np.uint16)
        J4[:, :2] = joint
        W4 = np.zeros((len(joint), 4), dtype=np.float32)
        W4[:, 0], W4[:, 1] = 1.0 - tb.weight, tb.weight
        ibm = np.linalg.inv(tb.frames0[used])  # (J, 4, 4), glTF stores columns first
        ibm_acc = buf.accessor(np.ascontiguousarray(ibm.transpose(0, 2, 1)).reshape(-1, 16)
                               .astype(np.float32), "MAT4")
        g.skins.append(G.Skin(name=tb.label, inverseBindMatrices=ibm_acc,
                              joints=[node_ids[i] for i in used]))
        g.materials.append(G.Material(name=f"beam {tb.color}", doubleSided=True,
                                      pbrMetallicRoughness=G.PbrMetallicRoughness(
                                          baseColorFactor=_linear(tb.color),
                                          metallicFactor=0.25, roughnessFactor=0.45)))
        prim = G.Primitive(attributes=G.Attributes(
            POSITION=buf.accessor(tb.bind.astype(np.float32), "VEC3", target=_ARRAY,
                                  minmax=True),
            NORMAL=buf.accessor(tb.bind_normal.astype(np.float32), "VEC3", target=_ARRAY),
            JOINTS_0=buf.accessor(J4, "VEC4", target=_ARRAY),
            WEIGHTS_0=buf.accessor(W4, "VEC4", target=_ARRAY)),
            indices=buf.accessor(tb.faces.reshape(-1).astype(np.uint32), "SCALAR",
                                 target=_ELEMENTS), material=len(g.materials) - 1)
        g.meshes.append(G.Mesh(name=tb.label, primitives=[prim]))
        g.nodes.append(G.Node(name=tb.label, mesh=len(g.meshes) - 1, skin=len(g.skins) - 1))
        g.nodes[0].children.append(len(g.nodes) - 1)


def export_gltf(res, path, *, model=None, model_path=None, mesh_dirs=(), scene: Scene | None =
                None) -> Path:
    """Write the animated glTF 2.0 file of a result (see the module docstring).

    Parameters
    ----------
    res : Results
    path : path
        ``.glb`` (binary) or ``.gltf`` (JSON, buffer embedded).
    model, model_path, mesh_dirs
        As for :func:`se3dyn.viewer.html.write_html`.
    scene : Scene, optional
        A scene built already (default: :func:`~se3dyn.viewer.shapes.build_scene`).

    Returns
    -------
    Path

    Raises
    ------
    ViewerError
        pygltflib or trimesh missing, wrong suffix, unwritable file, bad model or mesh files.
    """
    p = Path(path)
    if p.suffix.lower() not in (".glb", ".gltf"):
        raise ViewerError(f"output: field 'path': expected a file name ending in .glb or .gltf, "
                          f"got {os.fspath(p)!r}")
    try:
        import pygltflib as G
        import trimesh  # noqa: F401  (unit solids)
    except ImportError as e:
        raise ViewerError(f"glTF export needs pygltflib and trimesh ({e.name} is missing): pip "
                          "install 'se3dyn[view]'") from None
    from se3dyn._version import __version__

    if scene is None:
        scene = build_scene(res, model, model_path=model_path, mesh_dirs=mesh_dirs)
    t = np.asarray(res.t, dtype=np.float32)
    if len(t) == 0:
        raise ViewerError("results: field 't': expected at least one stored time, got none")
    H = np.asarray(res.H, dtype=float)
    M = len(scene.node_names)
    g = G.GLTF2(asset=G.Asset(version="2.0", generator=f"se3dyn {__version__}"))
    g.scenes, g.nodes, g.meshes, g.materials = [], [], [], []
    g.accessors, g.bufferViews, g.animations, g.skins = [], [], [], []
    buf = _Buffer(g)

    # materials and meshes: one per (geometry, colour, role)
    geo_cache: dict[str, tuple[int, int, int]] = {}
    mesh_of: dict[tuple, int] = {}
    mat_of: dict[tuple, int] = {}

    def mesh_index(part) -> int:
        key = (part.geometry_key, part.color, part.role)
        if key in mesh_of:
            return mesh_of[key]
        gk = part.geometry_key
        if gk not in geo_cache:
            P, N, idx = unit_solid(part.kind, part.params,
                                   scene.meshes[part.mesh] if part.kind == "mesh" else None)
            geo_cache[gk] = (buf.accessor(P, "VEC3", target=_ARRAY, minmax=True),
                             buf.accessor(N, "VEC3", target=_ARRAY),
                             buf.accessor(idx, "SCALAR", target=_ELEMENTS))
        mk = (part.color, part.role)
        if mk not in mat_of:
            metal, rough = _ROLE_PBR[part.role]
            g.materials.append(G.Material(
                name=f"{part.role} {part.color}",
                pbrMetallicRoughness=G.PbrMetallicRoughness(
                    baseColorFactor=_linear(part.color), metallicFactor=metal,
                    roughnessFactor=rough)))
            mat_of[mk] = len(g.materials) - 1
        pos, nrm, ind = geo_cache[gk]
        g.meshes.append(G.Mesh(name=f"{part.kind} {part.role}", primitives=[G.Primitive(
            attributes=G.Attributes(POSITION=pos, NORMAL=nrm), indices=ind,
            material=mat_of[mk])]))
        mesh_of[key] = len(g.meshes) - 1
        return mesh_of[key]

    # node hierarchy: root (up -> +Y), model nodes, their solids
    g.nodes.append(G.Node(name="se3dyn", rotation=[float(x) for x in _shortest_arc(
        scene.up / np.linalg.norm(scene.up), np.array([0.0, 1.0, 0.0]))], children=[]))
    q = quaternions(H[:, :, :3, :3], continuous=True)  # (n, M, 4)
    node_ids = []
    for i, name in enumerate(scene.node_names):
        gi = len(g.nodes)
        g.nodes.append(G.Node(name=str(name), translation=[float(x) for x in H[0, i, :3, 3]],
                              rotation=[float(x) for x in q[0, i]], children=[],
                              extras={"se3dyn_node": str(name),
                                      "fixed": bool(scene.node_fixed[i])}))
        g.nodes[0].children.append(gi)
        node_ids.append(gi)
    for part in scene.parts:
        tr, rot, sc = _trs(part)
        ci = len(g.nodes)
        g.nodes.append(G.Node(name=part.label, mesh=mesh_index(part), translation=tr,
                              rotation=rot, scale=sc))
        g.nodes[node_ids[part.node]].children.append(ci)
    _tubes(g, buf, scene, node_ids)
    for n_ in g.nodes:  # glTF: no empty children lists
        if n_.children == []:
            n_.children = None
    if not g.skins:
        g.skins = None
    g.scenes.append(G.Scene(name=scene.model_name, nodes=[0]))
    g.scene = 0

    # animation
    moving = [i for i in range(M) if not scene.node_fixed[i]]
    if moving:
        times = buf.accessor(t, "SCALAR", minmax=True)
        anim = G.Animation(name="motion", samplers=[], channels=[])
        for i in moving:
            for path_, data, typ in (("translation", H[:, i, :3, 3], "VEC3"),
                                     ("rotation", q[:, i], "VEC4")):
                out = buf.accessor(np.asarray(data, dtype=np.float32), typ)
                anim.samplers.append(G.AnimationSampler(input=times, output=out,
                                                        interpolation="LINEAR"))
                anim.channels.append(G.AnimationChannel(
                    sampler=len(anim.samplers) - 1,
                    target=G.AnimationChannelTarget(node=node_ids[i], path=path_)))
        g.animations.append(anim)
    blob = buf.blob()
    g.buffers = [G.Buffer(byteLength=len(blob))]
    g.set_binary_blob(blob)
    try:
        if p.suffix.lower() == ".glb":
            g.save_binary(str(p))
        else:
            g.convert_buffers(G.BufferFormat.DATAURI)
            g.save_json(str(p))
    except OSError as e:
        raise ViewerError(f"output: field 'path': expected a writable file, got {os.fspath(p)!r} "
                          f"({e.strerror})") from None
    return p
