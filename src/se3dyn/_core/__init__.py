"""The compiled core: the C++ sources of the engine (``*.hpp``, ``module.cpp``; nanobind) and the
module built from them when se3dyn is installed, :mod:`se3dyn._core._engine`. The lowest layer
with :mod:`se3dyn.lie` (which hands it its series) and :mod:`se3dyn.errors`."""
