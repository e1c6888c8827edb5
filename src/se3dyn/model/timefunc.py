"""Time functions for actuators, control targets and external loads.

Each function ``f`` is a frozen spec with ``f(t)`` (value, scalar or array) and ``f.rate(t)`` (time
derivative, used for the target velocity of a PD controller). Built-ins: :class:`Constant`,
:class:`Step`, :class:`Ramp`, :class:`Table` (piecewise linear), :class:`Sine`. Any Python
callable ``f(t)`` is accepted too (wrapped in :class:`Callable`, whose rate is a central finite
difference).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable as _CallableABC
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from se3dyn.errors import ModelError

__all__ = ["TimeFunction", "Constant", "Step", "Ramp", "Table", "Sine", "Callable", "Component",
           "as_timefunc"]


class TimeFunction:
    """Base class: ``f(t)`` and ``f.rate(t)``; ``kind`` is the model-file key."""

    kind = ""

    def __call__(self, t: float) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def rate(self, t: float) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def accel(self, t: float) -> Any:
        """Second derivative ``f''(t)``: exact for the built-ins (zero on the linear pieces of
        :class:`Ramp`, :class:`Step` and :class:`Table`, whose kinks it does not see); by a
        fourth-order central difference of :meth:`rate` otherwise, with step ``h = 1e-3
        max(1, |t|)`` (truncation ``h^4 |f^(5)| / 30``). Used for the initial acceleration of a
        driven coordinate (:meth:`se3dyn.ModelBuilder.drive`) and by
        :func:`se3dyn.analysis.kinematics.time_derivatives`."""
        h = 1e-3 * max(1.0, abs(t))
        p = [np.asarray(self.rate(t + c * h), dtype=float) for c in (-2, -1, 1, 2)]
        return (p[0] - 8 * p[1] + 8 * p[2] - p[3]) / (12 * h)

    def sample(self, times: np.ndarray) -> np.ndarray:
        """Values at many times: (nt,) for a scalar function, (nt, k) for a k-vector; the
        same numbers as ``f(t)`` one time at a time (vectorised by the built-ins)."""
        return np.array([np.asarray(self(t), dtype=float) for t in times], dtype=float)

    def sample_rate(self, times: np.ndarray) -> np.ndarray:
        """Rates ``f.rate(t)`` at many times, shaped as :meth:`sample`."""
        return np.array([np.asarray(self.rate(t), dtype=float) for t in times], dtype=float)

    def sample_accel(self, times: np.ndarray) -> np.ndarray:
        """Second derivatives ``f.accel(t)`` at many times, shaped as :meth:`sample`."""
        return np.array([np.asarray(self.accel(t), dtype=float) for t in times], dtype=float)


def _many(times: np.ndarray, v: Any) -> np.ndarray:
    """A constant value repeated at every time: (nt,) or (nt, k)."""
    v = np.asarray(v, dtype=float)
    return np.broadcast_to(v, (len(times),) + v.shape).copy()


def _where(on: np.ndarray, v: Any) -> np.ndarray:
    """``v`` where ``on`` (nt,), else ``0 * v`` (the zeros of the scalar methods)."""
    v = np.asarray(v, dtype=float)
    return np.where(on.reshape((-1,) + (1,) * v.ndim), v, 0.0 * v)


def _value(v: Any, item: str, fld: str) -> np.ndarray | float:
    try:
        if isinstance(v, bool | str | bytes):
            raise TypeError(v)
        a = np.asarray(v, dtype=float) if not isinstance(v, int | float) else float(v)
    except (TypeError, ValueError, OverflowError):
        raise ModelError(item, fld, "a number or a 1-D array of numbers", v) from None
    if isinstance(a, np.ndarray):
        if a.ndim > 1:
            raise ModelError(item, fld, "a number or a 1-D array", v)
        if not np.all(np.isfinite(a)):
            raise ModelError(item, fld, "finite numbers", v)
        if a.ndim == 0:
            return float(a)
    elif not math.isfinite(a):
        raise ModelError(item, fld, "a finite number", v)
    return a


def _scalar(obj: Any, name: str, item: str, inf_ok: bool = False) -> None:
    """Validate the scalar parameter ``name`` of ``obj`` (a real number; +-inf when
    ``inf_ok``) and store it as a float."""
    v = getattr(obj, name)
    ok = isinstance(v, numbers.Real) and not isinstance(v, bool)
    if ok:
        v = float(v)
        ok = math.isfinite(v) or (inf_ok and not math.isnan(v))
    if not ok:
        raise ModelError(item, name, "a finite number" + (" (or infinity)" if inf_ok else ""),
                         v)
    object.__setattr__(obj, name, v)


@dataclass(frozen=True)
class Constant(TimeFunction):
    """``f(t) = value``."""

    value: Any
    kind = "constant"

    def __post_init__(self):
        object.__setattr__(self, "value", _value(self.value, "time function 'constant'", "value"))

    def __call__(self, t):
        return self.value

    def rate(self, t):
        return 0.0 * np.asarray(self.value)

    def accel(self, t):
        return 0.0 * np.asarray(self.value)

    def sample_accel(self, times):
        return _many(times, 0.0 * np.asarray(self.value))

    def sample(self, times):
        return _many(times, self.value)

    def sample_rate(self, times):
        return _many(times, 0.0 * np.asarray(self.value))


@dataclass(frozen=True)
class Step(TimeFunction):
    """``value`` for ``start <= t < stop``, zero otherwise (e.g. the paper's torque, Sec. 11.2)."""

    value: Any
    start: float = 0.0
    stop: float = math.inf
    kind = "step"

    def __post_init__(self):
        object.__setattr__(self, "value", _value(self.value, "time function 'step'", "value"))
        _scalar(self, "start", "time function 'step'", inf_ok=True)
        _scalar(self, "stop", "time function 'step'", inf_ok=True)
        if not (self.stop > self.start):
            raise ModelError("time function 'step'", "stop", f"a time after start={self.start}",
                             self.stop)

    def __call__(self, t):
        on = self.start <= t < self.stop
        return self.value if on else 0.0 * np.asarray(self.value)

    def rate(self, t):
        return 0.0 * np.asarray(self.value)

    def accel(self, t):
        return 0.0 * np.asarray(self.value)

    def sample_accel(self, times):
        return _many(times, 0.0 * np.asarray(self.value))

    def sample(self, times):
        t = np.asarray(times, dtype=float)
        return _where((self.start <= t) & (t < self.stop), self.value)

    def sample_rate(self, times):
        return _many(times, 0.0 * np.asarray(self.value))


@dataclass(frozen=True)
class Ramp(TimeFunction):
    """Zero before ``start``, linear to ``value`` at ``start + duration``, constant after."""

    value: Any
    start: float = 0.0
    duration: float = 1.0
    kind = "ramp"

    def __post_init__(self):
        object.__setattr__(self, "value", _value(self.value, "time function 'ramp'", "value"))
        _scalar(self, "start", "time function 'ramp'")
        _scalar(self, "duration", "time function 'ramp'")
        if not (self.duration > 0):
            raise ModelError("time function 'ramp'", "duration", "a positive time", self.duration)

    def __call__(self, t):
        s = min(max((t - self.start) / self.duration, 0.0), 1.0)
        return s * np.asarray(self.value) if isinstance(self.value, np.ndarray) else s * self.value

    def rate(self, t):
        on = self.start <= t < self.start + self.duration
        return np.asarray(self.value) / self.duration * (1.0 if on else 0.0)

    def accel(self, t):
        return 0.0 * np.asarray(self.value)

    def sample_accel(self, times):
        return _many(times, 0.0 * np.asarray(self.value))

    def sample(self, times):
        t = np.asarray(times, dtype=float)
        sc = np.minimum(np.maximum((t - self.start) / self.duration, 0.0), 1.0)
        v = np.asarray(self.value, dtype=float)
        return sc.reshape((-1,) + (1,) * v.ndim) * v

    def sample_rate(self, times):
        t = np.asarray(times, dtype=float)
        on = ((self.start <= t) & (t < self.start + self.duration)).astype(float)
        v = np.asarray(self.value, dtype=float) / self.duration
        return v * on.reshape((-1,) + (1,) * v.ndim)


@dataclass(frozen=True)
class Table(TimeFunction):
    """Piecewise-linear interpolation of ``values`` at increasing ``times``; held constant outside.

    ``values`` has shape ``(n,)`` or ``(n, k)`` for a k-vector function.
    """

    times: Any
    values: Any
    kind = "table"

    def __post_init__(self):
        item = "time function 'table'"
        try:
            t = np.asarray(self.times, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise ModelError(item, "times", "a list of numbers", self.times) from None
        try:
            y = np.asarray(self.values, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise ModelError(item, "values", "a list of numbers", self.values) from None
        if t.ndim != 1 or t.size < 2:
            raise ModelError(item, "times", "at least two times in a 1-D list", self.times)
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise ModelError(item, "times", "finite, strictly increasing times", self.times)
        if y.shape[:1] != t.shape or y.ndim > 2 or not np.all(np.isfinite(y)):
            raise ModelError(item, "values", f"{t.size} finite values (one per time)", self.values)
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "values", y)

    def _interp(self, t, y):
        if y.ndim == 1:
            return float(np.interp(t, self.times, y))
        return np.array([np.interp(t, self.times, y[:, i]) for i in range(y.shape[1])])

    def __call__(self, t):
        return self._interp(t, self.values)

    def sample(self, times):
        t = np.asarray(times, dtype=float)
        y = self.values
        if y.ndim == 1:
            return np.interp(t, self.times, y)
        return np.stack([np.interp(t, self.times, y[:, i]) for i in range(y.shape[1])], axis=1)

    def rate(self, t):
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        if i < 0 or i >= self.times.size - 1:
            return 0.0 * self.values[0]
        return (self.values[i + 1] - self.values[i]) / (self.times[i + 1] - self.times[i])

    def accel(self, t):
        return 0.0 * self.values[0]

    def sample_accel(self, times):
        return _many(times, 0.0 * self.values[0])


@dataclass(frozen=True)
class Sine(TimeFunction):
    """``offset + amplitude * sin(2 pi frequency t + phase)`` (frequency in Hz, phase in rad)."""

    amplitude: Any
    frequency: float
    phase: float = 0.0
    offset: Any = 0.0
    kind = "sine"

    def __post_init__(self):
        item = "time function 'sine'"
        object.__setattr__(self, "amplitude", _value(self.amplitude, item, "amplitude"))
        object.__setattr__(self, "offset", _value(self.offset, item, "offset"))
        _scalar(self, "frequency", item)
        _scalar(self, "phase", item)
        if not (math.isfinite(self.frequency) and self.frequency >= 0):
            raise ModelError(item, "frequency", "a non-negative frequency in Hz", self.frequency)

    def __call__(self, t):
        w = 2 * math.pi * self.frequency
        return self.offset + self.amplitude * math.sin(w * t + self.phase)

    def rate(self, t):
        w = 2 * math.pi * self.frequency
        return self.amplitude * w * math.cos(w * t + self.phase)

    def accel(self, t):
        w = 2 * math.pi * self.frequency
        return -self.amplitude * w * w * math.sin(w * t + self.phase)


@dataclass(frozen=True)
class Callable(TimeFunction):
    """Any Python callable ``fn(t)``; ``rate`` by central differences with step ``dt``."""

    fn: _CallableABC = field(compare=False)
    dt: float = 1e-6
    kind = "callable"

    def __post_init__(self):
        item = "time function 'callable'"
        if not callable(self.fn):
            raise ModelError(item, "fn", "a callable fn(t)", self.fn)
        _scalar(self, "dt", item)
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ModelError(item, "dt", "a positive finite step (s)", self.dt)

    def __call__(self, t):
        v = self.fn(t)
        return np.asarray(v, dtype=float) if np.ndim(v) else float(v)

    def rate(self, t):
        a = np.asarray(self.fn(t + self.dt), dtype=float)
        b = np.asarray(self.fn(t - self.dt), dtype=float)
        return (a - b) / (2 * self.dt)

    def accel(self, t):
        # a fourth-order second difference of fn, h = 2e-3 max(1, |t|): truncation
        # h^4 |f^(6)| / 90, round-off ~ 5 u |f| / h^2 (~1e-10 relative on a time scale of 1)
        h = 2e-3 * max(1.0, abs(t))
        q = [np.asarray(self.fn(t + c * h), dtype=float) for c in (-2, -1, 0, 1, 2)]
        return (-q[0] + 16 * q[1] - 30 * q[2] + 16 * q[3] - q[4]) / (12 * h * h)


@dataclass(frozen=True)
class Component(TimeFunction):
    """Component ``index`` of a vector-valued time function ``base`` (e.g. one hinge of a
    universal joint driven by a 2-vector actuator)."""

    base: TimeFunction
    index: int
    kind = "component"

    def _pick(self, v: Any) -> float:
        a = np.atleast_1d(np.asarray(v, dtype=float))
        return float(a[self.index] if a.size > 1 else a[0])

    def __call__(self, t):
        return self._pick(self.base(t))

    def rate(self, t):
        return self._pick(self.base.rate(t))

    def accel(self, t):
        return self._pick(self.base.accel(t))

    def sample_accel(self, times):
        return self._pick_many(self.base.sample_accel(times))

    def _pick_many(self, v: np.ndarray) -> np.ndarray:
        v = np.asarray(v, dtype=float)
        if v.ndim == 1 or v.shape[1] == 1:
            return v.reshape(len(v))
        return v[:, self.index].copy()

    def sample(self, times):
        return self._pick_many(self.base.sample(times))

    def sample_rate(self, times):
        return self._pick_many(self.base.sample_rate(times))


def as_timefunc(v: Any, item: str, fld: str, size: int | None = None) -> TimeFunction:
    """Turn a number, an array, a :class:`TimeFunction` or a callable into a TimeFunction.

    ``size`` is the length a vector value must have (``None``: any). The value at ``t = 0`` is
    evaluated to check its shape, so a wrong callable fails at build time, naming the item.
    """
    if isinstance(v, TimeFunction):
        f = v
    elif callable(v):
        f = Callable(v)
    else:
        try:
            f = Constant(v)
        except (TypeError, ValueError):
            raise ModelError(item, fld, "a number, an array, a time function or a callable of t",
                             v) from None
    try:
        val = np.asarray(f(0.0), dtype=float)
    except Exception as exc:  # user callables may raise anything
        raise ModelError(item, fld, "a function of t that can be evaluated at t = 0",
                         f"{type(exc).__name__}: {exc}") from None
    if size is not None and val.size not in (1, size) or val.ndim > 1:
        raise ModelError(item, fld, f"{size} component(s)", val)
    if not np.all(np.isfinite(val)):
        raise ModelError(item, fld, "finite values", val)
    return f
