"""Tests of the synthetic stereo renderer (ray casting, boundary, noise, Eq. 3)."""

from dataclasses import replace

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import ndimage

from fesdic_core.cameras.camera import Camera
from fesdic_core.synthetic.rays import intersect_surface, pixel_rays
from fesdic_core.synthetic.render import (GRAY_RANGE, demo_cameras, render_stereo, speckle_mm_for,
                                          true_normal_offset, true_surface_points)
from fesdic_core.synthetic.specimen import Specimen, flat_plate, twisted_plate

DIST = np.array([-0.08, 0.02, 4e-4, -3e-4, 0.01])


def _uniform(value):
    return lambda x, y: np.full(np.shape(x), float(value))


def _twisted(**kwargs):
    return twisted_plate(100.0, 24.0, corner_mm=0.6, waviness_mm=0.25, view_length_mm=48.0, **kwargs)


def _project_cv2(camera, X):
    """Projection through cv2.projectPoints, skew applied after (OpenCV ignores K[0, 1])."""
    xd, _ = cv2.projectPoints(X, camera.rvec, camera.tvec, np.eye(3), camera.dist)
    xd = xd.reshape(-1, 2)
    K = camera.K
    return np.column_stack([K[0, 0] * xd[:, 0] + K[0, 1] * xd[:, 1] + K[0, 2], K[1, 1] * xd[:, 1] + K[1, 2]])


@pytest.mark.parametrize("skew", [0.0, 3.5])
def test_ray_hits_surface_and_projects_back_on_its_pixel(skew):
    cam, _ = demo_cameras((320, 240), distance_mm=300.0, field_mm=48.0, dist=DIST)
    K = cam.K.copy()
    K[0, 1] = skew
    cam = Camera(K, cam.dist, cam.rvec, cam.tvec, cam.image_size, "skewed")
    specimen = _twisted()
    px = np.random.default_rng(3).uniform([-0.5, -0.5], [319.5, 239.5], size=(500, 2))
    centre, directions = pixel_rays(cam, px)
    lam = intersect_surface(specimen, centre, directions)
    X = centre + lam[:, None] * directions
    assert np.mean(np.abs(X[:, 2])) > 0.1  # the surface is really off the plane z = 0
    assert np.max(np.abs(X[:, 2] - specimen.height(X[:, 0], X[:, 1]))) < 1e-9
    assert np.max(np.abs(_project_cv2(cam, X) - px)) < 1e-6
    assert np.max(np.abs(cam.project(X) - px)) < 1e-6
    if skew == 0.0:
        uv, _ = cv2.projectPoints(X, cam.rvec, cam.tvec, cam.K, cam.dist)
        assert np.max(np.abs(uv.reshape(-1, 2) - px)) < 1e-6


def test_ray_parallel_to_the_plate_misses():
    lam = intersect_surface(_twisted(), np.array([0.0, 0.0, 5.0]), np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]))
    assert np.isnan(lam[0])
    assert abs(lam[1] - (5.0 - 0.25)) < 1e-12  # straight down onto the 0.25 mm central bump


def test_true_surface_points_and_normal_offsets_land_on_the_surface():
    specimen = _twisted()
    xy = np.random.default_rng(0).uniform([-24, -12], [24, 12], size=(200, 2))
    X = true_surface_points(specimen, xy)
    assert_allclose(X[:, 2], specimen.height(xy[:, 0], xy[:, 1]), rtol=0, atol=0)
    X0 = np.column_stack([xy, np.zeros(len(xy))])
    assert_allclose(true_normal_offset(specimen, X0, np.tile([0.0, 0.0, 1.0], (len(xy), 1))), X[:, 2], atol=1e-12)
    n = np.column_stack([0.2 * np.sin(xy[:, 0]), 0.1 * np.cos(xy[:, 1]), np.ones(len(xy))])
    n /= np.linalg.norm(n, axis=1)[:, None]
    Xs = X0 + true_normal_offset(specimen, X0, n)[:, None] * n
    assert np.max(np.abs(Xs[:, 2] - specimen.height(Xs[:, 0], Xs[:, 1]))) < 1e-9


