"""The gray-level residual of Eq. 3 and where it holds: edges and visibility of the integration points."""

from fesdic_core.residual.edges import (DEFAULT_EDGE_MARGIN_PX, boundary_samples, edge_distance_px,
                                        edge_margin_mask)
from fesdic_core.residual.graylevel import NORMALISATIONS, GrayLevelResidual, gray_level_residual
from fesdic_core.residual.visibility import (VisibilitySettings, DEFAULT_MAX_VIEW_ANGLE_DEG,
                                             TOLERANCE_FRACTION, DEFAULT_MARGIN_PX,
                                             surface_triangles, point_normals, occluded, grazing,
                                             visibility_mask, embree_available, median_edge_mm)

__all__ = ["DEFAULT_EDGE_MARGIN_PX", "boundary_samples", "edge_distance_px", "edge_margin_mask",
           "NORMALISATIONS", "GrayLevelResidual", "gray_level_residual", "VisibilitySettings",
           "DEFAULT_MAX_VIEW_ANGLE_DEG", "TOLERANCE_FRACTION", "DEFAULT_MARGIN_PX",
           "surface_triangles", "point_normals", "occluded", "grazing", "visibility_mask",
           "embree_available", "median_edge_mm"]
