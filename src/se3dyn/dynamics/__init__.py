"""Time integration: the state (``state``), the Lie-group generalized-alpha step with Newton
(``integrator``), step-size control (``stepcontrol``), the condensation of rigid groups
(``condense``) and the run driver with its recorder (``run``)."""
