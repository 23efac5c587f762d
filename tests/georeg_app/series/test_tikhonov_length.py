"""``[displacement] tikhonov_length_mm = "auto"`` (georeg_app.series.tikhonov_length): the
longest length of the ladder 10 mm / sqrt(2)**k at which the last frame measures.

The series: the flat plate of tests/series_data.py, then the same paint on a waviness of
0.6 mm and 10 mm wavelength (rendered with the exact cameras), on a 16 x 10 Q9 mesh (2.75 mm
elements: the ladder is 10, 7.07 mm). Measured: 10 mm leaves a residual 3.1 times the noise
floor (fails); 7.07 mm measures it (2.4 times), with an out-of-plane RMS error at the nodes of
164 um against 208 um at 10 mm (the waviness's RMS: 300 um; a 10 mm wavelength is at the
limit of what a 7 mm smoothness prior holds).
"""
import json

import meshio
import numpy as np
import pytest

from fesdic_core.cameras.rig import write_cameras_json
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.fe.mesh_io import write_mesh
from fesdic_core.synthetic.motion import HeightMotion
from georeg_app import cli
from georeg_app.series.tikhonov_length import LADDER_RATIO, length_ladder
from series_data import write_series

pytestmark = pytest.mark.slow           # two rendered pairs, three Tikhonov measurements

WAVE_MM, WAVELENGTH_MM = 0.6, 10.0


def _wave(x, y):
    return WAVE_MM * np.cos(2 * np.pi * x / WAVELENGTH_MM) * np.cos(2 * np.pi * y / WAVELENGTH_MM)


@pytest.fixture(scope="module")
def wavy_series(tmp_path_factory):
    folder = tmp_path_factory.mktemp("wavy")
    cameras, _ = write_series(folder, [HeightMotion(_wave)], frames="frames")
    write_cameras_json(folder / "cameras.json", cameras)
    mesh = rectangle_mesh(44.0, 30.0, 16, 10, family="Q9")
    write_mesh(folder / "shape_out" / "fe.vtu", mesh)
    return folder, mesh


def _track(folder, out, length):
    config = folder / f"track_{length}.toml"
    config.write_text('[images]\ncam0 = "ref_cam0.png"\ncam1 = "ref_cam1.png"\n'
                      '[series]\ncam0 = "frames/f*_cam0.png"\ncam1 = "frames/f*_cam1.png"\n'
                      f'[displacement]\nmethod = "tikhonov"\ntikhonov_length_mm = {length}\n'
                      '[reference]\ndir = "shape_out"\n')
    code = cli.main(["-q", "track", str(config), "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    vtu = meshio.read(next(out.glob("frame_*.vtu")))
    error = vtu.point_data["displacement_mm"][:, 2] - _wave(vtu.points[:, 0], vtu.points[:, 1])
    return code, summary, float(np.sqrt(np.mean(error ** 2)))


def test_the_ladder_runs_from_10_mm_down_to_two_element_sizes(wavy_series):
    _, mesh = wavy_series
    lengths = length_ladder(mesh)
    assert lengths[0] == 10.0 and np.allclose(np.diff(np.log(lengths)), -np.log(LADDER_RATIO))
    assert lengths[-1] >= 2 * 2.75 > lengths[-1] / LADDER_RATIO            # 2.75 mm elements
    assert length_ladder(rectangle_mesh(44.0, 30.0, 4, 3, family="Q4")) == [10.0]   # 11 mm


def test_auto_steps_down_from_a_length_the_frame_refutes(wavy_series, tmp_path):
    folder, _ = wavy_series
    code_10, fixed, error_10 = _track(folder, tmp_path / "fixed", 10.0)
    assert code_10 == 1 and fixed["frames"][0]["status"] == "failed"    # the case: 10 mm fails
    code, auto, error = _track(folder, tmp_path / "auto", '"auto"')
    assert code == 0 and auto["frames"][0]["status"] == "ok"
    chosen = auto["displacement"]["tikhonov_length_chosen"]
    assert chosen["measured"] and np.allclose(chosen["tried_mm"], [10.0, 10.0 / LADDER_RATIO])
    assert auto["displacement"]["tikhonov_length_mm"] == pytest.approx(10.0 / LADDER_RATIO)
    assert chosen["residual_percent"][0] == pytest.approx(fixed["frames"][0]["residual_percent"])
    assert error < 0.9 * error_10, (error, error_10)        # nearer the true waviness (mm)
