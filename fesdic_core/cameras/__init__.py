"""Cameras and the stereo rig: the projection P_c of Eq. 3, its Jacobians, and calibration files."""

from fesdic_core.cameras.camera import Camera, Linearisation, rodrigues
from fesdic_core.cameras.io import (read_opencv_stereo, write_opencv_stereo, read_vic3d, read_dice,
                                    rotation_from_angles_deg, OPENCV_DISTORTION_LENGTHS)
from fesdic_core.cameras.rig import (CalibrationError, stereo_transform, place_camera1,
                                     apply_stereo, stereo_extrinsic_jacobian, read_cameras_json,
                                     write_cameras_json, read_pyvale_csv, initial_pose,
                                     initial_rig_pose)
from fesdic_core.cameras.triangulation import (StereoPoints, normalised_points,
                                               epipolar_distance_px, triangulate, Features,
                                               detect_features, match_descriptors, match_features,
                                               stereo_points, depth_per_px)
from fesdic_core.cameras.icp import TriangleSurface, IcpResult, point_to_plane_icp
from fesdic_core.cameras.icp_start import principal_axes_starts, best_start

__all__ = ["Camera", "Linearisation", "rodrigues", "read_opencv_stereo", "write_opencv_stereo",
           "read_vic3d", "read_dice", "rotation_from_angles_deg", "OPENCV_DISTORTION_LENGTHS",
           "CalibrationError", "stereo_transform", "place_camera1", "apply_stereo",
           "stereo_extrinsic_jacobian", "read_cameras_json", "write_cameras_json",
           "read_pyvale_csv", "initial_pose", "initial_rig_pose", "StereoPoints", "normalised_points",
           "epipolar_distance_px", "triangulate", "Features", "detect_features",
           "match_descriptors", "match_features", "stereo_points", "depth_per_px",
           "TriangleSurface", "IcpResult", "point_to_plane_icp", "principal_axes_starts",
           "best_start"]
