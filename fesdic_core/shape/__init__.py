"""The shape measurement: Eqs. 7-8 at fixed cameras, calibration (Eq. 6), the gauge, the multiscale fixed point and its uncertainty."""

from fesdic_core.shape.calibration import (CalibrationResult, truncated_solve, rigid_rig_gradients,
                                           calibrate_extrinsics)
from fesdic_core.shape.driver import measure, conclude, MeasurementInputError
from fesdic_core.shape.gauge import (TANGENTIAL_RTOL, rigid_normal_modes, checked_weights,
                                     split_rigid_part, move_cameras_with_specimen,
                                     transfer_rigid_part, tangential_motions, pose_directions,
                                     best_fit_plane_distance, rigid_align)
from fesdic_core.shape.operators import (current_nodes, shape_operators, GaussNewtonLog,
                                         ShapeResult, chi_square, chi_square_change,
                                         predicted_chi_square_change, shape_gauss_newton)
from fesdic_core.shape.settings import (SHAPE_MAX_INVALID_SHARE, Measurement, MeasurementSettings,
                                        ScaleReport)
from fesdic_core.shape.uncertainty import (NoiseModel, LinearisedState, linearised_state,
                                           noise_model, shape_std)
from fesdic_core.shape.validity import shape_validity
from fesdic_core.shape.verdict import ShapeDivergedError, VerdictSettings, judge

__all__ = ["CalibrationResult", "truncated_solve", "rigid_rig_gradients", "calibrate_extrinsics",
           "measure", "conclude", "MeasurementInputError", "TANGENTIAL_RTOL", "rigid_normal_modes",
           "checked_weights", "split_rigid_part", "move_cameras_with_specimen",
           "transfer_rigid_part", "tangential_motions", "pose_directions",
           "best_fit_plane_distance", "rigid_align", "current_nodes", "shape_operators",
           "GaussNewtonLog", "ShapeResult", "chi_square", "chi_square_change",
           "predicted_chi_square_change", "shape_gauss_newton", "Measurement",
           "MeasurementSettings", "ScaleReport", "NoiseModel", "LinearisedState",
           "linearised_state", "noise_model", "shape_std", "ShapeDivergedError", "VerdictSettings",
           "judge", "shape_validity", "SHAPE_MAX_INVALID_SHARE"]
