"""Bushing: 6 x 6 stiffness and damping on the relative motion of two frames attached to two
nodes.

The frames ``H_a' = H_a X_a`` and ``H_b' = H_b X_b`` coincide at the bushing point ``at`` with
the inertial orientation (or the given ``orientation``) in the initial configuration
(``X = H0^-1 H(I, at)``, the convention of joints with ``at``), unless an initial
``deformation`` d0 is given (``H_b' = H_a' exp(d0)`` at t0). Their relative motion is the twist
``d = log(H_a'^-1 H_b')`` (6,), translation first (inverse of Eq. (17)), in the frame of the
bushing; the elastic energy is ``d^T K d / 2`` and the dissipation function
``d_dot^T D d_dot / 2`` with the rate ``d_dot = T(d)^-1 w`` of the log coordinates (Eqs.
(26)-(27)), ``w`` the relative velocity of the frames. The generalised forces
``T(d)^-T (K d + D d_dot)`` mapped to the two nodes are exactly the gradient of the energy plus
the damping force, objective and energy-consistent.

The logarithm of SE(3) measures screw motions: a finite translation u couples with rotation
(``d_U = T_SO(3)(d_Omega)^-T u``), so that a force off the eigen-directions of ``K_UU`` also
turns the body, by ``K_rot^-1 (u x K u) / 2`` at second order. The relative rotation angle must
stay below pi (principal logarithm).

Kernel ``se3dyn/_core/elements/bushing.hpp`` (exact linearisation in configuration and
velocity).
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie

KEY = "bushing"
TRAITS = dict(conservative=True, constraint=False, objective=True)


def frames(s) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Node indices and attachment frames of the bushings of the compiled system ``s``.

    Returns
    -------
    fa, fb : ndarray (n,) int
        Node (frame) indices of node a and node b.
    Xa, Xb : ndarray (n, 4, 4)
        The attached frames in the material frames of the nodes: ``X_a = H_a0^-1 P`` and
        ``X_b = H_b0^-1 P exp(deformation)`` with ``P = H(orientation, at)``.
    """
    specs = s.model.bushings
    nidx = {name: i for i, name in enumerate(s.node_names)}
    fa = np.array([nidx[b.node_a] for b in specs], np.int64)
    fb = np.array([nidx[b.node_b] for b in specs], np.int64)
    if not specs:
        z = np.zeros((0, 4, 4))
        return fa, fb, z, z.copy()
    P = lie.make_frame(np.array([b.orientation for b in specs], float),
                       np.array([b.at for b in specs], float))
    Xa = lie.compose(lie.inverse(s.node_H0[fa]), P)
    Xb = lie.compose(lie.compose(lie.inverse(s.node_H0[fb]), P),
                     lie.exp_se3(np.array([b.deformation for b in specs], float)))
    return fa, fb, Xa, Xb


def tables(s, lay) -> dict:
    specs = s.model.bushings
    n = len(specs)
    fa, fb, Xa, Xb = frames(s)
    t = dict(fa=fa, fb=fb, Xa=np.ascontiguousarray(Xa, float),
             Xb=np.ascontiguousarray(Xb, float),
             PA=lie.adjoint_inv(Xa) if n else np.zeros((0, 6, 6)),
             PB=lie.adjoint_inv(Xb) if n else np.zeros((0, 6, 6)),
             K=np.array([b.stiffness for b in specs], float).reshape(n, 6, 6),
             D=np.array([b.damping for b in specs], float).reshape(n, 6, 6))
    for key, (p, q) in (("aa", (fa, fa)), ("ab", (fa, fb)), ("ba", (fb, fa)), ("bb", (fb, fb))):
        t["off_" + key] = np.array([lay.frame_block(x, y) for x, y in zip(p, q, strict=True)],
                                   np.int64)
    for a, b in zip(fa, fb, strict=True):
        for x in (a, b):
            for y in (a, b):
                lay.velocity_block(x, y)
    return t


def _spd(rng, scale):
    """A random symmetric positive-definite 6 x 6 matrix."""
    B = rng.normal(size=(6, 6))
    return scale * (B @ B.T / 6 + 0.5 * np.eye(6))


