"""Experiments that reproduce the seed paper (not part of the calibration core)."""

from kincal.lazy import lazy_names

__all__ = ["ExperimentConfig", "ExperimentResult", "run", "run_many"]
__getattr__, __dir__ = lazy_names(__name__, {n: "paper_experiment" for n in __all__})
