"""Stereo points from a calibrated rig: feature matches, the epipolar check, triangulation.

What a DIC user's tool does before any correlation when the specimen has no CAD: features
of camera 0's image inside a mask (OpenCV SIFT, Lowe's ratio test) matched in camera 1's
image; the matches that do not lie on the epipolar line of the CALIBRATED pair are outliers
(the rig is known: no fundamental matrix is estimated, the consensus set is the matches
within a distance of their epipolar line, distortion included); the rest are triangulated
(linear DLT, ``cv2.triangulatePoints``, on undistorted normalised points).
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import cv2
import numpy as np

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.rig import stereo_transform

logger = logging.getLogger(__name__)

__all__ = ["StereoPoints", "normalised_points", "epipolar_distance_px", "triangulate",
           "Features", "detect_features", "match_descriptors", "depth_per_px", "match_features",
           "stereo_points", "DEFAULT_MAX_EPIPOLAR_PX", "RATIO_TEST"]

#: matches farther than this from their epipolar line (px, in camera 1) are outliers
DEFAULT_MAX_EPIPOLAR_PX = 1.0
#: Lowe's ratio test: best match distance below this fraction of the second best
RATIO_TEST = 0.75


@dataclasses.dataclass(frozen=True, eq=False)
class StereoPoints:
    """Triangulated matches of a calibrated pair.

    Attributes
    ----------
    px0, px1 : (n, 2) matched pixels (x = column, y = row) in cameras 0 and 1.
    xyz_mm : (n, 3) triangulated points in the cameras' world frame.
    epipolar_px : (n,) distance of ``px1`` to the epipolar line of ``px0`` (px).
    reprojection_px : (n,) largest reprojection error of the point in the two cameras (px).
    n_matches : matches before the epipolar check.
    """

    px0: np.ndarray
    px1: np.ndarray
    xyz_mm: np.ndarray
    epipolar_px: np.ndarray
    reprojection_px: np.ndarray
    n_matches: int

    @property
    def n_points(self) -> int:
        """Number of points kept (inliers of the epipolar check)."""
        return len(self.xyz_mm)


def normalised_points(camera: Camera, px: np.ndarray) -> np.ndarray:
    """Undistorted normalised image coordinates (n, 2) of pixels ``px`` (n, 2).

    The skew of ``K`` is removed first (``cv2.undistortPoints`` ignores ``K[0, 1]``), then
    the distortion is inverted by OpenCV's iteration; the result ``(x/z, y/z)`` is in the
    camera frame.
    """
    px = np.asarray(px, dtype=np.float64).reshape(-1, 2)
    if len(px) == 0:
        return np.zeros((0, 2))
    K = camera.K
    y_d = (px[:, 1] - K[1, 2]) / K[1, 1]
    K0 = K.copy()
    K0[0, 1] = 0.0
    unskewed = np.column_stack([px[:, 0] - K[0, 1] * y_d, px[:, 1]])
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    out = cv2.undistortPoints(unskewed.reshape(-1, 1, 2), K0, camera.dist, None, None, None, crit)
    return out.reshape(-1, 2)


def epipolar_distance_px(cam0: Camera, cam1: Camera, px0: np.ndarray,
                         px1: np.ndarray) -> np.ndarray:
    """Distance (n,) in px of each ``px1`` (n, 2) to the epipolar line of ``px0`` (n, 2).

    Computed on undistorted normalised points with the essential matrix of the calibrated
    pair, ``E = [t]_x R`` (``x1 = R x0 + t``), then scaled by camera 1's mean focal length.
    """
    R, t = stereo_transform(cam0, cam1)
    t = np.asarray(t, dtype=np.float64).ravel()
    E = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ R
    x0 = np.column_stack([normalised_points(cam0, px0), np.ones(len(px0))])
    x1 = np.column_stack([normalised_points(cam1, px1), np.ones(len(px1))])
    lines = x0 @ E.T                                               # (n, 3) in camera 1
    d = np.abs(np.sum(lines * x1, axis=1)) / np.hypot(lines[:, 0], lines[:, 1])
    return d * 0.5 * (cam1.K[0, 0] + cam1.K[1, 1])


def triangulate(cam0: Camera, cam1: Camera, px0: np.ndarray, px1: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """World points (n, 3) of matches ``px0``, ``px1`` (n, 2) and their reprojection error.

    Linear triangulation (DLT, ``cv2.triangulatePoints``) of the undistorted normalised
    points with ``P_c = [R_c | t_c]``.

    Returns
    -------
    xyz_mm : (n, 3) points in the world frame of the cameras.
    reprojection_px : (n,) the larger of the two reprojection errors (px), through the
        cameras' full model (distortion and skew).
    """
    if len(px0) == 0:
        return np.zeros((0, 3)), np.zeros(0)
    x0, x1 = normalised_points(cam0, px0), normalised_points(cam1, px1)
    P0 = np.column_stack([cam0.R, cam0.tvec])
    P1 = np.column_stack([cam1.R, cam1.tvec])
    h = cv2.triangulatePoints(P0, P1, x0.T.copy(), x1.T.copy())
    xyz = (h[:3] / h[3]).T
    err = np.maximum(np.linalg.norm(cam0.project(xyz) - px0, axis=1),
                     np.linalg.norm(cam1.project(xyz) - px1, axis=1))
    return xyz, err


def _gray8(values: np.ndarray) -> np.ndarray:
    """An 8-bit view of gray levels (min-max stretched) for the feature detector."""
    v = np.asarray(values, dtype=np.float64)
    lo, hi = float(np.min(v)), float(np.max(v))
    return np.zeros(v.shape, np.uint8) if hi <= lo else \
        np.round(255.0 * (v - lo) / (hi - lo)).astype(np.uint8)


def _spread(keypoints: Sequence, shape: tuple[int, int], cells: int, quota: int) -> list:
    """The ``quota`` strongest keypoints of each of ``cells x cells`` tiles of an image of
    ``shape`` (h, w): features spread over the image, not only where the contrast is best."""
    if not keypoints:
        return []
    xy = np.array([k.pt for k in keypoints])
    response = np.array([k.response for k in keypoints])
    tile = (np.minimum((xy[:, 1] * cells / shape[0]).astype(int), cells - 1) * cells
            + np.minimum((xy[:, 0] * cells / shape[1]).astype(int), cells - 1))
    order = np.lexsort((-response, tile))                      # by tile, strongest first
    first = np.searchsorted(tile[order], tile[order], side="left")
    rank = np.arange(len(order)) - first
    return [keypoints[i] for i in order[rank < quota]]


@dataclasses.dataclass(frozen=True, eq=False)
class Features:
    """SIFT features of one image: ``px`` (k, 2) pixels (x = column, y = row) and
    ``descriptors`` (k, 128) float32."""

    px: np.ndarray
    descriptors: np.ndarray

    def __len__(self) -> int:
        return len(self.px)


def detect_features(values: np.ndarray, mask: np.ndarray | None = None,
                    max_features: int = 5000, spread_cells: int = 0) -> Features:
    """SIFT features of an image (inside ``mask``).

    Parameters
    ----------
    values : (h, w) gray levels.
    mask : (h, w) bool, where features are looked for (None: everywhere).
    max_features : at most this many features.
    spread_cells : 0: the ``max_features`` strongest; ``k > 0``: the ``max_features / k**2``
        strongest of each of ``k x k`` tiles of the image (features where the contrast is
        weaker too, e.g. under uneven lighting).

    Returns
    -------
    Features (possibly empty).
    """
    image = _gray8(values)
    m = None if mask is None else np.asarray(mask, bool).astype(np.uint8) * 255
    if spread_cells > 0:
        sift = cv2.SIFT_create()  # type: ignore[attr-defined]
        quota = int(np.ceil(max_features / spread_cells ** 2))
        keypoints = _spread(sift.detect(image, m), image.shape, spread_cells, quota)
        if keypoints:
            keypoints, descriptors = sift.compute(image, keypoints)
        else:
            keypoints, descriptors = [], None
    else:
        sift = cv2.SIFT_create(nfeatures=int(max_features))  # type: ignore[attr-defined]
        keypoints, descriptors = sift.detectAndCompute(image, m)
    if descriptors is None or len(keypoints) == 0:
        return Features(np.zeros((0, 2)), np.zeros((0, 128), np.float32))
    return Features(np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2),
                    np.asarray(descriptors, np.float32))


def match_descriptors(features0: Features, features1: Features) -> tuple[np.ndarray, np.ndarray]:
    """Indices (n,) and (n,) of the matches of ``features0`` in ``features1``: nearest
    descriptor (L2, brute force), Lowe's ratio test."""
    if len(features0) < 2 or len(features1) < 2:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(features0.descriptors, features1.descriptors, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < RATIO_TEST * p[1].distance]
    return (np.array([m.queryIdx for m in good], dtype=np.intp),
            np.array([m.trainIdx for m in good], dtype=np.intp))


