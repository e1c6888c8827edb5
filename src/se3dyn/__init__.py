"""se3dyn: multibody dynamics on the special Euclidean group SE(3).

The method is the finite-element formulation of multibody systems on SE(3) with a Lie-group
generalized-alpha integrator (see ``docs/`` and the module :mod:`se3dyn.lie` for conventions).
"""

from se3dyn import lie

__version__ = "0.1.0"

__all__ = ["lie", "__version__"]
