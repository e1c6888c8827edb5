"""Lie-group generalized-alpha time integration (Eqs. (38)-(46)) with Newton iterations.

One step from ``t_n`` to ``t_{n+1} = t_n + h`` solves for the increments ``n_{n+1}`` (Eq. (41)):

* ``H_{n+1} = H_n exp(A n_{n+1})`` (Eq. (38)) for every node and joint;
* the equations of motion (39) and the constraints (40) at ``t_{n+1}``;
* ``v_{n+1} = v_n + (1-gamma) h a_n + gamma h a_{n+1}`` (42),
  ``(1-alpha_m) a_{n+1} + alpha_m a_n = (1-alpha_f) vd_{n+1} + alpha_f vd_n`` (43),
  with the parameters of Eq. (44) from the spectral radius ``rho_inf``.

Newton corrections use ``dv = gamma' dn``, ``dvd = beta' dn`` and the scaled iteration matrix
described in :mod:`se3dyn.system`. Converged when the residual is below ``tol_residual`` relative
to the magnitude of the forces entering it and the constraints below ``tol_constraint`` (times the
model's length scale), or when the increment correction reaches round-off with the constraints
satisfied.
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
