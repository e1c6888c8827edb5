"""One evaluation of the compiled system at a configuration: the residual (Eq. (39)), the
constraints (Eqs. (54)-(56)) and the values of the iteration matrix (Eq. (46), scaled as described
in :mod:`se3dyn.engine.system`), with the fixed sparsity pattern (:func:`pattern`) they fill.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.engine.workspace import Workspace, engine_of, layout_of

if TYPE_CHECKING:
    from se3dyn.engine.system import System

sla = LazyModule("scipy.linalg")
sp = LazyModule("scipy.sparse")
spla = LazyModule("scipy.sparse.linalg")


def _pattern(s: System, index2: bool = False) -> dict:
    """Fixed sparsity pattern of the iteration matrix in CSC storage and the map ``inv`` of each
    value, in the order the engine writes them (:mod:`se3dyn.engine.layout`), to its slot there
    (blocks do not overlap: one slot per value)."""
    lay = layout_of(s)
    N = s.nq + (2 * s.nm if index2 else s.nm)
    indptr, indices, inv = lay.csc(index2)
    return dict(inv=inv, nnz=len(indices), indices=indices, indptr=indptr.astype(np.int32),
                nvals=len(inv), N=N)


def pattern_entries(s: System, index2: bool = False) -> tuple:
    """(N, rows, cols): the matrix size and the row and column (nvals,) of every value."""
    lay = layout_of(s)
    N = s.nq + (2 * s.nm if index2 else s.nm)
    return (N, *lay.entries(index2))


def pattern(s: System, index2: bool = False) -> dict:
    """The (cached) pattern of the index-3 or the stabilized index-2 iteration matrix."""
    key = "index2" if index2 else "index3"
    if key not in s.pattern:
        s.pattern[key] = _pattern(s, index2)
    return s.pattern[key]


# ---------------------------------------------------------------------------------------------
@dataclass
class Evaluation:
    """Everything evaluated at one Newton iterate.

    Attributes
    ----------
    H : (M, 4, 4) node frames; HJ : (m, 4, 4) joint transformations
    r : (nq,) residual of Eq. (39); phi : (nm,) constraints Eq. (55)
    alpha : (nq,) relative coordinates (joint unknowns; zero on node unknowns)
    f_scale : float, magnitude of the forces entering r (for relative tolerances)
    values : (nvals,) iteration-matrix values in pattern order, or None
    psi : (nm,) velocity constraints ``Phi_q v`` (only when asked for), or None
    energy : (6,) kinetic, potential, elastic energy and the actuator, load and dissipation
        powers of the iterate (see :func:`se3dyn.dynamics.integrator.energies`)
    """

    H: np.ndarray
    HJ: np.ndarray
    r: np.ndarray
    phi: np.ndarray
    alpha: np.ndarray
    f_scale: float
    values: np.ndarray | None = None
    cache: dict | None = field(default=None, repr=False)
    psi: np.ndarray | None = None
    energy: np.ndarray | None = None
    arhs: np.ndarray | None = None
    #: (2 npid,) the PID laws' states of the iterate (``State.ctrl``, joint_force.hpp)
    ctrl: np.ndarray | None = None


def evaluate(s: System, Hn: np.ndarray, HJn: np.ndarray, alpha_n: np.ndarray, n: np.ndarray,
             v: np.ndarray, vd: np.ndarray, lam: np.ndarray, inputs: dict,
             coef: tuple[float, float, float] | None = None, *,
             full_alpha: bool = True, velocity: bool = False, stab: dict | None = None,
             accel: bool = False, ws: Workspace | None = None) -> Evaluation:
    """Evaluate the residual, the constraints and (if ``coef``) the scaled iteration matrix by
    the element kernels of the compiled engine (one implementation, :mod:`se3dyn.engine.layout`).

    Parameters
    ----------
    s : System
    Hn : (M, 4, 4), HJn : (m, 4, 4)
        Frames at the start of the step; the iterate is ``H = Hn exp(n)`` (Eq. (38)).
    alpha_n : (nq,)
        Relative coordinates at the start of the step (joint unknowns).
    n, v, vd : (nq,)
        Increments (Eq. (41)), velocities and accelerations of the iterate.
    lam : (nm,)
        Multipliers.
    inputs : dict
        ``u`` (nu,): the time-dependent inputs at the end of the step (:func:`se3dyn.
        integrator.step_inputs`).
    coef : (cM, cC, cK) or None
        Coefficients of M, C_T and K_T T in the iteration matrix (``(1, gamma'/beta', 1/beta')``
        for the scaled Newton matrix; ``(1, 0, 0)`` for the initial accelerations).
    full_alpha : bool
        Compute the log coordinates of non-abelian joints (outputs) too.
    velocity : bool
        Also evaluate the velocity constraints ``psi = Phi_q v`` (nm,) (index 2).
    stab : dict or None
        With ``coef``: the stabilized index-2 matrix, ``cv`` = 1/gamma' (its blocks ``B_n``
        come from the frames at the start of the step, ``Hn``/``HJn``).
    accel : bool
        Also evaluate the right-hand side ``arhs`` (nm,) of the acceleration-level constraints
        ``Phi_q vd = arhs`` (the time derivative of ``Phi_q v = 0``).
    ws : Workspace, optional
        The workspace whose engine evaluates (the system's default one otherwise).

    Returns
    -------
    Evaluation
    """
    eng, lay = engine_of(s, ws)
    F = s.M + s.m
    Hall = np.ascontiguousarray(np.concatenate([Hn, HJn]).reshape(F, 4, 4), dtype=float)
    Hout = np.empty_like(Hall)
    r = np.empty(s.nq)
    phi = np.empty(s.nm)
    alpha = np.zeros(s.nq)
    idx2 = stab is not None
    psi = np.empty(s.nm) if (velocity or idx2) else None
    vals = None
    if coef is not None:
        vals = np.empty(lay.nvals2 if idx2 else lay.nvals)
    energy = np.empty(6)
    arhs = np.empty(s.nm)
    ctrl = np.zeros(s.inputs.nctrl)
    c = (0.0, 0.0, 0.0) if coef is None else coef
    u = np.ascontiguousarray(inputs["u"], dtype=float)
    f = lambda x: np.ascontiguousarray(x, dtype=float)  # noqa: E731
    fs = eng.evaluate(Hall, f(alpha_n), f(n), f(v), f(vd), f(lam), u, Hout, r, phi, alpha,
                      psi, vals, energy, float(c[0]), float(c[1]), float(c[2]), idx2,
                      float(stab["cv"]) if idx2 else 0.0, bool(full_alpha),
                      arhs if accel else None, ctrl)
    ev = Evaluation(H=Hout[:s.M], HJ=Hout[s.M:], r=r, phi=phi, alpha=alpha, f_scale=fs,
                    values=vals, psi=psi if (velocity or idx2) else None, energy=energy,
                    arhs=arhs if accel else None, ctrl=ctrl)
    ev.cache = dict(args=(Hn, HJn, alpha_n, n, v, vd, lam, inputs), full_alpha=full_alpha)
    return ev


def increment_correction(s: System, Hn: np.ndarray, HJn: np.ndarray, xi: np.ndarray
                         ) -> np.ndarray:
    """``B_n^T xi`` (nq,): the increment correction of the stabilized index-2 formulation, with
    ``B_n`` the constraint gradient of Eq. (58) at the frames ``Hn`` (M, 4, 4), ``HJn`` (m, 4,
    4) of the start of the step."""
    eng, _ = engine_of(s)
    F = s.M + s.m
    Hall = np.ascontiguousarray(np.concatenate([Hn, HJn]).reshape(F, 4, 4), dtype=float)
    out = np.empty(s.nq)
    eng.BnT(Hall, np.ascontiguousarray(xi, dtype=float), out)
    return out


def matrix_values(s: System, ev: Evaluation, coef: tuple[float, float, float],
                  stab: dict | None = None) -> np.ndarray:
    """Values of the scaled iteration matrix (Eq. (46)) at an evaluated iterate, pattern order
    (the element kernels evaluated again at the same iterate, see :func:`evaluate`)."""
    Hn, HJn, alpha_n, n, v, vd, lam, inputs = ev.cache["args"]
    return evaluate(s, Hn, HJn, alpha_n, n, v, vd, lam, inputs, coef,
                    full_alpha=ev.cache["full_alpha"], stab=stab).values
