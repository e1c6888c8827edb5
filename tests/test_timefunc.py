"""Vectorised sampling of time functions (TimeFunction.sample / sample_rate), used to tabulate
the loads of every step of a fixed-step run: the same numbers as evaluating f(t) one time at
a time, for every built-in, scalar and vector valued, across the switching times."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import se3dyn as sd
from se3dyn.errors import SimulationError
from se3dyn.model import timefunc as tf

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
value = st.one_of(finite, st.lists(finite, min_size=2, max_size=3))


def _one_by_one(f, times, rate=False):
    g = f.rate if rate else f
    return np.array([np.asarray(g(t), dtype=float) for t in times])


def _check(f, times):
    for rate in (False, True):
        many = (f.sample_rate if rate else f.sample)(times)
        ref = _one_by_one(f, times, rate)
        assert many.shape == ref.shape
        # bit for bit, signed zeros included
        assert np.array_equal(many, ref) and np.array_equal(np.signbit(many), np.signbit(ref))


@st.composite
def grids(draw):
    t0 = draw(st.floats(-2.0, 2.0))
    h = draw(st.floats(1e-4, 0.5))
    n = draw(st.integers(1, 60))
    return t0 + h * np.arange(1, n + 1)


@settings(max_examples=60, deadline=None)
@given(v=value, start=st.floats(-1.0, 1.0), length=st.floats(1e-3, 2.0), times=grids())
def test_builtins_sample_like_scalar_calls(v, start, length, times):
    for f in (tf.Constant(v), tf.Step(v, start=start, stop=start + length),
              tf.Ramp(v, start=start, duration=length)):
        _check(f, times)


@settings(max_examples=40, deadline=None)
@given(times=grids(), k=st.integers(1, 3), data=st.data())
def test_table_and_component_sample_like_scalar_calls(times, k, data):
    n = data.draw(st.integers(2, 6))
    knots = np.cumsum(data.draw(st.lists(st.floats(1e-2, 1.0), min_size=n, max_size=n))) - 1.0
    vals = np.array(data.draw(st.lists(finite, min_size=n * k, max_size=n * k))).reshape(n, k)
    f = tf.Table(knots, vals[:, 0] if k == 1 else vals)
    _check(f, times)
    if k > 1:
        _check(tf.Component(f, k - 1), times)


def test_sine_and_callables_use_the_scalar_path():
    times = np.linspace(0.01, 1.0, 37)
    _check(tf.Sine([1.0, -2.0], 1.3, phase=0.2, offset=[0.5, 0.0]), times)
    _check(tf.Callable(lambda t: np.sin(3 * t) * t), times)


def test_failing_function_in_a_fixed_step_run_is_named_with_its_time():
    # a callable failing at t > 0.05: the vectorised tables fall back to the time-by-time
    # path, which names the item and the time; results up to there are kept
    def torque(t):
        if t > 0.05:
            raise ValueError("sensor unplugged")
        return 0.1

    mb = sd.ModelBuilder(gravity=(0, 0, -9.81))
    mb.node("g", position=(0, 0, 0), fixed=True)
    mb.node("b", position=(0.5, 0, 0), mass=1.0, inertia=(0.01, 0.01, 0.01))
    mb.joint("h", "hinge", "g", "b", axis=(0, 1, 0), at=(0, 0, 0), torque=torque)
    with pytest.raises(SimulationError, match=r"h.*sensor unplugged") as ei:
        sd.simulate(mb.build(), 0.2, 0.01)
    assert "0.06" in str(ei.value)
    assert ei.value.result is not None and ei.value.result.t[-1] == pytest.approx(0.05)
