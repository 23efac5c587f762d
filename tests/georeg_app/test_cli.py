"""georeg_app.cli: one-line errors with exit status 1, nothing written on error, the
commands wired to the pipeline contract (a stand-in pipeline here; the end-to-end run with
the real pipeline lives in its own test)."""
import os
import subprocess
import sys
import types
from pathlib import Path

import pytest

from fesdic_core.shape.verdict import ShapeDivergedError
from georeg_app import cli
from georeg_app_fakes import FakeSpec, fake_run
from cli_checks import one_error_line, placeholder_run

ROOT = Path(__file__).resolve().parents[2]



@pytest.mark.parametrize("command", ["measure", "compare"])
def test_bad_config_exits_1_with_one_line_naming_the_key(tmp_path, capsys, command):
    out = tmp_path / "out"
    code = cli.main([command, str(_config(tmp_path, levels='"three"')), "--out", str(out)])
    line = one_error_line(capsys.readouterr().err)
    assert code == 1
    assert '[method] levels: expected an integer or "auto", got "three"' in line
    assert not out.exists() and "Traceback" not in line


def test_missing_config_file(tmp_path, capsys):
    assert cli.main(["-q", "measure", str(tmp_path / "none.toml")]) == 1
    assert "none.toml: configuration file not found" in one_error_line(capsys.readouterr().err)


@pytest.mark.slow
def test_subprocess_exit_status_and_verbose_traceback(tmp_path):
    config = _config(tmp_path, levels="0")
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    quiet = subprocess.run([sys.executable, "-m", "georeg_app", "measure", str(config), "--out", str(out)],
                           capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert quiet.returncode == 1 and quiet.stdout == ""
    assert '[method] levels: must be >= 1 or "auto", got 0' in one_error_line(quiet.stderr)
    verbose = subprocess.run([sys.executable, "-m", "georeg_app", "measure", str(config), "--verbose"],
                             capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert verbose.returncode == 1 and "Traceback" in verbose.stderr
    assert verbose.stderr.strip().splitlines()[-1].startswith("georeg: error: ")
    assert sorted(os.listdir(tmp_path)) == ["cameras.json", "config.toml", "left.tif", "right.tif"]


def _config(folder: Path, name="georeg", levels="3") -> Path:
    return placeholder_run(folder, f'name = "{name}"\nlevels = {levels}\ntikhonov_length_mm = [5, 10]')


def test_version_and_usage(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["--version"])
    assert info.value.code == 0 and capsys.readouterr().out.startswith("georeg ")
    with pytest.raises(SystemExit) as info:
        cli.main([])                                       # a command is required
    assert info.value.code == 2


@pytest.fixture
def fake_pipeline(monkeypatch):
    """A stand-in ``georeg_app.shape.pipeline`` recording its calls (same names as the contract)."""
    calls = {}
    module = types.ModuleType("georeg_app.shape.pipeline")
    module.MethodSpec = FakeSpec

    def default_specs(config):
        return [FakeSpec("fe", None, (2, 1, 0), "FE"), FakeSpec("georeg", None, (0,), "georeg (monoscale)")]

    def run_methods(config, specs, *, images=None, truth=None, progress=False):
        calls.update(config=config, specs=list(specs), images=images, truth=truth, progress=progress)
        if calls.get("fail"):
            raise ShapeDivergedError("shape Gauss-Newton diverged at scale 0 (fixed point 2)")
        return fake_run(with_spline=False)

    def demo_config(out_dir):
        calls["demo_out"] = out_dir
        return "demo-config", "demo-images", "demo-truth"

    monkeypatch.setattr("georeg_app.shape.methods.default_specs", default_specs)
    monkeypatch.setattr("georeg_app.shape.pipeline.run_methods", run_methods)
    monkeypatch.setattr("georeg_app.shape.demo.demo_config", demo_config)
    monkeypatch.setattr("georeg_app.shape.outputs.make_figures", lambda run: {"convergence": b"\x89PNG"},
                        raising=False)
    monkeypatch.setattr("georeg_app.report.figures.make_figures", lambda run: {"convergence": b"\x89PNG"})
    return calls


def test_pipeline_error_exits_1_and_writes_nothing(tmp_path, capsys, fake_pipeline):
    fake_pipeline["fail"] = True
    out = tmp_path / "out"
    assert cli.main(["measure", str(_config(tmp_path)), "--out", str(out)]) == 1
    err = capsys.readouterr().err                        # progress log lines, then the error
    assert "Traceback" not in err and err.count("georeg: error: ") == 1
    assert err.strip().splitlines()[-1].startswith("georeg: error: shape Gauss-Newton diverged")
    assert cli.main(["-q", "measure", str(_config(tmp_path)), "--out", str(out)]) == 1
    assert "diverged at scale 0" in one_error_line(capsys.readouterr().err)
    assert not out.exists() and not [p for p in os.listdir(tmp_path) if "staging" in p]


def test_measure_runs_the_configured_method(tmp_path, fake_pipeline, capsys):
    out = tmp_path / "out"
    assert cli.main(["--quiet", "measure", str(_config(tmp_path, name="tikhonov")), "--out", str(out)]) == 0
    specs = fake_pipeline["specs"]
    assert [(s.name, s.param, s.scales) for s in specs] == [("tikhonov", 5.0, (2, 1, 0)),
                                                           ("tikhonov", 10.0, (2, 1, 0))]
    assert fake_pipeline["config"].output.dir == out and fake_pipeline["progress"] is False
    assert (out / "summary.json").is_file() and (out / "report.html").is_file()
    assert capsys.readouterr().err == ""                 # --quiet: nothing but warnings


def test_compare_and_demo_use_default_specs(tmp_path, fake_pipeline, caplog, monkeypatch):
    caplog.set_level("INFO")
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)      # bars only on a terminal
    assert cli.main(["compare", str(_config(tmp_path)), "--out", str(tmp_path / "c")]) == 0
    assert [s.label for s in fake_pipeline["specs"]] == ["FE", "georeg (monoscale)"]
    assert fake_pipeline["progress"] is True
    assert cli.main(["demo", "--out", str(tmp_path / "d"), "-v"]) == 0
    assert fake_pipeline["demo_out"] == tmp_path / "d"
    assert (fake_pipeline["images"], fake_pipeline["truth"]) == ("demo-images", "demo-truth")
    assert (tmp_path / "d" / "report.html").is_file()
    assert any("report:" in r.getMessage() and "report.html" in r.getMessage() for r in caplog.records)
