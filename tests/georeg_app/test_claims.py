"""The paper's central claims on the real code path: `georeg compare` and `georeg demo`, no fakes.

The scene is the demo's (twisted open-hole plate, 1 mm twist at the corners of the view plus a
0.2 mm waviness that no spline level holds exactly, noise of 2 gray levels, specimen pose off by
0.5 deg / 0.5 mm so that the fixed point calibration <-> shape runs), rendered small. Errors are
distances to the TRUE surface after the best rigid alignment.
"""
import functools
import json
from html import escape as html_escape

import meshio
import numpy as np
import pytest

from fesdic_core.synthetic.accuracy import shape_error_to_surface
from georeg_app import cli
from georeg_app.report import html as report
from georeg_app.shape import demo, pipeline
from georeg_app.config.measure import MethodConfig
from georeg_app.report.figures import georeg_pair
from shape_truth import bounded_shape_error, rms
from user_data import PLATE_WITH_HOLE, perturbed_pose, user_config, write_user_data

pytestmark = pytest.mark.slow         # the demo end to end (the README's claims)

COMPARE = user_config(PLATE_WITH_HOLE + "\nelements = 128",
                      "levels = 3\nscales = 3\ntikhonov_length_mm = [5.0, 10.0, 20.0]\ncalibrate = true")


