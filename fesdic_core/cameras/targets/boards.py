"""Checkerboards, ChArUco boards and circle grids: OpenCV's detectors.

- checkerboard: :func:`cv2.findChessboardCornersSB` (the sector-based detector), else the
  classic :func:`cv2.findChessboardCorners`, refined by :func:`cv2.cornerSubPix`; ``rows x
  columns`` inner corners, numbered from the end whose outer square is dark;
- charuco: :class:`cv2.aruco.CharucoDetector` on a ``rows x columns`` squares board; the
  corners it finds carry their ids, so partial views count;
- circles / asymmetric_circles: :func:`cv2.findCirclesGrid` with a blob detector sized to
  the image (dark dots on a light ground).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

if TYPE_CHECKING:
    from fesdic_core.cameras.targets.target import Target

__all__ = ["detect_board", "charuco_board"]


def charuco_board(target: "Target"):
    """OpenCV's ChArUco board of ``target``."""
    name = str(target.dictionary)
    if not hasattr(cv2.aruco, name):
        raise ValueError(f"target dictionary {name!r} is not one of OpenCV's ArUco dictionaries "
                         "(e.g. DICT_4X4_50, DICT_5X5_100, DICT_6X6_250)")
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    if target.marker_mm is None:
        raise ValueError("a charuco target needs marker_mm")
    return cv2.aruco.CharucoBoard((target.columns, target.rows), float(target.pitch_mm),
                                  float(target.marker_mm), dictionary)


def _blob_detector(gray: np.ndarray):
    params = cv2.SimpleBlobDetector_Params()  # type: ignore[attr-defined]
    params.minArea = 10.0
    params.maxArea = 0.05 * gray.size
    params.filterByColor, params.blobColor = True, 0
    params.filterByCircularity, params.minCircularity = True, 0.6
    params.filterByConvexity, params.minConvexity = True, 0.8
    params.filterByInertia, params.minInertiaRatio = True, 0.2
    return cv2.SimpleBlobDetector_create(params)  # type: ignore[attr-defined]


def _refined(gray: np.ndarray, corners: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Corners refined by :func:`cv2.cornerSubPix` in a window of a quarter square (on
    rendered boards: 0.22 px RMS from the sector-based detector, 0.07 px refined)."""
    grid = corners.reshape(size[1], size[0], 2)
    square = min(np.min(np.linalg.norm(np.diff(grid, axis=0), axis=2)),
                 np.min(np.linalg.norm(np.diff(grid, axis=1), axis=2)))
    half = int(max(2, min(15, round(0.25 * square))))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    return cv2.cornerSubPix(gray, corners.astype(np.float32).reshape(-1, 1, 2), (half, half),
                            (-1, -1), criteria).reshape(-1, 2).astype(float)


def _first_corner_dark(gray: np.ndarray, corners: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """The corners in the order whose first corner has the dark square outside it.

    OpenCV may start the grid at either end (a 180 degree turn). On a board of an odd and an
    even number of squares the two end squares differ in colour, which fixes the start for
    every view and both cameras alike (the target's convention: the square diagonally outside
    corner 0 is dark)."""
    grid = corners.reshape(size[1], size[0], 2)

    def outside_level(g: np.ndarray) -> float:
        p = g[0, 0] - 0.5 * (g[1, 1] - g[0, 0])
        x, y = (int(round(v)) for v in p)
        h, w = gray.shape
        if not (0 <= x < w and 0 <= y < h):
            return np.nan
        return float(np.mean(gray[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2]))

    start, end = outside_level(grid), outside_level(grid[::-1, ::-1])
    if np.isfinite(start) and np.isfinite(end) and start > end:
        grid = grid[::-1, ::-1]
    return grid.reshape(-1, 2).astype(float)


def detect_board(gray: np.ndarray, target: "Target") -> tuple[np.ndarray, np.ndarray, str]:
    """(ids (m,), px (m, 2), note) of ``target``'s points in the 8-bit image ``gray``."""
    empty = np.zeros(0, int), np.zeros((0, 2))
    size = (target.columns, target.rows)
    if target.kind == "checkerboard":
        flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE
        found, corners = cv2.findChessboardCornersSB(gray, size, flags=flags)
        if not found:                            # the classic detector, refined to sub-pixel
            found, corners = cv2.findChessboardCorners(
                gray, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not found:
            return *empty, f"no {size[0]} x {size[1]} checkerboard found"
        corners = _refined(gray, corners.reshape(-1, 2), size)
        return np.arange(len(corners)), _first_corner_dark(gray, corners, size), ""
    if target.kind == "charuco":
        detector = cv2.aruco.CharucoDetector(charuco_board(target))
        corners, ids, _, _ = detector.detectBoard(gray)
        if ids is None or len(ids) < 6:
            return *empty, (f"{0 if ids is None else len(ids)} ChArUco corners found, at "
                            "least 6 needed")
        return ids.ravel().astype(int), corners.reshape(-1, 2).astype(float), ""
    flags = (cv2.CALIB_CB_SYMMETRIC_GRID if target.kind == "circles"
             else cv2.CALIB_CB_ASYMMETRIC_GRID) | cv2.CALIB_CB_CLUSTERING
    found, centres = cv2.findCirclesGrid(gray, size, flags=flags,
                                         blobDetector=_blob_detector(gray))
    if not found:
        return *empty, f"no {size[0]} x {size[1]} {target.kind.replace('_', ' ')} grid found"
    return np.arange(len(centres)), centres.reshape(-1, 2).astype(float), ""
