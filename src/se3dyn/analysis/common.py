"""What the analyses share: a model or system argument, joint names to unknowns, zero inputs, the
constraint blocks of an evaluation and the accessors of their result objects.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.engine.evaluate import matrix_values
from se3dyn.engine.linsolve import LinearSolver
from se3dyn.engine.system import System, compile_model
from se3dyn.errors import ModelError, close_matches
from se3dyn.model.specs import Model
from se3dyn.results.results import node_dofs

sla = LazyModule("scipy.linalg")


# =============================================================================================
# shared helpers (also used by se3dyn.analysis.statics)
# =============================================================================================
def _as_system(obj: Any, where: str) -> System:
    """A compiled System from a Model or a System (ModelError naming ``where`` otherwise)."""
    if isinstance(obj, System):
        return obj
    if isinstance(obj, Model):
        return compile_model(obj)
    raise ModelError(where, "model_or_system", "an se3dyn Model or a compiled System",
                     type(obj).__name__)


def _unknown_name(kind: str, name: Any, valid: list[str]) -> str:
    close = close_matches(str(name), valid, n=1)
    hint = f"did you mean '{close[0]}'? " if close else ""
    shown = ", ".join(repr(v) for v in valid[:20]) + (" ..." if len(valid) > 20 else "")
    return f"unknown {kind} {name!r}; {hint}valid: {shown}"


def _joint_ids(s: System, name: Any, item_kind: str, fld: str) -> list[int]:
    """Indices of the joint called ``name`` (the parts of a composite joint, e.g. universal)."""
    names = list(s.joint_names)
    comp = s.composites
    if isinstance(name, str) and name in comp:
        return [names.index(n) for n in comp[name]]
    if isinstance(name, str) and name in names:
        return [names.index(name)]
    valid = [n for n in names if ":" not in n] + list(comp)
    raise ModelError(f"{item_kind} {name!r}", fld, "the name of a joint of the model", name,
                     _unknown_name("joint", name, valid))


def _joint_item(s: System, name: str) -> str:
    ids = _joint_ids(s, name, "joint", "name")
    typ = "universal" if name in s.composites else s.joint_type[ids[0]]
    return f"joint {name!r} ({typ})"


def _zero_inputs(s: System) -> dict:
    """Inputs of :func:`evaluate` with no load at all, not even gravity (assembly)."""
    return dict(u=np.zeros(s.inputs.nu))


class _Blocks:
    """Dense blocks of the matrix of :func:`matrix_values`: ``[[K, Phi_q^T], [B, 0]]``."""

    def __init__(self, s: System):
        self.s = s
        self.solver = LinearSolver(s, dense_max=2000)

    def __call__(self, ev, coef=(0.0, 0.0, 0.0)):
        return self.split(matrix_values(self.s, ev, coef))

    def split(self, values: np.ndarray):
        """``(K, Phi_q^T, B)`` dense, from the values of an evaluation with coefficients."""
        A = self.solver.matrix(values)
        nq = self.s.nq
        if not isinstance(A, np.ndarray):
            A = A.tocsr()
            return (A[:nq, :nq].toarray(), A[:nq, nq:].toarray(), A[nq:, :nq].toarray())
        return A[:nq, :nq], A[:nq, nq:], A[nq:, :nq]


# ---------------------------------------------------------------------------------------------
class _Accessors:
    """Accessors by node and joint name on arrays with a leading axis (one row per configuration).

    Subclasses provide ``system`` and the arrays ``_H`` (n, M, 4, 4), ``_alpha``, ``_v``, ``_vd``
    (n, nq), ``_lam`` (n, nm) and ``_squeeze`` (drop the leading axis for single configurations).
    """

    system: System
    _squeeze: bool = False

    def _out(self, a: np.ndarray) -> np.ndarray:
        return a[0] if self._squeeze else a

    def _node(self, name: str) -> int:
        names = list(self.system.node_names)
        if name in names:
            return names.index(name)
        raise KeyError(_unknown_name("node", name, names))

    def _jids(self, name: str) -> list[int]:
        try:
            return _joint_ids(self.system, name, "joint", "name")
        except ModelError as exc:
            raise KeyError(str(exc)) from None

    def node_position(self, name: str) -> np.ndarray:
        """Position of a node in the inertial frame, shape (n, 3) ((3,) for one configuration)."""
        return self._out(self._H[:, self._node(name), :3, 3].copy())

    def node_rotation(self, name: str) -> np.ndarray:
        """Rotation of a node (material axes in the inertial frame), shape (n, 3, 3) / (3, 3)."""
        return self._out(self._H[:, self._node(name), :3, :3].copy())

    def node_frame(self, name: str) -> np.ndarray:
        """Homogeneous frame of a node, shape (n, 4, 4) / (4, 4)."""
        return self._out(self._H[:, self._node(name)].copy())

    def _node_dof(self, name: str, arr: np.ndarray, frame: str) -> np.ndarray:
        return self._out(node_dofs(self.system, self._H, arr, self._node(name), frame))

    def _joint_cols(self, name: str, arr: np.ndarray) -> np.ndarray:
        s = self.system
        cols = [arr[:, s.joint_dofadr[j]:s.joint_dofadr[j] + s.joint_k[j]]
                for j in self._jids(name) if s.joint_k[j]]
        return self._out(np.concatenate(cols, axis=1) if cols else np.zeros((len(arr), 0)))

    def joint_coordinates(self, name: str) -> np.ndarray:
        """Relative coordinates alpha of a joint (Eq. (60)), measured from the model's initial
        configuration, shape (n, k) / (k,); the parts side by side for a composite joint."""
        return self._joint_cols(name, self._alpha)

    def joint_multipliers(self, name: str) -> np.ndarray:
        """Multipliers of a joint: the reaction wrench (force, moment) on node B in its material
        frame (in its attachment frame ``H_B X_B`` for a joint with ``at``) with the sign of
        Eq. (36), shape (n, 6) / (6,) (6 per part for a composite)."""
        s = self.system
        lam = self._lam
        return self._out(np.concatenate([lam[:, s.joint_multadr[j]:s.joint_multadr[j] + 6]
                                         for j in self._jids(name)], axis=1))


class _OneConfiguration(_Accessors):
    """The accessors of one configuration (``H`` (M, 4, 4), ``alpha`` (nq,)): its arrays seen
    with a leading axis of one, dropped again on output (``_squeeze``)."""

    @property
    def _H(self):
        return self.H[None]

    @property
    def _alpha(self):
        return self.alpha[None]
