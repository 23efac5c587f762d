"""Accuracy against a known truth, modulo the gauge (synthetic images with a known surface).

The gray levels cannot see a rigid motion of the specimen that the camera poses undo, nor
a slide of a surface in its own plane. A measured shape is therefore compared with the
truth modulo rigid-body motion, and the poses through what the gray levels do see:

- :func:`shape_error_to_surface`: distance of the measured points to the TRUE surface,
  after the best rigid alignment (least squares on the point-to-surface distance);
- :func:`stereo_correspondence_error`: at each measured point, where the estimated rig
  sees it in camera 1, against where camera 1 truly sees the material point that the
  estimated camera 0 shows at that pixel (and symmetrically); this is the reprojection
  error that matters for stereo, independent of the gauge.
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares

from fesdic_core.synthetic.rays import intersect_surface, pixel_rays
from fesdic_core.synthetic.specimen import Specimen

__all__ = ["MAX_ALIGN_ROTATION_RAD", "MAX_ALIGN_SHIFT_FRACTION", "shape_error_to_surface",
           "stereo_correspondence_error"]


def _normal_distance(specimen: Specimen, X: np.ndarray) -> np.ndarray:
    gx, gy = specimen.height_gradient(X[:, 0], X[:, 1])
    return (X[:, 2] - specimen.height(X[:, 0], X[:, 1])) / np.sqrt(1.0 + gx ** 2 + gy ** 2)


def _moved(X: np.ndarray, p: np.ndarray, centre: np.ndarray) -> np.ndarray:
    R, _ = cv2.Rodrigues(p[:3].reshape(3, 1))
    return (X - centre) @ R.T + centre + p[3:]


#: bounds of the rigid alignment: the gauge of a measurement is a rigid motion about as
#: large as the error of the initial pose (degrees, millimetres), never one that slides the
#: points across the specimen (which could dodge a localized feature of the truth)
MAX_ALIGN_ROTATION_RAD = np.deg2rad(5.0)
MAX_ALIGN_SHIFT_FRACTION = 0.05


def shape_error_to_surface(points: np.ndarray, specimen: Specimen,
                           max_rotation_rad: float = MAX_ALIGN_ROTATION_RAD,
                           max_shift_mm: float | None = None) -> np.ndarray:
    """Signed distances (n,) of measured points to the true surface after best rigid alignment.

    The alignment is bounded: rotations up to ``max_rotation_rad`` (each component of the
    rotation vector, about the points' centroid) and shifts up to ``max_shift_mm`` (default
    :data:`MAX_ALIGN_SHIFT_FRACTION` of the points' extent): a gauge as large as a pose
    error, so that it cannot slide a flat measurement off a localized feature of the truth.

    Parameters
    ----------
    points : (n, 3) measured surface points (mm), in the measurement's world frame.
    specimen : the synthetic specimen whose surface ``z = height(x, y)`` is the truth.
    """
    centre = points.mean(axis=0)
    shift = (MAX_ALIGN_SHIFT_FRACTION * float(np.linalg.norm(np.ptp(points, axis=0)))
             if max_shift_mm is None else float(max_shift_mm))
    bound = np.r_[np.full(3, float(max_rotation_rad)), np.full(3, shift)]
    fit = least_squares(lambda p: _normal_distance(specimen, _moved(points, p, centre)),
                        np.zeros(6), x_scale=np.r_[np.full(3, 1e-3), np.full(3, 1e-2)],
                        bounds=(-bound, bound), method="trf", xtol=1e-12, ftol=1e-12)
    return _normal_distance(specimen, _moved(points, fit.x, centre))


def stereo_correspondence_error(points: np.ndarray, cameras: Sequence, true_cameras: Sequence,
                                specimen: Specimen) -> np.ndarray:
    """Stereo reprojection error (n, 2) px at measured points, for views (0 -> 1, 1 -> 0).

    For view ``a -> b``: the pixel ``x_a`` where the estimated camera ``a`` sees the point is
    cast with the TRUE camera ``a`` onto the TRUE surface; the true camera ``b`` projects that
    material point to ``x_b*``; the error is ``|P_b(X) - x_b*|`` with the estimated ``P_b``.
    """
    errors = []
    for a, b in ((0, 1), (1, 0)):
        xa = cameras[a].project(points)
        origin, directions = pixel_rays(true_cameras[a], xa)
        origins = np.broadcast_to(origin, directions.shape)
        lam = intersect_surface(specimen, origins, directions)
        X_true = origins + lam[:, None] * directions
        errors.append(np.linalg.norm(cameras[b].project(points) - true_cameras[b].project(X_true), axis=1))
    return np.stack(errors, axis=1)
