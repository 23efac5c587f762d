"""Calibration of a stereo rig from images of a planar target.

:mod:`~fesdic_core.cameras.targets.target` (the targets and their detection),
:mod:`~fesdic_core.cameras.targets.dot_grid` (dot grids with ring markers),
:mod:`~fesdic_core.cameras.targets.boards` (OpenCV's boards and circle grids),
:mod:`~fesdic_core.cameras.targets.calibration` (intrinsics, stereo relation, their
uncertainty, bad views rejected).
"""
from fesdic_core.cameras.targets.target import TARGET_KINDS, Detection, Target, detect

__all__ = ["TARGET_KINDS", "Detection", "Target", "detect"]
