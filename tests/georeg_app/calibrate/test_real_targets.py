"""``georeg calibrate`` on real target images, against other tools' calibrations of the same rig.

The data live in ../shared/data (never committed); without them these tests are skipped.
Figures measured when they were written are in the comments.
"""
import json
from pathlib import Path

import pytest

from georeg_app import cli

ROOT = Path(__file__).resolve().parents[3]
EXAMPLES = ROOT / "examples" / "calibration"
DATA = ROOT.parent / "shared" / "data"


def _run(config: Path, out: Path) -> dict:
    assert cli.main(["-q", "calibrate", str(config), "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "stereo_dic_sample3" / "calibration_target").is_dir(),
                    reason="needs ../shared/data/stereo_dic_sample3")
def test_gt4_dot_target_gives_the_rig_of_vic3d_and_its_epipolar_geometry(tmp_path):
    s = _run(EXAMPLES / "gt4_dots.toml", tmp_path / "gt4")
    assert s["views_used"] == s["views_total"] == 22          # every view, none rejected
    assert s["reprojection_rms_px"] < 0.06                    # 0.038 px, target refined
    rows = {r["name"]: r for r in s["comparison"]}
    assert abs(rows["baseline_mm"]["difference"]) < 0.5       # 123.38 against VIC's 123.21 mm
    assert abs(rows["stereo_angle_deg"]["difference"]) < 0.1  # 18.90 against 18.83 deg
    for c in (0, 1):
        assert abs(rows[f"cam{c}.fx"]["difference"]) < 5.0    # 0.5 and 1.0 px of 6600
    check = s["speckle_check"]
    assert check["matches"] > 2000
    # the speckle's SIFT matches: median symmetric epipolar distance 0.1084 px with ours,
    # 0.1085 px with VIC-3D's calibration
    assert check["ours"]["median_px"] <= check["vic3d"]["median_px"] + 0.002


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "opencv_stereo_checkerboard").is_dir(),
                    reason="needs ../shared/data/opencv_stereo_checkerboard")
def test_opencv_checkerboard_set_calibrates_every_pair(tmp_path):
    s = _run(EXAMPLES / "opencv_checkerboard.toml", tmp_path / "cb")
    assert s["views_used"] == s["views_total"] == 13
    # OpenCV's own sample reports a stereo RMS of about 0.2 px (per coordinate): ours 0.14
    assert s["reprojection_rms_per_coordinate_px"] < 0.2
    assert s["epipolar_px"]["median"] < 0.15                  # 0.094 px
