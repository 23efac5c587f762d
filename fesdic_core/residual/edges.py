"""The specimen's edges in the images: points whose image model reaches across the mesh boundary.

At the boundary of the mesh the images change from the speckle to whatever lies beyond
it (the background, a hole, another part). The image model (Gaussian prefilter, then
the cubic B-spline with its 4 x 4 px support, :mod:`fesdic_core.imaging.image`) and the pixels'
own area spread that step over about two pixels, differently in the two views: the edge
projects with another foreshortening and another sub-pixel phase in each camera. A point
inside that band compares gray levels that mix both sides of the edge; the mismatch is
systematic (it follows the edge, not the noise) and drags the boundary nodes. On the
tests' noise-free flat plate (``scenes.FAMILY``, FE, exact cameras) it made the error of
the boundary nodes four times that of the interior ones (all nodes 3.7 um RMS, interior
0.9 um); leaving out the points within 2 px of the projected boundary brings all nodes to
1.1 um and leaves the interior unchanged.

A point is kept when its projection lies at least ``margin_px`` pixels from the projected
boundary of the mesh in every camera. The boundary is the mesh's boundary edges (edges of
one element only), sampled every half pixel along each edge's own curve (the Lagrange
interpolation of its nodes), projected by the camera model and searched with a k-d tree;
only the points of elements that touch the boundary are looked at.
"""
from __future__ import annotations

import logging
from typing import Sequence

import numpy as np
from scipy.spatial import cKDTree

from fesdic_core.fe.mesh import SurfaceMesh, boundary_edges, boundary_nodes
from fesdic_core.fe.quadrature import PixelQuadrature

logger = logging.getLogger(__name__)

__all__ = ["DEFAULT_EDGE_MARGIN_PX", "boundary_samples", "edge_distance_px", "edge_margin_mask"]

#: points closer than this to the projected mesh boundary (pixels of the full-resolution
#: images) are left out of the residual: the image model's support (4 x 4 px) and the
#: 0.5 px prefilter reach about two pixels (measured: benchmarks/bench_edges.py)
DEFAULT_EDGE_MARGIN_PX = 2.0
#: spacing of the boundary samples, in pixels of the camera that sees the edge largest
_SPACING_PX = 0.5


def boundary_samples(mesh: SurfaceMesh, nodes: np.ndarray, cameras: Sequence,
                     spacing_px: float = _SPACING_PX) -> np.ndarray:
    """World points (m, 3) along the mesh's boundary edges, at most ``spacing_px`` apart in
    every camera (each edge along its own Lagrange curve through its nodes)."""
    nodes = np.asarray(nodes, dtype=float)
    samples = []
    for edge in boundary_edges(mesh):                         # (k, degree + 1)
        ends = nodes[edge[:, :2]]                                # (k, 2, 3)
        length = max(float(np.max(np.linalg.norm(np.diff(c.project(ends.reshape(-1, 3))
                                                            .reshape(-1, 2, 2), axis=1), axis=-1)))
                     for c in cameras)
        t = np.linspace(-1.0, 1.0, 2 * int(np.ceil(0.75 * length / spacing_px)) + 3)  # odd: the nodes too
        if edge.shape[1] == 3:                                   # quadratic edge: c0 at -1, c1 at 1, mid at 0
            basis = np.stack([0.5 * t * (t - 1.0), 0.5 * t * (t + 1.0), 1.0 - t * t], axis=1)
        else:
            basis = np.stack([0.5 * (1.0 - t), 0.5 * (1.0 + t)], axis=1)
        samples.append(np.einsum("tn,knd->ktd", basis, nodes[edge]).reshape(-1, 3))
    return np.vstack(samples) if samples else np.empty((0, 3))


def edge_distance_px(X: np.ndarray, samples: np.ndarray, camera,
                     upper_px: float = np.inf) -> np.ndarray:
    """Distance (px) from the projection of each point ``X`` (g, 3) to the projected boundary
    ``samples`` (m, 3) in ``camera``; ``inf`` beyond ``upper_px``."""
    if not len(samples):
        return np.full(len(X), np.inf)
    tree = cKDTree(camera.project(samples))
    distance, _ = tree.query(camera.project(X), distance_upper_bound=upper_px)
    return distance


def edge_margin_mask(X: np.ndarray, quad: PixelQuadrature, mesh: SurfaceMesh, nodes: np.ndarray,
                     cameras: Sequence, margin_px: float) -> np.ndarray:
    """(g,) bool: True for the points ``X`` at least ``margin_px`` pixels from the projected
    mesh boundary in every camera (see the module docstring).

    An element that would lose all of its points keeps them (its nodes must stay seen).
    """
    keep = np.ones(len(X), dtype=bool)
    if margin_px <= 0:
        return keep
    near = np.zeros(quad.n_elements, dtype=bool)
    on_boundary = np.zeros(len(nodes), dtype=bool)
    on_boundary[boundary_nodes(mesh)] = True
    start = 0
    for block in mesh.blocks:                                    # elements touching the boundary
        near[start:start + block.n_elements] = on_boundary[block.connectivity].any(axis=1)
        start += block.n_elements
    candidates = np.flatnonzero(near[quad.element])
    samples = boundary_samples(mesh, nodes, cameras)
    for camera in cameras:
        distance = edge_distance_px(X[candidates], samples, camera, upper_px=margin_px)
        keep[candidates[distance < margin_px]] = False
    lost = quad.element_sum(keep.astype(float)) == 0
    if lost.any():
        keep[lost[quad.element]] = True
        logger.debug("edge margin: %d elements lie within %.2g px of the boundary; kept",
                     int(lost.sum()), margin_px)
    logger.debug("edge margin %.2g px: %d of %d points left out", margin_px,
                 int(np.count_nonzero(~keep)), keep.size)
    return keep
