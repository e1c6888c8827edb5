"""Sampled PID laws reading sensors (``sd.PID(..., sample_time=T, sensor=channel)``, issue 30
item 3): a marker's position, the distance of two markers, another joint's coordinate,
evaluated by the compiled kernel at the sample times.

References are independent of se3dyn's numbers: the same law on the joint's own coordinate
(the sensor being that coordinate, or a fixed offset of it), the equilibria that integral
action must reach (closed forms: Hooke's law in series, the law of cosines), and the measured
order of convergence.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.errors import ModelError, Se3dynWarning
from se3dyn.io.modelfile import load_model, save_model

TS = 0.01


def _run(model, t_end, h, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Se3dynWarning)
        return sd.simulate(model, t_end, h, **kw)


def _cart(sensor=None, target=0.3, x0=0.1, marker=(0.2, 0.1, 0.0)):
    """A cart on a prismatic joint along x under a sampled PID law."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("cart", (x0, 0, 0), mass=2.0, inertia=(0.1, 0.1, 0.1))
    mb.marker("tip", "cart", offset=marker)
    mb.joint("rail", "prismatic", "g", "cart", axis=(1, 0, 0), damping=0.5,
             control=sd.PID(40.0, 25.0, 3.0, target=target, limit=6.0, sample_time=TS,
                            sensor=sensor))
    return mb.build()


@pytest.mark.parametrize("formulation", ["index2", "index3"])
def test_a_law_reading_its_own_coordinate_as_a_sensor_is_the_plain_law_bit_for_bit(
        formulation):
    a = _run(_cart(), 0.5, TS / 4, formulation=formulation)
    b = _run(_cart("joint/rail/alpha/0"), 0.5, TS / 4, formulation=formulation)
    assert np.array_equal(a.H, b.H) and np.array_equal(a.lam, b.lam)
    assert np.array_equal(a.stats["final_state"].ctrl, b.stats["final_state"].ctrl)


def test_a_marker_position_law_is_the_coordinate_law_with_the_marker_offset():
    # x_tip = x0 + alpha + 0.2: reading it with target T is the coordinate law with target
    # T - x0 - 0.2 (the same motion up to round-off)
    a = _run(_cart("marker/tip/position/x", target=0.6), 1.0, TS / 2)
    b = _run(_cart(None, target=0.6 - 0.1 - 0.2), 1.0, TS / 2)
    np.testing.assert_allclose(a.joint_coordinates("rail"), b.joint_coordinates("rail"),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.marker_position("tip")[:, 0],
                               0.3 + a.joint_coordinates("rail")[:, 0], rtol=0, atol=1e-14)


