"""Analyses beside the time loop: assembly of inconsistent configurations (``assemble``),
kinematics with inverse dynamics (``kinematics``), static equilibrium (``statics``), and their
shared pieces (``common``). Linearisation and sensitivities will live here."""