@pytest.fixture(scope="module")
def compare_run(small_demo_scene, tmp_path_factory):
    """`georeg compare` on the small demo pair, from files, as a user runs it."""
    scene = small_demo_scene
    folder = write_user_data(tmp_path_factory.mktemp("compare"), scene.arrays,
                             perturbed_pose(scene.cameras))
    (folder / "config.toml").write_text(COMPARE)
    out = folder / "out"
    assert cli.main(["-q", "compare", str(folder / "config.toml"), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    errors = {}
    for m in summary["methods"]:
        mesh = meshio.read(out / m["mesh_file"])
        points = mesh.points
        std = mesh.point_data["shape_std_mm"]               # every method writes its std map
        assert np.all(np.isfinite(std)) and np.all(std >= 0) and std.max() > 0, m["label"]
        assert m["shape_std_median_mm"] == pytest.approx(np.median(std))
        errors[m["label"]] = (rms(shape_error_to_surface(points, scene.specimen)),
                              rms(bounded_shape_error(points, scene.specimen)))
    return summary, errors


def test_compare_georeg_beats_fe_and_every_tikhonov_length_against_the_truth(compare_run):
    """georeg < each Tikhonov length and <= 0.3 x FE, RMS error to the true surface.

    Measured (500 x 333 px, 256 Q9 elements): georeg 3.4 um; Tikhonov 5/10/20 mm 7.1/11/29 um;
    FE 27 um (ratio 0.12). The same holds modulo a bounded rigid motion (2 deg, 2 mm).
    """
    summary, errors = compare_run
    labels = [m["label"] for m in summary["methods"]]
    assert labels == ["FE (multiscale)", "Tikhonov 5 mm", "Tikhonov 10 mm", "Tikhonov 20 mm",
                      "georeg 3 levels (multiscale)", "georeg 3 levels (monoscale)"]
    assert summary["truth_available"] is False            # compare knows no truth: we do
    for k in (0, 1):                                        # unbounded, bounded alignment
        geo, fe = errors["georeg 3 levels (multiscale)"][k], errors["FE (multiscale)"][k]
        tik = {label: e[k] for label, e in errors.items() if label.startswith("Tikhonov")}
        assert all(geo < e for e in tik.values()), (geo, tik)
        assert geo <= report.FE_ERROR_RATIO * fe, (geo, fe)
    # and it is accurate in absolute terms: < 1 % of the 1 mm twist (0.045 px at 0.22 mm/px)
    assert errors["georeg 3 levels (multiscale)"][1] < 0.01


def test_compare_multiscale_is_at_least_as_good_as_monoscale(compare_run):
    """Multiscale georeg ends at the monoscale residual (within 0.1 %) and error (within 5 %).

    Measured: residual 1.544 % vs 1.546 %; error 3.38 vs 3.38 um.
    """
    summary, errors = compare_run
    by = {m["label"]: m for m in summary["methods"]}
    multi, mono = by["georeg 3 levels (multiscale)"], by["georeg 3 levels (monoscale)"]
    assert multi["scales"] == [2, 1, 0] and mono["scales"] == [0]
    assert multi["converged"] and mono["converged"]
    assert multi["residual_percent"] <= mono["residual_percent"] * (1 + report.RESIDUAL_RTOL)
    assert errors["georeg 3 levels (multiscale)"][1] <= 1.05 * errors["georeg 3 levels (monoscale)"][1]


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """`georeg demo` for real, images 612 x 408 px (half the demo's), scales (1, 0).

    Halving the images and dropping the coarsest scale keeps the pixels per element of the
    full demo's scales 2 and 1 (its scale s is this run's s - 1); with 3 scales at this size
    the FE run diverges at the coarsest (8 px per element: error 15 mm after 232 iterations).
    Returns the output folder and the RunResult the report was made from.
    """
    runs = []
    real_run_methods = pipeline.run_methods

    def keep(*args, **kwargs):
        runs.append(real_run_methods(*args, **kwargs))
        return runs[-1]

    out = tmp_path_factory.mktemp("demo") / "out"
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(demo.DEMO, "image_size", (612, 408))
        mp.setattr(demo, "MethodConfig", functools.partial(MethodConfig, scales=2))
        mp.setattr(pipeline, "run_methods", keep)
        assert cli.main(["-q", "demo", "--out", str(out)]) == 0
    (run,) = runs
    return out, run


def test_demo_end_to_end_at_half_size_passes_the_shape_claim(demo_run):
    """Exit 0, report.html, summary.json with eight methods and errors against the truth;
    georeg (automatic and fixed levels) below every Tikhonov length, the automatic one
    included, on the real results. At this size the unregularized
    FE run drifts at scale 1 (8 px per element) to a correction of about 14 mm: it is
    marked failed (the shape diverged) and the others are delivered; the report's shape
    claim then PASSes, or is not checked when its FE reference failed."""
    out, run = demo_run
    summary = json.loads((out / "summary.json").read_text())
    assert summary["truth_available"] is True
    assert [m["name"] for m in summary["methods"]] == ["fe"] + ["tikhonov"] * 4 + ["georeg"] * 3
    methods = {m["label"]: m for m in summary["methods"]}
    for m in summary["methods"]:
        if m["status"] == "ok":
            assert m["shape_rms_error_mm"] is not None
        else:
            assert m["name"] == "fe" and "diverged" in m["failure"], m
            assert summary["failed_methods"] == [m["label"]]
    tikhonov = [m["shape_rms_error_mm"] for m in summary["methods"] if m["name"] == "tikhonov"]
    for label in ("georeg auto (multiscale)", "georeg 3 levels (multiscale)"):
        georeg = methods[label]
        assert georeg["status"] == "ok"
        assert georeg["shape_rms_error_mm"] < min(tikhonov), (georeg, tikhonov)
    assert methods["georeg auto (multiscale)"]["levels_chosen"]["trials"]
    shape, multiscale = report.check_claims(run)
    html = (out / "report.html").read_text()
    if methods["FE (multiscale)"]["status"] == "ok":
        assert shape.status == "PASS", shape.detail
        assert f'<span class="PASS">PASS</span> {html_escape(shape.name)}' in html
    else:
        assert shape.status in ("PASS", "NOT CHECKED"), shape.detail
    # the deterministic half of the multiscale claim: the final residuals are equal (0.1 %)
    multi, mono = georeg_pair(run)
    assert multi.measurement.residual_percent <= mono.measurement.residual_percent * (1 + report.RESIDUAL_RTOL)


def _work_to_reach(result, target_percent):
    """Integration-point evaluations (sum of n_points over the history's iterations, every
    scale and stage) until the first scale-0 record at or below ``target_percent``."""
    work = 0
    for record in result.measurement.history:
        work += record["n_points"]
        if record["scale"] == 0 and record["residual_percent"] <= target_percent:
            return work
    return None


def test_demo_multiscale_reaches_the_monoscale_residual_with_half_the_work(demo_run):
    """Fig. 11 in deterministic units (integration-point evaluations instead of seconds): the
    multiscale run reaches the monoscale final residual with at most half its work. (Before
    the Levenberg-Marquardt steps and the stagnation criteria of the finest scale it did
    not: ratio 0.557.)"""
    _, run = demo_run
    multi, mono = georeg_pair(run)
    target = mono.measurement.residual_percent * (1 + report.RESIDUAL_RTOL)
    mono_work = sum(r["n_points"] for r in mono.measurement.history)
    multi_work = _work_to_reach(multi, target)
    assert multi_work is not None and multi_work <= report.TIME_RATIO * mono_work, \
        (multi_work, mono_work)
