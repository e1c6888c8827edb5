"""Scalar metrics of a run: ``NAME=FUNC(EXPR)``.

FUNC is one of ``max``, ``min``, ``final``, ``mean``, ``rms``; EXPR is a channel name
(:mod:`se3dyn.results.channels`, e.g. ``joint/1/multiplier/3``), optionally wrapped in
``abs(...)``::

    peak=max(abs(joint/1/multiplier/3))
    e_end=final(energy/total)
    v_rms=rms(node/6/velocity/inertial/x)

``mean`` and ``rms`` are time averages over the stored rows (trapezoidal rule in time, so
adaptive or uneven outputs are weighted by their intervals); ``max``, ``min`` and ``final`` take
the stored rows. A small regular grammar parses the text: nothing is ever evaluated.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from se3dyn.sweep.spec import SweepSpecError

__all__ = ["Metric", "parse_metric", "FUNCS", "RESERVED"]

FUNCS = ("max", "min", "final", "mean", "rms")
#: Column names of the summary that a metric cannot take.
RESERVED = ("run", "status", "message", "wall_time", "steps", "newton_iterations", "worker",
            "results")

_FORM = "NAME=FUNC(CHANNEL) or NAME=FUNC(abs(CHANNEL)) with FUNC in " + ", ".join(FUNCS)
_METRIC = re.compile(r"\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*([a-z]+)\s*\(\s*(.*?)\s*\)\s*")
_ABS = re.compile(r"abs\s*\(\s*(.*?)\s*\)")
_CHANNEL = re.compile(r"[A-Za-z0-9_%.\-]+(?:/[A-Za-z0-9_%.\-]+)*")


@dataclass(frozen=True)
class Metric:
    """One metric column: ``name = func(abs?(channel))``."""

    name: str
    func: str
    channel: str
    absolute: bool = False

    @property
    def text(self) -> str:
        inner = f"abs({self.channel})" if self.absolute else self.channel
        return f"{self.name}={self.func}({inner})"

    def evaluate(self, res) -> float:
        """The metric of a :class:`~se3dyn.results.results.Results` (NaN when it has no rows)."""
        from se3dyn.results.channels import get_channel

        x = np.asarray(get_channel(res, self.channel), dtype=float)
        if self.absolute:
            x = np.abs(x)
        if x.size == 0:
            return float("nan")
        if self.func == "max":
            return float(np.max(x))
        if self.func == "min":
            return float(np.min(x))
        if self.func == "final":
            return float(x[-1])
        t = np.asarray(res.t, dtype=float)
        span = float(t[-1] - t[0]) if t.size > 1 else 0.0
        y = x if self.func == "mean" else x * x
        if span > 0:
            avg = float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)) / span)
        else:
            avg = float(np.mean(y))
        return avg if self.func == "mean" else float(np.sqrt(avg))


def parse_metric(text: str, name: str | None = None) -> Metric:
    """Parse ``NAME=FUNC(EXPR)`` (or ``FUNC(EXPR)`` with ``name`` given separately).

    Raises
    ------
    SweepSpecError
        Naming the metric, the form expected and the text that came.
    """
    item = f"--metric {text!r}"
    if not isinstance(text, str):
        raise SweepSpecError("--metric", "metric", _FORM, text)
    full = f"{name}={text}" if name is not None else text
    m = _METRIC.fullmatch(full)
    if not m:
        raise SweepSpecError(item, "metric", _FORM, full)
    mname, func, expr = m.groups()
    if func not in FUNCS:
        raise SweepSpecError(item, "FUNC", "one of " + ", ".join(FUNCS), func)
    if mname in RESERVED:
        raise SweepSpecError(item, "NAME", "a name that is not a summary column (" +
                             ", ".join(RESERVED) + ")", mname)
    absolute = False
    a = _ABS.fullmatch(expr)
    if a:
        absolute, expr = True, a.group(1)
    if not _CHANNEL.fullmatch(expr):
        raise SweepSpecError(item, "EXPR", "a channel name such as joint/1/multiplier/3, "
                             "optionally inside abs(...)", expr)
    return Metric(mname, func, expr, absolute)


def check_channels(metrics: list[Metric], system) -> None:
    """Check the metric channels against a compiled system (before any run starts).

    Raises
    ------
    SweepSpecError
        An unknown channel, with close valid names.
    """
    from se3dyn.results.channels import get_channel

    res = _empty_results(system)
    for m in metrics:
        try:
            get_channel(res, m.channel)
        except KeyError as exc:
            msg = str(exc.args[0]) if exc.args else f"unknown channel {m.channel!r}"
            raise SweepSpecError(f"--metric {m.text!r}", "channel", "a channel of the model "
                                 "(see 'se3dyn channels RESULTS')", m.channel, msg) from None


def _empty_results(system):
    """One row of zeros on ``system``'s layout: enough to resolve channel names."""
    from se3dyn.results.results import Results

    z = np.zeros(1)
    H = np.tile(np.eye(4), (1, system.M, 1, 1))
    nq, nm = system.nq, system.nm
    return Results(system=system, t=z, H=H, v=np.zeros((1, nq)), vd=np.zeros((1, nq)),
                   lam=np.zeros((1, nm)), alpha=np.zeros((1, nq)), kinetic=z, potential=z,
                   spring=z, work_actuators=z, work_loads=z, dissipation=z,
                   iterations=np.zeros(1, dtype=int), residual=z, constraint=z)
