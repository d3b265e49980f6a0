"""Measurement kinds: the data a calibration reads and what each kind predicts.

One module per kind, sharing the interface of :mod:`.kind`: :mod:`.point` (3-D points
on the tool; :mod:`.data` reads them), :mod:`.pose` (6-DoF tool poses), :mod:`.distance`
(distances to a fixed pivot), :mod:`.plane` (contacts with planes). :mod:`.sets` builds a
set's model and tells a file's kind from its columns."""

from kincal.lazy import lazy_names

__all__ = ["Measurements", "PoseData", "DistanceData", "PlaneData", "FlushData", "SampleSet", "KindModel",
           "read_set_file", "kind_model", "kind_of", "KINDS"]
__getattr__, __dir__ = lazy_names(__name__, {
    "Measurements": "data", "PoseData": "pose", "DistanceData": "distance",
    "PlaneData": "plane", "FlushData": "flush", "SampleSet": "kind", "KindModel": "kind", "read_set_file": "sets",
    "kind_model": "sets", "kind_of": "sets", "KINDS": "sets"})
