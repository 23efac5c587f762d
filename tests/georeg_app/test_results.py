"""georeg_app.results.ShapeRun: the command line's verdicts (what it delivers and what it refuses),
on stand-in runs (no measurement computed here)."""
import pytest

from georeg_app.results import MeasurementFailed, ShapeRun
from georeg_app_fakes import fake_run


def test_the_chosen_method_is_the_first_of_measure_and_the_first_georeg_of_compare():
    run = fake_run()
    assert ShapeRun(run, "measure").chosen == "FE (multiscale)"
    assert ShapeRun(run, "compare").chosen == "georeg (multiscale)"
    assert ShapeRun(run, "compare", method="Tikhonov 10 mm").chosen == "Tikhonov 10 mm"
    assert ShapeRun(run, "compare", method="tikhonov").chosen == "Tikhonov 5 mm"
    with pytest.raises(ValueError, match="method 'spline': not in this run"):
        ShapeRun(run, "compare", method="spline")
    with pytest.raises(ValueError, match="command 'track'"):
        ShapeRun(run, "track")


@pytest.mark.slow
def test_a_failed_method_fails_measure_and_is_delivered_by_compare(tmp_path):
    run = fake_run(failed={"georeg (multiscale)": "best"})
    failed = ShapeRun(run, "measure", method="georeg (multiscale)")
    assert not failed.ok and failed.failure and failed.failed == ("georeg (multiscale)",)
    with pytest.raises(MeasurementFailed, match=r"georeg \(multiscale\) failed: "):
        failed.save(tmp_path / "measure")
    assert not (tmp_path / "measure").exists()                 # nothing written
    compared = ShapeRun(run, "compare")
    assert not compared.ok                                     # the chosen one failed
    written = compared.save(tmp_path / "compare")
    assert (tmp_path / "compare" / "summary.json") in written
    assert compared.summary["failed_methods"] == ["georeg (multiscale)"]


def test_compare_fails_only_when_every_method_failed(tmp_path):
    run = fake_run(failed={label: "best" for label in (
        "FE (multiscale)", "Tikhonov 5 mm", "Tikhonov 10 mm", "Tikhonov 20 mm",
        "georeg (multiscale)", "georeg (monoscale)")})
    with pytest.raises(MeasurementFailed):
        ShapeRun(run, "compare").save(tmp_path / "out")
    assert not (tmp_path / "out").exists()
