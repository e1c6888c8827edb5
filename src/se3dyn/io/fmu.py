"""FMI 2.0 co-simulation export (issue 30 item 6): :func:`export_fmu` packs a model into an FMU
whose slave is a :class:`~se3dyn.dynamics.simulator.Simulator` (:mod:`se3dyn.io.fmu_slave`),
built with pythonfmu; ``se3dyn export-fmu MODEL -o model.fmu`` on the command line (the
:data:`SIMULATOR_SETTINGS` of the model file's ``simulation:`` section apply).

The FMU holds the model as a model file (built-in time functions only), the settings, the
slave's Python module and pythonfmu's binary for Linux and Windows (x86-64). It runs in the
importing tool's process through that binary, which starts the Python found on the machine:
the importing machine needs Python with se3dyn installed (and numpy, scipy); pythonfmu itself
travels inside the FMU (``docs/control.md``, "FMU export").

Inputs are the simulator's inputs (:attr:`Simulator.inputs`), one FMI variable per component
(``joint/j1/actuator``; ``load/push/force/x``; ``joint/j/actuator/0`` for multi-coordinate
joints), held from the master's first ``fmi2SetReal`` on; outputs are results channels
(default: every joint coordinate and rate and every marker position). The model description
lists both with their units and uses flat variable names (the channel names as they are).
"""

from __future__ import annotations

import json
import os
import re
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from se3dyn.errors import ModelError

if TYPE_CHECKING:
    from se3dyn.model.specs import Model

__all__ = ["export_fmu", "SIMULATOR_SETTINGS"]

#: The settings of a model file's ``simulation:`` section that the FMU's simulator takes.
SIMULATOR_SETTINGS = ("step", "rho_inf", "t_start", "tol_residual", "tol_constraint",
                      "max_iter", "formulation", "redundant", "newton", "initial_velocities",
                      "condense")

#: SI units of the inputs and outputs: exponents of (kg, m, s, rad) for the model description.
_BASE = {"m": (0, 1, 0, 0), "rad": (0, 0, 0, 1), "m/s": (0, 1, -1, 0), "rad/s": (0, 0, -1, 1),
         "m/s^2": (0, 1, -2, 0), "rad/s^2": (0, 0, -2, 1), "N": (1, 1, -2, 0),
         "N m": (1, 2, -2, 0), "J": (1, 2, -2, 0), "s": (0, 0, 1, 0), "N s/m": (1, 0, -1, 0)}


def export_fmu(model: Model | str | os.PathLike, path: str | os.PathLike, *,
               step: float | None = None, outputs: list[str] | None = None,
               stop_time: float | None = None, **settings) -> Path:
    """Write an FMI 2.0 co-simulation FMU of ``model`` to ``path`` (see the module docstring).

    Parameters
    ----------
    model : Model or path of a model file
        A model file's ``simulation:`` settings are used where they apply
        (:data:`SIMULATOR_SETTINGS`; keywords given here take precedence).
    path : path of the ``.fmu`` file to write
    step : float
        The simulator's step (s); communication steps must be multiples of it.
    outputs : list of str, optional
        Results channels to output (``se3dyn.results.channels``); default: every joint
        coordinate and rate, every marker position.
    stop_time : float, optional
        The default experiment's stop time.
    **settings :
        Further keywords of :class:`~se3dyn.dynamics.simulator.Simulator`.

    Returns
    -------
    Path of the FMU written. Raises :class:`~se3dyn.errors.ModelError` for a model that cannot
    be written (a Python callable as time function), unknown settings or channels, and when
    pythonfmu is not installed (``pip install se3dyn[fmu]``).
    """
    from se3dyn.dynamics.simulator import Simulator
    from se3dyn.engine.system import system_of
    from se3dyn.io.modelfile import load_model, save_model
    from se3dyn.results.channels import channel_unit, list_channels

    try:
        from pythonfmu import FmuBuilder
    except ImportError:
        raise ModelError("export_fmu", "pythonfmu", "pythonfmu installed (pip install "
                         "'se3dyn[fmu]')", "not installed") from None
    if isinstance(model, str | os.PathLike):
        model, file_settings = load_model(model)
        settings = {**{k: v for k, v in file_settings.items() if k in SIMULATOR_SETTINGS},
                    **settings}
    if step is None:
        step = settings.pop("step", None)
    settings.pop("step", None)
    if step is None:
        raise ModelError("export_fmu", "step", "the simulator's step (s)", None)
    sim = Simulator(model, step=step, **settings)  # (checks the model and the settings)
    res = sim.results()
    if outputs is None:
        outputs = [c for c in list_channels(res)
                   if re.fullmatch(r"joint/[^/]+/(alpha|velocity)/\d+|marker/[^/]+/position/."
                                   r"", c)]
    outputs = list(outputs)
    for ch in outputs:
        sim.read(ch)  # (an unknown channel: its error, naming it)
    units = {ch: channel_unit(ch, res) for ch in outputs}
    inputs = _inputs(sim, system_of(model), units)
    ident = re.sub(r"\W", "_", model.name or "model")
    ident = ident if re.match(r"[A-Za-z]", ident) else f"model_{ident}"
    cfg = dict(settings={**settings, "step": sim.h}, outputs=outputs,
               inputs=[(n, comps, start) for n, comps, start in inputs],
               stop_time=stop_time, description=f"se3dyn model {model.name!r}: a Simulator "
               f"with step {sim.h:g} s")
    path = Path(path)
    from se3dyn.io.fmu_slave import MODEL_FILE, SETTINGS_FILE

    with tempfile.TemporaryDirectory(prefix="se3dyn_fmu_") as tmp:
        tmp = Path(tmp)
        save_model(model, tmp / MODEL_FILE)
        (tmp / SETTINGS_FILE).write_text(json.dumps(cfg, indent=1), encoding="utf-8")
        script = tmp / f"se3dyn_fmu_{ident}.py"
        script.write_text(
            f'"""The FMU slave of the se3dyn model {model.name!r} (se3dyn.io.fmu)."""\n'
            "from se3dyn.io.fmu_slave import Se3dynSlave\n\n\n"
            f"class {ident}(Se3dynSlave):\n    pass\n", encoding="utf-8")
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            # (canBeInstantiatedOnlyOncePerProcess: pythonfmu 0.7's binary releases the slave
            # module it imported once too often when an instance is freed, and the next
            # instance in the same process fails, "module has no attribute ...": pythonfmu
            # issue 228; said in the model description so that importers use a process each)
            built = FmuBuilder.build_FMU(script, dest=tmp / "out", project_files=[
                tmp / MODEL_FILE, tmp / SETTINGS_FILE], canGetAndSetFMUstate=True,
                canBeInstantiatedOnlyOncePerProcess=True)
        finally:
            # the builder imports the slave module from the temporary folder and leaves both
            # in sys.modules and sys.path: the FMU must import its own copy
            sys.modules.pop(script.stem, None)
            while str(tmp) in sys.path:
                sys.path.remove(str(tmp))
        comp_units = {c: units[n] for n, comps, _ in inputs for c in comps}
        _describe(built, path, {**units, **comp_units})
    return path


