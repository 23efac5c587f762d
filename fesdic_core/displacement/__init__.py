"""3-D displacements of the measured surface from a series of stereo pairs, and their surface strains."""

from fesdic_core.displacement.driver import (JACOBIANS, MIN_POINTS_PER_ELEMENT,
                                             DisplacementSettings, DisplacementReference,
                                             DisplacementMeasurement, DisplacementGNResult,
                                             displacement_reference, displacement_gauss_newton,
                                             measure_displacement, displacement_verdict)
from fesdic_core.displacement.residual import (ReferenceView, DisplacementResidual, reference_view,
                                               reference_jacobian, displacement_residual,
                                               displacement_operators, displacement_rhs,
                                               component_dofs)
from fesdic_core.displacement.solvers import componentwise, ComponentTikhonovSolver
from fesdic_core.displacement.smooth_fit import FieldFit, fit_field
from fesdic_core.displacement.start import (StartSettings, FeatureReference, StartReport,
                                            FeatureStart, feature_reference, feature_start,
                                            start_residual_percent, coarse_noise_percent,
                                            image_shift_px)
from fesdic_core.displacement.strain import tangent_frame, surface_green_lagrange, RECOVERIES
from fesdic_core.displacement.validity import (node_blocks, residual_blocks, hessian_blocks,
                                               displacement_validity)

__all__ = ["JACOBIANS", "MIN_POINTS_PER_ELEMENT", "DisplacementSettings", "DisplacementReference",
           "DisplacementMeasurement", "DisplacementGNResult", "displacement_reference",
           "displacement_gauss_newton", "measure_displacement", "displacement_verdict", "ReferenceView", "DisplacementResidual",
           "reference_view", "reference_jacobian", "displacement_residual",
           "displacement_operators", "displacement_rhs", "component_dofs", "componentwise",
           "ComponentTikhonovSolver", "StartSettings", "FeatureReference", "StartReport",
           "FeatureStart", "FieldFit", "feature_reference", "feature_start", "fit_field",
           "start_residual_percent", "coarse_noise_percent", "image_shift_px", "tangent_frame",
           "surface_green_lagrange", "RECOVERIES", "node_blocks", "residual_blocks", "hessian_blocks",
           "displacement_validity"]
