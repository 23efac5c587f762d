"""`georeg measure` end to end with the real pipeline: files in, files out, and bad inputs.

A small rendered stereo pair (640 x 480 px, the session's twisted plate) is written to disk
as a user would have it: two PNG images, a JSON camera file and a TOML configuration.
"""
import dataclasses
import json

import cv2
import meshio
import numpy as np
import pytest

from fesdic_core.synthetic.accuracy import shape_error_to_surface
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.fe.mesh_io import write_mesh
from georeg_app import cli
from user_data import write_user_data
from cli_checks import fails_naming

CONFIG = """
[images]
cam0 = "{cam0}"
cam1 = "{cam1}"
[cameras]
file = "{cameras}"
[geometry]
{geometry}
[method]
name = "georeg"
levels = 2
scales = 2
calibrate = false
"""
RECTANGLE = 'kind = "rectangle"\nlength_mm = 60.0\nwidth_mm = 40.0\nelements = 24'


@pytest.fixture(scope="module")
def case(twisted_scene, tmp_path_factory):
    specimen, cameras, images = twisted_scene
    folder = write_user_data(tmp_path_factory.mktemp("user_data"),
                             [im.values for im in images], cameras)
    return folder, specimen, cameras, images


def _config(folder, name="config.toml", cam0="cam0.png", cam1="cam1.png", cameras="cameras.json",
            geometry=RECTANGLE):
    path = folder / name
    path.write_text(CONFIG.format(cam0=cam0, cam1=cam1, cameras=cameras, geometry=geometry))
    return path


@pytest.mark.slow
def test_measure_writes_a_shape_that_matches_the_truth(case, tmp_path, capsys):
    folder, specimen, _, _ = case
    out = tmp_path / "out"
    assert cli.main(["-q", "measure", str(_config(folder)), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["truth_available"] is False
    (method,) = summary["methods"]
    assert method["name"] == "georeg" and method["shape_rms_error_mm"] is None
    assert method["iterations"] > 0 and 0 < method["residual_percent"] < 5
    vtu = meshio.read(out / method["mesh_file"])
    assert {"shape_correction_mm", "distance_to_bfp_mm"} <= set(vtu.point_data)
    error = shape_error_to_surface(vtu.points, specimen)          # modulo a rigid motion
    assert np.sqrt(np.mean(error ** 2)) < 0.02 * 0.5, np.sqrt(np.mean(error ** 2))
    # the correction itself: the twist z = k x y (0.5 mm at the corners) along +z
    x, y = vtu.points[:, 0], vtu.points[:, 1]
    twist = 0.5 * x * y / (30.0 * 20.0)
    q = vtu.point_data["shape_correction_mm"]
    assert np.sqrt(np.mean((q - q.mean() - (twist - twist.mean())) ** 2)) < 0.02
    assert {p.name for p in out.iterdir()} >= {"summary.json", "report.html", "convergence.csv",
                                               method["mesh_file"]}


def test_missing_image_is_named(case, tmp_path, capsys):
    folder = case[0]
    fails_naming(capsys, _config(folder, "c1.toml", cam1="nowhere.png"), tmp_path / "out",
                  "nowhere.png")


def test_images_of_different_sizes_are_named(case, tmp_path, capsys):
    folder, _, _, images = case
    cv2.imwrite(str(tmp_path / "small.png"), images[1].values[:400, :600].astype(np.uint8))
    fails_naming(capsys, _config(folder, "c2.toml", cam1=str(tmp_path / "small.png")),
                  tmp_path / "out", "small.png", "different sizes")


def test_nan_in_an_image_is_named(case, tmp_path, capsys):
    folder, _, _, images = case
    values = images[1].values.astype(np.float32)
    values[100, 200] = np.nan
    cv2.imwrite(str(tmp_path / "nan.tiff"), values)
    fails_naming(capsys, _config(folder, "c3.toml", cam1=str(tmp_path / "nan.tiff")),
                  tmp_path / "out", "nan.tiff", "non-finite")


def test_calibration_missing_a_field_is_named(case, tmp_path, capsys):
    folder = case[0]
    data = json.loads((folder / "cameras.json").read_text())
    del data["cameras"][1]["tvec_mm"]
    (tmp_path / "cams.json").write_text(json.dumps(data))
    fails_naming(capsys, _config(folder, "c4.toml", cameras=str(tmp_path / "cams.json")),
                  tmp_path / "out", "cams.json", "tvec_mm")


def test_degenerate_element_is_named(case, tmp_path, capsys):
    folder = case[0]
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, "Q4")
    nodes = mesh.nodes.copy()
    conn = mesh.blocks[0].connectivity
    nodes[conn[7, 2]] = nodes[conn[7, 0]]                         # element 7 folds onto a line
    write_mesh(tmp_path / "bad.vtu", dataclasses.replace(mesh, nodes=nodes))
    line = fails_naming(capsys, _config(folder, "c5.toml", geometry=f'kind = "mesh"\nfile = '
                                         f'"{tmp_path / "bad.vtu"}"'), tmp_path / "out", "bad.vtu", "elements 7,")
    assert "degenerate" in line or "inverted" in line


def test_mesh_outside_the_images_is_named(case, tmp_path, capsys):
    folder = case[0]
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, "Q4", center=(500.0, 0.0))
    write_mesh(tmp_path / "far.vtu", mesh)
    fails_naming(capsys, _config(folder, "c6.toml", geometry=f'kind = "mesh"\nfile = '
                                  f'"{tmp_path / "far.vtu"}"'), tmp_path / "out",
                  "outside", "cam0")


