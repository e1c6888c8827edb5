"""A run streamed into a results file and read back (the sensor, drive and coupling tests
compare their channels in memory and from the file)."""

from __future__ import annotations

import warnings

import se3dyn as sd
from se3dyn.io.h5 import ResultsWriter, read_results


def run_and_read(model, t_end: float, path, step: float = 1e-2):
    """A run at the fixed ``step`` streamed into the results file ``path``: (results in
    memory, results read back from the file). Warnings of the run are not shown."""
    s = sd.compile_model(model) if isinstance(model, sd.Model) else model
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with ResultsWriter(path, s, settings={"t_end": t_end, "step": step}) as w:
            res = sd.simulate(s, t_end, step, on_output=w.append)
            w.close(res.stats)
    return res, read_results(path)
