"""Tests of the stereo rig (fesdic_core.cameras.rig): stereo transform, camera files, pyvale text, PnP."""
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.rig import (CalibrationError, apply_stereo, initial_pose, initial_rig_pose,
                                     place_camera1, read_cameras_json, read_pyvale_csv,
                                     stereo_extrinsic_jacobian, stereo_transform, write_cameras_json)

DATA = Path(__file__).resolve().parents[3] / "data" / "dic_challenge_stereo"
DIST = [0.059, 1.58, 6.7e-4, 2.1e-3, -125.6]


def _rig():
    K0 = np.array([[10646.0, 6.03, 1277.3], [0.0, 10634.5, 1042.0], [0.0, 0.0, 1.0]])
    K1 = np.array([[10752.8, 3.52, 1346.9], [0.0, 10742.2, 1061.9], [0.0, 0.0, 1.0]])
    cam0 = Camera(K0, DIST, [0.02, -0.03, 0.01], [-3.0, 4.0, 690.0], (2448, 2048), "cam0")
    R = Rotation.from_euler("ZYX", [-0.08, 25.6, 0.07], degrees=True).as_matrix()
    x1 = cv2.composeRT(cam0.rvec.reshape(3, 1), cam0.tvec.reshape(3, 1), cv2.Rodrigues(R)[0],
                       np.array([[-295.2], [-1.0], [72.2]]))
    cam1 = Camera(K1, [0.034, 1.93, 1.7e-3, 3.4e-3, -109.9], x1[0].ravel(), x1[1].ravel(),
                  (2448, 2048), "cam1")
    return cam0, cam1


