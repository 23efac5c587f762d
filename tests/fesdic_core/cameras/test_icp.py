"""Point-to-plane ICP on a triangle soup (fesdic_core.cameras.icp): closest points, the
surface's moments, a known rigid motion recovered, the principal-axes start of a part."""
import numpy as np
import pytest

from fesdic_core.cameras.icp import (TriangleSurface, closest_points_on_triangles,
                                     point_to_plane_icp, rotation_matrix, rotation_vector)
from fesdic_core.cameras.icp_start import best_start, principal_axes_starts

#: the known motion of the points off the part: a few degrees and mm
ROTATION_DEG = np.array([2.0, -3.0, 4.0])
SHIFT_MM = np.array([1.5, -2.0, 2.5])
NOISE_MM = 0.02


def _quad(p0, p1, p2, p3):
    return [np.array([p0, p1, p2], float), np.array([p0, p2, p3], float)]


def _part() -> np.ndarray:
    """A 100 x 80 mm plate (z = 0) with a 30 x 30 mm block top at z = 6 (its four walls), a
    ramp rising to 8 mm and a 45-degree prism: features that fix every rigid motion."""
    t = []
    t += _quad([-50, -40, 0], [50, -40, 0], [50, 40, 0], [-50, 40, 0])
    t += _quad([-30, -10, 6], [0, -10, 6], [0, 20, 6], [-30, 20, 6])
    t += _quad([-30, -10, 0], [0, -10, 0], [0, -10, 6], [-30, -10, 6])
    t += _quad([0, -10, 0], [0, 20, 0], [0, 20, 6], [0, -10, 6])
    t += _quad([-30, 20, 0], [-30, -10, 0], [-30, -10, 6], [-30, 20, 6])
    t += _quad([0, 20, 0], [-30, 20, 0], [-30, 20, 6], [0, 20, 6])
    t += _quad([10, 10, 0], [40, 10, 0], [40, 35, 8], [10, 35, 8])
    t += _quad([10, -35, 0], [40, -35, 0], [40, -25, 5], [10, -25, 5])
    t += _quad([10, -25, 5], [40, -25, 5], [40, -15, 0], [10, -15, 0])
    return np.array(t)


def _heights(xy: np.ndarray) -> np.ndarray:
    """The part's height at ``xy`` (n, 2) as seen from above (the tops of the features)."""
    x, y = xy[:, 0], xy[:, 1]
    z = np.zeros(len(xy))
    block = (x > -30) & (x < 0) & (y > -10) & (y < 20)
    ramp = (x > 10) & (x < 40) & (y > 10) & (y < 35)
    prism = (x > 10) & (x < 40) & (y > -35) & (y < -15)
    z[block] = 6.0
    z[ramp] = 8.0 * (y[ramp] - 10.0) / 25.0
    z[prism] = 5.0 - 0.5 * np.abs(y[prism] + 25.0)
    return z


