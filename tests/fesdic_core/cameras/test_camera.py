"""Tests of the pinhole + distortion camera (fesdic_core.cameras.camera) against OpenCV and finite differences."""
import cv2
import numpy as np
import pytest

from fesdic_core.cameras.camera import Camera

# distortion of the DIC-challenge stereo cameras (pyvale calibration), and a milder set
CHALLENGE_DIST = [0.059449362415370306, 1.5792286900793455, 0.0006657306839709375,
                  0.0020726026105884242, -125.56115053624104]
MILD_DIST = [-0.12, 0.05, 1e-3, -2e-3, 0.01]


def _camera(dist, skew=0.0, rvec=(0.1, -0.25, 0.05), tvec=(5.0, -3.0, 650.0), f=10646.0):
    K = np.array([[f, skew, 1277.3], [0.0, f * 0.999, 1042.0], [0.0, 0.0, 1.0]])
    return Camera(K, dist, rvec, tvec, (2448, 2048), "test")


def _points_in_view(cam, n=200, seed=0, half_width_px=1100):
    """World points projecting within about ``half_width_px`` of the principal point."""
    rng = np.random.default_rng(seed)
    K = cam.K
    xn = rng.uniform(-half_width_px, half_width_px, size=(n, 2)) / K[0, 0]
    z = rng.uniform(600.0, 700.0, size=n)
    Xc = np.column_stack([xn * z[:, None], z])
    return (Xc - cam.tvec) @ cam.R                                  # R^T (Xc - t)


def _cv2_project(cam, X, K=None):
    K = cam.K if K is None else K
    x, J = cv2.projectPoints(X.reshape(-1, 1, 3), cam.rvec, cam.tvec, K, cam.dist)
    return x.reshape(-1, 2), J


@pytest.mark.parametrize("dist", [CHALLENGE_DIST, MILD_DIST, [0.0] * 5])
def test_project_matches_opencv_without_skew(dist):
    cam = _camera(dist)
    X = _points_in_view(cam)
    x_cv, _ = _cv2_project(cam, X)
    np.testing.assert_allclose(cam.project(X), x_cv, rtol=0, atol=1e-6)


@pytest.mark.parametrize("dist", [CHALLENGE_DIST, MILD_DIST])
def test_project_with_skew_matches_opencv_normalised_then_K(dist):
    cam = _camera(dist, skew=6.03)
    X = _points_in_view(cam, seed=1)
    xd, _ = _cv2_project(cam, X, K=np.eye(3))                      # distorted normalised coordinates
    x_ref = np.column_stack([xd, np.ones(len(xd))]) @ cam.K.T
    np.testing.assert_allclose(cam.project(X), x_ref[:, :2], rtol=0, atol=1e-6)


