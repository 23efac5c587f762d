"""Nominal geometries as single spline patches (section 4.1, Fig. 7(a)).

* :func:`rectangle`: a flat B-spline patch, one element, ``x`` along the length;
* :func:`plate_with_hole`: the open-hole plate as ONE NURBS patch: degree 2 in the
  circumferential direction ``u`` with knots {0,0,0,.25,.25,.5,.5,.75,.75,1,1,1}
  (four C0-C0 elements, one 90-degree rational arc of the hole each) and degree 2 in
  the radial direction ``v`` (hole at ``v = 0``, plate boundary at ``v = 1``);
* :func:`cylinder`: an exact NURBS cylindrical patch (arcs of at most 90 degrees);
* :func:`quadrilateral`: a flat B-spline patch through four corners in 3-D (a face of a
  CAD model: a block top, a prism face);
* :func:`transformed`: any patch moved by a rigid motion (NURBS are affinely invariant:
  moving the control points moves the surface exactly).

All patches have the normal ``S_u x S_v`` pointing outwards (+z for the plates).
"""
from __future__ import annotations

import logging

import numpy as np

from georeg_plugin.spline.patch import SplinePatch

logger = logging.getLogger(__name__)

__all__ = ["rectangle", "plate_with_hole", "cylinder", "arc_control_points", "quadrilateral",
           "transformed"]


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name}: must be a finite number > 0, got {value}")
    return value


def _open_uniform(degree: int) -> np.ndarray:
    return np.r_[np.zeros(degree + 1), np.ones(degree + 1)]


def rectangle(length_mm: float, width_mm: float, center=(0.0, 0.0),
              degrees=(2, 2)) -> SplinePatch:
    """Flat rectangle ``z = 0``, ``x`` along the length, one element, normal +z.

    Parameters
    ----------
    length_mm, width_mm : sizes along x and y
    center : (x, y) of the centre
    degrees : (p_u, p_v) >= 1

    Returns
    -------
    SplinePatch (B-spline) with u along x and v along y.
    """
    length, width = _positive(length_mm, "length_mm"), _positive(width_mm, "width_mm")
    pu, pv = (int(d) for d in degrees)
    if pu < 1 or pv < 1:
        raise ValueError(f"degrees: must be >= 1, got {degrees}")
    # Bezier control points equally spaced: linear precision gives x = x0 + u * length.
    x = center[0] + length * (np.linspace(0.0, 1.0, pu + 1) - 0.5)
    y = center[1] + width * (np.linspace(0.0, 1.0, pv + 1) - 0.5)
    X, Y = np.meshgrid(x, y, indexing="ij")
    cp = np.stack([X, Y, np.zeros_like(X)], axis=-1)
    return SplinePatch((pu, pv), (_open_uniform(pu), _open_uniform(pv)), cp)


def arc_control_points(radius: float, angles_deg) -> tuple[np.ndarray, np.ndarray]:
    """Quadratic rational arcs through the given angles (each step <= 90 degrees).

    Returns the 2-D control points ``(2 k + 1, 2)`` and weights ``(2 k + 1,)`` of the
    ``k`` arcs between consecutive angles; the middle control point of an arc of
    opening ``2 a`` is at radius ``r / cos a`` on the bisector, with weight ``cos a``.
    """
    a = np.radians(np.asarray(angles_deg, dtype=float))
    half = 0.5 * np.diff(a)
    if np.any(np.abs(half) > np.pi / 4 + 1e-12) or np.any(half == 0):
        raise ValueError(f"angles_deg: consecutive angles must differ by 0 < |d| <= 90, "
                         f"got {angles_deg}")
    theta = np.empty(2 * len(a) - 1)
    theta[0::2] = a
    theta[1::2] = a[:-1] + half
    rho = np.full(theta.shape, float(radius))
    rho[1::2] /= np.cos(half)
    weights = np.ones(theta.shape)
    weights[1::2] = np.cos(half)
    return np.column_stack([rho * np.cos(theta), rho * np.sin(theta)]), weights


