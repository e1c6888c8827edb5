"""What the user describes, with names: the builder, the frozen specs and the model, joint types,
time functions, beam sections, visual shapes and the example models (the lowest layer above
:mod:`se3dyn.lie` and :mod:`se3dyn.errors`)."""

from se3dyn.model.builder import ModelBuilder
from se3dyn.model.specs import (
    PD,
    PID,
    BeamSpec,
    BushingSpec,
    JointSpec,
    LoadSpec,
    Model,
    NodeSpec,
    SpringDamperSpec,
)

__all__ = ["ModelBuilder", "Model", "NodeSpec", "JointSpec", "LoadSpec", "PD", "PID",
           "SpringDamperSpec", "BushingSpec", "BeamSpec"]
