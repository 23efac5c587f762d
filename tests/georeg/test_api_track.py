"""georeg.track on Python values: the files of `georeg track`, each frame as meshio, the
progress callback. A small rendered series (the plate of tests/georeg_app/test_track.py,
320 x 240 px, two translations, 2 x 2 rays a pixel) and a reference folder made from the
exact cameras."""
import json

import meshio
import numpy as np
import pytest

import georeg
from fesdic_core.synthetic.motion import RigidMotion
from georeg_app import cli
from series_data import write_series

pytestmark = pytest.mark.slow         # a series measured end to end

MOTIONS = (RigidMotion((0.1, -0.05, 0.05)), RigidMotion((0.2, -0.1, 0.1)))


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    folder = tmp_path_factory.mktemp("api_series")
    write_series(folder, MOTIONS, supersample=2)
    (folder / "track.toml").write_text(
        '[images]\ncam0 = "ref_cam0.png"\ncam1 = "ref_cam1.png"\n'
        '[series]\ncam0 = "f*_cam0.png"\ncam1 = "f*_cam1.png"\n'
        '[displacement]\nmethod = "fe"\nscales = 2\n[reference]\ndir = "shape_out"\n')
    return folder


def _without_timings(value):
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if k != "time_s"}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def test_track_saves_the_files_of_georeg_track_and_each_frame_as_meshio(series, tmp_path):
    cli_out = tmp_path / "cli"
    assert cli.main(["-q", "track", str(series / "track.toml"), "--out", str(cli_out)]) == 0
    calls = []
    run = georeg.track([series / "ref_cam0.png", series / "ref_cam1.png"],
                       reference=series / "shape_out",
                       series=(str(series / "f*_cam0.png"), str(series / "f*_cam1.png")),
                       displacement={"method": "fe", "scales": 2},
                       progress=lambda *a: calls.append(a))
    assert run.ok and run.failure is None and len(run.frames) == 2
    assert calls == [("frames", 1, 2), ("frames", 2, 2)]
    out = tmp_path / "api"
    run.save(out)
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in cli_out.iterdir())
    ours = json.loads((out / "summary.json").read_text())
    theirs = json.loads((cli_out / "summary.json").read_text())
    assert _without_timings(ours) == _without_timings(theirs)
    for frame, motion in zip(ours["frames"], MOTIONS):
        mesh = run.to_meshio(frame["index"])
        written = meshio.read(cli_out / frame["mesh_file"])
        np.testing.assert_allclose(mesh.points, written.points)
        np.testing.assert_allclose(mesh.point_data["displacement_mm"],
                                   written.point_data["displacement_mm"], atol=1e-12)
        rms = np.sqrt(np.mean((mesh.point_data["displacement_mm"] - motion(mesh.points)) ** 2))
        assert rms < 0.01, rms                       # the frame's motion, within 10 um
    with pytest.raises(ValueError, match="frame 3: not in this series"):
        run.to_meshio(3)


def test_track_toml_file(series, tmp_path):
    run = georeg.track(series / "track.toml", out=tmp_path / "out")
    assert run.ok and (tmp_path / "out" / "displacement.pvd").is_file()
    assert run.summary["frames"][1]["mesh_file"] == "frame_0002_f2_cam0.vtu"
