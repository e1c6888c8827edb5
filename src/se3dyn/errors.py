"""Exceptions of se3dyn.

Every message names the item, the field, what was expected and what came.
"""

from __future__ import annotations

from typing import Any


class Se3dynError(Exception):
    """Base class of all se3dyn errors."""


class ModelError(Se3dynError, ValueError):
    """An invalid model description.

    Parameters
    ----------
    item : str
        The offending item, e.g. ``"joint '7' (hinge)"``.
    field : str
        The offending field, e.g. ``"axis"``.
    expected : str
        What was expected.
    got : Any
        What came (``repr`` is shown, shortened).
    """

    def __init__(self, item: str, field: str, expected: str, got: Any = None, hint: str = ""):
        self.item = item
        self.field = field
        self.expected = expected
        self.got = got
        shown = _short_repr(got)
        msg = f"{item}: field '{field}': expected {expected}, got {shown}"
        if hint:
            msg += f" ({hint})"
        super().__init__(msg)


class UnknownNameError(Se3dynError, KeyError):
    """A node, joint or channel name that does not exist; the message lists the valid ones."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown name"


class Se3dynWarning(UserWarning):
    """Results that may mislead: initial velocities changed to satisfy the joints, an energy
    balance error large against the energy exchanged (the message says what and how much)."""


class SimulationError(Se3dynError, RuntimeError):
    """A simulation that could not proceed; ``result`` holds everything computed so far."""

    def __init__(self, message: str, result: Any = None):
        super().__init__(message)
        self.result = result


class NewtonError(SimulationError):
    """Newton iterations of a time step failed to converge.

    Attributes
    ----------
    t : float
        Time the step was aiming for.
    h : float
        Step size.
    iterations : int
        Iterations performed.
    residual_norm, constraint_norm : float
        Final scaled residual norm and constraint violation.
    item : str
        Name of the node or joint carrying the largest residual entry.
    result : Results or None
        Results up to the last converged step.
    """

    def __init__(self, message: str, *, t: float, h: float, iterations: int,
                 residual_norm: float, constraint_norm: float, item: str, result: Any = None):
        super().__init__(message, result)
        self.t = t
        self.h = h
        self.iterations = iterations
        self.residual_norm = residual_norm
        self.constraint_norm = constraint_norm
        self.item = item


def _short_repr(x: Any, limit: int = 120) -> str:
    try:
        import numpy as np

        if isinstance(x, np.generic):
            x = x.item()  # 0.707, not np.float64(0.707)
        if isinstance(x, np.ndarray):
            s = np.array2string(x, threshold=12, precision=6)
            s = f"array of shape {x.shape}: {s}"
        else:
            try:  # numpy >= 2: scalars inside tuples and lists shown as plain numbers
                with np.printoptions(legacy="1.25"):
                    s = repr(x)
            except ValueError:  # numpy < 2: already plain
                s = repr(x)
    except Exception:  # pragma: no cover - repr of exotic objects
        s = object.__repr__(x)
    return s if len(s) <= limit else s[: limit - 3] + "..."


def close_matches(word: str, possibilities, n: int = 1, cutoff: float = 0.6) -> list[str]:
    """``difflib.get_close_matches`` for the "did you mean" hints (difflib is imported only
    when a name is wrong, not at start-up)."""
    import difflib

    return difflib.get_close_matches(word, possibilities, n=n, cutoff=cutoff)
