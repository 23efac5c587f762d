"""Calibration files of other tools (OpenCV FileStorage, VIC-3D, DICe, pyvale CSV) read as core cameras."""

from fesdic_core.cameras.io.formats import (read_opencv_stereo, write_opencv_stereo, read_vic3d,
                                            read_dice, rotation_from_angles_deg,
                                            OPENCV_DISTORTION_LENGTHS)

__all__ = ["read_opencv_stereo", "write_opencv_stereo", "read_vic3d", "read_dice",
           "rotation_from_angles_deg", "OPENCV_DISTORTION_LENGTHS"]
