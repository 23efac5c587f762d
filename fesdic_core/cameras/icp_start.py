"""Rough poses of a part from its points alone: principal axes, then a slide search.

A part seen without landmarks has no pose to start ICP from
(:func:`fesdic_core.cameras.icp.point_to_plane_icp`). :func:`principal_axes_starts` matches
the points' principal axes to the surface's, in each choice of signs (and, for axes of
nearly equal moments, turned about the distinct one); :func:`best_start` slides each start
over a grid along the surface's plane, keeps the best few by the share of points near the
surface, runs a short ICP from them and keeps the best fit.
"""
from __future__ import annotations

import logging
from typing import Sequence

import numpy as np

from fesdic_core.cameras.icp import TriangleSurface, point_to_plane_icp, rotation_matrix

logger = logging.getLogger(__name__)

__all__ = ["principal_axes", "principal_axes_starts", "best_start"]

_DEGENERATE = 0.2       # principal moments within this relative gap: the axes are ambiguous


def principal_axes(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroid (3,), principal axes (3, 3) (columns, largest moment first, right-handed)
    and the moments (3,) (variances along the axes, mm^2) of ``points`` (n, 3)."""
    x = np.asarray(points, dtype=float).reshape(-1, 3)
    centroid = x.mean(axis=0)
    return (centroid, *_axes(np.cov((x - centroid).T, bias=True)))


def _axes(covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    moments, axes = np.linalg.eigh(covariance)
    moments, axes = moments[::-1], axes[:, ::-1]
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return axes, moments


def principal_axes_starts(points: np.ndarray, surface: TriangleSurface, turns: int = 36
                          ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Rough poses ``(R, t)`` (``x_surface = R x + t``) of ``points`` (n, 3) on ``surface``:
    the points' centroid on the surface's, their principal axes on its axes, in every
    proper choice of signs (4). When two principal moments of the surface lie within 20 %
    of each other (a square plate: its in-plane axes are arbitrary), the axis of the third
    is matched (both signs) and the rest turned about it by each multiple of
    ``360 / turns`` degrees instead."""
    c_p, axes_p, _ = principal_axes(points)
    c_s, cov_s = surface.moments()
    axes_s, m = _axes(cov_s)
    rel = lambda i, j: abs(m[i] - m[j]) / max(m[i], m[j], 1e-300)   # noqa: E731
    flips = [np.diag(s) for s in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1))]
    about = next((a for a, (i, j) in ((2, (0, 1)), (0, (1, 2))) if rel(i, j) < _DEGENERATE),
                 None)
    if about is None:
        starts = [axes_s @ S @ axes_p.T for S in flips]
    else:                          # the distinct axis, either way up, and turns about it
        flip = np.diag([-1.0, 1.0, -1.0] if about == 2 else [1.0, -1.0, -1.0])
        starts = [rotation_matrix(axes_s[:, about] * 2 * np.pi * j / turns) @ axes_s @ S
                  @ axes_p.T for S in (np.eye(3), flip) for j in range(turns)]
    return [(R, c_s - R @ c_p) for R in starts]


def _slide_scores(x: np.ndarray, surface: TriangleSurface, offsets: np.ndarray,
                  tolerance_mm: float) -> np.ndarray:
    """(k,) the share of the points ``x`` (n, 3) within ``tolerance_mm`` of a sample of the
    surface once moved by each of ``offsets`` (k, 3)."""
    moved = (x[None, :, :] + offsets[:, None, :]).reshape(-1, 3)
    d, _ = surface.tree.query(moved, distance_upper_bound=tolerance_mm)
    return np.isfinite(d).reshape(len(offsets), len(x)).mean(axis=1)


def best_start(points: np.ndarray, surface: TriangleSurface,
               starts: Sequence[tuple[np.ndarray, np.ndarray]], sample: int = 300,
               span: float = 0.25, steps: int = 11, keep: int = 4, iterations: int = 30,
               floor_mm: float = 1e-6, seed: int = 0
               ) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """The start that fits best, with its slide along the surface's two largest principal
    axes (the centroids of a part and of the points on what the cameras see of it need not
    agree: a visible share, a hidden strip).

    For each start, ``sample`` points drawn at random are slid over a grid of ``steps`` x
    ``steps`` offsets spanning ``span`` of the surface's extent either way along those axes,
    each offset scored by the share of points within 1 % of the surface's diagonal of it;
    the ``keep`` best (start, offset) pairs get an ICP of ``iterations`` steps on the sample,
    scored by the mean truncated square residual ``mean(min(r^2, tau^2))`` (tau five times
    the smallest median absolute residual among them). Returns the best ICP's ``(R, t)`` and
    the grid's best share for each start."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(p) > sample:
        p = p[np.random.default_rng(seed).choice(len(p), sample, replace=False)]
    axes_s, _ = _axes(surface.moments()[1])
    corners = surface.triangles.reshape(-1, 3)
    extent = np.ptp(corners @ axes_s[:, :2], axis=0)
    tolerance = 0.01 * float(np.linalg.norm(np.ptp(corners, axis=0)))
    a, b = np.meshgrid(np.linspace(-span, span, steps) * extent[0],
                       np.linspace(-span, span, steps) * extent[1], indexing="ij")
    offsets = a.reshape(-1, 1) * axes_s[:, 0] + b.reshape(-1, 1) * axes_s[:, 1]
    candidates, shares = [], []
    for R, t in starts:
        score = _slide_scores(p @ R.T + t, surface, offsets, tolerance)
        k = int(np.argmax(score))
        shares.append(float(score[k]))
        candidates.append((float(score[k]), R, t + offsets[k]))
    candidates.sort(key=lambda c: -c[0])
    runs = [point_to_plane_icp(p, surface, R, t, max_iterations=iterations, floor_mm=floor_mm)
            for _, R, t in candidates[:keep]]
    tau = 5.0 * max(min(float(np.median(np.abs(r.residual_mm))) for r in runs), floor_mm)
    scores = [float(np.mean(np.minimum(r.residual_mm ** 2, tau ** 2))) for r in runs]
    best = runs[int(np.argmin(scores))]
    logger.debug("ICP starts: best shares %s; their ICP scores %s mm^2 (tau %.3g mm)",
                 np.round(sorted(shares)[::-1][:keep], 3).tolist(), np.round(scores, 6).tolist(),
                 tau)
    return (best.rotation, best.translation), np.array(shares)
