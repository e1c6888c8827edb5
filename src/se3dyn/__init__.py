"""se3dyn: multibody dynamics on the special Euclidean group SE(3).

The method is the finite-element formulation of multibody systems on SE(3) with a Lie-group
generalized-alpha integrator. Conventions are written once in :mod:`se3dyn.lie`.

>>> import se3dyn as sd
>>> model = sd.examples.slider_crank()
>>> result = sd.simulate(model, t_end=5.0, step=1e-2, rho_inf=0.9)  # doctest: +SKIP

Beyond dynamics: :func:`static_equilibrium` (load stepping), :func:`assemble` (inconsistent
initial configurations), :func:`kinematics` (driven mechanisms, inverse dynamics),
:class:`JointSpace` (mass matrix, inverse and forward dynamics, Jacobians in the joint
coordinates) and :func:`linearize` (linear models, modes, state space).
Parameter studies on dask.distributed: ``se3dyn.sweep(...)`` (:mod:`se3dyn.sweep`).
Results in the browser: ``sd.show(result)`` (:mod:`se3dyn.viewer`).

The package is layered (``docs/design.md``, checked by the import-linter contract of
``pyproject.toml``): ``model`` -> ``elements`` -> ``engine`` -> ``results`` -> ``dynamics`` ->
``analysis`` -> ``io`` -> ``viewer``, ``sweep`` -> ``cli``. This face imports none of them
itself: each public name (listed once, in ``__init__.pyi``, which editors and type checkers
read) loads its module on first use (PEP 562), so ``import se3dyn`` costs nothing and the
``se3dyn`` command can set up its process before numpy loads (:mod:`se3dyn.cli`).
"""

from se3dyn._oldpaths import install as _install_old_paths
from se3dyn._version import __version__ as __version__


def _public_names() -> dict[str, tuple[str, str]]:
    """name -> (module, attribute) from the stub's ``from M import A as A`` lines."""
    import os

    table = {}
    with open(os.path.join(os.path.dirname(__file__), "__init__.pyi"), encoding="utf-8") as f:
        for line in f:
            if line.startswith("from "):
                _, module, _, attr, _, name = line.split()
                table[name] = (module, attr)
    return table


_PUBLIC = _public_names()
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module 'se3dyn' has no attribute {name!r}")
    import importlib

    module, attr = _PUBLIC[name]
    if module == "se3dyn":  # a module of the face itself: se3dyn.lie, se3dyn.sweep
        value = importlib.import_module(f"se3dyn.{attr}")
    else:
        value = getattr(importlib.import_module(module), attr, None)
        if value is None:  # a submodule: se3dyn.model.examples
            value = importlib.import_module(f"{module}.{attr}")
    globals()[name] = value  # once: later look-ups are plain attribute reads
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


_install_old_paths()
