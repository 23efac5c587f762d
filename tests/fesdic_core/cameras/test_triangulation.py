"""Stereo points of a calibrated pair: triangulation, the epipolar distance, SIFT matches on a render."""
import cv2
import numpy as np
import pytest

from fesdic_core.cameras.triangulation import (epipolar_distance_px, normalised_points,
                                               stereo_points, triangulate)
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import Specimen

DISTORTED = np.array([-0.12, 0.05, 0.001, -0.0008, 0.01])


def _distorted_skewed_pair():
    cams = demo_cameras(image_size=(640, 480), field_mm=80.0, dist=DISTORTED)
    K = cams[1].K.copy()
    K[0, 1] = 3.0                                                  # skew
    return cams[0], type(cams[1])(K, cams[1].dist, cams[1].rvec, cams[1].tvec, cams[1].image_size)


def _moved(cameras, rvec, t):
    """The same rig in a world frame X_new = R X_old + t (the plate z = 0 moves with it)."""
    R = cv2.Rodrigues(np.asarray(rvec, float))[0]
    out = []
    for c in cameras:
        Rc = c.R @ R.T
        out.append(c.with_extrinsics(np.concatenate([cv2.Rodrigues(Rc)[0].ravel(),
                                                     c.tvec - Rc @ t])))
    return out, R


def test_triangulate_recovers_points_through_distortion_and_skew():
    cam0, cam1 = _distorted_skewed_pair()
    X = np.random.default_rng(0).uniform([-30, -20, -3], [30, 20, 3], (200, 3))
    Y, err = triangulate(cam0, cam1, cam0.project(X), cam1.project(X))
    assert np.max(np.abs(Y - X)) < 1e-8
    assert np.max(err) < 1e-8


def test_normalised_points_invert_the_projection():
    cam0, cam1 = _distorted_skewed_pair()
    X = np.random.default_rng(1).uniform([-30, -20, -3], [30, 20, 3], (50, 3))
    xc = cam1.to_camera(X)
    np.testing.assert_allclose(normalised_points(cam1, cam1.project(X)), xc[:, :2] / xc[:, 2:],
                               atol=1e-10)


def test_epipolar_distance_is_zero_on_the_line_and_the_offset_across_it():
    cam0, cam1 = demo_cameras(image_size=(640, 480), field_mm=80.0)
    X = np.random.default_rng(2).uniform([-30, -20, -3], [30, 20, 3], (50, 3))
    p0, p1 = cam0.project(X), cam1.project(X)
    assert np.max(epipolar_distance_px(cam0, cam1, p0, p1)) < 1e-9
    # demo cameras are side by side (baseline along x): epipolar lines run along the rows
    d = epipolar_distance_px(cam0, cam1, p0, p1 + [0.0, 0.7])
    assert np.all(np.abs(d - 0.7) < 0.05), d


@pytest.fixture(scope="module")
def flat_render():
    cams = demo_cameras(image_size=(640, 480), field_mm=80.0)
    spec = Specimen(60.0, 40.0, speckle_mm=speckle_mm_for(cams[0], 4.0), seed=3)
    return cams, render_stereo(spec, cams, supersample=2, noise_std=2.0, seed=1, progress=False)


@pytest.mark.slow
def test_stereo_points_of_a_flat_plate_lie_on_it(flat_render):
    cams, arrays = flat_render
    moved, R = _moved(cams, [0.3, -0.2, 0.5], np.array([10.0, -5.0, 300.0]))
    h, w = arrays[0].shape
    corners = cams[0].project(np.array([[-27, -18, 0], [27, -18, 0], [27, 18, 0], [-27, 18, 0.0]]))
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.round(corners).astype(np.int32)], 1)
    pts = stereo_points(moved[0], moved[1], arrays[0], arrays[1], mask > 0)
    assert pts.n_points > 1000 and pts.n_points >= 0.9 * pts.n_matches
    assert np.median(pts.epipolar_px) < 0.1
    back = (pts.xyz_mm - [10.0, -5.0, 300.0]) @ R                   # the plate's own frame
    inside = (np.abs(back[:, 0]) < 30) & (np.abs(back[:, 1]) < 20)
    assert inside.mean() > 0.99
    z = back[:, 2]
    # 1 px of disparity is about 0.25 mm here: the RMS, a few matches wrong along their
    # epipolar line included, is about 0.2 px; the typical point is within 0.04 px
    assert np.sqrt(np.mean(z ** 2)) < 0.05, np.sqrt(np.mean(z ** 2))
    assert np.median(np.abs(z)) < 0.01


def test_no_match_gives_empty_points_not_an_error():
    cam0, cam1 = demo_cameras(image_size=(64, 48), field_mm=80.0)
    xyz, err = triangulate(cam0, cam1, np.zeros((0, 2)), np.zeros((0, 2)))
    assert xyz.shape == (0, 3) and err.shape == (0,)
    flat = np.full((48, 64), 100.0)
    pts = stereo_points(cam0, cam1, flat, flat)
    assert pts.n_points == 0 and pts.n_matches == 0
