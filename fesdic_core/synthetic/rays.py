"""Rays of the synthetic cameras and where they meet a specimen's surface.

:func:`pixel_rays` gives each pixel's ray in world coordinates (the inverse of the camera
model, distortion undone by OpenCV); :func:`intersect_surface` finds, by Newton on the ray
parameter, where it meets ``z = height(x, y)``.
"""
from __future__ import annotations

import logging

import cv2
import numpy as np

from fesdic_core.synthetic.specimen import Specimen

logger = logging.getLogger(__name__)

__all__ = ["pixel_rays", "intersect_surface"]


def pixel_rays(camera, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Back-project pixel coordinates to world rays (inverse of the projection).

    Parameters
    ----------
    camera : duck-typed camera (``K``, ``dist``, ``rvec``, ``tvec``)
    xy : (n, 2) pixel coordinates (column, row)

    Returns
    -------
    centre : (3,) camera centre in world mm; directions : (n, 3) world
    directions with unit z_cam component (the point at depth z_cam is
    ``centre + z_cam * direction``).
    """
    K = np.asarray(camera.K, float)
    dist = np.asarray(camera.dist, float).ravel()
    xy = np.asarray(xy, float).reshape(-1, 2)
    fx, skew, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    # remove the skew: u = fx x_d + skew y_d + cx, v = fy y_d + cy
    yd = (xy[:, 1] - cy) / fy
    if np.any(dist != 0.0):
        K0 = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        src = np.stack([xy[:, 0] - skew * yd, xy[:, 1]], axis=1).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-9)  # eps in px
        xn = cv2.undistortPoints(src, K0, dist, criteria=criteria).reshape(-1, 2)
    else:
        xn = np.stack([(xy[:, 0] - cx - skew * yd) / fx, yd], axis=1)
    R = cv2.Rodrigues(np.asarray(camera.rvec, float).reshape(3, 1))[0]
    t = np.asarray(camera.tvec, float).ravel()
    d_cam = np.column_stack([xn, np.ones(len(xn))])
    return -R.T @ t, d_cam @ R  # rows R^T d_cam


def intersect_surface(
    specimen: Specimen, origins: np.ndarray, directions: np.ndarray, tol_mm: float = 1e-10, max_iter: int = 50
) -> np.ndarray:
    """Ray parameters ``lam`` with ``origins + lam directions`` on ``z = height(x, y)``.

    Vectorised Newton on ``g(lam) = o_z + lam d_z - height(o_x + lam d_x, o_y + lam d_y)``
    started from the nominal plane ``z = 0``; ``origins`` (3,) or (n, 3),
    ``directions`` (n, 3). Rays parallel to the plane or not converged get NaN.
    """
    o = np.broadcast_to(np.asarray(origins, float), np.shape(directions))
    d = np.asarray(directions, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = -o[:, 2] / d[:, 2]
    lam[~np.isfinite(lam)] = np.nan
    for _ in range(max_iter):
        x, y = o[:, 0] + lam * d[:, 0], o[:, 1] + lam * d[:, 1]
        g = o[:, 2] + lam * d[:, 2] - specimen.height(x, y)
        if not np.nanmax(np.abs(g), initial=0.0) > tol_mm:
            return lam
        hx, hy = specimen.height_gradient(x, y)
        lam = lam - g / (d[:, 2] - hx * d[:, 0] - hy * d[:, 1])
    x, y = o[:, 0] + lam * d[:, 0], o[:, 1] + lam * d[:, 1]
    bad = ~(np.abs(o[:, 2] + lam * d[:, 2] - specimen.height(x, y)) <= tol_mm)
    logger.warning("ray-surface Newton: %d of %d rays did not converge", int(np.sum(bad & np.isfinite(lam))), lam.size)
    lam[bad] = np.nan
    return lam
