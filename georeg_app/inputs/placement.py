"""Does the nominal mesh lie where the rig's triangulation puts the specimen? (issue 22, item 5)

A flat mesh, or the landmarks that posed the cameras, can place the specimen off its real
surface (a mesh shifted by 0.5 mm along its normal was accepted silently). Before measuring,
stereo matches inside the mesh's image in camera 0 are triangulated
(:func:`fesdic_core.cameras.triangulation.stereo_points`) and their signed distances to the
mesh (along the normal of the nearest node) fitted by an offset and a tilt (robust least
squares over the mesh's two principal axes). The real surface departs from the nominal (the
shape being measured) and the points scatter: only an offset or a tilt beyond
:data:`SIGMAS` times the robust scatter of the distances, and beyond :data:`MIN_MM`, is
reported, as a loud warning with the numbers. Few matches (an untextured or synthetic
image): no verdict, one debug line.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import cv2
import numpy as np
from scipy.spatial import cKDTree

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.triangulation import stereo_points
from fesdic_core.fe.mesh import SurfaceMesh, node_normals
from fesdic_core.imaging.image import Image

logger = logging.getLogger(__name__)

__all__ = ["Placement", "placement_check", "SIGMAS", "MIN_MM", "MIN_POINTS"]

SIGMAS = 5.0          # an offset or tilt beyond this many robust std of the distances ...
MIN_MM = 0.05         # ... and beyond this (mm, at the mesh's edge for a tilt) is reported
MIN_POINTS = 30       # fewer triangulated points: no verdict


@dataclasses.dataclass(frozen=True)
class Placement:
    """The mesh against the triangulated points.

    ``offset_mm``: mean signed distance of the points from the mesh along its normals (at
    the mesh's centroid); ``tilt_deg``: the angle between the points' best plane and the
    mesh; ``edge_mm``: what the tilt adds at the mesh's farthest node; ``scatter_mm``: the
    robust std of the distances about that plane; ``points``: the points used;
    ``agrees``: False when the offset or the tilt is beyond the thresholds.
    """

    offset_mm: float
    tilt_deg: float
    edge_mm: float
    scatter_mm: float
    points: int
    agrees: bool


def _mesh_mask(mesh: SurfaceMesh, camera: Camera, shape: tuple[int, int]) -> np.ndarray:
    """Camera 0's pixels (h, w) bool covered by the elements wholly in front of it and in
    its image, eroded by 3 px."""
    h, w = shape
    mask = np.zeros(shape, np.uint8)
    for block in mesh.blocks:
        n_corners = 3 if block.family.name.startswith("T") else 4
        X = mesh.nodes[block.connectivity[:, :n_corners].ravel()]
        corners = camera.project(X).reshape(-1, n_corners, 2)
        inside = (camera.in_front(X).reshape(-1, n_corners).all(axis=1)
                  & np.all(np.isfinite(corners), axis=(1, 2))
                  & np.all((corners >= 0) & (corners <= [w - 1, h - 1]), axis=(1, 2)))
        if inside.any():
            cv2.fillPoly(mask, list(np.round(corners[inside]).astype(np.int32)), 1)
    return cv2.erode(mask, np.ones((7, 7), np.uint8)) > 0


def placement_check(mesh: SurfaceMesh, cameras: Sequence[Camera], images: Sequence[Image]
                    ) -> Placement | None:
    """Compare ``mesh`` (n nodes, mm) with the specimen triangulated by ``cameras``.

    Returns None when fewer than :data:`MIN_POINTS` matches are triangulated on the mesh;
    else the :class:`Placement` (logged, as a warning when it does not agree).
    """
    if not all(np.all(np.isfinite(im.values)) for im in images):
        return None                              # refused later, naming the image
    mask = _mesh_mask(mesh, cameras[0], images[0].shape)
    if not mask.any():
        return None
    points = stereo_points(cameras[0], cameras[1], images[0].values, images[1].values, mask)
    if points.n_points < MIN_POINTS:
        logger.debug("placement check: %d triangulated points on the mesh, no verdict",
                     points.n_points)
        return None
    nodes, normals = mesh.nodes, node_normals(mesh)
    gap, nearest = cKDTree(nodes).query(points.xyz_mm)
    d = np.einsum("ij,ij->i", points.xyz_mm - nodes[nearest], normals[nearest])
    centre = nodes.mean(axis=0)
    _, _, vt = np.linalg.svd(nodes - centre, full_matrices=False)
    uv = (points.xyz_mm - centre) @ vt[:2].T
    A = np.column_stack([np.ones(len(d)), uv])
    keep = np.ones(len(d), bool)
    for _ in range(10):
        coef = np.linalg.lstsq(A[keep], d[keep], rcond=None)[0]
        r = d - A @ coef
        sigma = 1.4826 * float(np.median(np.abs(r[keep] - np.median(r[keep]))))
        new = np.abs(r) <= 3.0 * max(sigma, 1e-9)
        if new.sum() < MIN_POINTS or np.array_equal(new, keep):
            break
        keep = new
    reach = float(np.max(np.linalg.norm((nodes - centre) @ vt[:2].T, axis=1)))
    slope = float(np.hypot(coef[1], coef[2]))
    bound = max(SIGMAS * sigma, MIN_MM)
    result = Placement(offset_mm=float(coef[0]), tilt_deg=float(np.degrees(np.arctan(slope))),
                       edge_mm=slope * reach, scatter_mm=sigma, points=int(keep.sum()),
                       agrees=bool(abs(coef[0]) <= bound and slope * reach <= bound))
    text = (f"{result.points} triangulated points lie {result.offset_mm * 1e3:+.1f} um from the "
            f"nominal mesh along its normal, tilted {result.tilt_deg:.3f} deg from it "
            f"({result.edge_mm * 1e3:.1f} um at its edge), scatter {sigma * 1e3:.1f} um")
    if result.agrees:
        logger.info("placement check: %s", text)
    else:
        logger.warning("placement check: the nominal mesh is not where the calibrated rig "
                       "puts the specimen: %s (more than %.0f um); check the mesh's position "
                       "or the landmarks", text, bound * 1e3)
    return result
