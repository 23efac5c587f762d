"""Which integration points each camera sees: rays cast against the features' solids.

A point ``X`` of a face is hidden from camera ``c`` when the segment from ``X`` to the
camera centre ``C`` crosses a feature's convex solid (grown by a margin: the nominal
solids are approximate and the image interpolant reaches ~2 px across an edge). On the
segment ``X + s (C - X)``, ``s`` in (0, 1], facet ``k`` keeps ``a_k + s b_k <= 0`` with
``a_k = n_k . X + d_k`` and ``b_k = n_k . (C - X)``: the segment enters the solid when the
largest lower bound on ``s`` stays below the smallest upper bound (Cyrus-Beck clipping).
Points are masked, not fitted (``fesdic_core.driver.measure(..., visibility=...)``).
"""
from __future__ import annotations

import logging
from typing import Callable, Sequence

import numpy as np

from .geometry import ConvexSolid

logger = logging.getLogger(__name__)

_BLOCK = 200_000          # points per vectorised block (bounds the (g, k) temporaries)


def _candidates(X: np.ndarray, centre: np.ndarray, solid: ConvexSolid) -> np.ndarray:
    """(g,) bool: points whose segment to ``centre`` may reach the solid's bounding box.

    Between the heights of ``X`` and the top of the box the segment drifts sideways by
    at most ``dz |C_xy - X_xy| / (C_z - X_z)``: only points that close to the box can be hidden.
    """
    lo, hi = solid.bounds
    dz = np.clip(hi[2] - X[:, 2], 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        drift = dz * np.linalg.norm(centre[:2] - X[:, :2], axis=1) / np.abs(centre[2] - X[:, 2])
    drift = np.where(np.isfinite(drift), drift, np.inf)
    return np.all((X[:, :2] >= lo[:2] - drift[:, None]) & (X[:, :2] <= hi[:2] + drift[:, None]),
                  axis=1) & (X[:, 2] <= hi[2]) | ((X[:, 2] > hi[2]) & (centre[2] < hi[2]))


def hidden_by(X: np.ndarray, centre: np.ndarray, solid: ConvexSolid) -> np.ndarray:
    """(g,) bool: the segment from ``X`` (g, 3) to ``centre`` (3,) crosses ``solid``."""
    out = np.zeros(len(X), bool)
    index = np.flatnonzero(_candidates(X, centre, solid))
    for start in range(0, len(index), _BLOCK):
        rows = index[start:start + _BLOCK]
        P = X[rows]
        a = P @ solid.normals.T + solid.offsets                     # (g, k) at s = 0
        b = (centre - P) @ solid.normals.T                          # (g, k) slope in s
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = -a / b
        lower = np.where(b < 0, bound, -np.inf).max(axis=1)
        upper = np.where(b > 0, bound, np.inf).min(axis=1)
        never = np.any((b == 0) & (a > 0), axis=1)                  # parallel and outside a facet
        out[rows] = ~never & (np.maximum(lower, 0.0) <= np.minimum(upper, 1.0))
    return out


def visibility(solids: Sequence[ConvexSolid], margin_mm: float
               ) -> Callable[[np.ndarray, Sequence], np.ndarray]:
    """``f(X (g, 3), cameras) -> bool (g,)``: points seen by every camera past every solid."""
    grown = tuple(s.inflated(margin_mm) for s in solids)

    def seen(X: np.ndarray, cameras: Sequence) -> np.ndarray:
        keep = np.ones(len(X), bool)
        for cam in cameras:
            for solid in grown:
                hidden = hidden_by(X, np.asarray(cam.center, float), solid)
                logger.debug("%s hides %d of %d points from %s", solid.name, hidden.sum(), len(X),
                             cam.name)
                keep &= ~hidden
        return keep

    return seen
