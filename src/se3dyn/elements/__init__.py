"""The element library: one module per element type, each registered here under the key of its
compiled kernel (``se3dyn/_core/elements/<key>.hpp``, listed in ``registry.hpp``).

A module provides

* ``KEY``: the type key;
* ``tables(s, lay) -> dict``: its struct-of-arrays batch for the kernel (from the compiled
  :class:`~se3dyn.engine.system.System` ``s``), declaring its dof map to the assembler ``lay``
  (:class:`se3dyn.engine.layout.Layout`): the blocks of the iteration matrix it writes
  (``lay.block``), the blocks that carry velocity-level terms (``lay.velocity_block``) and, for
  constraint elements, the frames the constraints act on (``lay.constraint``);
* ``examples(rng) -> list[Model]``: small models exercising every option of the type, on which
  the contract test (``tests/test_elements.py``) checks the kernel: tangent blocks against
  central finite differences of the residual, invariance under a superposed rigid motion, zero
  constraint violation and power along allowed motions (constraints), power of the internal
  forces equal to -dE/dt (conservative elements);
* ``TRAITS``: which of those checks apply (``conservative``, ``constraint``, ``objective``:
  invariant under a superposed rigid motion, i.e. no inertial-frame data such as gravity).

The order of the registry is the order of the batches in the engine.
"""

from __future__ import annotations

from se3dyn.elements import beam, body, bushing, contact, joint, joint_force, load, spring_damper

#: type key -> module, in engine order (and in the order of the model-file sections: beams
#: create nodes that joints, springs and loads may use)
REGISTRY = {m.KEY: m for m in (body, beam, joint, joint_force, load, spring_damper, bushing,
                               contact)}

__all__ = ["REGISTRY"]
