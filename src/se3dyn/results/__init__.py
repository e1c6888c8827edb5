"""Results of a run in memory (``results``) and their stable channel names and units
(``channels``)."""

from se3dyn.results.results import Results

__all__ = ["Results"]
