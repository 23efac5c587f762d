"""Calibration files of other tools (OpenCV FileStorage, VIC-3D, DICe, pyvale CSV) read as core cameras."""
