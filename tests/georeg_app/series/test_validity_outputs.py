"""``georeg track``'s outputs of the nodes' local validity, and the spline levels' frame.

A one-frame series on disk (tests/series_data.py: the displacement tests' plate and rig, a
small rigid motion): the frame's VTU carries ``valid`` (0/1) and ``residual_to_noise``,
summary.json counts the valid nodes, the report's statistics count only them. A reference
mesh 68 mm long on the 60 mm plate has nodes over the uniform background: they are invalid,
the frame fails on its invalid share and is still written (``_failed.vtu``).
"""
import json

import meshio
import numpy as np
import pytest

from adapters.fesdic_core import nominal_model
from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                             measure_displacement)
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.fe.mesh_io import write_mesh
from fesdic_core.synthetic.motion import RigidMotion
from georeg_app import cli
from georeg_app.series.reference import displacement_solver
from georeg_plugin.spline.geometries import rectangle
from series_data import write_series

MOTION = RigidMotion((0.1, -0.05, 0.05))


def _track(folder, out, extra=""):
    config = folder / "track.toml"
    config.write_text('[images]\ncam0 = "ref_cam0.png"\ncam1 = "ref_cam1.png"\n'
                      '[series]\ncam0 = ["f1_cam0.png"]\ncam1 = ["f1_cam1.png"]\n'
                      f'[displacement]\nmethod = "fe"\nscales = 2\n{extra}'
                      '[reference]\ndir = "shape_out"\n')
    status = cli.main(["-q", "track", str(config), "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    return status, summary, summary["frames"][0]


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    folder = tmp_path_factory.mktemp("validity_series")
    _, mesh = write_series(folder, [MOTION], supersample=2)
    return folder, mesh


@pytest.mark.slow
def test_the_frame_vtu_and_summary_carry_the_nodes_validity(series, tmp_path):
    folder, mesh = series
    status, summary, frame = _track(folder, tmp_path / "out")
    assert status == 0 and frame["status"] == "ok", frame["failure"]
    data = meshio.read(tmp_path / "out" / frame["mesh_file"]).point_data
    assert data["valid"].shape == (mesh.n_nodes,) and set(np.unique(data["valid"])) <= {0, 1}
    assert frame["n_valid"] == int(data["valid"].sum()) >= 0.95 * mesh.n_nodes
    assert frame["valid_share"] == pytest.approx(frame["n_valid"] / mesh.n_nodes)
    r = data["residual_to_noise"]
    assert r.shape == (mesh.n_nodes,) and np.all((r > 0.2) & (r < 1.0))    # about half the floor
    report = (tmp_path / "out" / "report.html").read_text()
    assert f"{frame['n_valid']} of {mesh.n_nodes}" in report
    assert "Statistics count only the nodes valid locally" in report


@pytest.mark.slow
def test_nodes_over_the_background_fail_the_frame_which_is_still_written(series, tmp_path):
    """The reference folder's mesh replaced by one 68 mm long: its 14 end nodes (beyond the
    plate) are invalid; with the renders' share of invalid nodes (3 %) the frame fails on
    them, its VTU is written, and the summary's mean displacement counts only the valid
    nodes. (The modified Gauss-Newton does not stagnate there; the full one, run again from
    the start, does.)"""
    folder, _ = series
    long = tmp_path / "long"
    long.mkdir()
    for item in folder.iterdir():
        if item.is_file():
            (long / item.name).write_bytes(item.read_bytes())
    (long / "shape_out").mkdir()
    for name in ("fe_cameras.json", "summary.json"):
        (long / "shape_out" / name).write_bytes((folder / "shape_out" / name).read_bytes())
    mesh = rectangle_mesh(68.0, 30.0, 17, 6, family="Q4")
    write_mesh(long / "shape_out" / "fe.vtu", mesh)
    status, summary, frame = _track(long, tmp_path / "out", "max_invalid_share = 0.03\n")
    assert status == 1 and frame["status"] == "failed"
    assert "not valid locally" in frame["failure"], frame["failure"]
    assert frame["mesh_file"].endswith("_failed.vtu")
    data = meshio.read(tmp_path / "out" / frame["mesh_file"]).point_data
    beyond = np.abs(mesh.nodes[:, 0]) > 30.0
    assert beyond.sum() == 14 and not np.any(data["valid"][beyond])
    assert frame["n_valid"] == int(data["valid"].sum()) < mesh.n_nodes - 13
    valid = data["valid"].astype(bool)
    np.testing.assert_allclose(frame["mean_displacement_mm"],
                               data["displacement_mm"][valid].mean(axis=0), rtol=1e-9)


@pytest.mark.slow
def test_a_georeg_frame_keeps_its_nodes_valid(twist_wave_pair):
    """The flat-to-twisted-and-wavy pair with the spline levels (2 per component) on 24 x 16
    Q9 elements, where plain FE diverges locally: the frame is ok with at least 95 % of its
    nodes valid (measured: all 1617), none of them more than 20 um off."""
    pair = twist_wave_pair
    model = nominal_model(rectangle(44.0, 30.0), (24, 16), "Q9")
    reference = displacement_reference(model.mesh, pair.reference, pair.cameras,
                                       DisplacementSettings(scales=(2, 1, 0)))
    m = measure_displacement(reference, pair.deformed,
                             displacement_solver("georeg", model.mesh, model, levels=2))
    assert m.ok, m.failure
    assert m.valid.mean() >= 0.95
    error = np.linalg.norm(m.U - pair.motion(model.mesh.nodes), axis=1)
    assert error[m.valid].max() < 0.02


def test_the_invalid_share_is_a_displacement_key(tmp_path):
    """``[displacement] max_invalid_share``: default 1 (reported, fails no frame), a share in
    [0, 1], named when wrong."""
    from georeg_app.config.toml_schema import ConfigError
    from georeg_app.config.track import displacement_table
    source = tmp_path / "track.toml"
    assert displacement_table({}, source).max_invalid_share == 1.0
    assert displacement_table({"max_invalid_share": 0.1}, source).max_invalid_share == 0.1
    for wrong in (1.5, "0.1"):
        with pytest.raises(ConfigError, match=r"\[displacement\].*max_invalid_share"):
            displacement_table({"max_invalid_share": wrong}, source)
