"""Parameter studies at scale: many runs of one model file on dask.distributed.

>>> import se3dyn
>>> table = se3dyn.sweep("examples/slider_crank.yaml",              # doctest: +SKIP
...                      {"joints.8.damping.0": "0.5,1,2,4"},
...                      metrics={"peak": "max(abs(joint/1/multiplier/3))"},
...                      overrides={"t_end": 2.0}, out="out/damping", workers=2)

``se3dyn.sweep(...)`` is :func:`run_sweep`: this module is callable (it is both the package and
the function, so ``import se3dyn.sweep`` never hides the function). The command line is
``se3dyn sweep MODEL --vary PATH=SPEC ... --out DIR`` (``docs/sweep.md``).

Layers (the core never imports this package; dask is imported only when runs start):

* :mod:`~se3dyn.sweep.spec` — model-file paths, value specs, grid/random/LHS plans;
* :mod:`~se3dyn.sweep.metrics` — ``NAME=FUNC(EXPR)`` metrics over channels;
* :mod:`~se3dyn.sweep.execute` — one run (model, simulate, metrics, results file), no dask;
* :mod:`~se3dyn.sweep.worker` — the dask worker plugin (kernels loaded once per worker) and
  task;
* :mod:`~se3dyn.sweep.runner` — cluster, submission, collection, resume;
* :mod:`~se3dyn.sweep.table` — journal, summary CSV/Parquet, progress bar.

Returned table: a pandas DataFrame when pandas is importable (``as_frame=None``, the default),
otherwise a list of dicts, one per run, in column order; pandas is never required.
"""

from __future__ import annotations

import importlib
import sys
import types

__all__ = ["run_sweep", "prepare", "execute_plan", "SweepSpecError", "SweepInterrupted",
           "Variable", "parse_spec", "plan_runs", "Metric", "parse_metric", "read_summary_csv"]

# names -> submodule: imported on first use (PEP 562), so that `se3dyn --help` or `se3dyn run`,
# which declare the sweep's options through se3dyn.sweep.cli, load none of the sweep machinery
_WHERE = {"run_sweep": "runner", "prepare": "runner", "execute_plan": "runner",
          "SweepInterrupted": "runner", "SweepSpecError": "spec", "Variable": "spec",
          "parse_spec": "spec", "plan_runs": "spec", "Metric": "metrics",
          "parse_metric": "metrics", "read_summary_csv": "table"}


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(f"se3dyn.sweep.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'se3dyn.sweep' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _CallableModule(types.ModuleType):
    """``se3dyn.sweep(...)`` calls :func:`run_sweep` (a module ``__class__`` assignment,
    supported by Python since 3.5)."""

    def __call__(self, *args, **kwargs):
        from se3dyn.sweep.runner import run_sweep

        return run_sweep(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
