"""``georeg track`` on a rendered series with known motion (the core's renderer).

The plate, rig and noise of tests/fesdic_core/test_displacement.py (0.225 mm/px, 4 px
speckle, 2 gray levels), images written as 8-bit PNG. The reference folder is what
``georeg measure`` writes (summary.json, <method>.vtu, <method>_cameras.json), made here
from the true surface and the exact cameras so that the series alone is under test; one
test measures the reference shape in the run instead.
"""
import json
import shutil
import sys
import xml.etree.ElementTree as ET

import cv2
import meshio
import numpy as np
import pytest

from fesdic_core.synthetic.motion import RigidMotion, StretchMotion
from fesdic_core.synthetic.render import demo_cameras
from fesdic_core.cameras.rig import write_cameras_json
from georeg_app import cli
from series_data import write_series

pytestmark = pytest.mark.slow         # series measured end to end, Dask clusters

#: the series: two translations (the second with a rotation), pure noise, a stretch
MOTIONS = (RigidMotion((0.1, -0.05, 0.05)), RigidMotion((0.2, -0.1, 0.1), rvec=(0.0, 0.002, 0.0)),
           None, StretchMotion(0.005))


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    folder = tmp_path_factory.mktemp("series")
    cameras, mesh = write_series(folder, MOTIONS, frames="frames")
    write_cameras_json(folder / "cameras.json", cameras)
    return folder, mesh


def _config(folder, series_keys='cam0 = "frames/f*_cam0.png"\ncam1 = "frames/f*_cam1.png"',
            extra='[reference]\ndir = "shape_out"', displacement='method = "fe"\nscales = 3'):
    path = folder / "track.toml"
    path.write_text(f'[images]\ncam0 = "ref_cam0.png"\ncam1 = "ref_cam1.png"\n'
                    f"[series]\n{series_keys}\n[displacement]\n{displacement}\n{extra}\n")
    return path


def _point_data(path):
    return meshio.read(path).point_data


