"""Geometrically exact two-node beam element on SE(3), after V. Sonneville, A. Cardona and
O. Bruls, "Geometrically exact beam finite element formulated on the special Euclidean group
SE(3)", Comput. Methods Appl. Mech. Engrg. 268 (2014) 451-474, doi:10.1016/j.cma.2013.10.008.

An element joins the section frames ``H_A X_A`` and ``H_B X_B`` of two nodes (``X`` constant,
the identity for the nodes a beam creates). Its deformation measure is the relative motion

    d = log(X_A^-1 H_A^-1 H_B X_B) in se(3),   eps = (d - d0) / L,

(``d0`` the same in the reference configuration, ``L = |d0_U|`` the reference length), constant
along the element: the element interpolates the beam by the screw motion ``H_A exp(s d / L)``
and is exact for constant strain (any constant curvature and twist, below a relative rotation
of pi per element). The section law ``f = K eps + D deps/dt`` with ``K = diag(EA, GA2, GA3, GJ,
EI2, EI3)`` (translation first, as the paper orders twists) gives the elastic energy
``L/2 eps^T K eps`` and the internal forces through the derivative of log, ``delta d = T^-1(d)
delta h_r`` (``T`` the tangent operator of Eqs. (21)-(22) of the multibody paper,
``delta h = T(n) delta n``, its Eqs. (20), (23), (26)):

    g_B = Ad(X_B^-1)^T T^-T(d) f,    g_A = -Ad(X_A^-1)^T Ad(H_r^-1)^T T^-T(d) f.

Mass: lumped, half of each element's mass and rotary inertia on each of its nodes (added to
the nodes' rigid-body inertia by :func:`se3dyn.engine.system.compile_model`; the body element then
gives the exact inertia forces, Eq. (51), and their tangent, Eq. (53)).

Kernel ``se3dyn/_core/elements/beam.hpp`` (exact linearisation in configuration and velocity).
:func:`section_forces` evaluates strains, section forces and energies from node frames.
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie

KEY = "beam"
TRAITS = dict(conservative=True, constraint=False, objective=True)

__all__ = ["KEY", "TRAITS", "tables", "examples", "section_forces", "arc_frames"]


def tables(s, lay) -> dict:
    bs = s.beams
    n = len(bs)
    fa = np.array([b["a"] for b in bs], np.int64)
    fb = np.array([b["b"] for b in bs], np.int64)
    XA = np.array([b["XA"] for b in bs], float).reshape(n, 4, 4)
    XB = np.array([b["XB"] for b in bs], float).reshape(n, 4, 4)
    t = dict(fa=fa, fb=fb, XAinv=lie.inverse(XA) if n else XA, XB=XB,
             AdA=lie.adjoint_inv(XA) if n else np.zeros((0, 6, 6)),
             AdB=lie.adjoint_inv(XB) if n else np.zeros((0, 6, 6)),
             d0=np.array([b["d0"] for b in bs], float).reshape(n, 6),
             L=np.array([b["L"] for b in bs], float),
             K=np.array([b["K"] for b in bs], float).reshape(n, 6, 6),
             D=np.array([b["D"] for b in bs], float).reshape(n, 6, 6),
             damped=np.array([int(np.any(b["D"] != 0)) for b in bs], np.int64))
    for key, (p, q) in (("aa", (fa, fa)), ("ab", (fa, fb)), ("ba", (fb, fa)), ("bb", (fb, fb))):
        t["off_" + key] = np.array([lay.frame_block(x, y) for x, y in zip(p, q, strict=True)],
                                   np.int64)
    for e in range(n):
        if t["damped"][e]:
            for x in (fa[e], fb[e]):
                for y in (fa[e], fb[e]):
                    lay.velocity_block(x, y)
    return t


def section_forces(s, H: np.ndarray, v: np.ndarray | None = None,
                   vq: np.ndarray | None = None) -> dict:
    """Strains, section forces and energies of every beam element of a compiled system.

    Parameters
    ----------
    s : System
    H : ndarray, shape (M, 4, 4) or (nt, M, 4, 4)
        Node frames (e.g. ``StaticResult.H``, or ``Results.H`` over time).
    v : ndarray, shape (M, 6) or (nt, M, 6), optional
        Material node velocities, for the strain rates and the damping forces.
    vq : ndarray, shape (nq,) or (nt, nq), optional
        Instead of ``v``: the velocities of the unknowns (``Results.v``).

    Returns
    -------
    dict
        ``beam`` (E,) beam name and ``index`` (E,) element index in it, ``L`` (E,) reference
        lengths, ``strain`` (..., E, 6) ``eps - eps0`` (axial and shear strains, torsion and
        curvatures relative to the reference; section frame), ``strain_rate`` (..., E, 6),
        ``force`` (..., E, 6) section forces ``f = K eps + D deps/dt`` (N: axial, shear 2,
        shear 3; N m: torsion, bending 2, bending 3), ``energy`` (..., E) elastic energy
        ``L/2 eps^T K eps`` (J).
    """
    H = np.asarray(H, float)
    bs = s.beams
    n = len(bs)
    a = np.array([b["a"] for b in bs], np.int64)
    b_ = np.array([b["b"] for b in bs], np.int64)
    XA = np.array([b["XA"] for b in bs], float).reshape(n, 4, 4)
    XB = np.array([b["XB"] for b in bs], float).reshape(n, 4, 4)
    L = np.array([b["L"] for b in bs], float)
    K = np.array([b["K"] for b in bs], float).reshape(n, 6, 6)
    D = np.array([b["D"] for b in bs], float).reshape(n, 6, 6)
    d0 = np.array([b["d0"] for b in bs], float).reshape(n, 6)
    Hr = lie.inverse(XA) @ lie.inverse(H[..., a, :, :]) @ H[..., b_, :, :] @ XB
    d = lie.log_se3(Hr)
    eps = (d - d0) / L[:, None]
    rate = np.zeros_like(eps)
    if vq is not None:
        vq = np.asarray(vq, float)
        v = np.zeros(vq.shape[:-1] + (s.M, 6))
        for i in np.flatnonzero(~s.node_fixed):
            v[..., i, :] = vq[..., s.node_dofadr[i]:s.node_dofadr[i] + 6]
    if v is not None:
        v = np.asarray(v, float)
        vA = np.einsum("eij,...ej->...ei", lie.adjoint_inv(XA), v[..., a, :])
        vB = np.einsum("eij,...ej->...ei", lie.adjoint_inv(XB), v[..., b_, :])
        vr = vB - np.einsum("...ij,...j->...i", lie.adjoint_inv(Hr), vA)
        rate = np.einsum("...ij,...j->...i", lie.tangent_se3_inv(d), vr) / L[:, None]
    f = np.einsum("eij,...ej->...ei", K, eps) + np.einsum("eij,...ej->...ei", D, rate)
    energy = 0.5 * L * np.einsum("...ei,eij,...ej->...e", eps, K, eps)
    return dict(beam=np.array([b["beam"] for b in bs]), index=np.array([b["index"] for b in bs]),
                L=L, strain=eps, strain_rate=rate, force=f, energy=energy)


def arc_frames(start, center, axis, angle: float, n: int) -> np.ndarray:
    """Section frames of a circular arc, for ``ModelBuilder.beam(..., frames=...)``.

    Parameters
    ----------
    start, center : array_like (3,)
        First point of the arc and centre of its circle (inertial frame).
    axis : array_like (3,)
        Axis of the circle (normal to the plane of the arc); the arc turns positively about it.
    angle : float
        Angle of the arc (rad), ``0 < |angle| < 2 pi``.
    n : int
        Number of elements.

    Returns
    -------
    ndarray, shape (n + 1, 4, 4)
        Frames at equal angles: axis 1 along the tangent, axis 2 towards the centre, axis 3
        along ``axis``.
    """
    x0, c = np.asarray(start, float), np.asarray(center, float)
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    r0 = c - x0
    r0 = r0 - (r0 @ a) * a
    nrm = r0 / np.linalg.norm(r0)
    R0 = np.column_stack([np.cross(nrm, a), nrm, a])
    out = []
    for phi in np.linspace(0.0, angle, n + 1):
        Q = lie.exp_so3(phi * a)
        out.append(lie.make_frame(Q @ R0, c + Q @ (x0 - c)))
    return np.array(out)


def examples(rng):
    """A straight free-flying beam with mass, damping and an anisotropic section; a pre-curved
    and pre-twisted beam (frames along a helix) from a fixed node to a node whose own frame is
    not the section frame, with damping proportional to the stiffness; a damped beam on a hinge
    with a body on a spherical joint at an inner node (beam and joints together, index 2)."""
    from se3dyn.model.builder import ModelBuilder

    out = []
    mb = ModelBuilder()
    mb.node("a", position=(0.0, 0.0, 0.0), mass=0.3, inertia=(0.01, 0.012, 0.014),
            velocity=tuple(rng.normal(size=3)), angular_velocity=tuple(rng.normal(size=3)))
    mb.node("b", position=(1.2, 0.3, -0.2), mass=0.2, inertia=(0.01, 0.01, 0.01))
    mb.beam("s", "a", "b", elements=2, EA=5.0, GA=(2.0, 3.0), GJ=0.7, EI=(0.9, 1.3),
            mass_per_length=0.5, rotary_inertia=(0.02, 0.01, 0.012),
            damping=tuple(rng.uniform(0.05, 0.3, 6)), axis2=(0.1, 1.0, 0.3))
    out.append(mb.build())

    mb = ModelBuilder()
    n = 3
    s_ = np.linspace(0.0, 1.0, n + 1)
    frames = []
    for si in s_:  # helix: radius 0.5, pitch 0.4 per turn, quarter turn, twisted sections
        th = 0.5 * np.pi * si
        x = np.array([0.5 * np.sin(th), 0.5 * (1 - np.cos(th)), 0.4 * th / (2 * np.pi)])
        t = np.array([0.5 * np.cos(th), 0.5 * np.sin(th), 0.4 / (2 * np.pi)])
        t /= np.linalg.norm(t)
        nrm = np.array([-np.sin(th), np.cos(th), 0.0])
        nrm -= (nrm @ t) * t
        nrm /= np.linalg.norm(nrm)
        R = np.column_stack([t, nrm, np.cross(t, nrm)]) @ lie.exp_so3(np.array([0.6 * si, 0, 0]))
        frames.append(lie.make_frame(R, x))
    frames = np.array(frames)
    mb.node("g", position=frames[0, :3, 3], fixed=True)
    mb.node("tip", position=frames[-1, :3, 3], orientation=lie.exp_so3(rng.normal(size=3)),
            mass=0.4, inertia=(0.02, 0.03, 0.04))
    mb.beam("h", "g", "tip", EA=4.0, GA=3.0, GJ=0.5, EI=(0.8, 0.6), damping=0.05,
            frames=frames, mass_per_length=0.2, rotary_inertia=(0.004, 0.002, 0.002))
    out.append(mb.build())

    # a damped beam hanging from a hinge, a spherical joint on one of its inner nodes: the
    # velocity-level blocks of the beam enter the index-2 products with the joints
    mb = ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("a", position=(0.0, 0.0, 0.0))
    mb.node("b", position=(0.0, 0.2, -1.0))
    mb.joint("hinge", "hinge", "g", "a", axis=(1.0, 0.0, 0.0))
    mb.beam("p", "a", "b", elements=3, EA=6.0, GA=(4.0, 5.0), GJ=0.4, EI=(0.5, 0.7),
            mass_per_length=0.3, rotary_inertia=(0.003, 0.0015, 0.0015),
            damping=0.02, initial_velocity="rigid")
    mb.node("c", position=(0.3, 0.1, -0.5), mass=0.2, inertia=(0.01, 0.01, 0.01))
    mb.joint("ball", "spherical", "p/1", "c")
    out.append(mb.build())
    return out


def model_file(mf):
    """The ``beams:`` section of model files (:class:`se3dyn.io.modelfile.ElementSection`); ``mf``
    is :mod:`se3dyn.io.modelfile` (its field types). A saved beam is written with ``elements`` and
    ``axis2`` when these rebuild its reference frames exactly, else with its ``frames``; its
    intermediate nodes are not written (the beam creates them)."""
    F = mf.Field
    pair = mf.OneOf((mf.Num(exclusive_minimum=0), mf.Vec(2)))
    fields = (
        F("a", mf.Str(ref="node"), None, "End node A (required).", True),
        F("b", mf.Str(ref="node"), None, "End node B (required).", True),
        F("elements", mf.Num(integer=True, minimum=1), 1, "Number of two-node elements; the "
          "beam creates the intermediate nodes `<name>/1` ... `<name>/<n-1>` (joints, springs "
          "and loads may use them)."),
        F("EA", mf.Num(exclusive_minimum=0), None, "Axial stiffness (N) (required).",
          True),
        F("GA", pair, None, "Shear stiffness along section axes 2 and 3 (N): one number or a "
          "pair (required).", True),
        F("GJ", mf.Num(exclusive_minimum=0), None, "Torsional stiffness (N m^2) "
          "(required).", True),
        F("EI", pair, None, "Bending stiffness about section axes 2 and 3 (N m^2): one number "
          "or a pair (required).", True),
        F("mass_per_length", mf.Num(minimum=0), 0, "Mass per unit length (kg/m), lumped on "
          "the nodes with the rotary inertia."),
        F("rotary_inertia", mf.Vec(3), None, "Rotary inertia of the section per unit length "
          "about axes 1, 2, 3 (kg m); required with a mass."),
        F("damping", mf.OneOf((mf.Num(minimum=0), mf.Vec(6))), 0, "Damping on the strain "
          "rates: a number beta (s) for D = beta K, or the 6 diagonal values of D."),
        F("axis2", mf.Vec(3), "z x axis 1", "Straight beam: direction of section axis 2."),
        F("frames", mf.MatList(4, 4), None, "Curved or pre-twisted beam: the stress-free "
          "section frames from node A to node B (4 x 4, inertial frame, axis 1 along the "
          "beam; n + 1 of them for n elements), instead of `elements` and `axis2`."),
        F("initial_velocity", mf.Str(("rest", "rigid")), "rest", "Intermediate nodes at rest, "
          "or moving rigidly with node A."),
    )

    def one_or_pair(a, b):
        return float(a) if a == b else [float(a), float(b)]

    def straight_kw(model, b):
        """elements and axis2 when they rebuild b's reference frames exactly, else None."""
        from se3dyn.model.builder import ModelBuilder

        ends = [model.node(b.nodes[0]), model.node(b.nodes[-1])]
        mb = ModelBuilder()
        for nd in ends:
            mb.node(nd.name, position=nd.position, orientation=nd.orientation, fixed=True)
        kw = dict(elements=b.elements, axis2=b.reference[0, :3, 1])
        try:
            mb.beam(b.name, ends[0].name, ends[1].name, EA=1.0, GA=1.0, GJ=1.0, EI=1.0, **kw)
        except Exception:  # noqa: BLE001 (not a straight beam)
            return None
        ref = mb._beams[b.name].reference
        return kw if np.array_equal(ref, b.reference) else None

    def save(model) -> dict:
        out = {}
        for b in model.beams:
            K = np.diag(b.stiffness)
            d = {"a": b.nodes[0], "b": b.nodes[-1]}
            kw = straight_kw(model, b)
            if kw is None:
                d["frames"] = mf.plain(b.reference)
            else:
                if kw["elements"] != 1:
                    d["elements"] = kw["elements"]
                d["axis2"] = mf.plain(kw["axis2"])
            d.update(EA=float(K[0]), GA=one_or_pair(K[1], K[2]), GJ=float(K[3]),
                     EI=one_or_pair(K[4], K[5]))
            if b.mass_per_length:
                d["mass_per_length"] = float(b.mass_per_length)
                d["rotary_inertia"] = mf.plain(b.rotary_inertia)
            D = np.diag(b.damping)
            if np.any(D != 0):
                d["damping"] = mf.plain(D)
            inner = [model.node(nd) for nd in b.nodes[1:-1]]
            if any(np.any(nd.velocity != 0) for nd in inner):
                d["initial_velocity"] = "rigid"
            out[b.name] = d
        return out

    def add(mb, name, kw):
        mb.beam(name, kw.pop("a"), kw.pop("b"), **kw)

    return mf.ElementSection(
        key="beams", kind="beam",
        doc="Geometrically exact beams (chains of SE(3) beam elements between two nodes) by "
            "name.",
        entry_doc="An entry of `beams:` (key: the name). A beam from node `a` to node `b` "
                  "meshed into `elements` two-node elements on SE(3) (Sonneville, Cardona & "
                  "Brüls 2014): strains from the relative motion of consecutive nodes, section "
                  "law diag(EA, GA2, GA3, GJ, EI2, EI3), lumped mass (docs/beams.md).",
        fields=fields, add=add, save=save,
        nodes=lambda model: {nd for b in model.beams for nd in b.nodes[1:-1]})
