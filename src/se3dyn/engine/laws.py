"""Actuator laws of the user's, ``tau = fn(t, q, v)`` on a joint's coordinates
(:class:`se3dyn.model.specs.Law`, ``ModelBuilder.joint(torque=lambda t, q, v: ...)``): the
callback the compiled engine calls once per evaluation (``Engine::law_cb``, engine.hpp), which
writes every law's force and its tangents ``d tau / d q``, ``d tau / d v`` into the buffer the
joint-force kernel reads.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from se3dyn.elements.joint_force import law_table

if TYPE_CHECKING:
    from se3dyn.engine.system import System


def _jacobian(fn, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d fn / d q and d fn / d v (k x k) by central differences, steps 1e-7 max(1, |x|)."""
    k = len(q)
    out = []
    for x, which in ((q, 0), (v, 1)):
        J = np.empty((k, k))
        for c in range(k):
            h = 1e-7 * max(1.0, abs(x[c]))
            xp, xm = x.copy(), x.copy()
            xp[c] += h
            xm[c] -= h
            args_p = (t, xp, v) if which == 0 else (t, q, xp)
            args_m = (t, xm, v) if which == 0 else (t, q, xm)
            J[:, c] = (np.broadcast_to(np.asarray(fn(*args_p), dtype=float), (k,))
                       - np.broadcast_to(np.asarray(fn(*args_m), dtype=float), (k,))) / (2 * h)
        out.append(J)
    return out[0], out[1]


def law_callback(s: System):
    """The engine's callback ``cb(t, alpha (nq,), v (nq,), out)`` for the laws of ``s``, or None
    without laws. A law that raises or gives a wrong or non-finite value writes NaN (the step
    then fails) and leaves its message in the callback's ``error``, which the failure names
    (:meth:`se3dyn.engine.workspace.Workspace.law_error`)."""
    laws, _ = law_table(s)
    if not laws:
        return None

    def cb(t, alpha, v, out):
        for name, dofs, law, off in laws:
            k = len(dofs)
            q, w = alpha[dofs].copy(), v[dofs].copy()
            try:
                f = np.broadcast_to(np.asarray(law.fn(t, q, w), dtype=float), (k,))
                if law.jacobian is None:
                    Jq, Jv = _jacobian(law.fn, t, q, w)
                else:
                    Jq, Jv = (np.asarray(x, dtype=float).reshape(k, k)
                              for x in law.jacobian(t, q, w))
                vals = np.concatenate([f, Jq.ravel(), Jv.ravel()])
                if not np.all(np.isfinite(vals)):
                    raise ValueError(f"non-finite values {f}")
            except Exception as exc:  # user code: anything; the failing step names it
                cb.error = (f"joint '{name}': its law f(t, q, v) at t={t:.9g}, "
                                          f"q={q}, v={w}: {type(exc).__name__}: {exc}")
                out[off:off + k + 2 * k * k] = np.nan
                continue
            out[off:off + k + 2 * k * k] = vals
    cb.error = None
    return cb
