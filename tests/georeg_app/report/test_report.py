"""georeg_app.report.html and figures: claims PASS/FAIL on known numbers, self-contained HTML,
failed methods marked and never setting a colour scale, the best method, errors in um,
error maps with the truth only, claims only where they apply, what produced the report."""
import base64
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from georeg_app.report import figures, maps
from georeg_app.report.html import check_claims, report_html, time_to_reach
from georeg_app.report.provenance import config_toml
from georeg_app.report.run_view import best_method, colour_range, is_failed
from georeg_app_fakes import FAILURE, FAKE_INPUTS, fake_run, history

PNG = b"\x89PNG\r\n\x1a\n"


def _row(page: str, label: str) -> str:
    """The methods-table row of ``label`` (its <tr ...> tag and cells)."""
    table = re.search(r'<table class="methods">.*?</table>', page, re.S).group(0)
    rows = [r for r in re.findall(r"<tr[^>]*>.*?</tr>", table, re.S) if f"<td>{label}</td>" in r]
    assert len(rows) == 1, label
    return rows[0]


def test_shape_claim_pass_and_fail_with_numbers():
    ok = check_claims(fake_run())[0]
    assert ok.passed is True and "ratio georeg/FE = 0.2" in ok.detail
    # georeg 0.01 > 0.3 x FE 0.02 = 0.006: FAIL, though below every Tikhonov run
    errors = {"fe": 0.02, "t5": 0.03, "t10": 0.025, "t20": 0.04, "geo": 0.01, "mono": 0.011}
    bad = check_claims(fake_run(errors=errors))[0]
    assert bad.passed is False and bad.status == "FAIL" and "ratio georeg/FE = 0.5" in bad.detail
    # one Tikhonov run better than georeg: FAIL
    errors = {"fe": 0.1, "t5": 0.03, "t10": 0.009, "t20": 0.04, "geo": 0.01, "mono": 0.011}
    assert check_claims(fake_run(errors=errors))[0].passed is False
    assert check_claims(fake_run(truth=False))[0].passed is None


def test_multiscale_claim_reads_the_histories():
    # multiscale: 12 records, scale 0 at times 0.7..1.0 s (residual -> 2.0); monoscale: 10 x 0.5 s
    multi = history(3, 4, 60.0, 2.0, 0.1)
    run = fake_run(multi_history=multi, residuals={"georeg (multiscale)": 1.9, "georeg (monoscale)": 2.0})
    claim = check_claims(run)[1]
    t_reach = time_to_reach(run.results[4], 2.0)
    expected = min(r["time_s"] for r in multi if r["scale"] == 0 and r["residual_percent"] <= 2.0)
    assert t_reach == pytest.approx(expected)
    assert claim.passed is (t_reach <= 0.5 * run.results[5].measurement.time_s) is True
    # monoscale lower than multiscale's final residual: never reached -> FAIL
    run = fake_run(residuals={"georeg (multiscale)": 2.5, "georeg (monoscale)": 1.5})
    claim = check_claims(run)[1]
    assert claim.passed is False and "never reaches" in claim.detail
    # reached, but too slowly (monoscale run fast): FAIL
    run = fake_run(mono_history=history(1, 3, 60.0, 2.0, 0.1),
                   residuals={"georeg (multiscale)": 1.9, "georeg (monoscale)": 2.0})
    assert check_claims(run)[1].passed is False


def test_report_is_self_contained_and_shows_fail():
    errors = {"fe": 0.02, "t5": 0.03, "t10": 0.025, "t20": 0.04, "geo": 0.01, "mono": 0.011}
    run = fake_run(errors=errors)
    png = figures.convergence(run)
    page = report_html(run, {"convergence": png})
    table = re.search(r'<table class="methods">.*?</table>', page, re.S).group(0)
    assert len(re.findall(r"<tr[ >]", table)) == 1 + len(run.results)
    assert ">FAIL<" in page
    assert not re.search(r"(src|href)=\"(?!data:)", page)                  # nothing external
    assert "http" not in page.replace("http-equiv", "")
    embedded = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page)
    assert [base64.b64decode(e) for e in embedded] == [png]


