"""georeg_app.shape.outputs: summary.json schema, atomic writers, all-or-nothing run outputs."""
import csv
import json
import os

import meshio
import numpy as np
import pytest

from georeg_app.shape import outputs
from georeg_app.shape.outputs import (OutputWriter, summary_dict, write_all, write_bytes_atomic,
                                      write_json_atomic, write_text_atomic)
from georeg_app_fakes import fake_run

SCHEMA = {"name": str, "param": (float, str, type(None)), "shape_rms_error_mm": (float, type(None)),
          "distance_to_bfp_rms_mm": float, "residual_percent": float, "iterations": int,
          "time_s": float, "mesh_file": str}
EXTRA = {"label": str, "converged": bool, "scales": list, "status": str,
         "failure": (str, type(None)), "noise_percent": (float, type(None)),
         "residual_to_noise": (float, type(None)), "scale_reports": list,
         # issue 10: the uncertainty and what the method chose from the data
         "shape_std_median_mm": (float, type(None)), "shape_std_max_mm": (float, type(None)),
         "shape_bias_median_mm": (float, type(None)), "shape_bias_max_mm": (float, type(None)),
         "noise_variance": (float, type(None)), "levels_chosen": (dict, type(None)),
         "regularization": (dict, type(None)),
         # issue 22: what each georeg level dropped on a non-rectangular outline
         "dropped_dofs": (dict, type(None)),
         # issue 27: the nodes valid locally (null without the local checks)
         "n_valid": (int, type(None)), "valid_share": (float, type(None)),
         # issue 23: one uncertainty a user can read (the std and the bias combined)
         "shape_uncertainty_median_mm": (float, type(None)),
         "shape_uncertainty_max_mm": (float, type(None))}


def _tiny_figures():
    return {"convergence": b"\x89PNG fake"}


def test_summary_schema_exactly_as_issue_4():
    run = fake_run()
    doc = json.loads(json.dumps(summary_dict(run), allow_nan=False))      # valid JSON
    assert set(doc) == {"truth_available", "failed_methods", "methods"} and doc["truth_available"] is True
    assert len(doc["methods"]) == len(run.results)
    for entry, result in zip(doc["methods"], run.results):
        assert set(entry) == set(SCHEMA) | set(EXTRA)
        for key, types in {**SCHEMA, **EXTRA}.items():
            assert isinstance(entry[key], types) and not (types is int and isinstance(entry[key], bool)), key
        assert entry["name"] in ("fe", "tikhonov", "georeg")
        assert (entry["param"] is None) == (entry["name"] != "tikhonov")
        d = result.distance_to_bfp_mm
        assert entry["distance_to_bfp_rms_mm"] == pytest.approx(np.linalg.norm(d) / np.sqrt(d.size))
        assert entry["residual_percent"] == pytest.approx(np.nanstd(result.measurement.residual.percent))
        assert entry["iterations"] == len(result.measurement.history)
        assert entry["mesh_file"].endswith(".vtu") and "/" not in entry["mesh_file"]
    files = [e["mesh_file"] for e in doc["methods"]]
    assert len(set(files)) == len(files)
    assert files[1] == "tikhonov_5_mm.vtu" and files[4] == "georeg_multiscale.vtu"


def test_summary_says_what_each_georeg_level_dropped():
    """A georeg result's ``dropped_dofs`` (level -> counts, from the solver's supports) is
    written as is; the other methods say null; every earlier key is still there."""
    import dataclasses

    from georeg_plugin.levels.support import LevelSupport
    run = fake_run()
    before = summary_dict(run)["methods"][4]
    counts = {"0": LevelSupport(0, 36, unseen_mesh=4, slivers=2).as_dict()}
    results = list(run.results)
    results[4] = dataclasses.replace(results[4], dropped_dofs=counts)
    after = summary_dict(dataclasses.replace(run, results=tuple(results)))["methods"]
    doc = json.loads(json.dumps(after[4], allow_nan=False))
    assert doc["dropped_dofs"] == {"0": {"n_dofs": 36, "dropped": 4, "unseen_mesh": 4,
                                         "unseen_images": 0, "slivers": 2}}
    assert {k: v for k, v in doc.items() if k != "dropped_dofs"} == \
        {k: v for k, v in json.loads(json.dumps(before)).items() if k != "dropped_dofs"}
    assert after[0]["dropped_dofs"] is None


