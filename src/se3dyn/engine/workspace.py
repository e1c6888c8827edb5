"""The scratch of a run: the compiled engine of a system (its element batches with their work
arrays) and the Newton steppers (sparse factors) by formulation and dropped equations
(:class:`Workspace`), and the layout of a system built once (:func:`layout_of`).
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING

import numpy as np

from se3dyn._lazy import LazyModule
from se3dyn.engine.compiled import compiled
from se3dyn.errors import SimulationError

if TYPE_CHECKING:
    from se3dyn.engine.system import System

sla = LazyModule("scipy.linalg")
sp = LazyModule("scipy.sparse")
spla = LazyModule("scipy.sparse.linalg")


def layout_of(s: System):
    """The :class:`se3dyn.engine.layout.Layout` of a system (built once, then only read)."""
    lay = s.pattern.get("layout")
    if lay is None:
        from se3dyn.engine.layout import layout

        lay = s.pattern["layout"] = layout(s)
    return lay


#: Stabilized index-2 steps under modified Newton iterate with a block-triangular part of their
#: Newton matrix (one index-3-sized factorisation and a small one instead of a matrix with
#: twice the separators; a step that contracts too slowly goes on with the full matrix:
#: ``_core/newton.hpp``). The converged steps are the same to the Newton tolerances; False
#: iterates with the full matrix (tests compare the two).
SPLIT_INDEX2 = True


class Workspace:
    """The scratch of a run: the compiled engine of a system (its element batches with their
    work arrays) and the Newton steppers (sparse LU factors) by formulation and set of dropped
    equations. One per run (:func:`se3dyn.simulate` makes its own), so runs of one system never
    share work arrays; :func:`workspace` gives a default one for one-off evaluations.

    Parameters
    ----------
    s : System
    """

    def __init__(self, s: System) -> None:
        self.s = s
        self.layout = layout_of(s)
        self.engine = compiled().Engine(self.layout.tables)
        from se3dyn.engine.laws import law_callback

        cb = self._law_cb = law_callback(s)
        if cb is not None:  # (the user's laws f(t, q, v): engine.hpp, Engine::law_cb)
            self.engine.set_laws(cb)
        self._steppers: dict = {}
        self._memo: dict = {}  # id(stepper) -> (stepper, its serials, SolverMemory it holds)

    def full_matrix_steps(self) -> int:
        """Steps of this workspace's split index-2 steppers done with the full matrix, once the
        split iteration contracted too slowly (``_core/newton.hpp``), over the workspace's
        life."""
        return sum(int(stp.full_steps()) for stp in self._steppers.values())

    def memory(self, stp):
        """The solver memory a stepper holds now (:class:`se3dyn.engine.memory.SolverMemory`, or
        None): a new object only when it changed since last asked."""
        from se3dyn.engine.memory import SolverMemory

        ser = stp.serials()
        c = self._memo.get(id(stp))
        if c is not None and c[0] is stp and c[1] == ser:
            return c[2]
        ref = stp.memory()
        mem = None if ref is None else SolverMemory(ref=ref)
        self._memo[id(stp)] = (stp, ser, mem)
        return mem

    def adopt(self, stp, mem) -> None:
        """Make a stepper hold the solver memory ``mem`` of a State (None: none), refactorising
        when it holds another one (a restart, a step repeated from an earlier state), so that
        the steps from that State give the numbers of the run that produced it, bit for bit."""
        ser = stp.serials()
        c = self._memo.get(id(stp))
        if c is not None and c[0] is stp and c[1] == ser and c[2] is mem:
            return
        ref = None if mem is None else mem.ref
        if ref is not None and len(ref) == stp.memory_size() - 1:
            # an index-2 memory without its mode (results files of se3dyn before the split
            # iteration, 2026-11-23): the full matrix's values, so the full matrix's mode
            ref = np.append(ref, 1.0)
        if not stp.holds(ref):
            code = stp.restore(ref)
            # (ref None: the factorisation of the model's generic matrix may fail, e.g. by
            # overflow along a chain of thousands of links with random frames; the stepper then
            # holds no reference and factorises the first matrix of the run anew, as a new
            # stepper whose generic matrix failed does: the same numbers)
            if code != 0 and ref is not None:
                raise SimulationError("restoring the linear solver's factors of the state failed "
                                      f"(LU status {code}): the state does not belong to this "
                                      "model or was altered")
        self._memo[id(stp)] = (stp, stp.serials(), mem)

    def law_error(self) -> str | None:
        """The message of the last failure of a law of the user's evaluated in this workspace
        (taken: None afterwards), or None."""
        cb = self._law_cb
        if cb is None:
            return None
        err, cb.error = cb.error, None
        return err

    def stepper(self, index2: bool, dropped: np.ndarray, keep: bool = True,
                split: bool = True):
        """The compiled Newton stepper for one formulation and one set of dropped (redundant)
        equations, its sparse LU analysed on first use; ``keep=False``: not kept for later
        calls (a one-off solve, e.g. the initial accelerations of an index-2 run);
        ``split``: index 2 iterates with the split matrix (modified Newton; see
        :data:`SPLIT_INDEX2`)."""
        split = bool(split and index2 and SPLIT_INDEX2)
        key = (bool(index2), np.asarray(dropped, np.int64).tobytes(), split)
        stp = self._steppers.get(key)
        if stp is None:
            s = self.s
            drop = np.zeros(s.nm, np.int64)
            drop[np.asarray(dropped, np.int64)] = 1
            lay = self.layout
            groups = lay.groups2 if index2 else lay.groups3
            N = s.nq + (2 * s.nm if index2 else s.nm)
            # the compiled stepper builds its pattern from the layout's blocks
            # (a one-off stepper solves one matrix: no factorisation of the generic matrix
            # as the reference of refactorisations; its one solve factorises afresh)
            stp = compiled().Stepper(self.engine, bool(index2), int(N), lay.block_table(index2),
                                  np.ascontiguousarray(groups, np.int64), drop,
                                  split=split, reference=keep)
            if keep:
                self._steppers[key] = stp
        return stp


_DEFAULT_WS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def workspace(s: System) -> Workspace:
    """The default :class:`Workspace` of a system, for evaluations outside a run (statics,
    kinematics, analysis, tests); not for concurrent use (give each run its own)."""
    ws = _DEFAULT_WS.get(s)
    if ws is None:
        ws = _DEFAULT_WS[s] = Workspace(s)
    return ws


def engine_of(s: System, ws: Workspace | None = None):
    """The compiled engine of a workspace (the system's default one) and the layout."""
    ws = ws or workspace(s)
    return ws.engine, ws.layout
