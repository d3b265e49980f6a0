"""Experiments that reproduce the seed paper (not part of the calibration core)."""

from kincal.lazy import lazy_names

__all__ = ["ExperimentConfig", "ExperimentResult", "run", "run_many", "tables", "demo",
           "write_report"]
__getattr__, __dir__ = lazy_names(__name__, {
    **{n: "paper_experiment" for n in ("ExperimentConfig", "ExperimentResult", "run", "run_many")},
    **{n: "paper_report" for n in ("tables", "demo", "write_report")}})