def _measured(seed: int = 1, n: int = 3000, outliers: int = 300):
    """Points on the part (noise NOISE_MM) plus background outliers, moved off it by the known
    motion; returns the points and the true motion back (x_part = R x + t)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([-50, -40], [50, 40], (n, 2))
    on = np.column_stack([xy, _heights(xy)]) + rng.normal(scale=NOISE_MM, size=(n, 3))
    P = np.vstack([on, rng.uniform(-60, 60, (outliers, 3))])
    R = rotation_matrix(np.radians(ROTATION_DEG))
    return (P - SHIFT_MM) @ R, R, SHIFT_MM        # x_measured = R^T (x_part - t)


def _pose_error(R, t, R_true, t_true, points):
    """The rotation error (deg) and the largest displacement error (mm) over ``points``."""
    angle = np.degrees(np.linalg.norm(rotation_vector(R @ R_true.T)))
    shift = np.max(np.linalg.norm(points @ (R - R_true).T + (t - t_true), axis=1))
    return angle, shift


def test_closest_points_are_on_the_triangles_and_never_farther_than_a_dense_sample():
    rng = np.random.default_rng(0)
    a, b, c = rng.normal(size=(3, 60, 3))
    p = 2.0 * rng.normal(size=(60, 3))
    q, inside = closest_points_on_triangles(p, a, b, c)
    u = np.linspace(0.0, 1.0, 201)
    U, V = np.meshgrid(u, u)
    keep = U + V <= 1.0
    U, V = U[keep], V[keep]
    for k in range(len(p)):
        dense = a[k] + U[:, None] * (b[k] - a[k]) + V[:, None] * (c[k] - a[k])
        best = np.min(np.linalg.norm(dense - p[k], axis=1))
        mine = np.linalg.norm(q[k] - p[k])
        assert mine <= best + 1e-12
        assert best - mine < 0.02                 # the dense sample's spacing
    n = np.cross(b - a, c - a)
    gap = p - q                                   # inside: the gap is along the normal
    along = np.abs(np.einsum("ij,ij->i", gap, n)) / np.linalg.norm(n, axis=1)
    np.testing.assert_allclose(along[inside], np.linalg.norm(gap[inside], axis=1), rtol=1e-9)
    assert inside.any() and (~inside).any()


def test_surface_moments_are_those_of_a_uniform_density():
    rng = np.random.default_rng(3)
    T = rng.normal(size=(2, 3, 3))
    centroid, covariance = TriangleSurface.of(T).moments()
    area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    n = 400000
    k = rng.choice(2, size=n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    x = ((1 - r1)[:, None] * T[k, 0] + (r1 * (1 - r2))[:, None] * T[k, 1]
         + (r1 * r2)[:, None] * T[k, 2])
    np.testing.assert_allclose(centroid, x.mean(axis=0), atol=5e-3)
    np.testing.assert_allclose(covariance, np.cov(x.T, bias=True), atol=5e-3)


def test_icp_recovers_a_known_rigid_motion_of_a_few_degrees_and_mm():
    points, R_true, t_true = _measured()
    surface = TriangleSurface.of(_part())
    fit = point_to_plane_icp(points, surface)
    angle, shift = _pose_error(fit.rotation, fit.translation, R_true, t_true, points[:3000])
    assert fit.converged
    assert angle < 0.05 and shift < 0.05, (angle, shift)          # noise 20 um
    assert abs(fit.rms_mm - NOISE_MM) < 0.3 * NOISE_MM, fit.rms_mm
    assert fit.inliers[:3000].mean() > 0.97                       # the points on the part
    assert fit.inliers[3000:].mean() < 0.1                        # the background


def test_icp_without_features_leaves_the_slide_of_a_plane_where_it_started():
    plate = np.array(_quad([-50, -40, 0], [50, -40, 0], [50, 40, 0], [-50, 40, 0]))
    rng = np.random.default_rng(4)
    points = np.column_stack([rng.uniform([-45, -35], [45, 35], (500, 2)), np.full(500, 0.7)])
    fit = point_to_plane_icp(points, TriangleSurface.of(plate))
    assert abs(fit.translation[2] + 0.7) < 1e-6                   # the offset is fitted
    assert np.linalg.norm(fit.translation[:2]) < 1e-6             # the slide is not
    assert fit.conditioning < 1e-6                                # and it says so


def test_principal_axes_start_finds_the_pose_of_a_part_turned_half_round():
    points, R_true, t_true = _measured(seed=2)
    turn = rotation_matrix(np.radians([0.0, 0.0, 150.0]))         # far beyond any ICP's reach
    points = points @ turn.T
    R_true, surface = R_true @ turn.T, TriangleSurface.of(_part())
    (R, t), shares = best_start(points, surface, principal_axes_starts(points, surface))
    fit = point_to_plane_icp(points, surface, R, t)
    angle, shift = _pose_error(fit.rotation, fit.translation, R_true, t_true, points[:3000])
    assert angle < 0.05 and shift < 0.05, (angle, shift)
    assert np.max(shares) > 0.85


def test_icp_refuses_too_few_points():
    with pytest.raises(ValueError, match="5 points, at least 6"):
        point_to_plane_icp(np.zeros((5, 3)), TriangleSurface.of(_part()))