def examples(rng):
    """Bushings with full symmetric positive-definite K and D between two moving bodies (at a
    point away from both nodes, one node turned), diagonal values to the ground, and K alone
    with turned axes and an initial deformation."""
    from se3dyn.model.builder import ModelBuilder

    mb = ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("a", position=(0.5, 0.0, 0.0), mass=1.0, inertia=(1, 1.2, 1.4),
            velocity=tuple(rng.normal(size=3)), angular_velocity=tuple(rng.normal(size=3)))
    mb.node("b", position=(1.0, 0.3, 0.2), mass=2.0, inertia=(1, 1.1, 1.3),
            orientation=lie.exp_so3(rng.normal(size=3)))
    mb.bushing("b1", "a", "b", at=tuple(rng.normal(size=3)), stiffness=_spd(rng, 3.0),
               damping=_spd(rng, 0.5))
    mb.bushing("b2", "g", "a", stiffness=(1.0, 2.0, 3.0, 0.5, 0.6, 0.7),
               damping=(0.1, 0.2, 0.3, 0.05, 0.06, 0.07))
    mb.bushing("b3", "b", "g", at=(0.2, -0.4, 0.9), stiffness=_spd(rng, 2.0),
               orientation=lie.exp_so3(rng.normal(size=3)),
               deformation=tuple(0.3 * rng.normal(size=6)))
    return [mb.build()]


def model_file(mf):
    """The ``bushings:`` section of model files (:class:`se3dyn.io.modelfile.ElementSection`);
    ``mf`` is :mod:`se3dyn.io.modelfile` (its field types)."""
    F = mf.Field
    kd = mf.OneOf((mf.Num(minimum=0), mf.Vec(6), mf.Mat(6, 6, 6)))
    fields = (
        F("a", mf.Str(ref="node"), None, "Node A (required).", True),
        F("b", mf.Str(ref="node"), None, "Node B (required).", True),
        F("at", mf.Vec(3), "position of b", "The bushing point in the inertial frame of the "
          "initial configuration (m): the frames attached to `a` and `b` are there, with the "
          "inertial orientation (or `orientation`), at t0."),
        F("stiffness", kd, None, "K on d = log(H_a'^-1 H_b') (translation first, in the "
          "bushing axes: the inertial axes at t0 by default): 6 diagonal values (kx, ky, kz "
          "in N/m, krx, kry, krz in N m/rad), one number for all six, or a symmetric positive "
          "semi-definite 6 x 6 matrix (list of rows) (required).", True),
        F("damping", kd, 0, "D on the rate of d (Eq. 27), same forms (N s/m, N m s/rad)."),
        F("orientation", mf.Mat(3, 3, 3), "identity", "Rotation of the bushing frame at t0 "
          "(rows of the matrix; its columns are the bushing axes, in which K and D are "
          "given, in the inertial frame)."),
        F("deformation", mf.Vec(6), [0, 0, 0, 0, 0, 0], "Relative motion d at t0 (a "
          "preloaded bushing), translation first, in the bushing axes: the frame attached to "
          "`b` starts at H(orientation, at) exp(deformation)."),
    )

    def six(K):
        return mf.plain(np.diag(K)) if np.array_equal(K, np.diag(np.diag(K))) else mf.plain(K)

    def save(model) -> dict:
        out = {}
        for b in model.bushings:
            d = {"a": b.node_a, "b": b.node_b, "at": mf.plain(b.at),
                 "stiffness": six(b.stiffness)}
            if np.any(b.damping != 0):
                d["damping"] = six(b.damping)
            if not np.array_equal(b.orientation, np.eye(3)):
                d["orientation"] = mf.plain(b.orientation)
            if np.any(b.deformation != 0):
                d["deformation"] = mf.plain(b.deformation)
            out[b.name] = d
        return out

    return mf.ElementSection(
        key="bushings", kind="bushing",
        doc="Bushings (6 x 6 stiffness and damping between two nodes) by name.",
        entry_doc="An entry of `bushings:` (key: the name). Stiffness K and damping D on the "
                  "relative motion d = log(H_a'^-1 H_b') (6 numbers, translation first) of two "
                  "frames attached to nodes `a` and `b` at the point `at`: energy d^T K d / 2, "
                  "forces T(d)^-T (K d + D d_dot) (Eqs. 26-27). The relative rotation must "
                  "stay below pi.",
        fields=fields,
        add=lambda mb, name, kw: mb.bushing(name, kw.pop("a"), kw.pop("b"), **kw), save=save)
