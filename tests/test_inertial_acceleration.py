"""node_acceleration(frame="inertial") is the acceleration of the node's origin in the inertial
frame (issue 16, section 5): checked against finite differences of the inertial velocity of a
spinning, translating body and against the centripetal acceleration of a conical pendulum."""

from __future__ import annotations

import math

import numpy as np

import se3dyn as sd


def test_inertial_acceleration_is_the_derivative_of_the_inertial_velocity():
    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("b", position=(0.2, 0.1, 0.0), mass=2.0, inertia=(0.3, 0.5, 0.7),
            velocity=(1.0, -0.5, 2.0), angular_velocity=(3.0, 1.0, -2.0),
            velocity_frame="material")
    res = sd.simulate(mb.build(), t_end=0.5, step=1e-4)
    vi = res.node_velocity("b", frame="inertial")
    ai = res.node_acceleration("b", frame="inertial")
    fd = (vi[2:] - vi[:-2]) / (2e-4)
    np.testing.assert_allclose(ai[1:-1], fd, rtol=0, atol=2e-5 * np.abs(fd).max())
    # a free body's centre of mass falls with g, whatever its spin (node at the centre)
    np.testing.assert_allclose(ai[:, :3], np.broadcast_to([0, 0, -9.81], ai[:, :3].shape),
                               atol=1e-8)


def test_a_conical_pendulum_has_the_centripetal_acceleration():
    # bob on a massless rod of length L from a spherical joint, steady cone of half-angle th:
    # w^2 = g / (L cos th), acceleration towards the axis r w^2 = L sin th w^2
    g, L, th = 9.81, 1.0, 0.5
    w = math.sqrt(g / (L * math.cos(th)))
    r = L * math.sin(th)
    mb = sd.ModelBuilder(gravity=(0, 0, -g))
    mb.node("o", fixed=True)
    mb.node("bob", position=(r, 0, -L * math.cos(th)), mass=1.0, inertia=(1e-6,) * 3,
            velocity=(0, r * w, 0), angular_velocity=(0, 0, w))
    mb.joint("s", "spherical", "o", "bob", at=(0, 0, 0))
    res = sd.simulate(mb.build(), t_end=1.0, step=1e-3)
    p = res.node_position("bob")
    a = res.node_acceleration("bob", frame="inertial")[:, :3]
    radial = -np.c_[p[:, 0], p[:, 1], np.zeros(len(p))]
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    np.testing.assert_allclose(np.einsum("ni,ni->n", a, radial), r * w * w, rtol=1e-4)
    np.testing.assert_allclose(a[:, 2], 0.0, atol=1e-4 * r * w * w)
