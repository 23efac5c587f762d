"""Gauge-invariant accuracy measures against a known synthetic truth."""
import cv2
import numpy as np

from fesdic_core.shape.gauge import move_cameras_with_specimen
from fesdic_core.synthetic.accuracy import shape_error_to_surface, stereo_correspondence_error
from fesdic_core.synthetic.render import demo_cameras, true_surface_points
from fesdic_core.synthetic.specimen import twisted_plate

SPECIMEN = twisted_plate(60.0, 40.0, corner_mm=0.5, speckle_mm=0.4, seed=3)
CAMERAS = demo_cameras(image_size=(640, 480), field_mm=72.0)
ROTATION = np.deg2rad(1.0) * np.array([1.0, 2.0, -1.0]) / np.sqrt(6.0)
TRANSLATION = np.array([0.6, -0.48, 0.64])


def _grid():
    x, y = np.meshgrid(np.linspace(-29.0, 29.0, 13), np.linspace(-19.0, 19.0, 9))
    return np.column_stack([x.ravel(), y.ravel()])


def _true_normals(xy):
    gx, gy = SPECIMEN.height_gradient(xy[:, 0], xy[:, 1])
    n = np.column_stack([-gx, -gy, np.ones_like(gx)])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _rigidly_moved(X, rotation, translation, centre):
    """X -> R (X - c) + c + t, the motion of gauge.move_cameras_with_specimen."""
    R = cv2.Rodrigues(rotation.reshape(3, 1))[0]
    return (X - centre) @ R.T + centre + translation


def test_shape_error_vanishes_on_the_true_surface_moved_rigidly():
    X = true_surface_points(SPECIMEN, _grid())
    moved = _rigidly_moved(X, ROTATION, TRANSLATION, np.array([5.0, -3.0, 1.0]))
    assert np.abs(moved - X).max() > 0.5                      # not a trivial motion
    np.testing.assert_allclose(shape_error_to_surface(moved, SPECIMEN), 0.0, atol=1e-6)


def test_shape_error_equals_a_known_normal_offset():
    """A non-rigid offset d along the true normal (orthogonal to the rigid modes) is found."""
    xy = _grid()
    # odd in x and in y: orthogonal to the normal effect of every rigid motion of the twisted
    # plate (1, x, y for the offset and tilts, k x, k y and k (x^2 - y^2) for the slides)
    d = 0.02 * xy[:, 0] * xy[:, 1] / (29.0 * 19.0)
    X = true_surface_points(SPECIMEN, xy) + d[:, None] * _true_normals(xy)
    moved = _rigidly_moved(X, ROTATION, TRANSLATION, np.zeros(3))
    np.testing.assert_allclose(shape_error_to_surface(moved, SPECIMEN), d, atol=2e-5 * np.abs(d).max())


def test_stereo_error_vanishes_for_the_exact_rig_and_is_gauge_invariant():
    X = true_surface_points(SPECIMEN, _grid())
    err = stereo_correspondence_error(X, CAMERAS, CAMERAS, SPECIMEN)
    assert err.shape == (X.shape[0], 2)
    np.testing.assert_allclose(err, 0.0, atol=1e-6)
    # the same measurement in another gauge: specimen and cameras moved together
    moved_cams = move_cameras_with_specimen(CAMERAS, TRANSLATION, ROTATION, np.zeros(3))
    R_inv_points = _rigidly_moved(X, np.zeros(3), -TRANSLATION, np.zeros(3))
    Y = _rigidly_moved(R_inv_points, -ROTATION, np.zeros(3), np.zeros(3))   # M^-1 X
    np.testing.assert_allclose(moved_cams[0].project(Y), CAMERAS[0].project(X), atol=1e-9)
    np.testing.assert_allclose(stereo_correspondence_error(Y, moved_cams, CAMERAS, SPECIMEN), 0.0,
                               atol=1e-6)


def test_stereo_error_sees_a_wrong_relative_pose():
    X = true_surface_points(SPECIMEN, _grid())
    dR = cv2.Rodrigues(np.deg2rad(0.02) * np.array([0.0, 1.0, 0.0]))[0]   # about its own centre
    cam1 = CAMERAS[1].with_extrinsics(np.r_[cv2.Rodrigues(dR @ CAMERAS[1].R)[0].ravel(),
                                            dR @ CAMERAS[1].tvec])
    shift = np.linalg.norm(cam1.project(X) - CAMERAS[1].project(X), axis=1)
    err = stereo_correspondence_error(X, (CAMERAS[0], cam1), CAMERAS, SPECIMEN)
    np.testing.assert_allclose(err[:, 0], shift, rtol=1e-6, atol=1e-9)   # view 0 -> 1: the shift
    assert err.min() > 0.5