def plate_with_hole(length_mm: float, width_mm: float, hole_radius_mm: float,
                    center=(0.0, 0.0)) -> SplinePatch:
    """Rectangular plate with a centred circular hole as one NURBS patch (Fig. 7(a)).

    The circumferential direction ``u`` runs clockwise (so that ``S_u x S_v = +z``)
    from the diagonal towards the corner (+L/2, +W/2): ``u`` in [0, .25] maps the hole
    arc from 45 to -45 degrees onto the right side, [.25, .5] onto the bottom,
    [.5, .75] onto the left and [.75, 1] onto the top side. The knots ``u = .25 k`` are
    the C0 lines towards the four plate corners; ``u = 0`` and ``u = 1`` coincide.
    The radial direction ``v`` (degree 2, one element) goes from the hole (``v = 0``)
    to the plate boundary (``v = 1``), middle control points midway, weights constant
    along ``v`` (so the patch is linear in ``v`` between hole and boundary).

    Parameters
    ----------
    length_mm, width_mm : plate sizes along x and y
    hole_radius_mm : radius of the hole, < min(length, width) / 2
    center : (x, y) of the hole centre (and of the plate)

    Returns
    -------
    SplinePatch, NURBS, degrees (2, 2), 9 x 3 control points, z = 0.
    """
    length, width = _positive(length_mm, "length_mm"), _positive(width_mm, "width_mm")
    r = _positive(hole_radius_mm, "hole_radius_mm")
    if r >= 0.5 * min(length, width):
        raise ValueError(f"hole_radius_mm: {r} must be < min(length, width)/2 = "
                         f"{0.5 * min(length, width)}")
    angles = [45.0, -45.0, -135.0, -225.0, -315.0]          # clockwise, 4 x 90 degrees
    hole, w = arc_control_points(r, angles)
    hx, hy = 0.5 * length, 0.5 * width
    # Plate boundary: corners on the diagonals, side midpoints on the axes (clockwise).
    outer = np.array([[hx, hy], [hx, 0], [hx, -hy], [0, -hy], [-hx, -hy],
                      [-hx, 0], [-hx, hy], [0, hy], [hx, hy]])
    rows = np.stack([hole, 0.5 * (hole + outer), outer], axis=1)  # (9, 3, 2)
    cp = np.concatenate([rows + np.asarray(center, float), np.zeros((9, 3, 1))], axis=-1)
    knots_u = np.array([0, 0, 0, .25, .25, .5, .5, .75, .75, 1, 1, 1], dtype=float)
    weights = np.repeat(w[:, None], 3, axis=1)
    return SplinePatch((2, 2), (knots_u, _open_uniform(2)), cp, weights)


def cylinder(radius_mm: float, length_mm: float, angle_deg: float = 180.0,
             axis: str = "x", center=(0.0, 0.0)) -> SplinePatch:
    """Exact cylindrical NURBS patch, crest up (towards +z), outward normal.

    The axis lies in the plane ``z = 0`` along ``axis``, through ``center``; the arc
    spans ``angle_deg`` symmetrically about +z (180 degrees: a half cylinder lying on
    ``z = 0``), split into ``ceil(angle / 90)`` equal rational quadratic arcs with C0
    knots between them. Degree 2 along the axis with one element.

    Returns
    -------
    SplinePatch, NURBS, u along the arc, v along the axis, ``S_u x S_v`` outwards.
    """
    r, length = _positive(radius_mm, "radius_mm"), _positive(length_mm, "length_mm")
    angle = _positive(angle_deg, "angle_deg")
    if angle > 360.0:
        raise ValueError(f"angle_deg: must be <= 360, got {angle}")
    if axis not in ("x", "y"):
        raise ValueError(f"axis: expected 'x' or 'y', got {axis!r}")
    k = int(np.ceil(angle / 90.0 - 1e-12))
    # theta measured from +z; with axis x, u runs towards -y so S_u x S_v is outwards.
    sign = -1.0 if axis == "x" else 1.0
    theta = sign * np.linspace(-0.5 * angle, 0.5 * angle, k + 1)
    arc, w = arc_control_points(r, theta)       # (cos, sin) of theta -> (z, lateral)
    z, lateral = arc[:, 0], arc[:, 1]
    along = length * np.array([-0.5, 0.0, 0.5])
    n = len(z)
    cp = np.zeros((n, 3, 3))
    a, b = (0, 1) if axis == "x" else (1, 0)    # index of the axis, of the lateral
    cp[:, :, a] = center[a] + along[None, :]
    cp[:, :, b] = center[b] + lateral[:, None]
    cp[:, :, 2] = z[:, None]
    inner = np.repeat(np.arange(1, k) / k, 2)
    knots_u = np.r_[0, 0, 0, inner, 1, 1, 1]
    return SplinePatch((2, 2), (knots_u, _open_uniform(2)), cp, np.repeat(w[:, None], 3, 1))


