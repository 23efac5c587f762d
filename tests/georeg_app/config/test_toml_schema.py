"""georeg_app.config.toml_schema: the shared checked reading of TOML tables."""
from pathlib import Path

import numpy as np
import pytest

from georeg_app.config import toml_schema as ts


def test_table_takes_converts_and_reports_leftovers():
    t = ts.Table({"levels": 3, "scale": 2.5, "levles": 1}, "[method]", Path("c.toml"))
    assert t.take("levels", ts.count, "an integer >= 1", required=True) == 3
    assert t.take("missing", ts.count, "an integer", default=7) == 7
    with pytest.raises(ts.ConfigError, match=r"^c.toml: \[method\] scale: expected an integer, "
                                             r"got 2.5$"):
        t.take("scale", ts.integer, "an integer")
    with pytest.raises(ts.ConfigError, match=r"levles: unknown key \(did you mean levels\?\)"):
        t.finish()


def test_messages_stay_on_one_line_whatever_the_key_or_path(tmp_path):
    t = ts.Table({"a\nb": 1}, "[images]", Path("c.toml"))
    with pytest.raises(ts.ConfigError) as info:
        t.finish()
    assert str(info.value).startswith('c.toml: [images] "a\\nb": unknown key')
    with pytest.raises(ts.ConfigFileNotFoundError) as info:
        ts.existing_file(t, "cam0", "x\ny.tif", tmp_path)
    assert "\n" not in str(info.value) and "x\\ny.tif" in str(info.value)
    assert ts.show_key("hole_radius_mm") == "hole_radius_mm" and ts.show_key("a b") == '"a b"'


@pytest.mark.parametrize("convert, bad", [
    (ts.table, []), (ts.table, "x"), (ts.table_list, {}), (ts.number, float("nan")),
    (ts.number, True), (ts.positive, 0.0), (ts.count, 0), (ts.count, 2.0), (ts.boolean, 1),
    (ts.one_of(("a", "b")), "c"), (ts.strings, ["a", 1]), (ts.numbers, []),
    (ts.vector(3), [1.0, 2.0]), (ts.array((2, 2)), [[1.0, 2.0], [3.0]]),
    (ts.array((1, 2)), [[1.0, float("inf")]]), (ts.pair(ts.count), [1, 2, 3])])
def test_converters_refuse_malformed_values(convert, bad):
    with pytest.raises((TypeError, ValueError)):
        convert(bad)


def test_arrays_are_read_only_floats():
    a = ts.array((2, 2))([[1, 2], [3.5, 4]])
    assert a.dtype == float and not a.flags.writeable
    np.testing.assert_array_equal(a, [[1.0, 2.0], [3.5, 4.0]])
    assert ts.numbers(5) == (5.0,) and ts.pair(ts.number)([1, 2.5]) == (1.0, 2.5)


def test_unreadable_or_binary_files_are_config_errors(tmp_path):
    path = tmp_path / "c.toml"
    path.write_bytes(b"\xff\xfe = 1")
    with pytest.raises(ts.ConfigError, match="c.toml: not valid TOML"):
        ts.load_toml(path)
    with pytest.raises(ts.ConfigFileNotFoundError, match="configuration file not found"):
        ts.load_toml(tmp_path / "none.toml")
