"""The dask side of a sweep: a worker plugin holding the sweep's shared context, and the task.

The plugin is registered once per sweep; dask installs it on every worker, including workers
that join (or are restarted) later. Its ``setup`` loads se3dyn's compiled kernels in the worker
process (:func:`~se3dyn.sweep.execute.warm_up`, in a thread so the worker keeps answering the
scheduler), so no run pays for it. Each task carries only its run number and varied values.
"""

from __future__ import annotations

import asyncio
from collections import OrderedDict

from distributed import WorkerPlugin, get_worker

from se3dyn.sweep.execute import RunContext, execute_run, warm_up

__all__ = ["SweepPlugin", "run_task"]


class SweepPlugin(WorkerPlugin):
    """Per-worker state of one sweep: the :class:`RunContext` and a small model cache."""

    def __init__(self, name: str, ctx: RunContext):
        self.name = name
        self.ctx = ctx
        self.cache: OrderedDict = OrderedDict()
        self.warm_up_time = 0.0

    async def setup(self, worker) -> None:
        self.cache = OrderedDict()
        loop = asyncio.get_running_loop()
        self.warm_up_time = await loop.run_in_executor(None, warm_up)


def run_task(plugin_name: str, run: int, values: dict) -> dict:
    """The dask task of one run: :func:`~se3dyn.sweep.execute.execute_run` with the context of
    the worker's plugin."""
    worker = get_worker()
    plugin = worker.plugins.get(plugin_name)
    if plugin is None:  # pragma: no cover - dask installs plugins before running tasks
        raise RuntimeError(f"se3dyn sweep: plugin {plugin_name!r} missing on worker "
                           f"{worker.address}")
    return execute_run(plugin.ctx, run, values, plugin.cache)
