"""``georeg calibrate``: the rig from rendered target views, its files, and its errors."""
import json

import numpy as np
import pytest
from cli_checks import one_error_line
from target_views import write_views

from fesdic_core.cameras.io.formats import read_opencv_stereo
from fesdic_core.cameras.rig import read_cameras_json, stereo_transform
from georeg_app import cli

CONFIG = """[images]
cam0 = "views/target_*_cam0.png"
cam1 = "views/target_*_cam1.png"
[target]
kind = "dots"
rows = 9
columns = 12
pitch_mm = 8.0
markers = [[2, 2], [2, 6], [9, 6]]
dot_diameter_mm = 3.2
[model]
distortion = "k1k2"
{extra}
"""


@pytest.fixture(scope="module")
def folder(tmp_path_factory, dot_target_views):
    views, rig = dot_target_views
    root = tmp_path_factory.mktemp("calibrate")
    write_views(root / "views", views)
    return root, rig


def _config(root, extra="", name="calibrate.toml"):
    path = root / name
    path.write_text(CONFIG.format(extra=extra))
    return path


@pytest.mark.slow
def test_calibrate_writes_a_rig_that_the_measure_readers_load(folder, tmp_path):
    root, rig = folder
    out = tmp_path / "out"
    assert cli.main(["-q", "calibrate", str(_config(root)), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["views_used"] == 8 and summary["reprojection_rms_px"] < 0.05
    cams = read_cameras_json(out / "cameras.json")
    assert np.allclose(cams[0].rvec, 0) and np.allclose(cams[0].tvec, 0)   # camera 0: world
    yml = read_opencv_stereo(out / "cameras.yml")
    (R, T), (Ry, Ty) = stereo_transform(*cams), stereo_transform(*yml)
    assert np.allclose(R, Ry, atol=1e-9) and np.allclose(T, Ty, atol=1e-9)
    R0, T0 = stereo_transform(*rig)
    assert abs(np.linalg.norm(T) - np.linalg.norm(T0)) < 3 * summary["stereo"]["baseline_std_mm"]
    assert {f"view_{v:02d}_cam{c}.png" for v in range(8) for c in range(2)} <= \
        {p.name for p in out.iterdir()}
    assert "Stereo calibration" in (out / "report.html").read_text()


@pytest.mark.slow
def test_compare_and_check_sections_put_the_true_rig_beside_ours(folder, tmp_path):
    root, rig = folder
    from fesdic_core.cameras.rig import write_cameras_json
    write_cameras_json(root / "true.json", rig)
    import cv2
    from fesdic_core.synthetic.render import render_stereo
    from fesdic_core.synthetic.specimen import flat_plate
    speckle = render_stereo(flat_plate(100.0, 80.0, speckle_mm=0.8, seed=2), rig, supersample=2,
                            noise_std=1.0, progress=False)
    for c, image in enumerate(speckle):
        cv2.imwrite(str(root / f"speckle_{c}.png"), image.astype(np.uint8))
    config = _config(root, '[compare]\nfile = "true.json"\n[check]\ncam0 = "speckle_0.png"\n'
                           'cam1 = "speckle_1.png"', name="compare.toml")
    out = tmp_path / "out"
    assert cli.main(["-q", "calibrate", str(config), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    rows = {r["name"]: r for r in summary["comparison"]}
    assert abs(rows["cam0.fx"]["sigmas"]) < 3 and abs(rows["baseline_mm"]["sigmas"]) < 3
    check = summary["speckle_check"]
    assert check["matches"] > 200
    assert check["ours"]["median_px"] < 0.05 and check["file"]["median_px"] < 0.05


@pytest.mark.parametrize("extra, names", [
    ('[model]\ndistortion = "rational"', ["[model]", "distortion"]),
    ("[target]\nrows = 1", None),
])
def test_bad_configurations_are_one_error_line_and_nothing_written(tmp_path, capsys, extra, names):
    (tmp_path / "views").mkdir()
    for c in range(2):
        (tmp_path / "views" / f"target_00_cam{c}.png").write_bytes(b"x")
    text = CONFIG.format(extra="")
    if names is None:                          # a duplicated table: invalid TOML, named
        text += extra
        names = ["not valid TOML"]
    else:
        text = text.replace('[model]\ndistortion = "k1k2"', extra)
    (tmp_path / "bad.toml").write_text(text)
    out = tmp_path / "out"
    assert cli.main(["-q", "calibrate", str(tmp_path / "bad.toml"), "--out", str(out)]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert all(n in line for n in names), line
    assert not out.exists()


def test_missing_images_and_uneven_pairs_are_named(tmp_path, capsys):
    (tmp_path / "views").mkdir()
    (tmp_path / "views" / "target_00_cam0.png").write_bytes(b"x")
    (tmp_path / "a.toml").write_text(CONFIG.format(extra=""))
    assert cli.main(["-q", "calibrate", str(tmp_path / "a.toml"), "--out", str(tmp_path / "o")]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert "[images] cam1" in line and "no file matches" in line
    (tmp_path / "views" / "target_00_cam1.png").write_bytes(b"x")
    (tmp_path / "views" / "target_01_cam1.png").write_bytes(b"x")
    assert cli.main(["-q", "calibrate", str(tmp_path / "a.toml"), "--out", str(tmp_path / "o")]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert "[images]" in line and "cam0 has 1 images but cam1 has 2" in line


def test_an_unreadable_image_is_named(tmp_path, capsys):
    (tmp_path / "views").mkdir()
    for c in range(2):
        (tmp_path / "views" / f"target_00_cam{c}.png").write_bytes(b"not an image")
    (tmp_path / "a.toml").write_text(CONFIG.format(extra=""))
    assert cli.main(["-q", "calibrate", str(tmp_path / "a.toml"), "--out", str(tmp_path / "o")]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert "target_00_cam0.png" in line and "not an image" in line
    assert not (tmp_path / "o").exists()
