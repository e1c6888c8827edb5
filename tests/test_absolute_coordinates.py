"""Absolute joint coordinates (issue 16, section 1): ``initial=`` gives the values of an abelian
joint's relative coordinates in the initial configuration, so coordinates, spring references
and PD targets are absolute (no angle offset by hand)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.errors import ModelError

L, M, K = 0.8, 1.5, 6.0


def _pendulum(theta0, *, initial=None, reference=0.0, gravity=9.81, control=None):
    """A point-like bob on a hinge about y at the origin, at the angle theta0 from the -z
    axis (towards +x): x = L sin(theta), z = -L cos(theta)."""
    mb = sd.ModelBuilder(gravity=(0, 0, -gravity))
    mb.node("g", fixed=True)
    mb.node("bob", position=(L * math.sin(theta0), 0, -L * math.cos(theta0)), mass=M,
            inertia=(1e-4, 1e-4, 1e-4))
    # the hinge axis is -y, so that the positive angle turns -z towards +x
    mb.joint("h", "hinge", "g", "bob", axis=(0, -1, 0), at=(0, 0, 0), stiffness=K,
             reference=reference, initial=initial, control=control)
    return mb.build()


def _angle(res):
    p = res.node_position("bob")
    return np.arctan2(p[:, 0], -p[:, 2])


def test_coordinates_and_spring_references_are_absolute_with_initial():
    th0 = 0.6
    absolute = sd.simulate(_pendulum(th0, initial=th0, reference=0.2), t_end=2.0, step=1e-3)
    # the same physics written with relative coordinates: reference shifted by hand
    relative = sd.simulate(_pendulum(th0, reference=0.2 - th0), t_end=2.0, step=1e-3)
    a_abs = absolute.joint_coordinates("h")[:, 0]
    a_rel = relative.joint_coordinates("h")[:, 0]
    assert a_abs[0] == th0 and a_rel[0] == 0.0
    np.testing.assert_allclose(a_abs, a_rel + th0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(absolute.node_position("bob"), relative.node_position("bob"),
                               rtol=0, atol=1e-10)
    # the absolute coordinate is the geometric angle of the bob (unwrapped: |theta| < pi here)
    np.testing.assert_allclose(a_abs, _angle(absolute), rtol=0, atol=1e-9)
    # the spring energy is K/2 (alpha - reference)^2 in absolute terms
    assert absolute.spring[0] == pytest.approx(0.5 * K * (th0 - 0.2) ** 2, rel=1e-12)


def test_static_equilibrium_sits_at_the_absolute_spring_reference():
    th0, ref = 0.9, -0.3
    eq = sd.static_equilibrium(_pendulum(th0, initial=th0, reference=ref, gravity=0.0))
    p = eq.node_position("bob") if hasattr(eq, "node_position") else None
    H = eq.H[list(eq.system.node_names).index("bob")] if p is None else None
    x, z = (p[0], p[2]) if p is not None else (H[0, 3], H[2, 3])
    assert math.atan2(x, -z) == pytest.approx(ref, abs=1e-9)


def test_pd_targets_are_absolute():
    th0, target = 0.4, 1.1
    res = sd.simulate(_pendulum(th0, initial=th0, gravity=0.0,
                                control=sd.PD(kp=40.0, kd=12.0, target=target)),
                      t_end=6.0, step=2e-3)
    # the PD law and the spring (reference 0) balance at kp (a - T) + K a = 0
    a_eq = 40.0 * target / (40.0 + K)
    assert _angle(res)[-1] == pytest.approx(a_eq, abs=1e-6)
    assert res.joint_coordinates("h")[-1, 0] == pytest.approx(a_eq, abs=1e-6)


def test_initial_values_need_an_abelian_joint_and_round_trip_through_model_files():
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("b", position=(0, 0, -1), mass=1.0, inertia=(0.1, 0.1, 0.1))
    with pytest.raises(ModelError, match="joint 's'.*initial"):
        mb.joint("s", "spherical", "g", "b", initial=(0.1, 0.2, 0.3))
    from se3dyn.io.modelfile import loads_model, save_model

    m = _pendulum(0.6, initial=0.6, reference=0.2)
    m2, _ = loads_model(save_model(m))
    assert np.array_equal(m2.joint("h").initial, [0.6])
    r1, r2 = (sd.simulate(x, t_end=0.2, step=1e-3) for x in (m, m2))
    assert np.array_equal(r1.joint_coordinates("h"), r2.joint_coordinates("h"))
