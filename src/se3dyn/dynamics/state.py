"""The state of a run: exactly what the generalized-alpha step needs to continue (Eqs. (38)-(46)),
immutable, so that a restart from it is bit-exact (:class:`State`), and the report of one step
(:class:`StepInfo`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from se3dyn.engine.memory import SolverMemory



@dataclass(frozen=True)
class State:
    """Exactly what integration needs, so a restart from a State is bit-exact; immutable (a
    frozen dataclass whose arrays are read-only: ``dataclasses.replace`` makes a new one).

    Attributes
    ----------
    t : float
    H : ndarray (M, 4, 4)      node frames
    HJ : ndarray (m, 4, 4)     joint transformations
    v, vd, a : ndarray (nq,)   velocities, accelerations, generalized-alpha variable a (Eq. (43))
    lam : ndarray (nm,)        multipliers
    alpha : ndarray (nq,)      relative coordinates on joint unknowns (Eq. (60)); 0 on nodes
    work_act, work_ext, dissipated : float
        Accumulated actuator work (incl. PD laws), work of external loads, damper dissipation.
    power : ndarray (3,)       (actuator, external, dissipation) powers at t (trapezoidal rule)
    dropped : ndarray (nr,)    redundant constraint equations left out (multiplier indices);
                               their multipliers stay zero (see :func:`GeneralizedAlpha.init`)
    h_last : float             size of the step that produced this state (0 initially)
    ctrl : ndarray (2 npid,)   PID laws: per controlled coordinate the integral of its error
                               and the error (z, e) at t (``_core/elements/joint_force.hpp``)
    solver : SolverMemory or None
        The linear solver's memory after the step that produced this state; None: the model's
        own (the pivot sequence of its generic matrix, which a new workspace starts with)
    """

    t: float
    H: np.ndarray
    HJ: np.ndarray
    v: np.ndarray
    vd: np.ndarray
    a: np.ndarray
    lam: np.ndarray
    alpha: np.ndarray
    work_act: float = 0.0
    work_ext: float = 0.0
    dissipated: float = 0.0
    power: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    dropped: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, np.int64))
    h_last: float = 0.0
    solver: SolverMemory | None = None
    ctrl: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))

    def __post_init__(self):
        for f in dataclasses.fields(self):
            x = getattr(self, f.name)
            if isinstance(x, np.ndarray):
                x.flags.writeable = False

    def copy(self) -> State:
        """A State with writeable copies of the arrays (not shared with this one)."""
        return dataclasses.replace(self, **{f.name: np.copy(getattr(self, f.name))
                                            for f in dataclasses.fields(self)
                                            if isinstance(getattr(self, f.name), np.ndarray)})


@dataclass(frozen=True)
class StepInfo:
    """Outcome of one step: Newton iterations, final scaled residual and constraint norms, the
    energies of the new state (see :func:`energies`), the converged increment ``n`` (nq,) of
    Eq. (41) and the local error estimate ``error`` (nq,) of the positions (see
    :meth:`GeneralizedAlpha.step`)."""

    iterations: int
    residual: float
    constraint: float
    energies: dict | None = None
    increment: np.ndarray | None = None
    error: np.ndarray | None = None
