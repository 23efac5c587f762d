"""georeg_app's exception family, and the command line telling user errors from bugs.

A user error (any of USER_ERRORS: the four packages' bases and OSError) is one line
``georeg: error: ...`` and exit status 1 (the traceback too under --verbose); any other
exception is a bug: its traceback, a line asking to report it, and exit status 70.
"""
import errno

import pytest

import georeg_app
from adapters.errors import AdapterError, LevelMeshError
from exception_family import exception_classes, outside_family
from fesdic_core.cameras.rig import CalibrationError
from fesdic_core.errors import FesdicCoreError
from fesdic_core.fe.mesh import MeshError
from georeg_app import cli
from georeg_app.config.toml_schema import ConfigError, ConfigFileNotFoundError
from georeg_app.errors import USER_ERRORS, GeoregError, InputError, MeasurementFailed
from georeg_plugin.errors import GeoregPluginError, SplineFileError
from cli_checks import one_error_line, placeholder_run



# ------------------------------------------------------------------ the family
def _config(folder, levels="3"):
    return placeholder_run(folder, f'name = "georeg"\nlevels = {levels}')


def test_every_exception_class_of_the_app_derives_from_its_base():
    assert outside_family(georeg_app, GeoregError) == []


@pytest.mark.parametrize("cls, builtin", [
    (InputError, ValueError), (MeasurementFailed, RuntimeError), (ConfigError, ValueError),
    (ConfigFileNotFoundError, FileNotFoundError)])
def test_each_class_is_found_and_keeps_its_builtin_base(cls, builtin):
    assert cls in exception_classes(georeg_app).values()
    assert issubclass(cls, GeoregError) and issubclass(cls, builtin)


def test_user_errors_are_the_four_bases_and_os_error():
    assert set(USER_ERRORS) == {FesdicCoreError, GeoregPluginError, AdapterError, GeoregError,
                                OSError}
    assert {"GeoregError", "InputError", "MeasurementFailed", "USER_ERRORS"} <= set(
        georeg_app.__all__)
    assert cli.MeasurementFailed is MeasurementFailed          # the old name still imports


# ------------------------------------------------------------------ user errors
def test_missing_config_file_is_one_line_and_exit_1(tmp_path, capsys):
    assert cli.main(["measure", str(tmp_path / "none.toml")]) == cli.EXIT_ERROR == 1
    assert "none.toml: configuration file not found" in one_error_line(capsys.readouterr().err)


def test_bad_toml_value_is_one_line_naming_the_key(tmp_path, capsys):
    out = tmp_path / "out"
    code = cli.main(["measure", str(_config(tmp_path, levels='"three"')), "--out", str(out)])
    line = one_error_line(capsys.readouterr().err)
    assert code == 1
    assert "config.toml: [method] levels" in line and "three" in line
    assert not out.exists()


@pytest.mark.parametrize("error", [
    ConfigError("c.toml: [method] scale: expected an integer"),
    InputError("frame 2: b.tif is 10 x 10 px but the reference images are 20 x 20 px"),
    MeasurementFailed("georeg (multiscale) failed: residual above the noise floor"),
    MeshError("mesh file m.vtu: points must be (n, 2) or (n, 3)"),
    CalibrationError("cameras.json: not valid JSON"),
    SplineFileError("part.igs: not an IGES file (missing G, D or P section)"),
    LevelMeshError("nominal model 'plate': face 0 has 4 FE elements per knot span"),
    PermissionError(errno.EACCES, "Permission denied", "out/report.html"),
], ids=lambda e: type(e).__name__)
def test_each_family_base_is_a_user_error(tmp_path, capsys, monkeypatch, error):
    def load_config(path):
        raise error
    monkeypatch.setattr(cli, "load_config", load_config)
    assert cli.main(["measure", str(_config(tmp_path))]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert line == f"georeg: error: {' '.join(str(error).split())}"


def test_verbose_adds_the_traceback_to_a_user_error(tmp_path, capsys):
    assert cli.main(["--verbose", "measure", str(tmp_path / "none.toml")]) == 1
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "ConfigFileNotFoundError" in err
    assert err.strip().splitlines()[-1].startswith("georeg: error: ")
    assert "bug" not in err


def test_interrupt_is_exit_130(tmp_path, capsys, monkeypatch):
    def load_config(path):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "load_config", load_config)
    assert cli.main(["measure", str(_config(tmp_path))]) == cli.EXIT_INTERRUPTED == 130
    assert "interrupted" in one_error_line(capsys.readouterr().err)


# ------------------------------------------------------------------ bugs
def _assert_bug_report(err: str, exc_line: str, command: str) -> None:
    lines = err.strip().splitlines()
    assert lines[0] == "Traceback (most recent call last):", err
    assert exc_line in lines
    assert "georeg: error:" not in err                    # not dressed as a user error
    assert "this is a bug in georeg" in lines[-1] and "please report it" in lines[-1]
    assert "traceback above" in lines[-1] and lines[-1].endswith(command)


@pytest.mark.parametrize("error", [KeyError("method"), TypeError("'NoneType' is not iterable"),
                                   ValueError("operands could not be broadcast"),
                                   RuntimeError("dictionary changed size during iteration"),
                                   ZeroDivisionError("division by zero")],
                         ids=lambda e: type(e).__name__)
def test_any_other_exception_is_a_bug_with_traceback_hint_and_exit_70(tmp_path, capsys,
                                                                      monkeypatch, error):
    """Plain ValueError and RuntimeError included: a user error must be a family member."""
    def load_config(path):
        raise error
    monkeypatch.setattr(cli, "load_config", load_config)
    config, out = _config(tmp_path), tmp_path / "out"
    argv = ["measure", str(config), "--out", str(out)]
    assert cli.main(argv) == cli.EXIT_BUG == 70
    _assert_bug_report(capsys.readouterr().err, f"{type(error).__name__}: {error}",
                       f"georeg measure {config} --out {out}")
    assert not out.exists()


def test_a_bug_deep_in_the_track_command_is_reported(tmp_path, capsys, monkeypatch):
    def load_track_config(path):
        sections: dict = {}
        return sections["output"]                          # a KeyError of a programmer
    monkeypatch.setattr("georeg_app.config.track.load_track_config", load_track_config)
    argv = ["-q", "track", str(tmp_path / "track.toml")]
    assert cli.main(argv) == 70
    err = capsys.readouterr().err
    _assert_bug_report(err, "KeyError: 'output'", f"georeg -q track {tmp_path / 'track.toml'}")
    assert "in load_track_config" in err                   # the traceback reaches the bug


def test_exit_statuses_are_in_the_help_and_the_module_docstring():
    text = " ".join(cli.build_parser().format_help().split())
    assert "70 a bug in georeg" in text and "1 user error" in text
    assert "70 a bug in georeg" in " ".join(cli.__doc__.split())
