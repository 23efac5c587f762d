"""`georeg measure` with an OpenCV stereo calibration and landmarks, and the rig files it writes.

Reuses the rendered pair of ``test_end_to_end`` (its ``case`` fixture and configuration). The
OpenCV file holds only the intrinsics and the stereo relation (camera 0 at the origin), so
the rig is posed from landmarks; the written ``<stem>_cameras.json/.yml`` must then agree
with each other and with the cameras that rendered the images.
"""
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from test_end_to_end import CONFIG, RECTANGLE, case  # noqa: F401  (case: the module fixture)

from fesdic_core.cameras.io.formats import read_opencv_stereo
from fesdic_core.cameras.rig import read_cameras_json, stereo_transform

ROOT = Path(__file__).resolve().parents[2]
CORNERS = np.array([[x, y, 0.5 * x * y / 600.0] for x in (-25.0, 0.0, 25.0) for y in (-15.0, 15.0)])


def _opencv_file(path, cameras):
    """What cv2.stereoCalibrate users save: K, D of each camera and R, T; no pose."""
    R, T = stereo_transform(*cameras)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for c, cam in enumerate(cameras, start=1):
        fs.write(f"cameraMatrix{c}", cam.K)
        fs.write(f"distCoeffs{c}", cam.dist.reshape(1, 5))
    fs.write("R", R)
    fs.write("T", T.reshape(3, 1))
    fs.write("imageSize", np.array([cameras[0].image_size], dtype=np.int32))
    fs.release()


@pytest.mark.slow
def test_measure_with_opencv_calibration_writes_the_posed_rig(case, tmp_path):  # noqa: F811
    folder, _, cameras, _ = case
    _opencv_file(tmp_path / "stereo.yml", cameras)
    marks = "".join(f"\n[[landmarks]]\nxyz_mm = {X.tolist()}\ncam0_px = {p0.tolist()}\ncam1_px = {p1.tolist()}\n"
                    for X, p0, p1 in zip(CORNERS, cameras[0].project(CORNERS), cameras[1].project(CORNERS)))
    text = CONFIG.format(cam0=folder / "cam0.png", cam1=folder / "cam1.png", cameras=tmp_path / "stereo.yml",
                         geometry=RECTANGLE).replace("file = ", "opencv = ", 1) + marks
    (tmp_path / "cfg.toml").write_text(text)
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "georeg_app.cli", "-q", "measure", str(tmp_path / "cfg.toml"),
                          "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    (method,) = json.loads((out / "summary.json").read_text())["methods"]
    stem = method["mesh_file"].removesuffix(".vtu")
    from_json = read_cameras_json(out / f"{stem}_cameras.json")
    from_yml = read_opencv_stereo(out / f"{stem}_cameras.yml")
    for a, b, truth in zip(from_json, from_yml, cameras):
        assert np.max(np.abs(a.project(CORNERS) - b.project(CORNERS))) < 1e-9
        assert np.max(np.abs(a.project(CORNERS) - truth.project(CORNERS))) < 1e-3   # posed by landmarks
    R, T = stereo_transform(*from_yml)
    R_true, T_true = stereo_transform(*cameras)
    np.testing.assert_allclose(R, R_true, atol=1e-9)
    np.testing.assert_allclose(T, T_true, atol=1e-6)
