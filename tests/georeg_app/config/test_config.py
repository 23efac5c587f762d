"""georeg_app.config.measure: the TOML schema, its errors (naming the key) and path resolution."""
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from georeg_app.config import measure as config_module
from georeg_app.config.measure import ConfigError, ConfigFileNotFoundError, load_config

ROOT = Path(__file__).resolve().parents[3]

GOOD = """
[images]
cam0 = "img/left.tif"
cam1 = "img/right.tif"

[cameras]
file = "cameras.json"

[geometry]
kind = "plate_with_hole"
length_mm = 100.0
width_mm = 50
hole_radius_mm = 14.0
elements = 300

[method]
name = "tikhonov"
levels = 2
scales = 3
tikhonov_length_mm = [5, 10.5]
calibrate = false

[output]
dir = "results"
"""


def _write(folder: Path, text: str, files=("img/left.tif", "img/right.tif", "cameras.json")) -> Path:
    for name in files:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(b"x")
    path = folder / "config.toml"
    path.write_text(textwrap.dedent(text))
    return path


def _error(tmp_path, text, cls=ConfigError, **kwargs) -> str:
    with pytest.raises(cls) as info:
        load_config(_write(tmp_path, text, **kwargs))
    message = str(info.value)
    assert "\n" not in message
    assert "config.toml" in message                      # names the file
    return message


def test_good_config_loads_with_paths_resolved_against_its_folder(tmp_path, monkeypatch):
    sub = tmp_path / "case"
    sub.mkdir()
    path = _write(sub, GOOD)
    monkeypatch.chdir(tmp_path)                          # relative to the file, not the cwd
    c = load_config(Path("case") / "config.toml")
    assert c.images.cam0 == sub / "img" / "left.tif" and c.images.cam1.is_absolute()
    assert c.cameras.file == sub / "cameras.json" and c.cameras.pyvale_csv is None
    assert c.geometry.kind == "plate_with_hole"
    assert (c.geometry.length_mm, c.geometry.width_mm, c.geometry.hole_radius_mm) == (100.0, 50.0, 14.0)
    assert isinstance(c.geometry.width_mm, float) and c.geometry.elements == 300
    assert c.method.name == "tikhonov" and c.method.levels == 2 and c.method.calibrate is False
    assert c.method.tikhonov_length_mm == (5.0, 10.5)
    assert c.method.scale_sequence == (2, 1, 0)
    assert c.method.keep_stereo is True and c.method.normalisation == "element"   # defaults
    assert c.method.coupling == "joint"
    assert c.output.dir == sub / "results"
    assert c.source == path.resolve()
    assert c.with_output_dir(tmp_path / "o").output.dir == tmp_path / "o"


def test_single_tikhonov_length_and_default_sections(tmp_path):
    text = GOOD.split("[method]")[0] + '[method]\nname = "fe"\ntikhonov_length_mm = 7\n'
    c = load_config(_write(tmp_path, text))
    assert c.method.tikhonov_length_mm == (7.0,) and c.method.name == "fe"
    assert c.output.dir == tmp_path / config_module.DEFAULT_OUTPUT_DIR


def test_automatic_levels_and_tikhonov_length(tmp_path):
    """levels = "auto" (the default) starts from start_levels fixed levels; "auto" can stand
    among the Tikhonov lengths; the methods of compare follow."""
    from georeg_app.shape.methods import default_specs
    text = GOOD.split("[method]")[0] + ('[method]\nlevels = "auto"\nstart_levels = 2\n'
                                        'tikhonov_length_mm = [5, "auto"]\n')
    c = load_config(_write(tmp_path, text))
    assert c.method.levels == "auto" and c.method.fixed_levels == 2
    assert c.method.tikhonov_length_mm == (5.0, "auto")
    labels = [s.label for s in default_specs(c)]
    assert labels == ["FE (multiscale)", "Tikhonov 5 mm", "Tikhonov auto", "georeg auto (multiscale)",
                      "georeg 2 levels (multiscale)", "georeg 2 levels (monoscale)"]
    assert config_module.MethodConfig().levels == "auto"


