"""georeg.inputs: Python values to the command line's configuration, through its readers."""
import json
from pathlib import Path

import numpy as np
import pytest

from fesdic_core.cameras.io.formats import write_opencv_stereo
from fesdic_core.cameras.rig import write_cameras_json
from fesdic_core.synthetic.render import demo_cameras
from georeg import api
from georeg.inputs import camera_source, cameras_config, geometry_config, images_config
from georeg_app.config.measure import GeometryConfig, MethodConfig, load_config
from georeg_app.config.toml_schema import ConfigError

LANDMARKS = [{"xyz_mm": [x, y, 0.0], "cam0_px": [100.0 + x, 50.0 + y], "cam1_px": [90.0 + x, 50.0 + y]}
             for x, y in ((-20, -10), (20, -10), (20, 10), (-20, 10))]


@pytest.fixture
def rig():
    return demo_cameras(image_size=(320, 240), field_mm=72.0)


@pytest.mark.parametrize("name, key", [("cams.json", "file"), ("stereo.json", "opencv"),
                                       ("stereo.yml", "opencv"), ("stereo.xml", "opencv")])
def test_camera_files_are_recognised_as_the_config_reader_names_them(tmp_path, rig, name, key):
    path = tmp_path / name
    (write_cameras_json if key == "file" else write_opencv_stereo)(path, rig)
    assert camera_source(path) == key
    config = cameras_config(path, tmp_path, landmarks=None if key == "file" else LANDMARKS)
    assert config.source == key and getattr(config, key) == path


def test_xml_of_dice_and_vic3d_and_csv_by_content_and_suffix(tmp_path):
    (tmp_path / "dice.xml").write_text('<ParameterList name="x"><Parameter name="a"/></ParameterList>')
    (tmp_path / "project.xml").write_text("<calibration><camera id='0'/></calibration>")
    (tmp_path / "calib.csv").write_text("a,b\n")
    assert camera_source(tmp_path / "dice.xml") == "dice"
    assert camera_source(tmp_path / "project.xml") == "vic3d"
    assert camera_source(tmp_path / "calib.csv") == "pyvale_csv"
    assert camera_source(tmp_path / "x.z3d") == "vic3d"
    with pytest.raises(ValueError, match=r"cameras: .*rig\.txt: unknown calibration file"):
        camera_source(tmp_path / "rig.txt")


def test_another_tool_s_calibration_needs_its_landmarks(tmp_path, rig):
    write_opencv_stereo(tmp_path / "stereo.yml", rig)
    with pytest.raises(ConfigError, match=r"cameras: \[cameras\] opencv: needs at least 4 \[\[landmarks\]\]"):
        cameras_config(tmp_path / "stereo.yml", tmp_path)
    config = cameras_config("stereo.yml", tmp_path, source="opencv", landmarks=LANDMARKS)
    np.testing.assert_array_equal(config.landmarks[2].cam1_px, [110.0, 60.0])


def test_camera_objects_go_through_a_json_the_config_owns(rig):
    config = cameras_config(tuple(rig), Path.cwd())
    assert config.source == "file" and config.file.is_file()
    assert json.loads(config.file.read_text())["cameras"][1]["K"] == rig[1].K.tolist()
    with pytest.raises(ValueError, match="cameras: cam1: expected a core Camera"):
        cameras_config((rig[0], "cam1.json"), Path.cwd())


def test_nominal_as_dict_geometry_config_or_file(tmp_path):
    plate = {"kind": "rectangle", "length_mm": 40, "width_mm": np.float64(30.0)}
    g = geometry_config(plate, tmp_path)
    assert (g.kind, g.length_mm, g.width_mm) == ("rectangle", 40.0, 30.0)
    assert geometry_config(g, tmp_path) == g
    with pytest.raises(ConfigError, match=r"nominal: \[geometry\] hole_radius_mm: not used with kind"):
        geometry_config(GeometryConfig("rectangle", 40.0, 30.0, hole_radius_mm=5.0), tmp_path)
    with pytest.raises(ConfigError, match=r"nominal: \[geometry\] file: file not found: .*part\.msh"):
        geometry_config(tmp_path / "part.msh", tmp_path)
    with pytest.raises(ConfigError, match=r"nominal: \[geometry\] file: file not found: .*part\.igs"):
        geometry_config(tmp_path / "part.igs", tmp_path)          # a CAD part by its suffix


