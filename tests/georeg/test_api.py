"""georeg.measure / compare / track on Python values: the command line's objects, its files,
and errors that name the value at fault before any computing."""
import json
import math

import meshio
import numpy as np
import pytest

import georeg
from fesdic_core.cameras.rig import read_cameras_json
from georeg import api
from georeg_app import cli
from user_data import PLATE_WITH_HOLE, perturbed_pose, user_config, write_user_data

CONFIG = user_config(PLATE_WITH_HOLE + "\nelements = 128", 'name = "georeg"\nlevels = 2\nscales = 2')
NOMINAL = {"kind": "plate_with_hole", "length_mm": 100.0, "width_mm": 50.0,
           "hole_radius_mm": 14.0, "elements": 128}
#: summary.json entries that differ between two runs of the same data (wall times)
TIMINGS = {"time_s"}


@pytest.fixture(scope="module")
def user_folder(small_demo_scene, tmp_path_factory):
    folder = write_user_data(tmp_path_factory.mktemp("api"), small_demo_scene.arrays,
                             perturbed_pose(small_demo_scene.cameras))
    (folder / "config.toml").write_text(CONFIG)
    return folder


@pytest.fixture(scope="module")
def cli_out(user_folder):
    out = user_folder / "cli_out"
    assert cli.main(["-q", "measure", str(user_folder / "config.toml"), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def api_run(user_folder):
    """The same measurement from Python values: the images as arrays, the cameras as objects."""
    import cv2
    arrays = [cv2.imread(str(user_folder / f"cam{k}.png"), cv2.IMREAD_UNCHANGED) for k in (0, 1)]
    cameras = read_cameras_json(user_folder / "cameras.json")
    return georeg.measure(arrays, cameras, NOMINAL, method="georeg", levels=2, scales=2)


def _without_timings(value):
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if k not in TIMINGS}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def _assert_same(a, b, where="summary"):
    if isinstance(a, dict):
        assert set(a) == set(b), where
        for k in a:
            _assert_same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{where}[{k}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12), (where, a, b)
    else:
        assert a == b, (where, a, b)


@pytest.mark.slow
def test_save_writes_the_files_of_georeg_measure(api_run, cli_out, tmp_path):
    assert api_run.ok and api_run.failure is None
    out = tmp_path / "api_out"
    written = api_run.save(out)
    assert sorted(p.name for p in written) == sorted(p.name for p in cli_out.iterdir())
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in cli_out.iterdir())
    saved = json.loads((out / "summary.json").read_text())
    _assert_same(_without_timings(saved), _without_timings(json.loads((cli_out / "summary.json").read_text())))
    _assert_same(_without_timings(saved), _without_timings(json.loads(json.dumps(api_run.summary))))