@pytest.mark.slow
def test_swapped_images_fail_the_measurement_and_write_nothing(case, tmp_path, capsys):
    """cam0 <-> cam1 swapped: the run ends, but its residual is many times what the images'
    noise explains; `measure` exits 1 with one line saying so and publishes nothing."""
    folder = case[0]
    line = fails_naming(capsys, _config(folder, "c7.toml", cam0="cam1.png", cam1="cam0.png"),
                         tmp_path / "out", "failed", "times the", "image noise explains")
    ratio = float(line.split(" is ")[1].split(" times")[0])
    assert ratio > 3.0, line


def test_pure_noise_images_are_refused(case, tmp_path, capsys):
    folder = case[0]
    rng = np.random.default_rng(3)
    for k in range(2):
        cv2.imwrite(str(tmp_path / f"noise{k}.png"), rng.integers(0, 256, (480, 640)).astype(np.uint8))
    fails_naming(capsys, _config(folder, "c8.toml", cam0=str(tmp_path / "noise0.png"),
                                  cam1=str(tmp_path / "noise1.png")), tmp_path / "out",
                  "noise0.png", "no texture")


@pytest.mark.slow
def test_a_non_empty_output_folder_is_refused_before_computing(case, tmp_path, capsys):
    folder = case[0]
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("a previous run")
    assert cli.main(["-q", "measure", str(_config(folder)), "--out", str(out)]) == 1
    assert "not empty" in capsys.readouterr().err and (out / "old.txt").exists()
    assert cli.main(["-q", "measure", str(_config(folder)), "--out", str(out), "--overwrite"]) == 0
    assert not (out / "old.txt").exists() and (out / "summary.json").is_file()


@pytest.mark.parametrize("method,message", [("levels = 9", "fewer levels"),
                                            ("scales = 9", "coarsest image would be")])
def test_sizes_beyond_the_images_are_refused_before_computing(case, tmp_path, capsys, method, message):
    folder = case[0]
    config = _config(folder, "c9.toml")
    config.write_text(config.read_text().replace("levels = 2", method) if "levels" in method
                      else config.read_text().replace("scales = 2", method))
    fails_naming(capsys, config, tmp_path / "out", message)