def _inputs(sim, s, units: dict) -> list[tuple[str, list[str], list[float]]]:
    """(name, component variable names, start values: the model's at t_start) of the inputs
    of the simulator ``sim`` of the system ``s``; their units into ``units`` (by name)."""
    from se3dyn.results.channels import joint_units, unescape_name

    k = np.asarray(s.joint_k, dtype=int)
    start, ju = np.cumsum(k) - k, joint_units(s)
    coord = {name: ju[start[j]:start[j] + k[j]] for j, name in enumerate(s.joint_names)}
    out = []
    for name, n in sim.inputs.items():
        parts = name.split("/")
        if parts[0] != "joint":  # gravity, load forces and torques
            comps = [f"{name}/{c}" for c in "xyz"]
            units[name] = {"force": "N", "torque": "N m"}.get(parts[-1], "m/s^2")
        else:
            comps = [name] if n == 1 else [f"{name}/{i}" for i in range(n)]
            base = (coord.get(unescape_name(parts[1])) or ("rad",))[0] or "rad"
            units[name] = {"actuator": "N m" if base == "rad" else "N", "target": base,
                           "target_rate": f"{base}/s"}[parts[-1]]
        out.append((name, comps, [float(x) for x in sim.input_value(name)]))
    return out


def _describe(built: Path, path: Path, units: dict) -> None:
    """Copy the FMU ``built`` to ``path`` with its model description completed: flat variable
    names (the channel names), the unit of every variable and their definitions."""
    import xml.etree.ElementTree as ET

    with zipfile.ZipFile(built) as zin:
        entries = {i.filename: zin.read(i) for i in zin.infolist()}
    root = ET.fromstring(entries["modelDescription.xml"])
    root.set("variableNamingConvention", "flat")
    used = set()
    for sv in root.iter("ScalarVariable"):
        unit = units.get(sv.get("name"))
        real = sv.find("Real")
        if unit and real is not None:
            real.set("unit", unit)
            used.add(unit)
    if used:
        defs = ET.Element("UnitDefinitions")
        for u in sorted(used):
            el = ET.SubElement(defs, "Unit", name=u)
            if u in _BASE:
                kg, m, s, rad = _BASE[u]
                ET.SubElement(el, "BaseUnit", {k: str(v) for k, v in
                                               (("kg", kg), ("m", m), ("s", s), ("rad", rad))
                                               if v})
        after = [i for i, el in enumerate(root) if el.tag in ("CoSimulation", "ModelExchange")]
        root.insert(max(after) + 1 if after else 0, defs)
    entries["modelDescription.xml"] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zout:
        for name, data in entries.items():
            zout.writestr(name, data)
