"""Experiments that reproduce the seed paper (not part of the calibration core)."""
