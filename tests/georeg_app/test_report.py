"""georeg_app.report and figures: claims PASS/FAIL on known numbers, self-contained HTML."""
import base64
import re

import numpy as np
import pytest

from georeg_app import figures
from georeg_app.report import check_claims, report_html, time_to_reach
from georeg_app_fakes import fake_run, history


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
    assert page.count("<tr>") == 1 + len(run.results)
    assert ">FAIL<" in page
    assert not re.search(r"(src|href)=\"(?!data:)", page)                  # nothing external
    assert "http" not in page.replace("http-equiv", "")
    embedded = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page)
    assert [base64.b64decode(e) for e in embedded] == [png]


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
