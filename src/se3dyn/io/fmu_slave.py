"""The co-simulation slave inside an FMU exported by :func:`se3dyn.io.fmu.export_fmu`: a
:class:`~se3dyn.dynamics.simulator.Simulator` behind pythonfmu's FMI 2.0 interface.

It runs in the importing tool's process, in the Python that pythonfmu's binary starts, with
se3dyn installed there; it reads the model file and the settings from the FMU's resources.
Inputs are the simulator's inputs, one FMI variable per component; an input is held (zero-order
hold) from the first ``fmi2SetReal`` on it, before that the model's own time function acts.
Outputs are results channels read at the current state. ``fmi2GetFMUstate`` /
``fmi2SetFMUstate`` save and restore :attr:`Simulator.state`, so a master that steps back
recomputes the same numbers bit for bit.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.default_experiment import DefaultExperiment

from se3dyn.dynamics.simulator import Simulator
from se3dyn.io.modelfile import load_model

#: The files of the FMU's resources that the slave reads.
MODEL_FILE, SETTINGS_FILE = "se3dyn_model.yaml", "se3dyn_fmu.json"


class Se3dynSlave(Fmi2Slave):
    """A :class:`Simulator` of the model in the FMU's resources (see the module docstring)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        res = Path(self.resources)
        cfg = json.loads((res / SETTINGS_FILE).read_text(encoding="utf-8"))
        model, _ = load_model(res / MODEL_FILE)
        self.description = cfg["description"]
        self.sim = Simulator(model, **cfg["settings"])
        self.default_experiment = DefaultExperiment(
            start_time=self.sim.t_start, step_size=self.sim.h, stop_time=cfg.get("stop_time"))
        self._values = {}  # input name -> its values (the start values until set)
        for name, comps, start in cfg["inputs"]:
            self._values[name] = np.array(start, dtype=float)
            for i, comp in enumerate(comps):
                self.register_variable(Real(
                    comp, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous,
                    getter=self._input_getter(name, i), setter=self._input_setter(name, i)),
                    nested=False)
        for channel in cfg["outputs"]:
            self.register_variable(Real(
                channel, causality=Fmi2Causality.output,
                variability=Fmi2Variability.continuous,
                getter=(lambda ch=channel: self.sim.read(ch))), nested=False)

    def _input_getter(self, name: str, i: int):
        return lambda: float(self._values[name][i])

    def _input_setter(self, name: str, i: int):
        def setter(value) -> None:
            vals = self._values[name].copy()
            vals[i] = value
            self.sim.set_input(name, vals if len(vals) > 1 else float(vals[0]))
            self._values[name] = vals

        return setter

    def do_step(self, current_time: float, step_size: float) -> bool:
        # (the time of the state reached: the simulator's grid, t_start + k step)
        self.sim.advance(current_time + step_size)
        return True

    def _get_fmu_state(self) -> dict:
        return {"state": self.sim.state,
                "values": {n: v.copy() for n, v in self._values.items()}}

    def _set_fmu_state(self, state: dict) -> None:
        self.sim.restore(state["state"])
        self._values = {n: v.copy() for n, v in state["values"].items()}