def _two_carts(k1=50.0, k2=80.0, sensor="marker/m2/position/x", target=1.25):
    """Cart 1 pushed by a sampled PID law that reads cart 2's position; cart 2 is held to the
    ground by a spring k2 and pulled by cart 1 through a spring-damper k1 of rest length 0.5."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("c1", (0.5, 0, 0), mass=1.0, inertia=(0.1, 0.1, 0.1))
    mb.node("c2", (1.0, 0, 0), mass=0.5, inertia=(0.1, 0.1, 0.1))
    mb.marker("m2", "c2")
    mb.joint("r1", "prismatic", "g", "c1", axis=(1, 0, 0), damping=2.0,
             control=sd.PID(100.0, 400.0, 8.0, target=target, limit=50.0, sample_time=TS,
                            sensor=sensor))
    mb.joint("r2", "prismatic", "g", "c2", axis=(1, 0, 0), stiffness=k2, damping=1.0)
    mb.spring_damper("s", "c1", "c2", stiffness=k1, damping=3.0, length=0.5)
    return mb.build()


def test_integral_action_on_a_remote_sensor_reaches_the_series_spring_equilibrium():
    # at rest cart 2 sits at the target (x2 = 1.25, alpha2 = 0.25) whatever the springs: the
    # law's force is k2 alpha2 (the springs in series carry it), cart 1 at
    # x2 - 0.5 + k2 alpha2 / k1 (the coupling spring compressed by it)
    k1, k2 = 50.0, 80.0
    res = _run(_two_carts(k1, k2), 10.0, TS / 2)
    x2 = res.marker_position("m2")[-1, 0]
    a1 = res.joint_coordinates("r1")[-1, 0]
    assert abs(x2 - 1.25) < 1e-8
    assert abs((0.5 + a1) - (1.25 - 0.5 + k2 * 0.25 / k1)) < 1e-8
    np.testing.assert_allclose(res.actuator_effort("r1")[-1, 0], k2 * 0.25, rtol=1e-7)


def _arm_to_distance(distance=0.9, h=TS / 2, t_end=8.0):
    """A hinge arm (tip marker at 1 m) turned by a sampled PID law until the tip is at the
    given distance from a ground marker at (1, 1, 0)."""
    mb = sd.ModelBuilder()
    mb.node("g", fixed=True)
    mb.node("arm", (0.5, 0, 0), mass=1.0, inertia=(0.01, 0.1, 0.1))
    mb.marker("tip", "arm", at=(1.0, 0, 0))
    mb.marker("post", "g", at=(1.0, 1.0, 0))
    mb.joint("pin", "hinge", "g", "arm", axis=(0, 0, 1), at=(0, 0, 0), damping=0.2,
             control=sd.PID(15.0, 30.0, 3.0, target=distance, limit=5.0, sample_time=TS,
                            sensor="marker/tip/distance/post", gear=-1.0))
    return _run(mb.build(), t_end, h)


def test_a_distance_law_settles_where_the_law_of_cosines_puts_the_tip():
    # |tip - post|^2 = 1 + 2 - 2 sqrt(2) cos(theta - pi/4) = d^2 (tip (cos, sin), post (1, 1))
    d = 0.9
    res = _arm_to_distance(d)
    theta = res.joint_coordinates("pin")[-1, 0]
    closed = math.pi / 4 - math.acos((3.0 - d * d) / (2.0 * math.sqrt(2.0)))
    assert abs(theta - closed) < 1e-8, (theta, closed)
    assert abs(res.marker_distance("tip", "post")[-1] - d) < 1e-8


def test_a_sensor_law_converges_at_order_2_between_samples():
    ref = _arm_to_distance(h=TS / 64, t_end=1.0).joint_coordinates("pin")[::64, 0]
    errs = [np.abs(_arm_to_distance(h=TS / m, t_end=1.0).joint_coordinates("pin")[::m, 0]
                   - ref).max() for m in (2, 4, 8)]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.9), (errs, orders)


def test_a_sensor_on_a_condensed_node_reads_the_same_point():
    # the marker's node welded to the cart (condensed into it in the time loop): the tip is at
    # x = 0.5 + alpha, so reading it with target 0.9 is the coordinate law with target 0.4,
    # condensed or not
    def model(sensor, target):
        mb = sd.ModelBuilder()
        mb.node("g", fixed=True)
        mb.node("cart", (0.1, 0, 0), mass=2.0, inertia=(0.1, 0.1, 0.1))
        mb.node("plate", (0.4, 0.2, 0), mass=0.5, inertia=(0.01, 0.01, 0.01))
        mb.joint("weld", "rigid", "cart", "plate")
        mb.marker("tip", "plate", offset=(0.1, 0, 0))
        mb.joint("rail", "prismatic", "g", "cart", axis=(1, 0, 0),
                 control=sd.PID(40.0, 25.0, 3.0, target=target, sample_time=TS,
                                sensor=sensor))
        return mb.build()
    for condense in (True, False):
        a = _run(model("marker/tip/position/x", 0.9), 1.0, TS / 2, condense=condense)
        b = _run(model(None, 0.4), 1.0, TS / 2, condense=condense)
        np.testing.assert_allclose(a.joint_coordinates("rail"), b.joint_coordinates("rail"),
                                   rtol=0, atol=1e-12)


def test_sensor_laws_in_model_files():
    model = _two_carts()
    text = save_model(model)
    assert "sensor:" in text and "marker/m2/position/x" in text
    back, _ = load_model(text)
    a, b = _run(model, 0.2, TS), _run(back, 0.2, TS)
    assert np.array_equal(a.H, b.H)


@pytest.mark.parametrize("law, field, match", [
    (dict(sensor="marker/tip/position/x"), "sensor", "sampled law"),
    (dict(sensor="marker/tip/speed/x", sample_time=TS), "sensor", "a sensor channel"),
    (dict(sensor=3, sample_time=TS), "sensor", "a sensor channel"),
])
def test_bad_sensor_laws_are_refused(law, field, match):
    with pytest.raises(ModelError, match=f"field '{field}'.*{match}"):
        sd.PID(1.0, **law)


@pytest.mark.parametrize("sensor, match", [
    ("marker/nope/position/x", "a marker of the model.*the model's markers: tip"),
    ("marker/tip/distance/tip", "two different markers"),
    ("joint/rail/alpha/1", "below 1"),
    ("joint/axle/alpha/0", "a joint of the model"),
    (["joint/rail/alpha/0", "marker/tip/position/x"], "1 sensor channel"),
])
def test_sensors_the_model_lacks_are_named(sensor, match):
    with pytest.raises(ModelError, match="joint 'rail'.*control.sensor.*" + match):
        _cart(sensor)


def test_statics_says_it_does_not_hold_a_sensor_law():
    with pytest.raises(ModelError, match="static_equilibrium.*reading a sensor"):
        sd.static_equilibrium(_two_carts())