def test_height_gradient_matches_finite_differences():
    specimen = _twisted()
    xy = np.random.default_rng(1).uniform([-50, -12], [50, 12], size=(100, 2))
    gx, gy = specimen.height_gradient(xy[:, 0], xy[:, 1])
    h = 1e-5
    fd_x = (specimen.height(xy[:, 0] + h, xy[:, 1]) - specimen.height(xy[:, 0] - h, xy[:, 1])) / (2 * h)
    fd_y = (specimen.height(xy[:, 0], xy[:, 1] + h) - specimen.height(xy[:, 0], xy[:, 1] - h)) / (2 * h)
    assert_allclose(gx, fd_x, atol=1e-8)
    assert_allclose(gy, fd_y, atol=1e-8)
    corners = np.array([[24.0, 12.0], [-24.0, 12.0], [24.0, -12.0], [-24.0, -12.0]])
    assert_allclose(specimen.height(corners[:, 0], corners[:, 1]), [0.6, -0.6, -0.6, 0.6], atol=1e-12)


def _crossings(curve_uv, axis, level):
    """Positions along ``1 - axis`` where the closed/open polyline crosses ``uv[:, axis] = level``."""
    a, b = curve_uv[:-1], curve_uv[1:]
    s = (level - a[:, axis]) / (b[:, axis] - a[:, axis])
    ok = (s >= 0) & (s < 1)
    return np.sort(a[ok, 1 - axis] + s[ok] * (b[ok, 1 - axis] - a[ok, 1 - axis]))


def test_boundary_of_plate_and_hole_land_on_the_projected_true_boundary():
    s = 3
    inside, outside = 150.0, 10.0
    specimen = twisted_plate(100.0, 24.0, corner_mm=0.6, waviness_mm=0.25, view_length_mm=48.0, hole_radius_mm=7.0)
    specimen = replace(specimen, texture=_uniform(inside))
    cam = demo_cameras((320, 240), distance_mm=300.0, field_mm=48.0, dist=DIST)[1]
    (image,) = render_stereo(specimen, [cam], supersample=s, background=outside, bit_depth=None)
    coverage = (image - outside) / (inside - outside)
    offsets = (np.arange(s) + 0.5) / s - 0.5
    t = np.linspace(0, 2 * np.pi, 40001)
    hole = cam.project(true_surface_points(specimen, 7.0 * np.column_stack([np.cos(t), np.sin(t)])))
    x = np.linspace(-50, 50, 40001)
    edges = [cam.project(true_surface_points(specimen, np.column_stack([x, np.full_like(x, y)]))) for y in (12, -12)]
    tol = 0.5 / s + 0.02  # a row of s sample columns locates an edge to 1/(2 s) px
    for v in (90, 100, 119, 130, 150):  # rows through the hole: background inside, plate around
        true = np.mean([_crossings(hole, 1, v + o) for o in offsets], axis=0)  # (left, right)
        u = np.arange(320)
        assert np.all(image[v, u < true[0] - 1] == inside) and np.all(image[v, u > true[1] + 1] == inside)
        assert np.all(image[v, (u > true[0] + 1) & (u < true[1] - 1)] == outside)
        mid = int(round(np.mean(true)))
        left = -0.5 + np.sum(coverage[v, :mid])  # plate length from the image border to the hole
        right = 319.5 - np.sum(coverage[v, mid:])
        assert abs(left - true[0]) < tol and abs(right - true[1]) < tol
    for u in (20, 80, 240, 300):  # columns through the long edges y = +-12 mm
        top, bottom = (np.mean([_crossings(e, 0, u + o)[0] for o in offsets]) for e in edges)
        v = np.arange(240)
        assert np.all(image[v < top - 1, u] == outside) and np.all(image[v > bottom + 1, u] == outside)
        assert np.all(image[(v > top + 1) & (v < bottom - 1), u] == inside)
        assert abs(239.5 - np.sum(1 - coverage[:, u][v > 120]) - bottom) < tol
        assert abs(-0.5 + np.sum(1 - coverage[:, u][v <= 120]) - top) < tol


def test_determinism_and_noise_level():
    cams = demo_cameras((160, 120), distance_mm=300.0, field_mm=30.0)
    specimen = flat_plate(60.0, 40.0, speckle_mm=0.5, seed=4)
    a = render_stereo(specimen, cams, supersample=2, noise_std=2.0, seed=7)
    b = render_stereo(specimen, cams, supersample=2, noise_std=2.0, seed=7)
    c = render_stereo(specimen, cams, supersample=2, noise_std=2.0, seed=8)
    d = render_stereo(flat_plate(60.0, 40.0, speckle_mm=0.5, seed=5), cams, supersample=2)
    for i in range(2):
        assert np.array_equal(a[i], b[i])
        assert not np.array_equal(a[i], c[i])
        assert np.array_equal(a[i], np.clip(np.rint(a[i]), 0, 255))
    assert np.mean(np.abs(d[0] - a[0])) > 20  # another speckle seed: another pattern
    uniform = Specimen(60.0, 40.0, texture=_uniform(100.0))
    for sigma, bits in ((2.0, None), (2.0, 8), (5.0, None)):
        img = render_stereo(uniform, cams, supersample=1, noise_std=sigma, seed=1, bit_depth=bits)[0]
        expected = np.sqrt(sigma**2 + (1 / 12 if bits else 0))  # + the quantisation noise
        assert abs(img.std() / expected - 1) < 0.1
        assert abs(img.mean() - 100.0) < 0.1