def _central_difference(fun, p, h):
    cols = []
    for i in range(len(p)):
        e = np.zeros(len(p))
        e[i] = h
        cols.append((fun(p + e) - fun(p - e)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("skew", [0.0, 6.03])
@pytest.mark.parametrize("dist", [CHALLENGE_DIST, MILD_DIST])
def test_project_jacobian_vs_finite_differences(dist, skew):
    cam = _camera(dist, skew)
    X = _points_in_view(cam, n=40, seed=2)
    x, J = cam.project_jacobian(X)
    np.testing.assert_array_equal(x, cam.project(X))
    for k in range(3):                     # one column at a time: d x_n / d X_n[k]
        e = np.zeros(3)
        e[k] = 1e-3
        fd = (cam.project(X + e) - cam.project(X - e)) / 2e-3
        err = np.abs(J[:, :, k] - fd).max() / np.abs(J).max()
        assert err < 1e-6, (k, err)


@pytest.mark.parametrize("skew", [0.0, 6.03])
@pytest.mark.parametrize("dist", [CHALLENGE_DIST, MILD_DIST])
def test_extrinsic_jacobian_vs_finite_differences(dist, skew):
    cam = _camera(dist, skew)
    X = _points_in_view(cam, n=40, seed=3)
    x, J = cam.extrinsic_jacobian(X)
    np.testing.assert_array_equal(x, cam.project(X))
    p0 = cam.extrinsics
    fd_r = _central_difference(lambda p: cam.with_extrinsics(p).project(X), p0, 1e-6)
    scale = np.abs(J).max(axis=(0, 1))
    err = np.abs(J - fd_r).max(axis=(0, 1)) / scale
    assert np.all(err < 1e-6), err


@pytest.mark.parametrize("dist", [CHALLENGE_DIST, MILD_DIST])
def test_extrinsic_jacobian_matches_opencv(dist):
    cam = _camera(dist)
    X = _points_in_view(cam, n=50, seed=4)
    _, J = cam.extrinsic_jacobian(X)
    _, Jcv = _cv2_project(cam, X)                                  # (2n, 15): rvec, tvec, f, c, dist
    Jcv = Jcv[:, :6].reshape(-1, 2, 6)
    np.testing.assert_allclose(J, Jcv, rtol=1e-9, atol=1e-9 * np.abs(Jcv).max())


def test_pose_helpers():
    cam = _camera(MILD_DIST)
    X = _points_in_view(cam, n=10, seed=5)
    np.testing.assert_allclose(cam.R @ cam.center + cam.tvec, 0.0, atol=1e-9)
    np.testing.assert_allclose(cam.depth(X), (X @ cam.R.T + cam.tvec)[:, 2], rtol=1e-14)
    behind = 2 * cam.center - X                                    # mirror through the centre
    assert cam.in_front(X).all() and not cam.in_front(behind).any()
    p = cam.extrinsics + np.array([0.01, 0.0, -0.02, 1.0, 2.0, -3.0])
    moved = cam.with_extrinsics(p)
    np.testing.assert_array_equal(moved.extrinsics, p)
    np.testing.assert_array_equal(moved.K, cam.K)
    assert moved.name == cam.name and moved.image_size == cam.image_size


@pytest.mark.parametrize("level", [1, 2, 3])
def test_scaled_camera_is_the_coarse_pixel_transform(level):
    cam = _camera(CHALLENGE_DIST, skew=6.03)
    X = _points_in_view(cam, n=30, seed=6)
    x = cam.project(X)
    for _ in range(level):
        x = (x - 0.5) / 2.0                  # one 2x2 aggregation, pixel centres at integers
    coarse = cam.scaled(level)
    np.testing.assert_allclose(coarse.project(X), x, rtol=0, atol=1e-9)
    w, h = cam.image_size
    for _ in range(level):
        w, h = w // 2, h // 2
    assert coarse.image_size == (w, h)
    assert cam.scaled(0) is cam


@pytest.mark.parametrize("field,kwargs", [
    ("K", {"K": np.eye(2)}),
    ("K", {"K": [[100.0, 0, 1], [1, 100, 1], [0, 0, 1]]}),
    ("K", {"K": [[-1.0, 0, 1], [0, 100, 1], [0, 0, 1]]}),
    ("dist", {"dist": [0.1, 0.2]}),
    ("rvec", {"rvec": [0.0, np.nan, 0.0]}),
    ("tvec", {"tvec": "abc"}),
    ("image_size", {"image_size": (100,)}),
    ("image_size", {"image_size": (100.5, 20)}),
    ("image_size", {"image_size": (0, 20)}),
])
def test_validation_names_the_field(field, kwargs):
    args = dict(K=np.diag([100.0, 100.0, 1.0]), dist=np.zeros(5), rvec=np.zeros(3),
                tvec=np.zeros(3), image_size=(64, 48), name="bad")
    args.update(kwargs)
    with pytest.raises(ValueError, match=field):
        Camera(**args)


def test_camera_is_frozen_and_arrays_read_only():
    cam = _camera(MILD_DIST)
    with pytest.raises(AttributeError):
        cam.K = np.eye(3)
    with pytest.raises(ValueError):
        cam.rvec[0] = 1.0


@pytest.mark.parametrize("dist", [np.zeros(5), CHALLENGE_DIST])
def test_pull_backs_are_the_transposed_jacobians(dist):
    """The vector-Jacobian products of Eqs. 6 and 8 equal J^T g with J checked against OpenCV."""
    cam = _camera(dist)                                             # OpenCV's model has no skew
    X = _points_in_view(cam, n=60, seed=5)
    g = np.random.default_rng(6).standard_normal((len(X), 2))
    x, lin = cam.linearise(X)
    np.testing.assert_array_equal(x, cam.project(X))
    _, Jcv = _cv2_project(cam, X)
    Jp = Jcv[:, :6].reshape(-1, 2, 6)                               # OpenCV's d pixel / d [rvec, tvec]
    np.testing.assert_allclose(lin.pull_extrinsic(g), np.einsum("nik,ni->nk", Jp, g),
                               rtol=1e-9, atol=1e-9 * np.abs(Jp).max())
    cam = _camera(dist, 6.03)                                       # skew: vs the FD-checked J
    x, lin = cam.linearise(X)
    _, JX = cam.project_jacobian(X)
    np.testing.assert_allclose(lin.pull_point(g), np.einsum("nik,ni->nk", JX, g), rtol=1e-12,
                               atol=1e-12 * np.abs(JX).max())
