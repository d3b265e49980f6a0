"""Measurement kinds: the data a calibration reads and what each kind predicts."""
