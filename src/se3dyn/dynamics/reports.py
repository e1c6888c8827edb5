"""Reports on a run: the energy balance (its error, the energy in play, its largest jump and
the warning naming the likely cause), the initial velocities projected, and the global error
estimate against ``tol``."""

from __future__ import annotations

import dataclasses

import numpy as np

from se3dyn.dynamics.integrator import energies
from se3dyn.dynamics.state import State
from se3dyn.engine.inputs import step_inputs
from se3dyn.engine.system import System
from se3dyn.results.results import Results

__all__ = ["energy_balance_check", "energy_jump", "energy_warning", "energy_cause",
           "energy_rows"]


def _velocity_report(s: System, st: State, kinetic: float, ws, stacklevel: int = 3) -> dict:
    """Stats entries on the initial velocities init changed (and a warning when they matter,
    issued ``stacklevel`` frames up: at the caller of :func:`~se3dyn.dynamics.run.simulate`)."""
    import warnings

    from se3dyn.dynamics.integrator import initial_velocity_changes
    from se3dyn.errors import Se3dynWarning

    changes = initial_velocity_changes(s, st)
    if not changes:
        return dict(initial_velocity_changes=[])
    v0 = np.zeros(s.nq)
    v0[s.node_dofidx] = s.node_v0[s.node_free]
    given = energies(s, dataclasses.replace(st, v=v0), step_inputs(s, st.t), ws)["kinetic"]
    rows = [dict(node=c["node"], dv=c["dv"], dw=c["dw"], given=c["given"].tolist(),
                 used=c["used"].tolist()) for c in changes]
    scale = max(float(np.abs(s.node_v0).max()), 1e-300)
    worst = max(changes, key=lambda c: max(c["dv"], c["dw"]))
    if max(worst["dv"], worst["dw"]) > 1e-6 * scale:
        names = ", ".join(repr(c["node"]) for c in changes[:5]) + (
            f" and {len(changes) - 5} more" if len(changes) > 5 else "")
        drives = sorted({s.model.drives[i].name for i in s.drive_of})
        by = (" and the rates of drive " + ", ".join(repr(d) for d in drives) + " at t0"
              if drives else "")
        warnings.warn(Se3dynWarning(
            f"initial velocities projected onto the joints' velocity constraints{by}: {names} "
            f"changed (largest: node {worst['node']!r}, velocity by {worst['dv']:.3g} m/s, "
            f"angular velocity by {worst['dw']:.3g} rad/s); kinetic energy {given:.6g} J "
            f"given, {kinetic:.6g} J used (stats['initial_velocity_changes']; "
            "initial_velocities='strict' refuses them)"), stacklevel=stacklevel)
    return dict(initial_velocity_changes=rows, initial_kinetic_energy_given=float(given),
                initial_kinetic_energy_used=float(kinetic))


def energy_balance_check(res: Results) -> tuple[float, float]:
    """The largest energy balance error of a run and the energy scale it compares with (J).

    The error is the largest drift of kinetic + potential + elastic energy - work of actuators
    and loads + dissipation from its initial value. The scale is the largest of the kinetic and
    the elastic energy (absolute quantities) and of the changes of the gravity potential (its
    zero is arbitrary), of the works and of the dissipation over the run: the energy in play (a
    pendulum released from rest has no energy at t0, a free spinning body exchanges none).
    """
    if not len(res.t):
        return 0.0, 0.0
    c = energy_rows(res)
    return _balance_and_scale(c, c[0])


def _balance(x: np.ndarray) -> np.ndarray:
    """``E - W_actuators - W_loads + dissipation`` of scalar rows in the order of SCALARS
    (kinetic, potential, spring, actuator work, load work, dissipated), shape (...,)."""
    return x[..., 0] + x[..., 1] + x[..., 2] - x[..., 3] - x[..., 4] + x[..., 5]


