"""The compiled system and its evaluation: numbering and :class:`~se3dyn.engine.system.System`
(``system``), the time-function inputs of a step (``inputs``), the element tables and the
pattern (``layout``), the compiled engine's handle and the per-run workspace (``workspace``),
residual, tangent and constraint evaluation (``evaluate``), the dense/sparse linear solver
(``linsolve``), the solver memory of a restart (``memory``), threads (``threads``), the
scaling of unknowns (``scaling``), constraint rank and redundancy (``rank``) and the velocity
projection (``projection``). It knows no time loop."""
