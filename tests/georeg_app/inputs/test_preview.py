"""`georeg preview`: the set-up at a glance (mesh in both images, landmarks), without measuring."""
import dataclasses
import json

import meshio
import numpy as np
import pytest

from georeg_app import cli
from georeg_app.config.measure import Landmark, load_config
from georeg_app.inputs.preview import PREVIEW_FILES, preview, preview_summary
from user_data import user_config, write_user_data

CONFIG = user_config('kind = "rectangle"\nlength_mm = {length}\nwidth_mm = 40.0\nelements = 24',
                     "levels = 2")


@pytest.fixture(scope="module")
def user_folder(twisted_scene, tmp_path_factory):
    _, cameras, images = twisted_scene
    return write_user_data(tmp_path_factory.mktemp("preview_data"), [im.values for im in images],
                           cameras)


def _config(folder, length=60.0):
    path = folder / f"plate_{length:g}.toml"
    path.write_text(CONFIG.format(length=length))
    return path


def test_preview_writes_the_views_the_mesh_and_the_summary(user_folder, tmp_path, capsys):
    out = tmp_path / "preview"
    assert cli.main(["-q", "preview", str(_config(user_folder)), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(PREVIEW_FILES)
    summary = json.loads((out / "preview.json").read_text())
    assert summary["elements_seen_fraction"] == {"cam0": 1.0, "cam1": 1.0, "both": 1.0}
    assert summary["mesh"]["family"] == "Q9" and summary["landmark_error_max_px"] is None
    vtu = meshio.read(out / "nominal.vtu")
    seen = np.concatenate(vtu.cell_data["seen_points"])
    points = np.concatenate(vtu.cell_data["points"])
    assert len(seen) == summary["mesh"]["n_elements"] and np.all((0 < seen) & (seen <= points))
    assert summary["points_per_element_seen"]["min"] == seen.min()
    assert (out / "preview.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_mesh_larger_than_the_field_is_shown_partly_unseen(user_folder, caplog):
    """The 72 mm field sees the middle of a 200 mm plate only: the preview says how much."""
    p = preview(load_config(_config(user_folder, length=200.0)))
    fraction = preview_summary(p)["elements_seen_fraction"]
    assert 0.1 < fraction["both"] < 0.6 and fraction["both"] <= min(fraction["cam0"], fraction["cam1"])
    unseen = p.seen_points == 0
    centres = np.array([p.model.mesh.nodes[c].mean(axis=0)
                        for b in p.model.mesh.blocks for c in b.connectivity])
    assert np.all(np.abs(centres[unseen, 0]) > 30.0)       # the unseen elements lie outside the view


def test_landmarks_are_shown_with_their_reprojection_error(user_folder, twisted_scene):
    _, cameras, _ = twisted_scene
    config = load_config(_config(user_folder))
    xyz = np.array([[-20.0, -10.0, 0.0], [20.0, 10.0, 0.0]])
    px = [c.project(xyz) for c in cameras]
    px[1][1] += [3.0, 4.0]                                 # the second one clicked 5 px off in cam1
    marks = tuple(Landmark(xyz_mm=xyz[k], cam0_px=px[0][k], cam1_px=px[1][k]) for k in range(2))
    config = dataclasses.replace(config, cameras=dataclasses.replace(config.cameras, landmarks=marks))
    errors = preview(config).landmark_errors_px
    np.testing.assert_allclose(errors, [[0.0, 0.0], [0.0, 5.0]], atol=1e-9)


def test_a_missing_image_is_one_error_line_and_nothing_written(user_folder, tmp_path, capsys):
    path = user_folder / "missing.toml"
    path.write_text(CONFIG.format(length=60.0).replace('cam1 = "cam1.png"', 'cam1 = "nowhere.png"'))
    out = tmp_path / "preview"
    assert cli.main(["-q", "preview", str(path), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nowhere.png" in err[0] and not out.exists()