def test_summary_without_truth_has_null_errors():
    doc = summary_dict(fake_run(truth=False))
    assert doc["truth_available"] is False
    assert all(e["shape_rms_error_mm"] is None for e in doc["methods"])


def test_atomic_writers_write_and_replace(tmp_path):
    p = tmp_path / "a.json"
    write_json_atomic(p, {"x": np.float64(1.5), "n": np.int64(3), "bad": float("nan"), "v": np.arange(2)})
    assert json.loads(p.read_text()) == {"x": 1.5, "n": 3, "bad": None, "v": [0, 1]}
    write_text_atomic(p, "replaced")
    assert p.read_text() == "replaced"
    assert os.listdir(tmp_path) == ["a.json"]


def test_atomic_writer_failure_keeps_old_file_and_leaves_no_temp(tmp_path, monkeypatch):
    p = tmp_path / "keep.txt"
    p.write_text("old")
    with pytest.raises(TypeError):
        write_bytes_atomic(p, object())                   # fails while writing
    def broken_replace(src, dst):
        raise OSError("disk full")
    monkeypatch.setattr(outputs.os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        write_text_atomic(p, "new")                       # fails while moving into place
    assert p.read_text() == "old"
    assert os.listdir(tmp_path) == ["keep.txt"]


def test_write_all_publishes_every_output(tmp_path):
    run = fake_run()
    out = tmp_path / "out"
    paths = write_all(out, run, _tiny_figures())
    names = sorted(p.name for p in paths)
    assert names == sorted(os.listdir(out))
    assert sorted(os.listdir(tmp_path)) == ["out"]                       # no staging left
    doc = json.loads((out / "summary.json").read_text())
    assert doc == json.loads(json.dumps(summary_dict(run)))
    for entry, result in zip(doc["methods"], run.results):
        mesh = meshio.read(out / entry["mesh_file"])
        np.testing.assert_allclose(mesh.points, result.measurement.nodes)
        np.testing.assert_allclose(mesh.point_data["shape_correction_mm"], result.measurement.q)
        np.testing.assert_allclose(mesh.point_data["distance_to_bfp_mm"], result.distance_to_bfp_mm)
    from georeg_plugin.io.spline_io import read_iges, read_scalar_field, read_spline_json
    geo = run.results[4]
    patch = read_spline_json(out / "georeg_multiscale_spline.json")
    np.testing.assert_allclose(patch.control_points, geo.spline.control_points)
    np.testing.assert_allclose(np.ravel(read_scalar_field(out / "georeg_multiscale_spline.json")),
                               geo.spline_values)
    np.testing.assert_allclose(read_iges(out / "georeg_multiscale_spline.igs").control_points,
                               geo.spline.control_points, atol=1e-9)
    with open(out / "convergence.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == outputs.CONVERGENCE_COLUMNS
    assert len(rows) == sum(len(r.measurement.history) for r in run.results)
    first = run.results[0].measurement.history[0]
    assert float(rows[0]["time_per_fine_iteration"]) == pytest.approx(first["time_s"] / run.one_fine_iteration_s)
    assert (out / "convergence.png").read_bytes() == b"\x89PNG fake"
    assert (out / "report.html").read_text().startswith("<!DOCTYPE html>")


def test_interrupted_run_leaves_no_file(tmp_path, monkeypatch):
    run = fake_run()
    out = tmp_path / "out"
    calls = []

    def crash_on_third_mesh(path, result):
        calls.append(path)
        path.write_bytes(b"partial")                      # a half-written file...
        if len(calls) == 3:
            raise KeyboardInterrupt                       # ...then the user hits Ctrl-C
    monkeypatch.setattr(outputs, "write_method_vtu", crash_on_third_mesh)
    with pytest.raises(KeyboardInterrupt):
        write_all(out, run, _tiny_figures())
    assert len(calls) == 3
    assert os.listdir(tmp_path) == []                     # no out folder, no staging, no temp

    out.mkdir()                                           # an earlier run's output stays intact
    (out / "summary.json").write_text("earlier")
    calls.clear()
    with pytest.raises(KeyboardInterrupt):
        write_all(out, run, _tiny_figures())
    assert os.listdir(out) == ["summary.json"] and (out / "summary.json").read_text() == "earlier"
    assert os.listdir(tmp_path) == ["out"]


def test_output_writer_replaces_into_existing_folder_and_rejects_bad_names(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("user file")
    (out / "summary.json").write_text("old")
    with OutputWriter(out) as w:
        w.write_json("summary.json", {"a": 1})
        with pytest.raises(ValueError, match="plain"):
            w.path("../escape.txt")
        assert not (out / "summary.json").read_text().startswith("{")  # not published yet
    assert json.loads((out / "summary.json").read_text()) == {"a": 1}
    assert (out / "mine.txt").read_text() == "user file"
    assert w.published == [out / "summary.json"]
    assert sorted(os.listdir(tmp_path)) == ["out"]


def test_safe_unique_file_stems():
    assert outputs.safe_stem("Tikhonov 10 mm") == "tikhonov_10_mm"
    assert outputs.safe_stem("georeg (multiscale)") == "georeg_multiscale"
    assert outputs.safe_stem("../../etc") == "etc" and outputs.safe_stem("***") == "method"


def test_published_folder_and_files_are_readable_by_others(tmp_path):
    import stat
    old = os.umask(0o022)
    try:
        with OutputWriter(tmp_path / "run") as w:
            w.write_text("report.html", "<html></html>")
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(tmp_path / "run").st_mode) == 0o755
    assert stat.S_IMODE(os.stat(tmp_path / "run" / "report.html").st_mode) == 0o644


def test_seen_fraction_is_the_share_of_each_element_s_points_in_the_mask():
    from types import SimpleNamespace
    from georeg_app.shape.outputs import seen_fraction
    m = SimpleNamespace(quadrature=SimpleNamespace(element=np.array([0, 0, 1, 1, 1, 3])),
                        residual=SimpleNamespace(mask=np.array([True, False, True, True, False, True])))
    np.testing.assert_allclose(seen_fraction(m, 5), [0.5, 2 / 3, 0.0, 1.0, 0.0])


def test_the_nodes_local_validity_goes_to_the_vtu_and_the_summary(tmp_path):
    """A measurement with its local checks (fesdic_core.shape.validity): the VTU's point data
    ``valid`` (0/1) and ``residual_to_noise``, summary.json's ``n_valid`` and ``valid_share``."""
    import dataclasses
    from fesdic_core.residual.validity import node_validity
    run = fake_run()
    result = run.results[0]
    n = len(result.measurement.q)
    ratio = np.full(n, 0.5)
    ratio[[1, 4]] = [2.5, 7.0]
    validity = node_validity(ratio, np.full(n, 10.0), np.ones(n), np.zeros(n))

    @dataclasses.dataclass(frozen=True)
    class Checked(type(result.measurement)):
        validity: object = None

    fields = {f.name: getattr(result.measurement, f.name)
              for f in dataclasses.fields(result.measurement)}
    checked = dataclasses.replace(result, measurement=Checked(**fields, validity=validity))
    run = dataclasses.replace(run, results=(checked,) + tuple(run.results[1:]))
    entry = summary_dict(run)["methods"][0]
    assert entry["n_valid"] == n - 2 and entry["valid_share"] == pytest.approx((n - 2) / n)
    assert summary_dict(run)["methods"][1]["n_valid"] is None         # no local checks
    path = outputs.write_method_vtu(tmp_path / "fe.vtu", checked)
    data = meshio.read(path).point_data
    np.testing.assert_array_equal(data["valid"], validity.valid.astype(np.uint8))
    np.testing.assert_allclose(data["residual_to_noise"], ratio)
