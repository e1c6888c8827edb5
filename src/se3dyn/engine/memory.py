"""What the Newton stepper of the time loop carries from one step to the next
(:class:`SolverMemory`), so that a restart from a state continues bit for bit.
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