def _landmarks(n=6, seed=0):
    """Non-coplanar landmarks on a 100 mm specimen around the world origin."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-45, 45, n), rng.uniform(-45, 45, n), rng.uniform(-4, 7, n)])


def test_stereo_transform_and_placement():
    cam0, cam1 = _rig()
    R, t = stereo_transform(cam0, cam1)
    X = _landmarks(20)
    x0 = X @ cam0.R.T + cam0.tvec
    x1 = X @ cam1.R.T + cam1.tvec
    np.testing.assert_allclose(x0 @ R.T + t, x1, atol=1e-9)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
    placed = place_camera1(cam0, cam1, R, t)
    np.testing.assert_allclose(placed.extrinsics, cam1.extrinsics, atol=1e-10)
    np.testing.assert_array_equal(placed.K, cam1.K)
    # moving camera 0 moves camera 1 rigidly with it
    moved0 = cam0.with_extrinsics(cam0.extrinsics + [0.05, -0.02, 0.1, 3.0, -2.0, 10.0])
    moved1 = apply_stereo(moved0, cam1, R, t)
    R2, t2 = stereo_transform(moved0, moved1)
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_allclose(t2, t, atol=1e-9)


def test_stereo_extrinsic_jacobian_vs_finite_differences():
    cam0, cam1 = _rig()
    R, t = stereo_transform(cam0, cam1)
    D = stereo_extrinsic_jacobian(cam0, R, t)
    p0, h = cam0.extrinsics, 1e-6
    fd = np.empty((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        plus = place_camera1(cam0.with_extrinsics(p0 + e), cam1, R, t).extrinsics
        minus = place_camera1(cam0.with_extrinsics(p0 - e), cam1, R, t).extrinsics
        fd[:, k] = (plus - minus) / (2 * h)
    assert np.abs(D - fd).max() / np.abs(D).max() < 1e-6
    np.testing.assert_allclose(D[3:, 3:], R, atol=1e-12)          # t1 = R t0 + t
    np.testing.assert_allclose(D[3:, :3], 0.0, atol=1e-12)


def test_cameras_json_round_trip(tmp_path):
    cams = list(_rig())
    path = tmp_path / "cams.json"
    write_cameras_json(path, cams)
    back = read_cameras_json(path)
    assert [c.name for c in back] == ["cam0", "cam1"]
    for a, b in zip(cams, back):
        for field in ("K", "dist", "rvec", "tvec"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
        assert a.image_size == b.image_size
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cams.json"]   # no temporary left
    data = json.loads(path.read_text())
    assert set(data["cameras"][0]) == {"name", "image_size_px", "K", "dist", "rvec", "tvec_mm"}


@pytest.mark.parametrize("edit,message", [
    (lambda d: d["cameras"][1].update(K=[[1, 2], [3, 4]]), r"cameras\[1\]\.K: expected 3x3 numbers"),
    (lambda d: d["cameras"][0].pop("dist"), r"cameras\[0\]\.dist: missing"),
    (lambda d: d["cameras"][1].update(tvec_mm=[1, "a", 2]), r"cameras\[1\]\.tvec_mm: expected 3 numbers"),
    (lambda d: d["cameras"][0].update(image_size_px=[10.5, 4]), r"cameras\[0\]\.image_size_px"),
    (lambda d: d["cameras"][0]["K"][2].__setitem__(2, 2.0), r"cameras\[0\]"),
    (lambda d: d.pop("cameras"), r"cameras: missing"),
])
def test_cameras_json_errors_name_file_and_field(tmp_path, edit, message):
    path = tmp_path / "bad_cams.json"
    write_cameras_json(path, _rig())
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    with pytest.raises(CalibrationError, match=r"bad_cams\.json.*" + message):
        read_cameras_json(path)


def test_cameras_json_missing_and_broken_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="absent.json"):
        read_cameras_json(tmp_path / "absent.json")
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(CalibrationError, match="broken.json"):
        read_cameras_json(broken)


def test_read_pyvale_csv_dic_challenge():
    path = DATA / "calibration.csv"
    cam0, cam1 = read_pyvale_csv(path, (2448, 2048))
    rows = dict(line.split(",") for line in path.read_text().split())
    v = {k: float(x) for k, x in rows.items()}
    np.testing.assert_array_equal(cam0.extrinsics, np.zeros(6))
    np.testing.assert_array_equal(cam1.K, [[v["cam1_fx_px"], v["cam1_fs_px"], v["cam1_cx_px"]],
                                           [0, v["cam1_fy_px"], v["cam1_cy_px"]], [0, 0, 1]])
    np.testing.assert_array_equal(cam0.dist, [v["cam0_" + k] for k in ("k1", "k2", "p1", "p2", "k3")])
    R_ref = Rotation.from_euler("ZYX", [v["psi_deg"], v["phi_deg"], v["theta_deg"]], degrees=True)
    R, t = stereo_transform(cam0, cam1)
    np.testing.assert_allclose(R, R_ref.as_matrix(), atol=1e-12)   # Rz(psi) Ry(phi) Rx(theta)
    np.testing.assert_allclose(t, [v["tx_mm"], v["ty_mm"], v["tz_mm"]], atol=1e-9)
    # the README's figures: stereo angle about 25.6 degrees, baseline about 304 mm
    assert np.degrees(Rotation.from_matrix(R).magnitude()) == pytest.approx(25.6, abs=0.1)
    assert np.linalg.norm(cam1.center - cam0.center) == pytest.approx(304.0, abs=1.0)
    assert cam0.image_size == cam1.image_size == (2448, 2048)


def test_read_pyvale_csv_errors(tmp_path):
    text = (DATA / "calibration.csv").read_text()
    bad = tmp_path / "calib.csv"
    bad.write_text("\n".join(line for line in text.splitlines() if not line.startswith("phi_deg")))
    with pytest.raises(CalibrationError, match=r"calib\.csv.*phi_deg"):
        read_pyvale_csv(bad, (2448, 2048))
    bad.write_text(text.replace("cam1_k2,", "cam1_k2,oops"))
    with pytest.raises(CalibrationError, match=r"calib\.csv.*cam1_k2"):
        read_pyvale_csv(bad, (2448, 2048))
    with pytest.raises(FileNotFoundError, match="none.csv"):
        read_pyvale_csv(tmp_path / "none.csv", (2448, 2048))


@pytest.mark.parametrize("which", [0, 1])
def test_initial_pose_recovers_a_known_pose_with_skew_and_distortion(which):
    cam = _rig()[which]
    X = _landmarks(6, seed=1)
    px = cam.project(X)
    start = cam.with_extrinsics([0.0, 0.0, 0.0, 0.0, 0.0, 500.0])
    posed = initial_pose(start, X, px)
    np.testing.assert_allclose(posed.extrinsics, cam.extrinsics, atol=1e-6)
    assert np.abs(posed.project(X) - px).max() < 1e-6


def test_initial_pose_errors():
    cam = _rig()[0]
    X = _landmarks(6)
    px = cam.project(X)
    with pytest.raises(ValueError, match="at least 4"):
        initial_pose(cam, X[:3], px[:3])
    px[2, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        initial_pose(cam, X, px)
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        initial_pose(cam, X[:, :2], px)


def test_initial_rig_pose_recovers_a_known_pose():
    cam0, cam1 = _rig()
    R, t = stereo_transform(cam0, cam1)
    X = _landmarks(8, seed=2)
    rng = np.random.default_rng(3)
    px0 = cam0.project(X)
    px1 = cam1.project(X)
    px0[:3] = np.nan                         # landmarks hidden in one view or the other
    px1[6:] = np.nan
    start0 = cam0.with_extrinsics(np.zeros(6))
    start1 = place_camera1(start0, cam1, R, t)
    got0, got1 = initial_rig_pose(start0, start1, X, px0, px1, R, t)
    np.testing.assert_allclose(got0.extrinsics, cam0.extrinsics, atol=1e-6)
    np.testing.assert_allclose(got1.extrinsics, cam1.extrinsics, atol=1e-6)
    # noisy pixels: the two-view fit is at least as good on camera 1 as camera 0's PnP alone
    noisy0 = cam0.project(X) + rng.normal(0, 0.3, size=(8, 2))
    noisy1 = cam1.project(X) + rng.normal(0, 0.3, size=(8, 2))
    both0, both1 = initial_rig_pose(start0, start1, X, noisy0, noisy1, R, t)
    alone1 = place_camera1(initial_pose(start0, X, noisy0), cam1, R, t)
    err_both = np.sum((both0.project(X) - noisy0) ** 2) + np.sum((both1.project(X) - noisy1) ** 2)
    err_alone = np.sum((initial_pose(start0, X, noisy0).project(X) - noisy0) ** 2) \
        + np.sum((alone1.project(X) - noisy1) ** 2)
    assert err_both <= err_alone + 1e-9


def test_shared_calibration_copy_keeps_attribution():
    readme = (DATA / "README.md").read_text()
    for words in ("SEM/iDICs Stereo-DIC Challenge", "pyvale", "MIT", "10.1007/s11340-024-01077-7"):
        assert words in readme