@pytest.mark.slow
def test_gray_level_conservation_between_the_views():
    """Eq. 3: f0(P_0(X)) = f1(P_1(X)) on the true surface, not 0.3 mm off it."""
    cams = demo_cameras((400, 300), distance_mm=300.0, field_mm=40.0, dist=DIST)
    specimen = twisted_plate(100.0, 30.0, corner_mm=0.6, waviness_mm=0.25, view_length_mm=40.0,
                             hole_radius_mm=6.0, speckle_mm=speckle_mm_for(cams[0], 4.0))
    images = render_stereo(specimen, cams, supersample=3, bit_depth=None)
    grid = np.stack(np.meshgrid(np.linspace(-16, 16, 81), np.linspace(-11, 11, 56)), -1).reshape(-1, 2)
    grid = grid[np.hypot(grid[:, 0], grid[:, 1]) > 7.0]
    X = true_surface_points(specimen, grid)
    gx, gy = specimen.height_gradient(grid[:, 0], grid[:, 1])
    n = np.column_stack([-gx, -gy, np.ones(len(grid))])
    n /= np.linalg.norm(n, axis=1)[:, None]
    dynamic = GRAY_RANGE[1] - GRAY_RANGE[0]

    def rms_difference(points):
        f = [ndimage.map_coordinates(im, cam.project(points)[:, ::-1].T, order=3, mode="nearest")
             for im, cam in zip(images, cams)]
        return np.sqrt(np.mean((f[0] - f[1]) ** 2)) / dynamic

    on = rms_difference(X)
    off = rms_difference(X + 0.3 * n)
    assert images[0].std() > 0.25 * dynamic  # a contrasted speckle
    assert on < 0.03
    assert off > 5 * on and off > 0.15


def test_demo_cameras_are_mirror_images_with_the_stereo_angle():
    cam0, cam1 = demo_cameras((600, 400), stereo_angle_deg=30.0, distance_mm=500.0, field_mm=100.0)
    axes = [cam.R[2] for cam in (cam0, cam1)]
    assert_allclose(np.degrees(np.arccos(axes[0] @ axes[1])), 30.0, atol=1e-9)
    X = np.random.default_rng(2).uniform(-20, 20, size=(50, 3))
    mirror = X * [-1, 1, 1]
    assert_allclose(cam1.project(mirror), (599.0, 0.0) + cam0.project(X) * (-1, 1), atol=1e-9)
    ends = cam0.project(np.array([[-50.0, 0.0, 0.0], [50.0, 0.0, 0.0]]))
    assert abs((ends[1, 0] - ends[0, 0]) / 600 - 1) < 0.01  # the field fills the image width
    assert_allclose(cam0.project(np.zeros((1, 3))), [[299.5, 199.5]], atol=1e-9)
    assert abs(speckle_mm_for(cam0, 4.0) - 4 * 100.0 * np.cos(np.radians(15)) / 600) < 1e-9


@pytest.mark.parametrize(
    "kwargs, field",
    [({"length_mm": -1.0, "width_mm": 5.0}, "length_mm"),
     ({"length_mm": 10.0, "width_mm": 5.0, "hole_radius_mm": 3.0}, "hole_radius_mm"),
     ({"length_mm": 10.0, "width_mm": 5.0, "speckle_mm": 0.0}, "speckle_mm")],
)
def test_bad_specimen_raises_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Specimen(**kwargs)


def test_bad_render_arguments_raise():
    cams = demo_cameras((20, 10))
    with pytest.raises(ValueError, match="supersample"):
        render_stereo(flat_plate(10.0, 5.0), cams, supersample=0)
    with pytest.raises(ValueError, match="noise_std"):
        render_stereo(flat_plate(10.0, 5.0), cams, noise_std=-1.0)
    with pytest.raises(ValueError, match="speckle_mm"):
        render_stereo(flat_plate(1000.0, 1000.0), cams, speckle_mm=0.01)
