"""The surface of a region of interest fitted to its triangulated points, and its frame.

A plane by total least squares, or a quadric ``z = f(x, y)`` in the plane's frame, both
robust: refitted on the points within 3 robust standard deviations (1.4826 x the median
absolute residual) until the inlier set settles. The specimen frame (issue 22): origin at
the ROI's centroid on the surface, z along the plane's normal towards camera 0, x along
camera 0's image rows (its x axis projected on the plane), y = z x x.
"""
from __future__ import annotations

import dataclasses
import logging

import numpy as np

from fesdic_core.cameras.camera import Camera

logger = logging.getLogger(__name__)

__all__ = ["SurfaceFit", "fit_surface", "height_fit", "specimen_frame", "ray_hits",
           "OUTLIER_SIGMAS"]

#: points beyond this many robust standard deviations from the fitted surface are outliers
OUTLIER_SIGMAS = 3.0


@dataclasses.dataclass(frozen=True, eq=False)
class SurfaceFit:
    """A fitted plane, or quadric in the plane's frame.

    Attributes
    ----------
    point : (3,) a point of the plane (the inliers' centroid), world frame (mm).
    normal : (3,) unit normal of the plane (sign: see :func:`specimen_frame`).
    quadric : (6,) ``z = c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2`` in the local frame
        ``(point, axes)``, or None for a plane.
    axes : (3, 3) rows x, y, z of the local frame (z = normal).
    inliers : (n,) bool, the points the fit kept.
    rms_mm : RMS distance of the inliers to the surface (along the normal).
    """

    point: np.ndarray
    normal: np.ndarray
    quadric: np.ndarray | None
    axes: np.ndarray
    inliers: np.ndarray
    rms_mm: float

    def height(self, xy: np.ndarray) -> np.ndarray:
        """(m,) the surface's ``z`` above the plane at local ``xy`` (m, 2) (0 for a plane)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self.quadric is None:
            return np.zeros(len(xy))
        return _quadric_terms(xy) @ self.quadric


def _quadric_terms(xy: np.ndarray) -> np.ndarray:
    x, y = xy[:, 0], xy[:, 1]
    return np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])


def _plane(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centre = xyz.mean(axis=0)
    _, _, vt = np.linalg.svd(xyz - centre, full_matrices=False)
    return centre, vt


def _robust_sigma(r: np.ndarray) -> float:
    return 1.4826 * float(np.median(np.abs(r - np.median(r))))


def _fit_on(xyz: np.ndarray, inliers: np.ndarray, surface: str):
    """The plane (and the quadric over it) fitted to the inliers; the residuals (n,) of every
    point along the plane's normal: ``(point, axes, quadric coefficients or None, r)``."""
    point, axes = _plane(xyz[inliers])
    local = (xyz - point) @ axes.T
    r = local[:, 2]
    coeffs = None
    if surface == "quadric":
        A = _quadric_terms(local[:, :2])
        coeffs = np.linalg.lstsq(A[inliers], r[inliers], rcond=None)[0]
        r = r - A @ coeffs
    return point, axes, coeffs, r


def fit_surface(xyz: np.ndarray, surface: str = "plane", iterations: int = 10) -> SurfaceFit:
    """Robust fit of a plane (or a quadric over it) to points ``xyz`` (n, 3) mm, n >= 6.

    The quadric is fitted in the frame of the robust plane; its residual is along that
    plane's normal. Raises ValueError for fewer than 6 points or an unknown ``surface``.
    """
    xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
    if len(xyz) < 6:
        raise ValueError(f"fit_surface: needs at least 6 points, got {len(xyz)}")
    if surface not in ("plane", "quadric"):
        raise ValueError(f"fit_surface: surface must be 'plane' or 'quadric', got {surface!r}")
    inliers = np.ones(len(xyz), bool)
    for _ in range(iterations):
        point, axes, coeffs, r = _fit_on(xyz, inliers, surface)
        sigma = _robust_sigma(r[inliers])
        new = np.abs(r - np.median(r[inliers])) <= OUTLIER_SIGMAS * max(sigma, 1e-12)
        if np.count_nonzero(new) < 6 or np.array_equal(new, inliers):
            break
        inliers = new
    point, axes, coeffs, r = _fit_on(xyz, inliers, surface)
    rms = float(np.sqrt(np.mean(r[inliers] ** 2)))
    return SurfaceFit(point=point, normal=axes[2], quadric=coeffs, axes=axes, inliers=inliers,
                      rms_mm=rms)


def height_fit(xyz: np.ndarray, inliers: np.ndarray) -> SurfaceFit:
    """The quadric ``z = f(x, y)`` of points ``xyz`` (n, 3) given in their own frame (the
    specimen's): least squares on the ``inliers`` (n,) bool, plane ``z = 0`` as reference."""
    xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
    A = _quadric_terms(xyz[:, :2])
    coeffs = np.linalg.lstsq(A[inliers], xyz[inliers, 2], rcond=None)[0]
    r = (xyz[:, 2] - A @ coeffs)[inliers]
    return SurfaceFit(point=np.zeros(3), normal=np.array([0.0, 0.0, 1.0]), quadric=coeffs,
                      axes=np.eye(3), inliers=np.asarray(inliers, bool),
                      rms_mm=float(np.sqrt(np.mean(r ** 2))))


def ray_hits(camera: Camera, rays: np.ndarray, fit: SurfaceFit,
             iterations: int = 8) -> np.ndarray:
    """Where camera rays meet the fitted surface, world frame (m, 3) mm.

    ``rays``: (m, 3) directions in the world frame from the camera's centre (undistorted
    normalised pixels ``(x, y, 1)`` rotated by ``R^T``). A quadric is reached by Newton
    iterations along each ray from its hit on the plane.
    """
    c = camera.center
    n = fit.normal
    s = ((fit.point - c) @ n) / (rays @ n)                          # on the plane
    if fit.quadric is not None:
        for _ in range(iterations):
            X = c + s[:, None] * rays
            local = (X - fit.point) @ fit.axes.T
            g = local[:, 2] - fit.height(local[:, :2])
            d = rays @ fit.axes.T                                   # ray in local axes
            q = fit.quadric
            x, y = local[:, 0], local[:, 1]
            dh = (q[1] + 2 * q[3] * x + q[4] * y) * d[:, 0] + (q[2] + q[4] * x + 2 * q[5] * y) * d[:, 1]
            s = s - g / (d[:, 2] - dh)
    return c + s[:, None] * rays


def specimen_frame(fit: SurfaceFit, camera0: Camera, origin: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The specimen frame: rotation ``R_f`` (3, 3) (columns x, y, z in the world frame) and
    ``origin`` (3,); a world point is ``X_w = R_f X_s + origin``.

    z is the fitted plane's normal turned towards camera 0's centre, x camera 0's image x axis
    (along its rows) projected on the plane, y = z x x.
    """
    z = fit.normal * (1.0 if (camera0.center - origin) @ fit.normal > 0 else -1.0)
    row = camera0.R.T @ np.array([1.0, 0.0, 0.0])
    x = row - (row @ z) * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z]), np.asarray(origin, dtype=float)