@pytest.mark.slow
def test_save_refuses_a_non_empty_folder_unless_overwrite(api_run, tmp_path):
    (tmp_path / "old.txt").write_text("x")
    with pytest.raises(FileExistsError, match="not empty.*overwrite=True"):
        api_run.save(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.txt"]
    api_run.save(tmp_path, overwrite=True)
    assert not (tmp_path / "old.txt").exists() and (tmp_path / "summary.json").is_file()


@pytest.mark.slow
def test_toml_file_gives_the_same_measurement(user_folder, api_run):
    run = georeg.measure(user_folder / "config.toml")
    np.testing.assert_allclose(run.nodes, api_run.nodes, rtol=0, atol=1e-9)
    assert run.residual_percent == pytest.approx(api_run.residual_percent, rel=1e-9)


def test_to_meshio_round_trips_the_command_line_vtu(api_run, cli_out, tmp_path):
    mesh = api_run.to_meshio()
    written = meshio.read(cli_out / api_run.mesh_file())
    np.testing.assert_allclose(mesh.points, api_run.nodes)
    np.testing.assert_allclose(mesh.points, written.points, atol=1e-9)
    assert set(mesh.point_data) == set(written.point_data)
    assert {"shape_correction_mm", "distance_to_bfp_mm", "shape_std_mm"} <= set(mesh.point_data)
    np.testing.assert_allclose(mesh.point_data["shape_std_mm"], api_run.shape_std_mm)
    for name, values in written.point_data.items():
        np.testing.assert_allclose(mesh.point_data[name], values, atol=1e-9, err_msg=name)
    again = tmp_path / "again.vtu"
    meshio.write(again, mesh)
    back = meshio.read(again)
    np.testing.assert_array_equal(back.points, mesh.points)
    assert [c.type for c in back.cells] == [c.type for c in mesh.cells] == ["quad9"]
    np.testing.assert_array_equal(back.cells[0].data, mesh.cells[0].data)


@pytest.mark.slow
def test_progress_callback_hears_every_scale(user_folder):
    calls = []
    run = georeg.measure(user_folder / "config.toml", progress=lambda *a: calls.append(a))
    assert calls == [("georeg 2 levels (multiscale)", 1, 2), ("georeg 2 levels (multiscale)", 2, 2)]
    assert run.chosen == "georeg 2 levels (multiscale)"


# ----------------------------------------------------------------------------- bad values
@pytest.fixture
def no_computing(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("computing started before the inputs were checked")
    monkeypatch.setattr(api, "run_methods", refuse)
    monkeypatch.setattr("georeg_app.series.track.run_track", refuse)


def test_missing_image_path_is_named_before_computing(user_folder, no_computing, tmp_path):
    missing = tmp_path / "nowhere" / "left.png"
    with pytest.raises(georeg.ConfigFileNotFoundError, match=r"images: \[images\] cam0: file not found: .*left\.png"):
        georeg.measure([missing, user_folder / "cam1.png"], user_folder / "cameras.json", NOMINAL)


def test_unknown_kind_is_named_before_computing(user_folder, no_computing):
    with pytest.raises(georeg.ConfigError, match=r'nominal: \[geometry\] kind: expected one of .*got "disc"'):
        georeg.measure([user_folder / "cam0.png", user_folder / "cam1.png"],
                       user_folder / "cameras.json", dict(NOMINAL, kind="disc"))


def test_one_camera_is_refused_before_computing(user_folder, no_computing):
    images = [user_folder / "cam0.png", user_folder / "cam1.png"]
    cameras = read_cameras_json(user_folder / "cameras.json")
    with pytest.raises(ValueError, match="cameras: a stereo pair needs 2 cameras, got 1"):
        georeg.measure(images, cameras[:1], NOMINAL)
    with pytest.raises(ValueError, match="cameras: a stereo pair needs 2 cameras, got 1"):
        georeg.measure(images, cameras[0], NOMINAL)


@pytest.mark.parametrize("kwargs, message", [
    (dict(levels="three"), r'method options: \[method\] levels: expected an integer or "auto", got "three"'),
    (dict(method="spline"), r'method options: \[method\] name: must be one of .*got "spline"'),
    (dict(calibrat=False), r"method options: \[method\] calibrat: unknown key \(did you mean calibrate\?\)"),
])
def test_bad_method_options_are_named(user_folder, no_computing, kwargs, message):
    with pytest.raises(georeg.ConfigError, match=message):
        georeg.measure([user_folder / "cam0.png", user_folder / "cam1.png"],
                       user_folder / "cameras.json", NOMINAL, **kwargs)


def test_bad_image_values_are_named(user_folder, no_computing):
    cams = user_folder / "cameras.json"
    with pytest.raises(ValueError, match="images: a stereo pair needs 2 images"):
        georeg.measure([user_folder / "cam0.png"], cams, NOMINAL)
    with pytest.raises(ValueError, match=r"images: cam1: expected a 2-D array .*shape \(4, 4, 3\)"):
        georeg.measure([np.zeros((4, 4)), np.zeros((4, 4, 3))], cams, NOMINAL)


def test_a_configuration_takes_no_second_set_of_inputs(user_folder, no_computing):
    with pytest.raises(TypeError, match="nominal: not used with a configuration"):
        georeg.measure(user_folder / "config.toml", nominal=NOMINAL)


def test_track_bad_values_are_named_before_computing(user_folder, no_computing):
    images = [user_folder / "cam0.png", user_folder / "cam1.png"]
    with pytest.raises(TypeError, match="missing series"):
        georeg.track(images, user_folder / "cameras.json", NOMINAL)
    with pytest.raises(georeg.ConfigFileNotFoundError, match=r"series: \[series\] cam0: no file matches"):
        georeg.track(images, user_folder / "cameras.json", NOMINAL,
                     series=(str(user_folder / "frames" / "*.png"), [str(images[1])]))
    with pytest.raises(georeg.ConfigError, match=r'displacement: \[displacement\] method: must be one of'):
        georeg.track(images, user_folder / "cameras.json", NOMINAL, series=(images[:1], images[1:]),
                     displacement="splines")
    with pytest.raises(ValueError, match="--scheduler"):
        georeg.track(images, user_folder / "cameras.json", NOMINAL, series=(images[:1], images[1:]),
                     scheduler="cluster")