@pytest.mark.slow
def test_figures_are_png_and_named():
    run = fake_run()
    out = figures.make_figures(run)
    assert list(out) == ["shape_maps", "residual_maps", "convergence", "multiscale_vs_monoscale",
                         "shape_errors"]
    assert all(v.startswith(b"\x89PNG\r\n\x1a\n") for v in out.values())
    single = fake_run()
    single = type(single)(single.results[:1], False, single.images, 0.5)
    assert figures.multiscale_vs_monoscale(single) is None


def test_bfp_frame_and_scale_factor():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-50, 50, 200), rng.uniform(-25, 25, 200), np.zeros(200)])
    R = np.array([[np.cos(0.3), 0, np.sin(0.3)], [0, 1, 0], [-np.sin(0.3), 0, np.cos(0.3)]])
    centre, axes = figures.bfp_frame(pts @ R.T + [1.0, 2.0, 3.0])
    np.testing.assert_allclose(axes @ axes.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(axes[2], R[:, 2], atol=1e-12)            # normal of the tilted plane
    assert figures.nice_scale_factor(100.0, 1.0, fraction=0.1) == 10.0
    assert figures.nice_scale_factor(100.0, 0.3, fraction=0.1) == 20.0  # 33.3 -> 20
    assert figures.nice_scale_factor(100.0, 1.0) == 20.0                # default: 20 % of the extent


def test_colour_range_ignores_a_failed_method():
    run = fake_run(failed={"FE (multiscale)": "best"})
    rng = np.random.default_rng(1)
    values = {id(r): (1000.0 if is_failed(r) else 1.0 + 0.1 * k) * rng.standard_normal(500)
              for k, r in enumerate(run.results)}                 # FE failed, 1000x larger
    field = values.__getitem__
    got = colour_range(run.results, lambda r: field(id(r)))
    ok = [r for r in run.results if not is_failed(r)]
    assert got == pytest.approx(colour_range(ok, lambda r: field(id(r))))
    assert got == pytest.approx(np.median([np.percentile(np.abs(field(id(r))), 99) for r in ok]))
    # FE and Tikhonov 5 mm only: the scale is Tikhonov's; counted, FE would set it 500x larger
    pair = run.results[:2]
    alone = np.percentile(np.abs(field(id(pair[1]))), 99)
    assert colour_range(pair, lambda r: field(id(r))) == pytest.approx(alone)
    counted = [type(r)(r.spec, r.measurement, r.mesh, r.distance_to_bfp_mm, None) for r in pair]
    ids = {id(a): id(b) for a, b in zip(counted, pair)}
    assert colour_range(counted, lambda r: field(ids[id(r)])) > 100 * alone
    # no successful method: a neutral scale
    assert colour_range(run.results[:1], lambda r: field(id(r))) == 1.0


@pytest.mark.slow
def test_failed_methods_are_marked_in_the_report_and_figures_drawn():
    run = fake_run(failed={"Tikhonov 10 mm": "none", "FE (multiscale)": "best"}, node_errors=True)
    out = figures.make_figures(run)
    assert list(out) == ["shape_maps", "residual_maps", "error_maps", "convergence",
                         "multiscale_vs_monoscale", "shape_errors"]
    assert all(v.startswith(PNG) for v in out.values())
    page = report_html(run, out)
    for label in ("Tikhonov 10 mm", "FE (multiscale)"):
        row = _row(page, label)
        assert row.startswith('<tr class="failed">') and f"failed: {FAILURE}" in row
    assert _row(page, "Tikhonov 10 mm").count("n/a") >= 5          # no measurement: no numbers
    assert 'class="failed"' not in _row(page, "Tikhonov 5 mm")
    assert "2 method(s) failed (FE (multiscale), Tikhonov 10 mm)" in page
    # the shape claim does not apply (a reference failed): left out, not shown as failing
    assert "below every Tikhonov" not in page and "NOT CHECKED" not in page


def test_best_method_highlighted_with_its_criterion():
    run = fake_run()                                           # georeg multiscale: 10 um
    page = report_html(run, {})
    assert _row(page, "georeg (multiscale)").startswith('<tr class="best">')
    assert page.count('<tr class="best">') == 1
    assert "by the lowest RMS shape error against the truth (10 µm)" in page
    # the best failed: the next one, never a failed method
    run = fake_run(failed={"georeg (multiscale)": "best"})
    assert best_method(run)[0].spec.label == "georeg (monoscale)"
    # no truth: the lowest final residual among the successful methods
    residuals = {"FE (multiscale)": 0.5, "Tikhonov 5 mm": 1.0, "georeg (monoscale)": 1.5}
    run = fake_run(truth=False, residuals=residuals, failed={"FE (multiscale)": "best"})
    best, why = best_method(run)
    assert best.spec.label == "Tikhonov 5 mm" and "lowest final gray-level residual" in why
    assert _row(report_html(run, {}), "Tikhonov 5 mm").startswith('<tr class="best">')


def test_errors_in_micrometres():
    page = report_html(fake_run(), {})
    assert "RMS shape error vs truth (µm)" in page and "(mm)</th><th>residual" in page
    assert "<td>50</td>" in _row(page, "FE (multiscale)")                # 0.05 mm
    assert "<th>noise floor (% dyn.)</th>" in page and "<td>1.8</td>" in _row(page, "FE (multiscale)")
    assert "georeg 10 µm" in page and "FE 50 µm" in page                 # the claim's numbers


@pytest.mark.slow
def test_error_maps_only_with_the_truth():
    assert figures.error_maps(fake_run(node_errors=True)).startswith(PNG)
    assert figures.error_maps(fake_run(truth=False, node_errors=True)) is None
    assert figures.error_maps(fake_run(node_errors=False)) is None      # pipeline gave none
    failed = fake_run(node_errors=True, failed={"Tikhonov 5 mm": "none", "FE (multiscale)": "best"})
    assert figures.error_maps(failed).startswith(PNG)


def test_claims_section_only_where_it_applies():
    page = report_html(fake_run(), {})
    assert 'id="claims"' in page and page.count(">PASS<") + page.count(">FAIL<") == 2
    page = report_html(fake_run(truth=False), {})           # the multiscale claim only
    assert 'id="claims"' in page and "below every Tikhonov" not in page
    assert "NOT CHECKED" not in page
    run = fake_run(truth=False)
    no_georeg = type(run)(run.results[:4], False, run.images, 0.5)
    page = report_html(no_georeg, {})
    assert 'id="claims"' not in page and "NOT CHECKED" not in page
    # a failed georeg multiscale fails its claims; a failed monoscale makes its claim not apply
    shape, multi = check_claims(fake_run(failed={"georeg (multiscale)": "none"}))
    assert shape.passed is False and multi.passed is False and FAILURE in shape.detail
    _, multi = check_claims(fake_run(failed={"georeg (monoscale)": "best"}))
    assert multi.passed is None


def test_header_lists_inputs_with_checksums_config_rig_version():
    page = report_html(fake_run(provenance=True), {})
    for label, path, sha in FAKE_INPUTS:
        assert re.search(f"<td>{label}</td><td>{path}</td><td>{sha}</td>", page)
    assert "georeg 9.8.7; run started 2026-11-29T10:00:00+00:00" in page
    assert "[images]\ncam0 = &quot;/data/left.tif&quot;" in page
    assert "[[landmarks]]\nxyz_mm = [-50.0, -25.0, 0.0]" in page
    assert page.count("<td>cam1</td>") == 6 and "-0.44" in page          # a pose per method
    bare = report_html(fake_run(failed={"FE (multiscale)": "none"}), {})
    assert "Input files: not recorded" in bare and "Configuration: not recorded" in bare


def test_config_toml_reads_back():
    from georeg_app.config.measure import (CamerasConfig, Config, GeometryConfig, ImagesConfig,
                                           MethodConfig, OutputConfig)
    config = Config(images=ImagesConfig(Path("/d/left.tif"), Path("/d/right.tif")),
                    cameras=CamerasConfig(file=Path("/d/cameras.json")),
                    geometry=GeometryConfig(kind="rectangle", length_mm=100.0, width_mm=50.0),
                    method=MethodConfig(), output=OutputConfig(Path("/out")),
                    source=Path("/d/config.toml"))
    data = tomllib.loads(config_toml(config))
    assert data["images"] == {"cam0": "/d/left.tif", "cam1": "/d/right.tif"}
    assert data["geometry"] == {"kind": "rectangle", "length_mm": 100.0, "width_mm": 50.0}
    assert data["method"]["levels"] == MethodConfig().levels
    assert data["method"]["tikhonov_length_mm"] == list(MethodConfig().tikhonov_length_mm)


def test_error_scale_ignores_a_failed_method():
    run = fake_run(node_errors=True)
    norm = maps.error_norm(run.results)
    huge = fake_run(node_errors=True, errors={"fe": 50.0, "t5": 0.03, "t10": 0.025, "t20": 0.04,
                                              "geo": 0.01, "mono": 0.011},
                    failed={"FE (multiscale)": "best"})
    ok = [r for r in huge.results if not is_failed(r)]
    assert maps.error_norm(huge.results).vmax == pytest.approx(maps.error_norm(ok).vmax)
    assert maps.error_norm(huge.results).vmax < 0.1 * 50e3                 # um, FE's would be ~1e5
    assert norm.linthresh == pytest.approx(min(
        np.sqrt(np.mean((r.shape_error_mm * 1e3) ** 2)) for r in run.results))


def test_every_method_failed_still_gives_a_report():
    labels = [r.spec.label for r in fake_run().results]
    run = fake_run(failed={label: "none" for label in labels}, node_errors=True)
    out = figures.make_figures(run)
    assert list(out) == ["shape_errors"]                                  # nothing else to draw
    page = report_html(run, out)
    assert "No best method: no method succeeded." in page and 'class="best"' not in page
    assert page.count('<tr class="failed">') == len(labels) and 'id="claims"' not in page


def test_level_search_table_gives_each_level_s_agreement_and_estimated_error():
    from types import SimpleNamespace

    from adapters.level_search import LevelSearch
    from georeg_app.report.html import level_search_html
    from georeg_plugin.levels.selection import LevelTrial
    trials = (LevelTrial(2, 120, 1.0, 2.0, 0.9, True, chosen=True, error_mm=5.77e-4,
                         std_mm=5.77e-4, agreement=1.56),
              LevelTrial(3, 48, 1.1, 2.1, 0.91, False, error_mm=1.023e-3, std_mm=3.48e-4,
                         agreement=2.32))
    run = SimpleNamespace(results=(SimpleNamespace(
        spec=SimpleNamespace(label="georeg auto"), level_search=LevelSearch(
            trials, chosen=2, start=2, n_levels=5, variance=1.8e-5, time_s=0.5)),))
    rows = re.findall(r"<tr><td>.*?</tr>", level_search_html(run), re.S)
    cells = [re.findall(r"<td>(.*?)</td>", r) for r in rows]
    assert cells[0] == ["2", "120", "measured", "0.9", "1.56", "0.577", "0.577", "chosen"]
    assert cells[1] == ["3", "48", "predicted", "0.91", "2.32", "1.02", "0.348", ""]
