"""``kind = "roi"`` on a real specimen: the GT4 D-specimen (Stereo-DIC Challenge sample 3), its
whole outline with the cut-out excluded, no landmarks, with its VIC-3D and its DICe calibration.

The data are not committed: they are read from ``../shared/data/stereo_dic_sample3`` beside the
project (see examples/gt4_roi/specimen.toml); the test skips without them.
"""
import json
from pathlib import Path

import numpy as np
import pytest

from fesdic_core.cameras.rig import read_cameras_json
from georeg_app import cli

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = ROOT / "examples" / "gt4_roi" / "specimen.toml"
DATA = ROOT.parent / "shared" / "data" / "stereo_dic_sample3"

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not (DATA / "images" / "GT4-0000_0.png").is_file(),
                                 reason=f"the GT4 data are not at {DATA}")]


def _run(tmp_path, calibration, example=EXAMPLE):
    text = example.read_text().replace('"../../../shared/data/', f'"{DATA.parent}/')
    if calibration == "dice":
        text = text.replace("\nvic3d = ", "\n# vic3d = ").replace("\n# dice = ", "\ndice = ")
    text = text.replace("elements = 800", "elements = 300")
    config = tmp_path / f"{calibration}_{example.stem}.toml"
    config.write_text(text)
    out = tmp_path / f"{calibration}_{example.stem}"
    assert cli.main(["-q", "measure", str(config), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    (method,) = summary["methods"]
    cam0 = read_cameras_json(out / method["mesh_file"].replace(".vtu", "_cameras.json"))[0]
    return summary["specimen"], method, cam0


def test_the_gt4_specimen_from_its_roi_with_two_calibrations(tmp_path):
    """The whole D, cut-out excluded, georeg levels "auto" (the example as it is)."""
    normals = []
    for calibration in ("vic3d", "dice"):
        specimen, method, cam0 = _run(tmp_path, calibration)
        # a flat plate: the plane fits the triangulated matches to about 10 um (the
        # calibrations' epipolar error is 0.1 px), and the matches in camera 1 within
        # 1.5 times their epipolar distance
        assert specimen["surface_rms_mm"] < 0.02, specimen
        assert specimen["misfit_px"] < 1.5 * specimen["epipolar_px"], specimen
        assert specimen["unseen_share"] < 0.05 and specimen["matches"] > 1000
        assert method["name"] == "georeg" and method["status"] == "ok", method
        assert method["residual_to_noise"] < 1.0, method
        assert method["distance_to_bfp_rms_mm"] < 0.03, method
        normals.append(cam0.R[:, 2])            # the specimen's normal in camera 0's frame
    # the two calibrations of the rig put the specimen's plane at the same angle to camera 0
    angle = np.degrees(np.arccos(np.clip(normals[0] @ normals[1], -1, 1)))
    assert angle < 1.0, angle


def test_georeg_auto_on_a_rectangle_of_the_gt4_specimen(tmp_path):
    for calibration in ("vic3d", "dice"):
        specimen, method, _ = _run(tmp_path, calibration, EXAMPLE.with_name("rectangle.toml"))
        assert method["name"] == "georeg" and method["status"] == "ok", method
        assert method["residual_to_noise"] < 1.0 and method["levels_chosen"]["chosen_level"] >= 1
        assert specimen["misfit_px"] < 1.5 * specimen["epipolar_px"], specimen
