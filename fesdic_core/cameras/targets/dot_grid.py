"""Dot grids with ring ("donut") markers, as VIC-3D and DICe print them: detection.

A target of ``rows x columns`` dark dots on a light ground, ``pitch_mm`` apart, a few of
them rings (a dot with a light centre) at known grid positions that fix the grid's origin
and orientation. In one image:

1. **Blobs.** The image over its local white level (a wide Gaussian blur: vignetting and
   uneven light cancel), Otsu's threshold, the outer contours of the dark regions; a blob is
   kept when its area is within a factor of the median blob's and its contour is an ellipse
   (area against the fitted ellipse's). Stray marks, blobs cut by the image border and merged
   blobs fall out here.
2. **Centres.** The gray-level centroid of each blob's darkness (local white level minus the
   image, over the blob dilated by a few pixels): sub-pixel, and the same point for a dot
   and a ring by symmetry. The perspective bias of a circle's centre (the centre of a
   projected circle is not the projection of its centre) is the calibration's business
   (:func:`fesdic_core.cameras.targets.calibration.circle_centre_bias`), which knows the poses.
3. **Markers.** A ring's centre is light: the mean normalised gray level in a small disc at
   its centroid is above :data:`RING_CENTRE_LEVEL`.
4. **The grid.** Each assignment of the detected rings to the target's marker positions
   gives an affine map of grid coordinates to pixels; it predicts every dot. The assignment
   that explains the most blobs is kept, then the map grows into a homography fitted to the
   blobs matched so far (within :data:`MATCH_FRACTION` of the local pitch of a prediction,
   one blob per grid point), until no match changes. Dots cut by the border or missing are
   simply absent from the detection.
"""
from __future__ import annotations

import itertools
import logging

import cv2
import numpy as np

logger = logging.getLogger(__name__)

__all__ = ["Blobs", "find_blobs", "match_grid", "RING_CENTRE_LEVEL", "MATCH_FRACTION"]

#: a blob whose centre's normalised gray level (0 = the dots' ink, 1 = the white) is above
#: this is a ring: solid dots measure 0.05-0.25 on the real targets, rings 0.6-0.9
RING_CENTRE_LEVEL = 0.45
#: a blob matches a predicted grid point within this fraction of the local pitch
MATCH_FRACTION = 0.3
_AREA_FACTOR = 3.0          # blobs within this factor of the median blob's area
_ELLIPSE_TOLERANCE = 0.2    # |contour area / fitted ellipse area - 1| at most this
_MIN_AREA_PX = 12.0         # a dot covers at least this many pixels
_BORDER_PX = 2              # a blob touching this margin is cut by the border


class Blobs:
    """The dot candidates of one image: centres (m, 2) px, areas (m,), ring flags (m,)."""

    def __init__(self, centres: np.ndarray, areas: np.ndarray, ring: np.ndarray):
        self.centres, self.areas, self.ring = centres, areas, ring

    def __len__(self) -> int:
        return len(self.centres)


