"""The same serial chains built twice: in Pinocchio with its own model-building API (the
independent reference: ``pin.Model().addJoint``, ``appendBodyToJoint``, ``pin.Inertia``) and in
se3dyn with ModelBuilder, from one neutral description.

A chain is a list of links; link i has a parent (-1: the world, or the floating base), a joint
type ``"R"`` (revolute) or ``"P"`` (prismatic) with a unit axis in the joint frame, the joint
placement ``(R, p)`` in the parent's joint frame (at q = 0), and a body: mass, centre of mass in
the joint frame, and the inertia about the centre of mass in the joint frame (rotated, full).
Pinocchio's joint frame i moves as ``oMi = oMparent * placement * exp(S q)``; se3dyn's node of
link i sits at the joint frame of q = 0 with the same orientation, the hinge or slider between
the parent's node and it (``H_B = H_A H_J``, Eq. (7)), so its node frame is Pinocchio's oMi.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

import se3dyn as sd

G = 9.81


def _rot(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _body(rng) -> tuple[float, np.ndarray, np.ndarray]:
    m = rng.uniform(0.5, 3.0)
    c = rng.uniform(-0.2, 0.2, 3)
    Rb = _rot(rng)
    I = Rb @ np.diag(rng.uniform(0.04, 0.07, 3)) @ Rb.T  # rotated principal axes
    return m, c, I


def random_chain(types: str, seed: int, floating: bool = False) -> dict:
    """A serial chain of the joint types in ``types`` (e.g. ``"RRRRRR"``, ``"PRR"``), with
    random offsets, axes and rotated inertias; ``floating``: on a free base with a body."""
    rng = np.random.default_rng(seed)
    links = []
    for i, t in enumerate(types):
        ax = rng.normal(size=3)
        links.append(dict(parent=i - 1, type=t, axis=ax / np.linalg.norm(ax), R=_rot(rng),
                          p=rng.uniform(-0.4, 0.4, 3), body=_body(rng)))
    return dict(links=links, base=_body(rng) if floating else None)


def pinocchio_model(chain: dict) -> tuple[pin.Model, list[int]]:
    """The Pinocchio model and the joint id of every link."""
    model = pin.Model()
    model.gravity.linear = np.array([0.0, 0.0, -G])
    parent0 = 0
    if chain["base"] is not None:
        parent0 = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
        m, c, I = chain["base"]
        model.appendBodyToJoint(parent0, pin.Inertia(m, c, I), pin.SE3.Identity())
    ids = []
    for i, lk in enumerate(chain["links"]):
        jm = (pin.JointModelRevoluteUnaligned(*lk["axis"]) if lk["type"] == "R"
              else pin.JointModelPrismaticUnaligned(*lk["axis"]))
        parent = parent0 if lk["parent"] < 0 else ids[lk["parent"]]
        jid = model.addJoint(parent, jm, pin.SE3(lk["R"], lk["p"]), f"j{i}")
        m, c, I = lk["body"]
        model.appendBodyToJoint(jid, pin.Inertia(m, c, I), pin.SE3.Identity())
        ids.append(jid)
    return model, ids


def se3dyn_model(chain: dict, velocities: dict | None = None) -> sd.Model:
    """The same chain with ModelBuilder: nodes at the joint frames of q = 0; ``velocities``:
    node name -> (linear, angular) initial velocity in the inertial frame."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -G), name="chain")
    mb.node("ground", fixed=True)
    world = {-1: np.eye(4)}
    parent_name = {-1: "ground"}
    if chain["base"] is not None:
        m, c, I = chain["base"]
        mb.node("base", mass=m, com=c, inertia=I)
        parent_name[-1] = "base"
    for i, lk in enumerate(chain["links"]):
        P = np.eye(4)
        P[:3, :3], P[:3, 3] = lk["R"], lk["p"]
        W = world[lk["parent"]] @ P
        world[i] = W
        R, x = W[:3, :3], W[:3, 3]
        m, c, I = lk["body"]
        vel = (velocities or {}).get(f"L{i}", (None, None))
        mb.node(f"L{i}", position=x, orientation=R, mass=m, com=x + R @ c,
                inertia=R @ I @ R.T, velocity=vel[0], angular_velocity=vel[1])
        typ = "hinge" if lk["type"] == "R" else "prismatic"
        mb.joint(f"j{i}", typ, parent_name[lk["parent"]], f"L{i}", axis=R @ lk["axis"])
        parent_name[i] = f"L{i}"
    return mb.build()


def random_states(model: pin.Model, n: int, seed: int) -> tuple[np.ndarray, ...]:
    """n random (q, v, a, tau) of a Pinocchio model (unit quaternions for a free base)."""
    rng = np.random.default_rng(seed)
    qs = []
    for _ in range(n):
        q = rng.uniform(-np.pi, np.pi, model.nq)
        if model.nq > model.nv:  # the free flyer: (x, y, z, qx, qy, qz, qw)
            q[:3] = rng.uniform(-1, 1, 3)
            quat = rng.normal(size=4)
            q[3:7] = quat / np.linalg.norm(quat)
        qs.append(q)
    shape = (n, model.nv)
    return (np.array(qs), rng.normal(size=shape), rng.normal(size=shape),
            rng.normal(size=shape))