def test_track_measures_the_series_and_marks_the_failed_frame(series, tmp_path, capsys):
    folder, mesh = series
    out = tmp_path / "out"
    assert cli.main(["-q", "track", str(_config(folder)), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    frames = summary["frames"]
    assert [f["index"] for f in frames] == [1, 2, 3, 4]
    assert [f["status"] for f in frames] == ["ok", "ok", "failed", "ok"]
    assert summary["failed_frames"] == [3] and "texture" in frames[2]["failure"]
    assert summary["displacement"]["jacobian"] == "reference"          # the default
    assert not frames[2]["converged"] and all(frames[k]["converged"] for k in (0, 1, 3))
    assert [f["start_frame"] for f in frames] == [0, 1, 2, 2]       # on from the last good one
    assert all(f["start"] for f in frames if f["status"] == "ok")     # where each start came from
    for key in ("index", "cam0", "cam1", "residual_percent", "iterations", "converged", "time_s",
                "mesh_file"):
        assert all(key in f for f in frames)
    for frame, motion in zip(frames, MOTIONS):
        if motion is None:
            assert frame["mesh_file"] == "frame_0003_f3_cam0_failed.vtu"  # named after its image
            continue
        data = _point_data(out / frame["mesh_file"])
        rms = np.sqrt(np.mean((data["displacement_mm"] - motion(mesh.nodes)) ** 2, axis=0))
        assert np.all(rms[:2] < 1.5e-3) and rms[2] < 6e-3, f"{frame['mesh_file']}: {1e3 * rms} um"
        assert {"residual", "strain_xx", "strain_yy", "strain_xy"} <= set(data)
        # plain FE: the uncertainty is the noise's std (its bias part only the last step's
        # remainder); summary.json gives its median and largest value over the valid nodes,
        # and two of them cover the error
        u = data["displacement_uncertainty_mm"]
        assert np.all(u >= data["displacement_std_mm"])
        np.testing.assert_allclose(u, data["displacement_std_mm"], rtol=0.05)
        valid = data["valid"].astype(bool)
        spread = frame["displacement_uncertainty_mm"]
        np.testing.assert_allclose(spread["median"], np.median(u[valid], axis=0), rtol=1e-12)
        np.testing.assert_allclose(spread["max"], np.max(u[valid], axis=0), rtol=1e-12)
        covered = np.mean(np.abs(data["displacement_mm"] - motion(mesh.nodes)) <= 2 * u)
        assert covered >= 0.85, f"{frame['mesh_file']}: {covered:.3f} within 2 uncertainties"
    stretch = _point_data(out / "frame_0004_f4_cam0.vtu")
    assert abs(np.mean(stretch["strain_xx"]) - (0.005 + 0.5 * 0.005 ** 2)) < 1e-4
    report = (out / "report.html").read_text()
    assert "FAILED: " in report and "1 frame(s) FAILED (3 (f3_cam0.png))" in report and "data:image/png" in report
    pvd = ET.parse(out / "displacement.pvd").getroot()
    assert [d.get("file") for d in pvd.iter("DataSet")] == ["frame_0001_f1_cam0.vtu",
                                                           "frame_0002_f2_cam0.vtu",
                                                           "frame_0004_f4_cam0.vtu"]


def test_each_frame_from_rest_and_tikhonov_on_each_component(series, tmp_path):
    folder, mesh = series
    out = tmp_path / "out"
    config = _config(folder, series_keys='cam0 = ["frames/f2_cam0.png"]\ncam1 = ["frames/f2_cam1.png"]',
                     displacement='method = "tikhonov"\ntikhonov_length_mm = 20.0\nincremental = false')
    assert cli.main(["-q", "track", str(config), "--out", str(out)]) == 0
    frame = json.loads((out / "summary.json").read_text())["frames"][0]
    assert frame["status"] == "ok" and frame["start_frame"] == 0
    U = _point_data(out / frame["mesh_file"])["displacement_mm"]
    rms = np.sqrt(np.mean((U - MOTIONS[1](mesh.nodes)) ** 2, axis=0))
    assert np.all(rms[:2] < 1.5e-3) and rms[2] < 6e-3, f"{1e3 * rms} um"


def test_track_measures_the_reference_shape_first(series, tmp_path):
    """Without [reference]: the shape of the reference pair (FE, exact cameras, no
    calibration) then the series, with the georeg displacement (the nominal spline)."""
    folder, mesh = series
    out = tmp_path / "out"
    extra = ('[cameras]\nfile = "cameras.json"\n[geometry]\nkind = "rectangle"\nlength_mm = 44.0\n'
             'width_mm = 30.0\nelements = 16\n[method]\nname = "fe"\ncalibrate = false\nscales = 2')
    summary, vtu = _track_first_frame(folder, extra, out)
    assert summary["reference"].startswith("measured here")


def test_track_with_a_region_of_interest_as_the_reference_geometry(series, tmp_path):
    """``[geometry] kind = "roi"`` without [reference]: the specimen placed by the rig from a
    polygon of camera 0's image, its shape measured (FE), then the first frame (FE)."""
    folder, _ = series
    cam0 = demo_cameras(image_size=(320, 240), field_mm=72.0)[0]
    corners = cam0.project(np.array([[-25, -17, 0], [25, -17, 0], [25, 17, 0], [-25, 17, 0.0]]))
    extra = ('[cameras]\nfile = "cameras.json"\n[geometry]\nkind = "roi"\n'
             f"polygon_px = {np.round(corners, 2).tolist()}\nelements = 30\n"
             '[method]\nname = "fe"\ncalibrate = false\nscales = 2')
    config = _config(folder, series_keys='cam0 = ["frames/f1_cam0.png"]\ncam1 = ["frames/f1_cam1.png"]',
                     extra=extra, displacement='method = "fe"\nscales = 3')
    out = tmp_path / "out"
    assert cli.main(["-q", "track", str(config), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    frame = summary["frames"][0]
    assert summary["reference"].startswith("measured here") and frame["status"] == "ok"
    U = _point_data(out / frame["mesh_file"])["displacement_mm"]
    # the specimen frame is the plate's to 1e-3 rad: a translation is the same in both;
    # measured 2.6, 2.2 and 9.6 um (FE displacement on the ROI's 30 elements, 320 x 240 px)
    rms = np.sqrt(np.mean((U - MOTIONS[0](np.zeros((len(U), 3)))) ** 2, axis=0))
    assert np.all(rms[:2] < 3e-3) and rms[2] < 1.2e-2, f"{1e3 * rms} um"


def _track_first_frame(folder, extra: str, out) -> tuple[dict, meshio.Mesh]:
    """`georeg track` of the first frame with the reference shape measured here (``extra``:
    the [cameras], [geometry] and [method] tables) and the georeg displacement with its
    levels chosen on that frame (the last, the default): the frame is ok, its displacement
    within 1.5 um in plane and 6 um out of plane of the truth, and the choice is recorded in
    summary.json (the levels the series ran on, the frame it was made on, one agreement per
    level, the finest level agreeing with itself). Returns the summary and the frame's
    VTU."""
    config = _config(folder, series_keys='cam0 = ["frames/f1_cam0.png"]\ncam1 = ["frames/f1_cam1.png"]',
                     extra=extra, displacement='method = "georeg"')
    assert cli.main(["-q", "track", str(config), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    frame = summary["frames"][0]
    assert frame["status"] == "ok", frame["failure"]
    chosen = summary["displacement"]["levels_chosen"]
    assert chosen["levels"] == summary["displacement"]["levels"] >= 1
    assert chosen["frame"].endswith("f1_cam0.png") and chosen["agreement"][-1] == 0.0
    assert len(chosen["agreement"]) == len(chosen["dofs"]) >= chosen["levels"]
    assert (f"Spline levels per component: {chosen['levels']}, chosen on f1_cam0.png"
            in (out / "report.html").read_text())
    vtu = meshio.read(out / frame["mesh_file"])
    truth = MOTIONS[0](vtu.points)
    rms = np.sqrt(np.mean((vtu.point_data["displacement_mm"] - truth) ** 2, axis=0))
    assert np.all(rms[:2] < 1.5e-3) and rms[2] < 6e-3, f"{1e3 * rms} um"
    # the uncertainty of each component: its std and bias parts, root sum of squares
    data = vtu.point_data
    np.testing.assert_allclose(data["displacement_uncertainty_mm"] ** 2,
                               data["displacement_std_mm"] ** 2 + data["displacement_bias_mm"] ** 2)
    assert frame["displacement_uncertainty_mm"]["max"] is not None
    return summary, vtu


def _write_halves(folder):
    """The plate as a CAD part: its two halves, IGES faces sharing the edge x = 0."""
    from georeg_plugin.io.spline_io import write_iges
    from georeg_plugin.spline.geometries import quadrilateral
    halves = [quadrilateral([[-22, -15, 0], [0, -15, 0], [0, 15, 0], [-22, 15, 0]], (2, 2)),
              quadrilateral([[0, -15, 0], [22, -15, 0], [22, 15, 0], [0, 15, 0]], (2, 2))]
    write_iges(folder / "halves.igs", halves, names=["left", "right"])


def test_track_follows_a_cad_part_of_two_faces(series, tmp_path):
    """The reference shape measured on a CAD part (the plate as two faces sharing an edge,
    from IGES): the part keeps its faces through the series, the georeg displacement runs on
    their glued component levels and the frame's VTU has the cell data `face`."""
    folder, mesh = series
    _write_halves(folder)
    out = tmp_path / "out"
    extra = ('[cameras]\nfile = "cameras.json"\n[geometry]\nkind = "cad"\nfile = "halves.igs"\n'
             'elements = 32\n[method]\nname = "georeg"\nlevels = 2\ncalibrate = false\nscales = 2')
    _, vtu = _track_first_frame(folder, extra, out)
    face = np.concatenate(vtu.cell_data["face"])
    assert np.bincount(face).tolist() == [16, 16]


def _measure_reference(folder, shape, geometry: str):
    """`georeg measure` (georeg, 2 levels, exact cameras) of the reference pair with the
    [geometry] lines ``geometry``, into the folder ``shape``; returns it."""
    measure = folder / "measure_reference.toml"
    measure.write_text('[images]\ncam0 = "ref_cam0.png"\ncam1 = "ref_cam1.png"\n[cameras]\n'
                       f'file = "cameras.json"\n[geometry]\n{geometry}\n[method]\nname = "georeg"\n'
                       'levels = 2\ncalibrate = false\nscales = 2\n')
    assert cli.main(["-q", "measure", str(measure), "--out", str(shape)]) == 0
    return shape


def _track_one_frame_from(folder, shape, out, frame: int, levels: int):
    """`georeg track` of rendered frame ``frame`` with [reference] dir = ``shape`` and the
    georeg displacement: ok, the reference named, within 1.5 / 6 um of the true motion (RMS,
    in plane / out of plane); returns the frame's VTU."""
    keys = f'cam0 = ["frames/f{frame}_cam0.png"]\ncam1 = ["frames/f{frame}_cam1.png"]'
    config = _config(folder, series_keys=keys, extra=f'[reference]\ndir = "{shape}"',
                     displacement=f'method = "georeg"\nlevels = {levels}')
    assert cli.main(["-q", "track", str(config), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    result = summary["frames"][0]
    assert result["status"] == "ok", result["failure"]
    assert str(shape) in summary["reference"]
    vtu = meshio.read(out / result["mesh_file"])
    truth = MOTIONS[frame - 1](vtu.points)
    rms = np.sqrt(np.mean((vtu.point_data["displacement_mm"] - truth) ** 2, axis=0))
    assert np.all(rms[:2] < 1.5e-3) and rms[2] < 6e-3, f"{1e3 * rms} um"
    return vtu


def test_a_part_s_measure_folder_is_a_reference(series, tmp_path):
    """Issue 27, item 3: the `georeg measure` folder of a CAD part of two faces (its nominal
    faces and its nodes' face parameters saved beside the VTU) is the [reference] of `georeg
    track`: the georeg displacement on the part's glued component levels, the faces kept."""
    from georeg_app.config.track import REFERENCE_NOMINAL
    from georeg_app.shape.outputs import NOMINAL_FILE
    folder, _ = series
    _write_halves(folder)
    shape = _measure_reference(folder, tmp_path / "shape",
                               'kind = "cad"\nfile = "halves.igs"\nelements = 32')
    assert REFERENCE_NOMINAL == NOMINAL_FILE and (shape / NOMINAL_FILE).is_file()
    vtu = _track_one_frame_from(folder, shape, tmp_path / "out", frame=1, levels=2)
    assert np.bincount(np.concatenate(vtu.cell_data["face"])).tolist() == [16, 16]


def test_a_part_s_folder_without_its_nominal_faces_is_refused_naming_the_way(series, tmp_path,
                                                                            capsys):
    """A part's folder written before the nominal faces were saved: refused naming the file
    it lacks and the configuration that works."""
    from georeg_app.shape.outputs import NOMINAL_FILE
    folder, _ = series
    _write_halves(folder)
    shape = _measure_reference(folder, tmp_path / "shape",
                               'kind = "cad"\nfile = "halves.igs"\nelements = 32')
    (shape / NOMINAL_FILE).unlink()
    config = _config(folder, extra=f'[reference]\ndir = "{shape}"',
                     displacement='method = "georeg"\nlevels = 1')
    _fails_naming(capsys, config, tmp_path / "out", "_spline.json", NOMINAL_FILE, 'kind = "cad"')


def _fails_naming(capsys, config, out, *names):
    code = cli.main(["-q", "track", str(config), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and err[0].startswith("georeg: error: "), err
    for name in names:
        assert name in err[0], err[0]
    assert not out.exists()


def test_frames_of_another_size_are_named(series, tmp_path, capsys):
    folder, _ = series
    work = tmp_path / "w"
    shutil.copytree(folder, work)
    cv2.imwrite(str(work / "frames" / "f2_cam1.png"), np.zeros((200, 300), np.uint8))
    _fails_naming(capsys, _config(work), tmp_path / "out", "f2_cam1.png", "300 x 200 px",
                  "320 x 240 px")


def test_counts_that_differ_between_cameras_are_named(series, tmp_path, capsys):
    folder, _ = series
    keys = 'cam0 = "frames/f*_cam0.png"\ncam1 = ["frames/f1_cam1.png"]'
    _fails_naming(capsys, _config(folder, series_keys=keys), tmp_path / "out",
                  "[series]", "cam0 has 4 frames but cam1 has 1")


def test_a_missing_file_in_the_list_is_named(series, tmp_path, capsys):
    folder, _ = series
    keys = 'cam0 = ["frames/f1_cam0.png", "frames/f9_cam0.png"]\ncam1 = ["frames/f1_cam1.png", "frames/f2_cam1.png"]'
    _fails_naming(capsys, _config(folder, series_keys=keys), tmp_path / "out",
                  "[series] cam0", "f9_cam0.png", "item 2 of 2")


@pytest.mark.parametrize("missing", ["fe_cameras.json", "fe.vtu", "summary.json"])
def test_a_reference_folder_lacking_a_file_is_named(series, tmp_path, capsys, missing):
    folder, _ = series
    work = tmp_path / "w"
    shutil.copytree(folder, work)
    (work / "shape_out" / missing).unlink()
    _fails_naming(capsys, _config(work), tmp_path / "out", "[reference] dir", missing)


@pytest.mark.parametrize("corrupt", ["fe_cameras.json", "fe.vtu", "fe_spline.json"])
def test_a_reference_folder_with_an_unreadable_file_is_named(series, tmp_path, capsys, corrupt):
    """A file of the folder that exists but does not read is a user error (one line, exit 1)
    naming it, not a bug of georeg."""
    folder, _ = series
    work = tmp_path / "w"
    shutil.copytree(folder, work)
    (work / "shape_out" / corrupt).write_text("{")
    displacement = 'method = "georeg"' if corrupt.endswith("_spline.json") else 'method = "fe"'
    _fails_naming(capsys, _config(work, displacement=displacement), tmp_path / "out", corrupt)


def test_georeg_needs_the_reference_spline(series, tmp_path, capsys):
    folder, _ = series
    _fails_naming(capsys, _config(folder, displacement='method = "georeg"'), tmp_path / "out",
                  "fe_spline.json")


def test_every_frame_failing_is_an_error_that_leaves_the_frames_to_inspect(series, tmp_path, capsys):
    folder, _ = series
    keys = 'cam0 = ["frames/f3_cam0.png"]\ncam1 = ["frames/f3_cam1.png"]'
    out = tmp_path / "out"
    assert cli.main(["-q", "track", str(_config(folder, series_keys=keys)), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()      # the frame's warning, then the error
    assert err[-1].startswith("georeg: error: every frame failed: frame 1: ")
    assert "no texture" in err[-1] and f"written to {out}" in err[-1]
    assert "(f3_cam0.png)" in err[-2]                      # the warning names the image
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed_frames"] == [1] and summary["frames"][0]["status"] == "failed"
    assert summary["frames"][0]["cam0"].endswith("f3_cam0.png")
    assert "1 frame(s) FAILED (1 (f3_cam0.png))" in (out / "report.html").read_text()
    pvd = ET.parse(out / "displacement.pvd").getroot()
    assert list(pvd.iter("DataSet")) == []                  # nothing in the time series


@pytest.mark.parametrize("incremental", ["true", "false"])
def test_a_local_cluster_of_two_workers_equals_the_serial_run(series, tmp_path, incremental):
    """The series through a distributed.LocalCluster of 2 worker processes gives the serial
    run's fields to round-off (the same frames, statuses and chain)."""
    pytest.importorskip("distributed")
    folder, _ = series
    # (the independent frames without their uncertainty: the setting, and a faster test)
    unc = "true" if incremental == "true" else "false"
    config = _config(folder, displacement=f'method = "fe"\nscales = 2\nincremental = {incremental}'
                     f'\nuncertainty = {unc}')
    runs = {}
    for scheduler in ("serial", "processes"):
        out = tmp_path / scheduler
        assert cli.main(["-q", "track", str(config), "--out", str(out), "--scheduler", scheduler,
                         "--workers", "2"]) == 0
        runs[scheduler] = (out, json.loads((out / "summary.json").read_text()))
    (serial_out, serial), (dask_out, dask) = runs["serial"], runs["processes"]
    assert dask["scheduler"] == "processes"
    for a, b in zip(serial["frames"], dask["frames"]):
        assert (a["status"], a["start_frame"], a["mesh_file"], a["iterations"]) == \
            (b["status"], b["start_frame"], b["mesh_file"], b["iterations"])
        if a["mesh_file"]:
            ua = _point_data(serial_out / a["mesh_file"])["displacement_mm"]
            ub = _point_data(dask_out / b["mesh_file"])["displacement_mm"]
            np.testing.assert_allclose(ua, ub, rtol=0, atol=1e-12)
            has = "displacement_uncertainty_mm" in _point_data(dask_out / b["mesh_file"])
            assert has == (a["status"] == "ok" and unc == "true")


def test_a_georeg_measure_folder_is_a_reference(series, tmp_path):
    """`georeg measure` (georeg, 2 levels) on the reference pair, then `georeg track` with
    [reference] dir = its folder and the georeg displacement on the measured spline."""
    folder, _ = series
    shape = _measure_reference(folder, tmp_path / "shape",
                               'kind = "rectangle"\nlength_mm = 44.0\nwidth_mm = 30.0\nelements = 16')
    _track_one_frame_from(folder, shape, tmp_path / "out", frame=2, levels=1)


def test_a_scheduler_without_dask_or_unknown_is_refused_before_computing(series, tmp_path, capsys,
                                                                        monkeypatch):
    folder, _ = series
    monkeypatch.setitem(sys.modules, "distributed", None)          # as if not installed
    _fails_with(capsys, ["--scheduler", "processes"], folder, tmp_path, "Dask is not installed")
    _fails_with(capsys, ["--scheduler", "mpi"], folder, tmp_path, "--scheduler 'mpi'")


def _fails_with(capsys, options, folder, tmp_path, text):
    out = tmp_path / "out"
    assert cli.main(["-q", "track", str(_config(folder)), "--out", str(out), *options]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("georeg: error: ") and text in err[0], err
    assert not out.exists()


def test_an_unknown_jacobian_is_named(series, tmp_path, capsys):
    folder, _ = series
    config = _config(folder, displacement='method = "fe"\njacobian = "deformed"')
    _fails_naming(capsys, config, tmp_path / "out", "[displacement]", "jacobian", "deformed",
                  '"reference"', '"current"')


def test_the_reference_and_every_frame_are_read_with_the_configured_image_model(monkeypatch):
    """``[method] prefilter_px`` and ``interpolation_order`` reach the reference pair and the
    frames (one image model for every pair the displacement compares)."""
    import dataclasses
    from types import SimpleNamespace

    from georeg_app.config.measure import MethodConfig
    from georeg_app.series import frames, reference

    seen = []

    def fake_read_image(path, prefilter_px, order):
        seen.append((path, prefilter_px, order))
        raise ValueError("stop here")

    monkeypatch.setattr(reference, "read_image", fake_read_image)
    monkeypatch.setattr(frames, "read_image", fake_read_image)
    method = MethodConfig(prefilter_px=0.7, interpolation_order=5)
    config = SimpleNamespace(method=method, images=SimpleNamespace(cam0="a.png", cam1="b.png"))
    with pytest.raises(ValueError, match="stop here"):
        reference._reference_images(config)
    ref = reference.SeriesReference(displacement=None, solver=None, prefilter_px=0.7, label="ref",
                                  interpolation_order=5)
    result = frames.measure_frame(ref, 1, ["c.png", "d.png"], None, 0)
    assert result.failure and "stop here" in result.failure
    assert seen == [("a.png", 0.7, 5), ("c.png", 0.7, 5)]
    defaults = {f.name: f.default for f in dataclasses.fields(reference.SeriesReference)}
    assert defaults["interpolation_order"] == 3


def test_automatic_levels_chosen_on_a_frame_that_fails_keep_the_start_levels(series, tmp_path):
    """The last frame is the failing one of the series (no texture): the level choice made
    on it keeps the start's 2 levels, records no agreement, and the series goes on: the
    good frame ok, the bad one failed, as with fixed levels."""
    folder, _ = series
    keys = ('cam0 = ["frames/f1_cam0.png", "frames/f3_cam0.png"]\n'
            'cam1 = ["frames/f1_cam1.png", "frames/f3_cam1.png"]')
    out = tmp_path / "out"
    extra = ('[cameras]\nfile = "cameras.json"\n[geometry]\nkind = "rectangle"\n'
             'length_mm = 44.0\nwidth_mm = 30.0\nelements = 16\n[method]\nname = "fe"\n'
             'calibrate = false\nscales = 2')
    config = _config(folder, series_keys=keys, extra=extra, displacement='method = "georeg"')
    assert cli.main(["-q", "track", str(config), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [f["status"] for f in summary["frames"]] == ["ok", "failed"]
    chosen = summary["displacement"]["levels_chosen"]
    assert chosen["levels"] == summary["displacement"]["levels"] == 2
    assert chosen["agreement"] == [] and chosen["frame"].endswith("f3_cam0.png")
