"""Figures of merit of the measured faces (world frame, mm; base plane z = 0).

* flatness: RMS distance to the best-fit plane and to the best-fit quadric
  ``z = a + b x + c y + d x^2 + e x y + f y^2`` (least squares, in the plane's own frame);
* block height: mean distance of the block top to the plane fitted to a ring of the
  base plate around the block (``ring_mm`` from its footprint);
* cylinders: least-squares cylinder (axis direction and position, radius) by
  Gauss-Newton (``scipy.optimize.least_squares``); crest height = height of the axis
  above the base plane + radius; the radius over sub-arcs about the crest.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.path import Path as Polygon
from scipy.optimize import least_squares

from .config import Feature


def rms(values: np.ndarray) -> float:
    values = np.asarray(values, float)
    return float(np.sqrt(np.mean(values ** 2))) if values.size else float("nan")


def plane_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre (3,) and axes (3, 3) (rows e1, e2, n; n towards +z) of the best-fit plane."""
    centre = points.mean(axis=0)
    vt = np.linalg.svd(points - centre, full_matrices=False)[2]
    n = vt[2] if vt[2][2] > 0 else -vt[2]
    e1 = vt[0] - (vt[0] @ n) * n
    e1 /= np.linalg.norm(e1)
    return centre, np.array([e1, np.cross(n, e1), n])


def plane_residuals(points: np.ndarray) -> np.ndarray:
    """Signed distances (n,) to the best-fit plane."""
    centre, axes = plane_frame(points)
    return (points - centre) @ axes[2]


def quadric_residuals(points: np.ndarray) -> np.ndarray:
    """Residuals (n,) of the best-fit quadric height ``w(u, v)`` over the best-fit plane."""
    centre, axes = plane_frame(points)
    u, v, w = ((points - centre) @ axes.T).T
    A = np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v])
    coef, *_ = np.linalg.lstsq(A, w, rcond=None)
    return w - A @ coef


def inside_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """(n,) bool: the (x, y) of ``points`` inside ``polygon`` (m, 2)."""
    return Polygon(np.asarray(polygon, float)).contains_points(points[:, :2])


def distance_to_footprint(points: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    """Distance (n,) in (x, y) from the points to a convex footprint polygon (0 inside)."""
    xy = points[:, :2]
    poly = np.asarray(footprint, float)
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("nkd,kd->nk", xy[:, None] - a, ab) / np.sum(ab * ab, axis=1), 0, 1)
    d = np.linalg.norm(xy[:, None] - (a + t[..., None] * ab), axis=-1).min(axis=1)
    return np.where(inside_polygon(points, poly), 0.0, d)


@dataclass(frozen=True)
class BlockHeight:
    height_mm: float          # mean distance of the block top to the ring's plane
    top_rms_plane_mm: float   # flatness of the block top
    ring_rms_plane_mm: float  # flatness of the ring
    n_top: int
    n_ring: int


def block_height(top: np.ndarray, base: np.ndarray, block: Feature,
                 ring_mm: tuple[float, float]) -> BlockHeight:
    """Height of the block top above the plane of the base ring around the block."""
    d = distance_to_footprint(base, block.footprint_mm)
    ring = base[(d >= ring_mm[0]) & (d <= ring_mm[1])]
    centre, axes = plane_frame(ring)
    h = (top - centre) @ axes[2]
    return BlockHeight(float(h.mean()), rms(plane_residuals(top)), rms((ring - centre) @ axes[2]),
                       len(top), len(ring))


@dataclass(frozen=True)
class CylinderFit:
    radius_mm: float
    axis_point_mm: np.ndarray     # (3,) point of the axis at the middle of the points
    axis_direction: np.ndarray    # (3,) unit
    crest_height_mm: float        # axis height + radius (base plane z = 0)
    rms_mm: float
    residuals_mm: np.ndarray      # (n,) radial distance - radius
    angle_deg: np.ndarray         # (n,) angle of each point about the axis from the crest


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` / ``|v|``."""
    return v / np.linalg.norm(v)


def fit_cylinder(points: np.ndarray, axis_guess: np.ndarray, radius_guess: float,
                 radius: float | None = None) -> CylinderFit:
    """Least-squares cylinder through ``points`` (n, 3); ``radius`` fixes it if given."""
    a0 = unit(np.asarray(axis_guess, float))
    e1 = unit(np.cross(a0, [0.0, 0.0, 1.0]))      # lateral
    e2 = np.cross(e1, a0)                           # up, normal to the axis
    c = points.mean(axis=0)
    span = (points - c) @ a0
    mid = c + 0.5 * (span.max() + span.min()) * a0

    def geometry(p):
        d = unit(a0 + p[0] * e1 + p[1] * e2)
        o = mid + p[2] * e1 + p[3] * e2
        return d, o

    def residual(p):
        d, o = geometry(p)
        arm = points - o
        r = p[4] if radius is None else radius
        return np.linalg.norm(arm - np.outer(arm @ d, d), axis=1) - r

    r0 = radius_guess if radius is None else radius
    # start: the nominal direction, the axis one radius below the highest point
    p0 = np.array([0.0, 0.0, 0.0, points[:, 2].max() - r0 - mid[2], r0])
    fit = least_squares(residual, p0, x_scale="jac", method="lm")
    d, o = geometry(fit.x)
    d = d if d @ a0 > 0 else -d
    r = float(fit.x[4]) if radius is None else float(radius)
    arm = points - o
    radial = arm - np.outer(arm @ d, d)
    up = np.cross(unit(np.cross(d, [0.0, 0.0, 1.0])), d)
    lateral = unit(np.cross(d, [0.0, 0.0, 1.0]))
    angle = np.degrees(np.arctan2(radial @ lateral, radial @ up))
    crest = float(o[2] + r * np.sqrt(1.0 - d[2] ** 2))
    return CylinderFit(r, o, d, crest, rms(fit.fun), fit.fun, angle)


def radius_by_arc(points: np.ndarray, fit: CylinderFit, half_angles=(20.0, 30.0, 40.0)
                  ) -> list[tuple[float, float, int]]:
    """(half angle, fitted radius, n points) over the sub-arcs ``|angle| <= half angle``."""
    out = []
    for a in half_angles:
        keep = np.abs(fit.angle_deg) <= a
        if keep.sum() > 100:
            sub = fit_cylinder(points[keep], fit.axis_direction, fit.radius_mm)
            out.append((a, sub.radius_mm, int(keep.sum())))
    return out
