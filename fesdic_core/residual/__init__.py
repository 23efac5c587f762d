"""The gray-level residual of Eq. 3 and where it holds: edges and visibility of the integration points."""

from fesdic_core.residual.edges import (DEFAULT_EDGE_MARGIN_PX, boundary_samples, edge_distance_px,
                                        edge_margin_mask)
from fesdic_core.residual.graylevel import NORMALISATIONS, GrayLevelResidual, gray_level_residual
from fesdic_core.residual.validity import (MAX_RESIDUAL_TO_NOISE, MIN_NODE_TEXTURE_RATIO,
                                           MIN_NODE_CONDITIONING, MAX_NEIGHBOUR_RATIO,
                                           DEFAULT_MAX_INVALID_SHARE, RESIDUAL_FACTOR,
                                           EXPLAINED_RESIDUAL_TO_NOISE, residual_limit, NodeValidity,
                                           Support, LocalImage, local_image, local_noise_gray,
                                           block_conditioning, node_neighbours, neighbour_ratio,
                                           node_validity)
from fesdic_core.residual.visibility import (VisibilitySettings, DEFAULT_MAX_VIEW_ANGLE_DEG,
                                               TOLERANCE_FRACTION, DEFAULT_MARGIN_PX,
                                               surface_triangles, point_normals, occluded, grazing,
                                               visibility_mask, embree_available, median_edge_mm)

__all__ = ["DEFAULT_EDGE_MARGIN_PX", "boundary_samples", "edge_distance_px", "edge_margin_mask",
           "NORMALISATIONS", "GrayLevelResidual", "gray_level_residual", "VisibilitySettings",
           "DEFAULT_MAX_VIEW_ANGLE_DEG", "TOLERANCE_FRACTION", "DEFAULT_MARGIN_PX",
           "surface_triangles", "point_normals", "occluded", "grazing", "visibility_mask",
           "embree_available", "median_edge_mm", "MAX_RESIDUAL_TO_NOISE",
           "MIN_NODE_TEXTURE_RATIO", "MIN_NODE_CONDITIONING", "MAX_NEIGHBOUR_RATIO",
           "DEFAULT_MAX_INVALID_SHARE", "RESIDUAL_FACTOR", "EXPLAINED_RESIDUAL_TO_NOISE",
           "residual_limit", "NodeValidity", "Support", "LocalImage", "local_image",
           "local_noise_gray", "block_conditioning", "node_neighbours", "neighbour_ratio",
           "node_validity"]
