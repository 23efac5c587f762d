"""What a stereo calibration's optimum says about itself: parameter covariance, epipolar
error, and the perspective bias of circle centres.

- :func:`stereo_covariance`: the bundle of a stereo calibration (both cameras' intrinsics,
  the stereo relation ``(R, T)`` and one target pose per view) linearised at the optimum,
  the Jacobian from :func:`cv2.projectPoints` chained through :func:`cv2.composeRT`;
  ``cov = s^2 (J^T J)^-1`` with ``s^2`` the residual's variance per degree of freedom.
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

__all__ = ["INTRINSIC_NAMES", "stereo_covariance", "epipolar_distances", "circle_centre_bias"]

#: the intrinsic parameters in OpenCV's Jacobian order (focal, principal point, distortion)
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def _project(X, rvec, tvec, K, dist):
    px, J = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, tvec, K, dist)
    return px.reshape(-1, 2), J                     # J columns: r(3) t(3) f(2) c(2) dist(5)


def stereo_covariance(objects: Sequence[np.ndarray], px0: Sequence[np.ndarray],
                      px1: Sequence[np.ndarray], K: Sequence[np.ndarray], dist: Sequence[np.ndarray],
                      R: np.ndarray, T: np.ndarray, rvecs: Sequence[np.ndarray],
                      tvecs: Sequence[np.ndarray], free: np.ndarray, tie_aspect: bool = False
                      ) -> tuple[np.ndarray, float, int]:
    """Covariance of the stereo calibration's parameters at its optimum.

    Parameters
    ----------
    objects, px0, px1 : per view, the target points (m, 3) mm and their pixels in each camera.
    K, dist : each camera's intrinsic matrix (3, 3) and distortion (5,).
    R, T : the stereo relation, ``X_1 = R X_0 + T``.
    rvecs, tvecs : per view, the target's pose in camera 0.
    free : (9,) bool, which of :data:`INTRINSIC_NAMES` were estimated (the same for both
        cameras).
    tie_aspect : a fixed aspect ratio: ``fy`` follows ``fx`` (``free[1]`` must be False).

    Returns
    -------
    cov : (p, p) covariance of ``[intrinsics cam 0 (free), intrinsics cam 1 (free), rvec(R) (3),
        T (3), one pose (6) per view]``.
    sigma_px : the residual's standard deviation per degree of freedom (px).
    dof : the degrees of freedom (residuals minus parameters).
    """
    rs = cv2.Rodrigues(np.asarray(R, float))[0]
    ts = np.asarray(T, float).reshape(3, 1)
    n_views, n_int = len(objects), int(np.count_nonzero(free))
    n_par = 2 * n_int + 6 + 6 * n_views
    rows, residuals = [], []
    for v in range(n_views):
        X, rv, tv = np.asarray(objects[v], float), rvecs[v].reshape(3, 1), tvecs[v].reshape(3, 1)
        r3, t3, dr3dr1, dr3dt1, dr3dr2, dr3dt2, dt3dr1, dt3dt1, dt3dr2, dt3dt2 = cv2.composeRT(rv, tv, rs, ts)
        for cam, (pose, seen) in enumerate((((rv, tv), px0[v]), ((r3, t3), px1[v]))):
            proj, J = _project(X, pose[0], pose[1], K[cam], dist[cam])
            residuals.append((np.asarray(seen, float).reshape(-1, 2) - proj).ravel())
            block = np.zeros((J.shape[0], n_par))
            full = J[:, 6:15].copy()
            if tie_aspect:                           # fy = a fx: d/dfx gains a d/dfy
                full[:, 0] += full[:, 1] * K[cam][1, 1] / K[cam][0, 0]
            intr = full[:, free]
            block[:, cam * n_int:(cam + 1) * n_int] = intr
            Jr, Jt = J[:, 0:3], J[:, 3:6]
            view = slice(2 * n_int + 6 + 6 * v, 2 * n_int + 12 + 6 * v)
            if cam == 0:
                block[:, view] = np.hstack([Jr, Jt])
            else:
                block[:, view] = np.hstack([Jr @ dr3dr1 + Jt @ dt3dr1, Jr @ dr3dt1 + Jt @ dt3dt1])
                block[:, 2 * n_int:2 * n_int + 6] = np.hstack([Jr @ dr3dr2 + Jt @ dt3dr2,
                                                               Jr @ dr3dt2 + Jt @ dt3dt2])
            rows.append(block)
    J = np.vstack(rows)
    r = np.concatenate(residuals)
    dof = int(r.size - n_par)
    if dof <= 0:
        raise ValueError(f"stereo calibration: {r.size} residuals for {n_par} parameters")
    sigma2 = float(r @ r) / dof
    cov = sigma2 * np.linalg.pinv(J.T @ J)
    return cov, float(np.sqrt(sigma2)), dof


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
