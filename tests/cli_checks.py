"""Checks of the command line shared by the tests: one error line, a failure that names its cause."""
from pathlib import Path

from georeg_app import cli
from user_data import RECTANGLE_100, user_config


def one_error_line(err: str) -> str:
    """The single ``georeg: error: ...`` line that stderr must hold."""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("georeg: error: ")
    return lines[0]


def fails_naming(capsys, config, out, *names) -> str:
    """``georeg measure config`` exits 1 with one error line holding every name, writes nothing."""
    assert cli.main(["-q", "measure", str(config), "--out", str(out)]) == 1
    line = one_error_line(capsys.readouterr().err)
    for name in names:
        assert name in line, (name, line)
    assert not Path(out).exists()
    return line


def placeholder_run(folder: Path, method: str) -> Path:
    """A configuration whose input files exist but hold nothing (``left.tif``, ``right.tif``,
    ``cameras.json``): what the command line does before reading them."""
    for name in ("left.tif", "right.tif", "cameras.json"):
        (folder / name).write_bytes(b"x")
    path = folder / "config.toml"
    path.write_text(user_config(RECTANGLE_100, method, cam0="left.tif", cam1="right.tif"))
    return path