@pytest.mark.slow
def test_georeg_on_an_l_shaped_mesh_file_reports_the_dofs_each_level_dropped(case, tmp_path, capsys):
    """Issue 22: an L-shaped legacy mesh (a 24 x 16 Q4 mesh of the 60 x 40 mm plate without
    its quadrant x > 0, y > 0); its spline is the bounding rectangle's, whose 3 levels have
    dofs outside the L (4 of 36 at level 0, 1 of 16 at level 1). Before: a singular level,
    exit 1. Now: exit 0, the summary says what each level dropped, the shape is right."""
    from fesdic_core.fe.mesh import CellBlock, SurfaceMesh
    folder, specimen, _, _ = case
    full = rectangle_mesh(60.0, 40.0, 24, 16, "Q4")
    block = full.blocks[0]
    centres = full.nodes[block.connectivity].mean(axis=1)
    connectivity = block.connectivity[~((centres[:, 0] > 0.0) & (centres[:, 1] > 0.0))]
    used, inverse = np.unique(connectivity, return_inverse=True)
    mesh = SurfaceMesh(nodes=full.nodes[used], name="L", blocks=(CellBlock(
        family=block.family, connectivity=inverse.reshape(connectivity.shape)),))
    write_mesh(tmp_path / "l.vtu", mesh)
    config = _config(folder, "l.toml", geometry=f'kind = "mesh"\nfile = "{tmp_path / "l.vtu"}"')
    config.write_text(config.read_text().replace("levels = 2", "levels = 3"))
    out = tmp_path / "out"
    assert cli.main(["-q", "measure", str(config), "--out", str(out)]) == 0
    (method,) = json.loads((out / "summary.json").read_text())["methods"]
    dropped = {level: v["dropped"] for level, v in method["dropped_dofs"].items()}
    assert dropped == {"0": 4, "1": 1}, method["dropped_dofs"]
    assert method["dropped_dofs"]["0"]["n_dofs"] == 36
    assert method["levels_chosen"] == {"fixed_levels": 3, "chosen_level": 0}
    vtu = meshio.read(out / method["mesh_file"])
    error = shape_error_to_surface(vtu.points, specimen)
    assert np.sqrt(np.mean(error ** 2)) < 0.01, np.sqrt(np.mean(error ** 2))


def test_levels_beyond_a_legacy_mesh_are_refused(case, tmp_path, capsys):
    """A 6 x 4 Q4 mesh file (35 nodes) cannot carry 4 spline levels (100 dofs at the finest)."""
    folder = case[0]
    write_mesh(tmp_path / "coarse.vtu", rectangle_mesh(60.0, 40.0, 6, 4, "Q4"))
    config = _config(folder, "c10.toml", geometry=f'kind = "mesh"\nfile = "{tmp_path / "coarse.vtu"}"')
    config.write_text(config.read_text().replace("levels = 2", "levels = 4"))
    fails_naming(capsys, config, tmp_path / "out", "levels = 4", "100 dofs", "35 nodes", "coarse.vtu")


@pytest.mark.slow
def test_compare_delivers_the_others_when_one_method_fails(case, tmp_path, capsys, monkeypatch):
    """One method breaks inside (its step solver raises a singular system): `georeg compare`
    marks it failed in summary.json and the report, writes the others, and exits 0."""
    from fesdic_core.solve.solvers import SingularSystemError
    from georeg_app.shape import pipeline

    class Broken:
        def solve(self, H, b, q, scale):
            raise SingularSystemError("H_FE is numerically singular (test)")

    real_solver = pipeline._solver
    monkeypatch.setattr(pipeline, "_solver", lambda spec, model: Broken()
                        if spec.name == "tikhonov" and spec.param == 10.0
                        else real_solver(spec, model))
    folder = case[0]
    out = tmp_path / "out"
    assert cli.main(["-q", "compare", str(_config(folder)), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    status = {m["label"]: (m["status"], m["failure"]) for m in summary["methods"]}
    assert status["Tikhonov 10 mm"] == ("failed", "H_FE is numerically singular (test)")
    assert "Tikhonov 10 mm" in summary["failed_methods"]
    ok = [m for m in summary["methods"] if m["status"] == "ok"]
    assert {m["name"] for m in ok} == {"fe", "tikhonov", "georeg"}
    assert len(ok) == len(summary["methods"]) - 1                       # only the broken one
    assert all((out / m["mesh_file"]).is_file() for m in ok)
    assert "Tikhonov 10 mm" in capsys.readouterr().err                  # warned
    assert "failed" in (out / "report.html").read_text()