def quadrilateral(corners, degrees=(2, 2), planarity_tol_mm: float = 1e-6) -> SplinePatch:
    """Flat B-spline patch through four corners in 3-D, one element.

    Parameters
    ----------
    corners : (4, 3) corners ``c00, c10, c11, c01`` (mm), in order around the face; ``u``
        runs from ``c00`` to ``c10``, ``v`` from ``c00`` to ``c01``, and the normal
        ``S_u x S_v`` points to the side from which the corners turn counter-clockwise.
    degrees : (p_u, p_v) >= 1
    planarity_tol_mm : largest distance of a corner to the plane of the others

    Returns
    -------
    SplinePatch (B-spline), the bilinear map ``S(u, v)`` of the corners (control points
    equally spaced: linear precision), flat.
    """
    c = np.asarray(corners, dtype=float)
    if c.shape != (4, 3) or not np.all(np.isfinite(c)):
        raise ValueError(f"corners: expected (4, 3) finite coordinates, got shape {c.shape}")
    pu, pv = (int(d) for d in degrees)
    if pu < 1 or pv < 1:
        raise ValueError(f"degrees: must be >= 1, got {degrees}")
    normal = np.cross(c[2] - c[0], c[3] - c[1])               # diagonals: robust for a quad
    if np.linalg.norm(normal) <= 1e-12 * np.ptp(c, axis=0).max() ** 2:
        raise ValueError(f"corners: degenerate quadrilateral {c.tolist()}")
    normal /= np.linalg.norm(normal)
    off = float(np.max(np.abs((c - c.mean(axis=0)) @ normal)))
    if off > planarity_tol_mm:
        raise ValueError(f"corners: not coplanar, a corner is {off:.3g} mm off their mean plane "
                         f"(tolerance {planarity_tol_mm:g} mm)")
    u = np.linspace(0.0, 1.0, pu + 1)[:, None, None]
    v = np.linspace(0.0, 1.0, pv + 1)[None, :, None]
    cp = ((1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3])
    return SplinePatch((pu, pv), (_open_uniform(pu), _open_uniform(pv)), cp)


def transformed(patch: SplinePatch, rotation=np.eye(3), translation=(0.0, 0.0, 0.0)) -> SplinePatch:
    """The patch moved by ``X -> R X + t`` (exact: the control points are moved).

    Parameters
    ----------
    rotation : (3, 3) proper rotation matrix ``R``
    translation : (3,) ``t`` (mm)
    """
    R = np.asarray(rotation, dtype=float)
    t = np.asarray(translation, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) \
            or np.linalg.det(R) <= 0:
        raise ValueError(f"rotation: expected a proper 3 x 3 rotation matrix, got {R.tolist()}")
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"translation: expected 3 finite numbers, got {t.tolist()}")
    cp = patch.control_points @ R.T + t
    return SplinePatch(patch.degrees, patch.knots, cp, patch.weights)
