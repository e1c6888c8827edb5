"""URDF import: :func:`load_urdf` reads a robot description into a
:class:`~se3dyn.model.builder.ModelBuilder` (docs/urdf.md).

Modules: :mod:`~se3dyn.io.urdf.parse` (the XML, entity declarations refused, every value
checked), :mod:`~se3dyn.io.urdf.tree` (the link tree and its forward kinematics),
:mod:`~se3dyn.io.urdf.geometry` (rpy, joint motions, rotated inertias),
:mod:`~se3dyn.io.urdf.loops` (loop closures), :mod:`~se3dyn.io.urdf.meshes` (mesh paths),
:mod:`~se3dyn.io.urdf.build` (the model).
"""

from se3dyn.io.urdf.build import JointLimits, UrdfBuilder, UrdfInfo, load_urdf
from se3dyn.io.urdf.parse import MAX_LINKS, UrdfError

__all__ = ["load_urdf", "UrdfBuilder", "UrdfInfo", "JointLimits", "UrdfError", "MAX_LINKS"]