def match_features(values0: np.ndarray, values1: np.ndarray, mask0: np.ndarray | None = None,
                   max_features: int = 5000, spread_cells: int = 0
                   ) -> tuple[np.ndarray, np.ndarray, int]:
    """SIFT matches of image 0 (inside ``mask0``) in image 1, Lowe's ratio test.

    Parameters
    ----------
    values0, values1 : (h, w) gray levels of the two images.
    mask0 : (h, w) bool, where features of image 0 are looked for (None: everywhere).
    max_features, spread_cells : the features of each image (:func:`detect_features`).

    Returns
    -------
    px0, px1 : (n, 2) matched pixels (x = column, y = row).
    n_features : the features found in image 0 (inside the mask).
    """
    f0 = detect_features(values0, mask0, max_features, spread_cells)
    f1 = detect_features(values1, None, max_features, spread_cells)
    i0, i1 = match_descriptors(f0, f1)
    return f0.px[i0], f1.px[i1], len(f0)


def stereo_points(cam0: Camera, cam1: Camera, values0: np.ndarray, values1: np.ndarray,
                  mask0: np.ndarray | None = None,
                  max_epipolar_px: float = DEFAULT_MAX_EPIPOLAR_PX, max_features: int = 5000,
                  spread_cells: int = 0) -> StereoPoints:
    """Matches inside ``mask0`` that agree with the calibrated epipolar geometry, triangulated.

    Parameters
    ----------
    cam0, cam1 : the calibrated pair (any common world frame).
    values0, values1 : (h, w) gray levels of camera 0's and camera 1's images.
    mask0 : (h, w) bool, the region of camera 0's image to match (None: all).
    max_epipolar_px : matches farther from their epipolar line (px) are dropped.
    max_features, spread_cells : the features of each image (:func:`match_features`).

    Returns
    -------
    StereoPoints (possibly empty: the caller judges whether there are enough).
    """
    px0, px1, n_features = match_features(values0, values1, mask0, max_features, spread_cells)
    n = len(px0)
    if n == 0:
        logger.info("stereo matches: %d features in camera 0, no match", n_features)
        return StereoPoints(px0, px1, np.zeros((0, 3)), np.zeros(0), np.zeros(0), 0)
    d = epipolar_distance_px(cam0, cam1, px0, px1)
    keep = d <= max_epipolar_px
    xyz, err = triangulate(cam0, cam1, px0[keep], px1[keep])
    front = cam0.in_front(xyz) & cam1.in_front(xyz)
    idx = np.flatnonzero(keep)[front]
    logger.info("stereo matches: %d features in camera 0, %d matches, %d within %.2g px of "
                "their epipolar line (median %.3g px), %d in front of both cameras",
                n_features, n, int(keep.sum()), max_epipolar_px,
                float(np.median(d[keep])) if keep.any() else float("nan"), len(idx))
    return StereoPoints(px0[idx], px1[idx], xyz[front], d[idx], err[front], n)


def depth_per_px(cam0: Camera, cam1: Camera, px0: np.ndarray, px1: np.ndarray) -> np.ndarray:
    """How far (n,) mm each triangulated match ``px0``, ``px1`` (n, 2) moves when its
    camera-1 pixel moves by 1 px along its epipolar line (the triangulation's sensitivity
    to a matching error: a match's error of ``e`` px moves the point about ``e`` times this).

    The epipolar direction at ``px1`` is the image in camera 1 of camera 0's ray through
    ``px0`` (two points on the ray, 1 mm apart, projected)."""
    if len(px0) == 0:
        return np.zeros(0)
    xyz, _ = triangulate(cam0, cam1, px0, px1)
    ray = xyz - cam0.center
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    direction = cam1.project(xyz + ray) - cam1.project(xyz)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    moved, _ = triangulate(cam0, cam1, px0, np.asarray(px1, dtype=np.float64) + direction)
    return np.linalg.norm(moved - xyz, axis=1)
