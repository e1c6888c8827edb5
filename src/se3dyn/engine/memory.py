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

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class SolverMemory:
    """What the linear solver of the Newton iterations carries from a step to the next, so that
    a restart from a :class:`State`, in this process or another, continues bit for bit
    (``se3dyn/_core/newton.hpp``).

    Attributes
    ----------
    ref : ndarray (nv,)
        Values of the iteration matrix (in the engine's value order; dropped equations as
        identity rows and columns) of the last full sparse LU factorisation, whose pivot
        sequence the refactorisations of the following steps reuse; for the index-2 form one
        more entry, the mode of the iteration (0: the split matrix, 1: the full one; see
        ``se3dyn/_core/newton.hpp``). Read-only: the stepper and the States holding it share
        one array.
    """

    ref: np.ndarray

    def __post_init__(self):
        self.ref.flags.writeable = False
