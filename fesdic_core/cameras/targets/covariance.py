"""What a stereo calibration's optimum says about itself, beside its covariance (the stereo
bundle of :mod:`~fesdic_core.cameras.targets.bundle` linearised at the optimum): the epipolar
error and the perspective bias of circle centres.

- :func:`epipolar_distances`: each target point's distance to the epipolar line of its
  match, both ways, in undistorted pixels (what triangulation sees of the stereo relation).
- :func:`circle_centre_bias`: a printed circle projects to an ellipse whose centre is not
  the projection of the circle's centre; the detected centre (the dark area's centroid) is
  biased by the difference, computed here from the poses and the cameras.
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

__all__ = ["INTRINSIC_NAMES", "epipolar_distances", "circle_centre_bias"]

#: the intrinsic parameters in OpenCV's Jacobian order (focal, principal point, distortion)
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def _project(X, rvec, tvec, K, dist):
    px, J = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, tvec, K, dist)
    return px.reshape(-1, 2), J                     # J columns: r(3) t(3) f(2) c(2) dist(5)


def epipolar_distances(px0: np.ndarray, px1: np.ndarray, K: Sequence[np.ndarray],
                       dist: Sequence[np.ndarray], R: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(m, 2) each match's distance (px) to its epipolar line, in camera 1 then camera 0,
    after undistortion (the cameras' own pixels, distortion removed)."""
    u = [cv2.undistortPoints(np.asarray(p, float).reshape(-1, 1, 2), K[c], dist[c],
                             P=K[c]).reshape(-1, 2) for c, p in enumerate((px0, px1))]
    t = np.asarray(T, float).ravel()
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    F = np.linalg.inv(K[1]).T @ tx @ np.asarray(R, float) @ np.linalg.inv(K[0])
    h0, h1 = (np.column_stack([p, np.ones(len(p))]) for p in u)
    l1, l0 = h0 @ F.T, h1 @ F                                   # lines in camera 1, camera 0
    d1 = np.abs(np.sum(l1 * h1, axis=1)) / np.hypot(l1[:, 0], l1[:, 1])
    d0 = np.abs(np.sum(l0 * h0, axis=1)) / np.hypot(l0[:, 0], l0[:, 1])
    return np.column_stack([d1, d0])


def circle_centre_bias(X: np.ndarray, radius_mm: float, rvec: np.ndarray, tvec: np.ndarray,
                       K: np.ndarray, dist: np.ndarray, samples: int = 64) -> np.ndarray:
    """(m, 2) px: the centroid of each projected circle's area minus the projection of its
    centre, for circles of ``radius_mm`` centred at ``X`` (m, 3) in the target plane ``z = 0``
    seen with the pose ``(rvec, tvec)``: what a centroid detector adds to the true centre."""
    t = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
    ring = np.column_stack([np.cos(t), np.sin(t), np.zeros(samples)]) * radius_mm
    boundary = (np.asarray(X, float)[:, None, :] + ring[None]).reshape(-1, 3)
    b, _ = _project(boundary, rvec, tvec, K, dist)
    b = b.reshape(len(X), samples, 2)
    x, y = b[..., 0], b[..., 1]
    xn, yn = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    cross = x * yn - xn * y                                     # the shoelace formula
    area = 0.5 * cross.sum(axis=1)
    cx = ((x + xn) * cross).sum(axis=1) / (6.0 * area)
    cy = ((y + yn) * cross).sum(axis=1) / (6.0 * area)
    centre, _ = _project(np.asarray(X, float), rvec, tvec, K, dist)
    return np.column_stack([cx, cy]) - centre
