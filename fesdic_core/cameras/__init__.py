"""Cameras and the stereo rig: the projection P_c of Eq. 3, its Jacobians, and calibration files."""