@pytest.mark.parametrize("old, new, expected", [
    ("hole_radius_mm = 14.0", "radius = 14.0",
     "[geometry] radius: unknown key (did you mean hole_radius_mm?)"),
    ("levels = 2", "level = 2", "[method] level: unknown key (did you mean levels?)"),
    ('dir = "results"', 'dir = "results"\nfolder = "x"', "[output] folder: unknown key"),
    ("[output]", "[outputs]", "[outputs]: unknown key (did you mean output?)"),
])
def test_unknown_key_is_named(tmp_path, old, new, expected):
    assert expected in _error(tmp_path, GOOD.replace(old, new))


@pytest.mark.parametrize("old, new, expected", [
    ("levels = 2", 'levels = "three"', '[method] levels: expected an integer or "auto", got "three"'),
    ("levels = 2", "levels = 2.5", '[method] levels: expected an integer or "auto", got 2.5'),
    ("levels = 2", "levels = true", '[method] levels: expected an integer or "auto", got true'),
    ("calibrate = false", 'calibrate = "no"', '[method] calibrate: expected true or false, got "no"'),
    ("length_mm = 100.0", 'length_mm = "100"', '[geometry] length_mm: expected a number (mm), got "100"'),
    ("tikhonov_length_mm = [5, 10.5]", 'tikhonov_length_mm = [5, "x"]',
     '[method] tikhonov_length_mm: expected a number, "auto" or a list of them'),
    ('cam0 = "img/left.tif"', "cam0 = 3", "[images] cam0: expected a file path (string), got 3"),
    ('name = "tikhonov"', 'name = "pgd"', '[method] name: must be one of "fe", "tikhonov", "georeg"'),
    ("hole_radius_mm = 14.0", "hole_radius_mm = 25.0", "[geometry] hole_radius_mm: must be > 0 and < "),
    ("levels = 2", "levels = 0", '[method] levels: must be >= 1 or "auto", got 0'),
])
def test_wrong_type_or_value_is_named(tmp_path, old, new, expected):
    assert expected in _error(tmp_path, GOOD.replace(old, new))


@pytest.mark.parametrize("old, new, expected", [
    ('cam1 = "img/right.tif"', "", "[images] cam1: missing required key"),
    ("hole_radius_mm = 14.0", "", '[geometry] hole_radius_mm: missing required key (for kind = "plate_with_hole")'),
    ('kind = "plate_with_hole"', 'kind = "rectangle"', '[geometry] hole_radius_mm: not used with kind = "rectangle"'),
    ('file = "cameras.json"', "", "[cameras]: give exactly one of `file`"),
    ("[geometry]", "[geometry_]", "[geometry]: missing required key"),
])
def test_missing_or_misplaced_key_is_named(tmp_path, old, new, expected):
    assert expected in _error(tmp_path, GOOD.replace(old, new))


def test_missing_referenced_file_is_named(tmp_path):
    message = _error(tmp_path, GOOD, ConfigFileNotFoundError, files=("img/left.tif", "cameras.json"))
    assert "[images] cam1: file not found" in message
    assert str(tmp_path / "img" / "right.tif") in message
    assert issubclass(ConfigFileNotFoundError, FileNotFoundError)