def _normalised(gray: np.ndarray) -> np.ndarray:
    """The image over its local white level (0 ink .. 1 white)."""
    g = gray.astype(np.float32)
    h, w = g.shape
    shrink = max(1, max(h, w) // 240)                            # the white level is smooth:
    small = cv2.resize(g, (max(w // shrink, 1), max(h // shrink, 1)), interpolation=cv2.INTER_AREA)
    small = cv2.dilate(small, np.ones((9, 9), np.uint8))         # dots erased, then smoothed
    small = cv2.GaussianBlur(small, (0, 0), max(small.shape) / 40.0)
    white = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    ink = float(np.percentile(g, 1.0))
    return np.clip((g - ink) / np.maximum(white - ink, 1.0), 0.0, 1.5)


def find_blobs(gray: np.ndarray) -> Blobs:
    """Dark elliptical blobs of ``gray`` (h, w): sub-pixel centres, areas, ring flags."""
    n = _normalised(gray)
    n8 = (np.clip(n, 0.0, 1.0) * 255).astype(np.uint8)
    n8 = cv2.medianBlur(n8, 3)
    _, binary = cv2.threshold(n8, 0, 255, cv2.THRESH_BINARY_INV + cv2.THRESH_OTSU)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    h, w = gray.shape
    keep = []
    for c in contours:
        if len(c) < 6:
            continue
        x, y, bw, bh = cv2.boundingRect(c)
        if x < _BORDER_PX or y < _BORDER_PX or x + bw > w - _BORDER_PX or y + bh > h - _BORDER_PX:
            continue
        area = cv2.contourArea(c)
        if area < _MIN_AREA_PX:
            continue
        (_, _), (a, b), _ = cv2.fitEllipse(c)
        if not a * b > 0 or abs(area / (np.pi * a * b / 4.0) - 1.0) > _ELLIPSE_TOLERANCE:
            continue
        keep.append((c, area, (x, y, bw, bh)))
    if not keep:
        return Blobs(np.zeros((0, 2)), np.zeros(0), np.zeros(0, bool))
    areas = np.array([k[1] for k in keep])
    median = float(np.median(areas))
    sized = (areas > median / _AREA_FACTOR) & (areas < median * _AREA_FACTOR)
    darkness = 1.0 - np.clip(n, 0.0, 1.0)
    centres, ring = [], []
    grow = 3
    for (c, area, (x, y, bw, bh)), ok in zip(keep, sized):
        if not ok:
            continue
        x0, y0 = max(x - grow, 0), max(y - grow, 0)
        x1, y1 = min(x + bw + grow, w), min(y + bh + grow, h)
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.drawContours(mask, [c - [x0, y0]], -1, 1, thickness=-1)
        mask = cv2.dilate(mask, np.ones((2 * grow + 1, 2 * grow + 1), np.uint8))
        weight = darkness[y0:y1, x0:x1] * mask
        m = cv2.moments(weight.astype(np.float64))
        cx, cy = x0 + m["m10"] / m["m00"], y0 + m["m01"] / m["m00"]
        r = max(1.0, 0.15 * np.sqrt(area / np.pi))
        yy, xx = np.mgrid[y0:y1, x0:x1]
        core = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
        centre_level = float(np.mean(n[y0:y1, x0:x1][core])) if core.any() else 0.0
        centres.append((cx, cy))
        ring.append(centre_level > RING_CENTRE_LEVEL)
    return Blobs(np.array(centres, float), areas[sized], np.array(ring, bool))


def _nearest(predicted: np.ndarray, centres: np.ndarray, tolerance: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Grid points (their indices) and blobs matched one to one within ``tolerance`` px."""
    d = np.linalg.norm(predicted[:, None, :] - centres[None, :, :], axis=2)
    best = np.argmin(d, axis=1)
    ok = d[np.arange(len(predicted)), best] <= tolerance
    grid, blob = np.flatnonzero(ok), best[ok]
    # one grid point per blob: the nearest
    order = np.argsort(d[grid, blob])
    _, first = np.unique(blob[order], return_index=True)
    chosen = order[first]
    return grid[chosen], blob[chosen]


def _local_pitch(H: np.ndarray, grid_xy: np.ndarray) -> np.ndarray:
    """(n,) px per grid unit at each grid point under the homography ``H``."""
    def apply(p):
        q = cv2.perspectiveTransform(p.reshape(-1, 1, 2).astype(np.float64), H)
        return q.reshape(-1, 2)
    here = apply(grid_xy)
    return 0.5 * (np.linalg.norm(apply(grid_xy + [1, 0]) - here, axis=1)
                  + np.linalg.norm(apply(grid_xy + [0, 1]) - here, axis=1))


def match_grid(blobs: Blobs, grid_xy: np.ndarray, marker_xy: np.ndarray,
               max_iterations: int = 20) -> tuple[np.ndarray, np.ndarray, str]:
    """Assign blobs to grid points.

    Parameters
    ----------
    blobs : the image's candidates (:func:`find_blobs`).
    grid_xy : (N, 2) the target's grid points as (column, row).
    marker_xy : (k, 2) the rings' grid points (k >= 3, not collinear).

    Returns
    -------
    ids : (m,) indices into ``grid_xy`` of the matched points.
    px : (m, 2) their sub-pixel centres.
    note : why nothing was matched ("" when something was).
    """
    empty = (np.zeros(0, int), np.zeros((0, 2)), "")
    rings = np.flatnonzero(blobs.ring)
    if len(rings) < len(marker_xy):
        return empty[0], empty[1], (f"{len(rings)} ring markers found, the target has "
                                    f"{len(marker_xy)}")
    best = None
    for chosen in itertools.permutations(rings, len(marker_xy)):
        A = cv2.getAffineTransform(marker_xy[:3].astype(np.float32),
                                   blobs.centres[list(chosen[:3])].astype(np.float32))
        H = np.vstack([A, [0.0, 0.0, 1.0]])
        seeds = np.array([int(np.argmin(np.linalg.norm(grid_xy - m, axis=1))) for m in marker_xy])
        grid, blob = _grow(blobs, grid_xy, H, max_iterations, seeds)
        if best is None or len(grid) > len(best[0]):
            best = (grid, blob)
    if best is None:
        return empty[0], empty[1], "no assignment of the ring markers"
    grid, blob = best
    if len(grid) < 6:
        return empty[0], empty[1], f"only {len(grid)} dots fit the grid of the markers"
    return grid, blobs.centres[blob], ""


def _grow(blobs: Blobs, grid_xy: np.ndarray, H: np.ndarray, max_iterations: int,
          seeds: np.ndarray, reach: float = 2.0):
    """Match outwards from the grid points ``seeds``: at each pass the grid points within
    ``reach`` grid units of those matched so far, then a homography on all matches."""
    grid = blob = np.zeros(0, int)
    matched_xy = grid_xy[seeds]
    for _ in range(max_iterations):
        near = np.min(np.linalg.norm(grid_xy[:, None] - matched_xy[None], axis=2), axis=1) <= reach
        candidates = np.flatnonzero(near)
        predicted = cv2.perspectiveTransform(grid_xy[candidates].reshape(-1, 1, 2)
                                             .astype(np.float64), H).reshape(-1, 2)
        tolerance = MATCH_FRACTION * _local_pitch(H, grid_xy[candidates])
        sub, new_blob = _nearest(predicted, blobs.centres, tolerance)
        new_grid = candidates[sub]
        order = np.argsort(new_grid)
        new_grid, new_blob = new_grid[order], new_blob[order]
        if len(new_grid) < 4:
            return new_grid, new_blob
        if np.array_equal(new_grid, grid) and np.array_equal(new_blob, blob):
            break
        grid, blob = new_grid, new_blob
        matched_xy = grid_xy[grid]
        H, _ = cv2.findHomography(grid_xy[grid].astype(np.float64), blobs.centres[blob], 0)
        if H is None:
            break
    return grid, blob