def test_array_images_are_loaded_with_the_method_s_image_model(tmp_path):
    method = MethodConfig(prefilter_px=0.7, interpolation_order=5)
    names, loaded = images_config([np.ones((40, 50)), np.zeros((40, 50), np.uint8)], method, tmp_path)
    assert [im.prefilter_px for im in loaded] == [0.7, 0.7] and loaded[1].shape == (40, 50)
    assert [im.order for im in loaded] == [5, 5]
    assert str(names.cam0) == "cam0 (array)"


def test_compare_runs_the_methods_of_georeg_compare(tmp_path, monkeypatch, rig):
    """compare() hands run_methods the command line's default_specs of its options."""
    seen = {}

    def capture(config, specs, **kwargs):
        seen.update(config=config, specs=specs, **kwargs)
        raise RuntimeError("stop")
    monkeypatch.setattr(api, "run_methods", capture)
    images = [np.ones((240, 320)), np.ones((240, 320))]
    with pytest.raises(RuntimeError, match="stop"):
        api.compare(images, rig, {"kind": "rectangle", "length_mm": 40.0, "width_mm": 30.0},
                    levels=2, scales=2, tikhonov_length_mm=[10.0, "auto"], calibrate=False)
    assert [s.label for s in seen["specs"]] == [
        "FE (multiscale)", "Tikhonov 10 mm", "Tikhonov auto", "georeg 2 levels (multiscale)",
        "georeg 2 levels (monoscale)"]
    assert seen["config"].method.calibrate is False and len(seen["images"]) == 2


def test_measure_with_toml_and_out_checks_the_folder_before_computing(tmp_path, monkeypatch):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "old.txt").write_text("x")
    for name in ("a.png", "b.png", "c.json"):
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "run.toml").write_text('[images]\ncam0 = "a.png"\ncam1 = "b.png"\n[cameras]\n'
                                       'file = "c.json"\n[geometry]\nkind = "rectangle"\n'
                                       'length_mm = 40.0\nwidth_mm = 30.0\n')
    monkeypatch.setattr(api, "run_methods", lambda *a, **k: pytest.fail("computing started"))
    assert api.load_config(tmp_path / "run.toml") == load_config(tmp_path / "run.toml")
    with pytest.raises(FileExistsError, match="not empty.*overwrite=True"):
        api.measure(tmp_path / "run.toml", out=tmp_path / "out")


def test_a_geometry_that_places_itself_needs_no_landmarks_with_a_calibration_file(tmp_path):
    """As in a TOML file: kind = "roi", or kind = "cad" with a pose, places the specimen, so
    another tool's calibration is used without [[landmarks]]; any other geometry needs them."""
    path = write_opencv_stereo(tmp_path / "stereo.yml", demo_cameras(image_size=(320, 240)))
    roi = GeometryConfig("roi", polygon_px=((10, 10), (100, 10), (100, 90)))
    assert cameras_config(path, tmp_path, geometry=roi).opencv == path
    cad = GeometryConfig("cad", file=tmp_path / "part.igs", pose="auto")
    assert cameras_config(path, tmp_path, geometry=cad).landmarks == ()
    with pytest.raises(ValueError, match="needs at least 4 \\[\\[landmarks\\]\\]"):
        cameras_config(path, tmp_path, geometry=GeometryConfig("rectangle", length_mm=10.0,
                                                               width_mm=5.0))