def test_missing_config_and_bad_toml(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.toml"):
        load_config(tmp_path / "nowhere.toml")
    assert "not valid TOML" in _error(tmp_path, GOOD.replace("levels = 2", "levels = "))


def test_pyvale_csv_with_landmarks(tmp_path):
    marks = "".join(f"\n[[landmarks]]\nxyz_mm = [{k}.0, 1, 0]\ncam0_px = [1, 2]\ncam1_px = [3, {k}]\n"
                    for k in range(4))
    text = GOOD.replace('file = "cameras.json"', 'pyvale_csv = "calib.csv"') + marks
    files = ("img/left.tif", "img/right.tif", "calib.csv")
    c = load_config(_write(tmp_path, text, files=files))
    assert c.cameras.file is None and c.cameras.pyvale_csv == tmp_path / "calib.csv"
    assert len(c.cameras.landmarks) == 4
    np.testing.assert_array_equal(c.cameras.landmarks[3].xyz_mm, [3.0, 1.0, 0.0])
    np.testing.assert_array_equal(c.cameras.landmarks[2].cam1_px, [3.0, 2.0])
    three = text[:text.rindex("[[landmarks]]")]
    assert "at least 4 [[landmarks]]" in _error(tmp_path, three, files=files)
    bad = text.replace("xyz_mm = [2.0, 1, 0]", "xyz_mm = [2.0, 1]")
    assert "[[landmarks]][2] xyz_mm: expected a list of 3 numbers, got [2.0, 1]" in _error(
        tmp_path, bad, files=files)


@pytest.mark.parametrize("key, name", [("opencv", "stereo.yml"), ("vic3d", "project.z3d"),
                                       ("dice", "cal.xml")])
def test_calibrations_of_other_tools_need_landmarks(tmp_path, key, name):
    marks = "".join(f"\n[[cameras.landmarks]]\nxyz_mm = [{k}.0, 1, 0]\ncam0_px = [1, 2]\ncam1_px = [3, {k}]\n"
                    for k in range(4))
    text = GOOD.replace('file = "cameras.json"', f'{key} = "{name}"') + marks
    files = ("img/left.tif", "img/right.tif", name)
    c = load_config(_write(tmp_path, text, files=files))
    assert getattr(c.cameras, key) == tmp_path / name and c.cameras.file is None
    assert c.cameras.source == key and len(c.cameras.landmarks) == 4
    three = text[:text.rindex("[[cameras.landmarks]]")]
    assert f"[cameras] {key}: needs at least 4 [[landmarks]]" in _error(tmp_path, three, files=files)
    (tmp_path / "elsewhere").mkdir()
    missing = _error(tmp_path / "elsewhere", text, ConfigFileNotFoundError, files=files[:2])
    assert f"[cameras] {key}: file not found" in missing and name in missing


@pytest.mark.parametrize("cameras, expected", [
    ('file = "cameras.json"\nopencv = "stereo.yml"', "got 2 (file, opencv)"),
    ('vic3d = "p.z3d"\ndice = "cal.xml"\npyvale_csv = "c.csv"', "got 3 (pyvale_csv, vic3d, dice)"),
    ("", "got 0"),
])
def test_zero_or_several_camera_sources_are_named(tmp_path, cameras, expected):
    message = _error(tmp_path, GOOD.replace('file = "cameras.json"', cameras))
    assert "[cameras]: give exactly one of `file`, `pyvale_csv`, `opencv`, `vic3d`, `dice`" in message
    assert expected in message


def _documented_example(text: str) -> str:
    """The TOML example after 'A complete example' (indented block) of a docstring."""
    block = text.split("A complete example", 1)[1].split("::\n", 1)[1]
    lines = []
    for line in block.splitlines()[1:]:
        if line and not line.startswith("    "):
            break
        lines.append(line[4:])
    return "\n".join(lines)


def _readme_example() -> str:
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Quickstart", 1)[1]     # the configuration of README's quickstart
    return re.search(r"```toml\n(.*?)```", section, re.S).group(1)


@pytest.mark.parametrize("source", ["docstring", "readme"])
def test_documented_example_loads(tmp_path, source):
    text = _documented_example(config_module.__doc__) if source == "docstring" else _readme_example()
    c = load_config(_write(tmp_path, text, files=("images/left.tif", "images/right.tif", "cameras.json")))
    assert c.geometry.kind == "plate_with_hole" and c.method.name == "georeg"
    assert c.images.cam0 == tmp_path / "images" / "left.tif"
