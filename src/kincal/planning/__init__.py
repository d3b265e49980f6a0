"""Planning measurement campaigns: candidate poses, D-optimal selection, simulation."""

from kincal.lazy import lazy_names

__all__ = ["select_poses", "PoseSelection", "random_candidates", "read_candidates",
           "volume_candidates", "VolumeSpec", "AccuracyMap", "result_accuracy_map",
           "design_accuracy_map"]
__getattr__, __dir__ = lazy_names(__name__, {
    "select_poses": "pose_selection", "PoseSelection": "pose_selection",
    "random_candidates": "candidates", "read_candidates": "candidates",
    "volume_candidates": "volume_candidates", "VolumeSpec": "volume_candidates",
    "AccuracyMap": "accuracy_map", "result_accuracy_map": "accuracy_map",
    "design_accuracy_map": "accuracy_map"})
