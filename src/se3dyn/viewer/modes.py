"""Mode shapes as motions the viewer plays (issue 32, item 2): ``se3dyn modes MODEL``.

A mode of a linearisation (:meth:`se3dyn.analysis.linearize.Linearization.modes`) is a complex
shape ``phi`` over the model's unknowns (``full_shapes``: node increments in the material
frames, Eq. (38), and joint coordinates). Its animation is the motion ``n(t) = a Re(phi
e^(i theta))``, ``theta = 2 pi t / period``, over one period: node frames ``H_0 exp(n)``
(Eq. (38)), joint coordinates ``alpha_0 + n`` (Eq. (60)). A complex mode (damped or gyroscopic)
shows its travelling phase; the amplitude ``a`` makes the largest node translation a tenth of
the model's size (or its largest rotation 0.3 rad), as structural viewers scale modes.
"""

from __future__ import annotations

import numpy as np

from se3dyn import lie
from se3dyn.engine.scaling import _char_length
from se3dyn.errors import ModelError
from se3dyn.results.results import Results


def mode_results(lin, mode: int, *, frames: int = 48, period: float = 2.0,
                 amplitude: float | None = None) -> Results:
    """One period of mode ``mode`` of ``lin`` as :class:`~se3dyn.Results` (frames, joint
    coordinates; velocities, multipliers and energies zero) for :func:`se3dyn.viewer.
    write_html`.

    Parameters
    ----------
    lin : Linearization
    mode : int
        Index into ``lin.modes()`` (0: the slowest).
    frames : int
        Rows over the period.
    period : float
        Duration of the animation (s), whatever the mode's own frequency.
    amplitude : float, optional
        Scale of the (peak-normalised) shape; by default a tenth of the model's size in the
        largest node translation, or 0.3 rad in the largest rotation.
    """
    md = lin.modes()
    if isinstance(mode, bool) or not isinstance(mode, int | np.integer) or not (
            0 <= mode < len(md)):
        raise ModelError("modes", "mode", f"a mode index from 0 to {len(md) - 1}", mode)
    s, p = lin.system, lin._point
    phi = md.full_shapes[:, mode]
    a = _amplitude(s, phi) if amplitude is None else float(amplitude)
    t = np.linspace(0.0, period, frames + 1)
    free = np.flatnonzero(~s.node_fixed)
    dofs = s.node_dofadr[free][:, None] + np.arange(6)
    n = len(t)
    H = np.repeat(p.H[None], n, axis=0)
    alpha = np.repeat(p.alpha[None], n, axis=0)
    joint = np.flatnonzero(s.dof_is_joint)
    for k, th in enumerate(2 * np.pi * t / period):
        x = a * (phi * np.exp(1j * th)).real
        H[k, free] = lie.box_plus(p.H[free], x[dofs])
        alpha[k, joint] += x[joint]
    z, zn = np.zeros((n, s.nq)), np.zeros(n)
    return Results(system=s, t=t, H=H, v=z, vd=z.copy(), lam=np.zeros((n, s.nm)), alpha=alpha,
                   kinetic=zn, potential=zn, spring=zn, work_actuators=zn, work_loads=zn,
                   dissipation=zn, iterations=np.zeros(n, int), residual=zn, constraint=zn,
                   stats=dict(mode=int(mode), omega=float(md.omega[mode]),
                              frequency=float(md.frequency[mode]), amplitude=a))


def _amplitude(s, phi: np.ndarray) -> float:
    """A tenth of the model's size over the largest node translation of ``phi``, or 0.3 rad
    over its largest rotation (joint coordinates count as rotations), the smaller."""
    free = np.flatnonzero(~s.node_fixed)
    dofs = s.node_dofadr[free][:, None] + np.arange(6)
    mags = np.abs(phi)
    trans = float(mags[dofs[:, :3]].max(initial=0.0))
    rot = max(float(mags[dofs[:, 3:]].max(initial=0.0)),
              float(mags[s.dof_is_joint].max(initial=0.0)))
    size = _char_length(s)  # (the largest distance of a node from the centroid)
    scales = [x for x in (0.1 * size / trans if trans > 0 else None,
                          0.3 / rot if rot > 0 else None) if x is not None]
    return min(scales) if scales else 1.0