def _balance_and_scale(c: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(largest energy balance drift, energy in play) of scalar rows ``c`` (n, >= 6) in the
    order of SCALARS, measured from the first row of the run ``ref`` (6,); see
    :func:`energy_balance_check`."""
    err = float(np.abs(_balance(c[:, :6]) - _balance(ref)).max())
    rel = [1, 3, 4, 5]  # the gravity potential's zero is arbitrary; works start at ref
    scale = max(float(np.abs(c[:, 0]).max()), float(np.abs(c[:, 2]).max()),
                float(np.abs(c[:, rel] - ref[rel]).max()))
    return err, scale


def energy_jump(t: np.ndarray, c: np.ndarray) -> dict | None:
    """Where the energy balance changed most between two consecutive stored rows.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Stored times.
    c : ndarray, shape (n, >= 6)
        Energies and works in the order of :data:`SCALARS` (kinetic, potential, spring,
        actuator work, load work, dissipated).

    Returns
    -------
    dict or None
        ``t0``, ``t1`` (s): the rows around the largest change; ``jump`` (J): the change of
        ``E - W_actuators - W_loads + dissipation`` between them; ``first``: whether they are the
        run's first two rows. None with fewer than two rows.
    """
    c = np.asarray(c, dtype=float)
    if len(c) < 2:
        return None
    d = np.diff(_balance(c))
    k = int(np.argmax(np.abs(d)))
    return dict(t0=float(t[k]), t1=float(t[k + 1]), jump=float(d[k]), first=k == 0)


def energy_warning(err: float, scale: float, jump: dict | None = None) -> str | None:
    """The warning on a large energy balance error (above 10 % of the energy in play), with
    when and how large its largest jump between stored rows was (:func:`energy_jump`); None
    when the balance is fine."""
    if not (err > 0.1 * scale and err > 1e-12):
        return None
    return (f"energy balance error {err:.3g} J is {100 * err / max(scale, 1e-300):.3g} % of "
            f"the energy in play in the run ({scale:.3g} J)" + energy_cause(err, jump))


def energy_cause(err: float, jump: dict | None) -> str:
    """The end of :func:`energy_warning`: the largest jump (when known) and the likely cause,
    starting with ``"; "`` or ``": "``."""
    text = ""
    if jump is not None:
        share = abs(jump["jump"]) / max(err, 1e-300)
        text = (f"; its largest jump, {jump['jump']:+.3g} J ({100 * share:.3g} % of the "
                f"error), between t = {jump['t0']:.6g} and {jump['t1']:.6g} s")
        if jump["first"] and share >= 0.5:
            return text + (" (the first step): a start the step does not resolve, e.g. "
                           "velocities or forces switched on at t0 (an impulsive start), rather "
                           "than a step too large for the motion after it")
    return text + (": the step is probably too large for the motion (the results may be far "
                   "from the true motion; try a smaller step, or rho_inf < 1 with the index-3 "
                   "form)")


def energy_rows(res: Results) -> np.ndarray:
    """The energies and works of a result's rows, (n, 6) in the order of :data:`SCALARS`."""
    return np.stack([res.kinetic, res.potential, res.spring, res.work_actuators,
                     res.work_loads, res.dissipation], axis=1)


def _energy_check(res: Results) -> None:
    import warnings

    from se3dyn.errors import Se3dynWarning

    if "energy_scale" in res.stats:  # over every row, streamed ones included (_Recorder)
        err, scale = res.stats["energy_balance_error"], res.stats["energy_scale"]
    else:
        err, scale = energy_balance_check(res)
        res.stats.update(energy_balance_error=err, energy_scale=scale)
    if energy_warning(err, scale) is None:
        return
    jump = None
    if len(res.t) == res.stats.get("rows", len(res.t)):  # every row held (not streamed)
        jump = energy_jump(res.t, energy_rows(res))
        if jump is not None:
            res.stats["energy_jump"] = jump
    warnings.warn(Se3dynWarning(energy_warning(err, scale, jump)), stacklevel=3)


def _global_error_check(res: Results) -> None:
    import warnings

    from se3dyn.errors import Se3dynWarning

    ge, tol = res.stats.get("global_error"), res.stats.get("tol")
    if ge is not None and tol is not None and ge > tol:
        warnings.warn(Se3dynWarning(
            f"global error estimate {ge:.3g} m is {ge / tol:.3g} times tol = {tol:g} m (largest "
            f"at t = {res.stats['global_error_at']:.6g} s): the motion amplifies the local "
            "errors; a smaller tol brings it down (docs/accuracy.md)"), stacklevel=3)
