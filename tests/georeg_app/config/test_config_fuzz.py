"""Fuzzing the configuration readers: a malformed file is always one ConfigError naming it.

Each example starts from a valid document (georeg's config, with JSON cameras or with a
pyvale calibration and landmarks; the Stereo DIC Challenge example's analysis and specimen
files), breaks it one to three times (a wrong type, a non-finite number, a negative size,
an empty list, nested garbage, a missing required key, an unknown key, a table replaced
by garbage; every break on its own makes the file invalid, and a later break never
repairs an earlier one), writes it as TOML and reads it. The reader must raise
:class:`ConfigError` (nothing else) on one line that names the broken file, and write
nothing.
"""
import copy
import json
import math
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fesdic_core.shape.joint import COUPLINGS
from georeg_app.config.measure import GEOMETRY_KINDS, METHOD_NAMES, NORMALISATIONS, load_config
from georeg_app.config.toml_schema import ConfigError

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "dic_challenge"
sys.path.insert(0, str(EXAMPLE))

from challenge import config as challenge_config                      # noqa: E402

FUZZ = settings(max_examples=100, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


# --------------------------------------------------------------------------- TOML text
def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)                        # ASCII escapes, valid in a TOML string
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"


def _toml(doc: dict) -> str:
    """``doc`` as TOML: top-level tables as [sections], everything else inline."""
    lines = [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in doc.items() if not isinstance(v, dict)]
    for name, table in doc.items():
        if isinstance(table, dict):
            lines.append(f"[{json.dumps(name)}]")
            lines += [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- garbage
_text = st.text(st.characters(max_codepoint=0xFFFF, blacklist_categories=("Cs",)), max_size=12)
_key = _text.filter(bool)
_int = st.integers(-2 ** 63, 2 ** 63 - 1)
_float = st.floats(allow_nan=True, allow_infinity=True)
_non_finite = st.sampled_from([math.nan, math.inf, -math.inf])
_scalar = st.one_of(st.booleans(), _int, _float, _text)
_nested = st.recursive(_scalar, lambda inner: st.lists(inner, max_size=3)
                       | st.dictionaries(_key, inner, max_size=3), max_leaves=6)
_table = st.dictionaries(_key, _nested, max_size=3)
_not_a_number = st.one_of(st.booleans(), _text, st.lists(_nested, max_size=3), _table)
_not_an_integer = st.one_of(_not_a_number, _float)
_not_a_string = st.one_of(st.booleans(), _int, _float, st.lists(_nested, max_size=3), _table)
_not_a_table = st.one_of(_scalar, st.lists(_nested, max_size=3))


def _not_one_of(choices):
    return st.one_of(_not_a_string, _text.filter(lambda s: s not in choices))


def _bad_vector(n):
    return st.one_of(
        _not_a_number.filter(lambda v: not isinstance(v, list)), _non_finite,
        st.lists(st.floats(-1e3, 1e3), max_size=6).filter(lambda v: len(v) != n),
        st.lists(st.floats(-1e3, 1e3), min_size=n, max_size=n).flatmap(      # one bad entry
            lambda v: st.tuples(st.integers(0, n - 1), st.one_of(_not_a_number, _non_finite))
            .map(lambda bad: v[:bad[0]] + [bad[1]] + v[bad[0] + 1:])))


def _bad_array(rows, columns):
    return st.one_of(_not_a_number, _bad_vector(rows),
                     st.lists(_bad_vector(columns), min_size=rows, max_size=rows))


BAD = {
    "positive": st.one_of(_not_a_number, _non_finite, st.floats(max_value=0.0),
                          st.integers(-2 ** 63, 0)),
    "number": st.one_of(_not_a_number, _non_finite),
    "count": st.one_of(_not_an_integer, st.integers(-2 ** 63, 0)),
    "count_or_auto": st.one_of(_not_an_integer, st.integers(-2 ** 63, 0)).filter(lambda v: v != "auto"),
    "non_negative": st.one_of(_not_a_number, _non_finite, st.floats(max_value=-1e-9),
                              st.integers(-2 ** 63, -1)),
    "boolean": st.one_of(_int, _float, _text, st.lists(_nested, max_size=3), _table),
    "string": _not_a_string,
    "path": st.one_of(_not_a_string, _text.map(lambda s: "missing/" + s)),
    "positives": st.one_of(st.just([]), st.booleans(), _text, _table, _non_finite,
                           st.floats(max_value=0.0), st.integers(-2 ** 63, 0),
                           st.lists(st.one_of(_not_a_number, _non_finite,
                                              st.floats(max_value=0.0)), min_size=1, max_size=3)),
    "positives_or_auto": None,           # set below, from "positives"
    "vector3": _bad_vector(3),
    "vector2": _bad_vector(2),
    "count_pair": st.one_of(_not_a_number, _bad_vector(2),
                            st.lists(st.integers(-2 ** 63, 0), min_size=2, max_size=2)),
    "number_pair": _bad_vector(2),
    "corners3": _bad_array(4, 3),
    "corners2": _bad_array(4, 2),
    "segment": _bad_array(2, 3),
    "polygon": st.one_of(_not_a_number, st.lists(_bad_vector(2), min_size=1, max_size=4)),
    "names": st.one_of(_not_a_number.filter(lambda v: not isinstance(v, list)),
                       st.lists(_not_a_string, min_size=1, max_size=3),
                       st.lists(_text.filter(lambda s: s != "block"), min_size=1, max_size=3)),
    "feature": st.one_of(_not_a_string, _text.filter(lambda s: s != "block")),
    **{f"enum:{','.join(c)}": _not_one_of(c) for c in (GEOMETRY_KINDS, METHOD_NAMES, NORMALISATIONS,
                                                       COUPLINGS, challenge_config.FEATURE_KINDS)},
}


BAD["positives_or_auto"] = BAD["positives"].filter(
    lambda v: "auto" not in (v if isinstance(v, list) else [v]))


def _enum(choices):
    return f"enum:{','.join(choices)}"


class Schema:
    """A valid document and what breaks it.

    ``values``: path -> kind of value (a key of BAD); ``required``: paths whose removal
    breaks the document; ``tables``: paths of the tables and their known keys.
    """

    def __init__(self, doc, values, required, tables):
        self.doc, self.values, self.required, self.tables = doc, values, required, tables


def _get(doc, path):
    for part in path:
        if isinstance(part, int):
            if not isinstance(doc, list) or part >= len(doc):
                return None
        elif not isinstance(doc, dict) or part not in doc:
            return None
        doc = doc[part]
    return doc


def _break(draw, schema: Schema, doc: dict) -> bool:
    """Break ``doc`` once, in place; False if the place to break is no longer there."""
    how = draw(st.sampled_from(["value", "value", "missing", "unknown", "table"]))
    if how == "missing":
        path = draw(st.sampled_from(schema.required))
        parent, key = _get(doc, path[:-1]), path[-1]
        if isinstance(parent, dict) and isinstance(key, str) and key in parent:
            del parent[key]
            return True
        if isinstance(parent, list) and isinstance(key, int) and key < len(parent):
            del parent[key:]                                     # fewer [[landmarks]]
            return True
        return False
    if how == "value":
        path = draw(st.sampled_from(sorted(schema.values, key=str)))
        bad = draw(BAD[schema.values[path]])
    elif how == "unknown":
        where = draw(st.sampled_from(sorted(schema.tables, key=str)))
        path = (*where, draw(_key.filter(lambda k: k not in schema.tables[where])))
        bad = draw(_nested)
    else:
        path = draw(st.sampled_from([p for p in sorted(schema.tables, key=str) if p]))
        bad = draw(_not_a_table)
    parent, key = _get(doc, path[:-1]), path[-1]
    if isinstance(parent, dict) and isinstance(key, str) or (
            isinstance(parent, list) and isinstance(key, int) and key < len(parent)):
        parent[key] = bad
        return True
    return False


@st.composite
def broken(draw, schema: Schema) -> dict:
    """A copy of ``schema.doc`` broken one to three times."""
    doc = copy.deepcopy(schema.doc)
    assert _break(draw, schema, doc), "the schema names a place its document lacks"
    for _ in range(draw(st.integers(0, 2))):
        _break(draw, schema, doc)                # may find its place gone: then a no-op
    return doc


def _files(folder: Path) -> dict:
    return {p: p.stat().st_mtime_ns for p in folder.rglob("*")}


def _assert_one_config_error(read, path: Path, folder: Path) -> None:
    before = _files(folder)
    with pytest.raises(ConfigError) as info:
        read(path)
    message = str(info.value)
    assert path.name in message and "\n" not in message, message
    assert _files(folder) == before                 # nothing written


# --------------------------------------------------------------------------- georeg
_GEOMETRY = {"kind": "plate_with_hole", "length_mm": 100.0, "width_mm": 50.0,
             "hole_radius_mm": 14.0, "elements": 300}
_METHOD = {"name": "georeg", "levels": 3, "start_levels": 3, "scales": 3,
           "tikhonov_length_mm": [5.0, 10.0], "calibrate": True, "keep_stereo": True,
           "coupling": "joint", "normalisation": "element", "max_fixed_point": 10, "prefilter_px": 0.5,
           "edge_margin_px": 2.0}
_TOP_KEYS = {"images", "cameras", "landmarks", "geometry", "method", "output"}
_COMMON_VALUES = {
    ("images", "cam0"): "path", ("images", "cam1"): "path",
    ("geometry", "kind"): _enum(GEOMETRY_KINDS), ("geometry", "length_mm"): "positive",
    ("geometry", "width_mm"): "positive", ("geometry", "hole_radius_mm"): "positive",
    ("geometry", "elements"): "count",
    ("method", "name"): _enum(METHOD_NAMES), ("method", "levels"): "count_or_auto",
    ("method", "start_levels"): "count", ("method", "prefilter_px"): "non_negative",
    ("method", "edge_margin_px"): "non_negative",
    ("method", "scales"): "count", ("method", "tikhonov_length_mm"): "positives_or_auto",
    ("method", "calibrate"): "boolean", ("method", "keep_stereo"): "boolean",
    ("method", "coupling"): _enum(COUPLINGS),
    ("method", "normalisation"): _enum(NORMALISATIONS), ("method", "max_fixed_point"): "count",
    ("output", "dir"): "string"}
_COMMON_REQUIRED = [("images",), ("images", "cam0"), ("images", "cam1"), ("cameras",),
                    ("geometry",), ("geometry", "kind"), ("geometry", "length_mm"),
                    ("geometry", "width_mm"), ("geometry", "hole_radius_mm")]
_COMMON_TABLES = {(): _TOP_KEYS, ("images",): {"cam0", "cam1"},
                  ("cameras",): {"file", "pyvale_csv", "landmarks"},
                  ("geometry",): set(_GEOMETRY) | {"file"}, ("method",): set(_METHOD),
                  ("output",): {"dir"}}

GEOREG_JSON_CAMERAS = Schema(
    {"images": {"cam0": "left.tif", "cam1": "right.tif"}, "cameras": {"file": "cameras.json"},
     "geometry": _GEOMETRY, "method": _METHOD, "output": {"dir": "out"}},
    {**_COMMON_VALUES, ("cameras", "file"): "path", ("cameras", "pyvale_csv"): "path"},
    _COMMON_REQUIRED + [("cameras", "file")], _COMMON_TABLES)

_LANDMARK = {"xyz_mm": [0.0, 0.0, 0.0], "cam0_px": [10.0, 20.0], "cam1_px": [12.0, 21.0]}
GEOREG_PYVALE = Schema(
    {"images": {"cam0": "left.tif", "cam1": "right.tif"}, "cameras": {"pyvale_csv": "calib.csv"},
     "landmarks": [dict(_LANDMARK) for _ in range(4)], "geometry": _GEOMETRY, "method": _METHOD,
     "output": {"dir": "out"}},
    {**_COMMON_VALUES, ("cameras", "pyvale_csv"): "path", ("cameras", "file"): "path",
     **{("landmarks", i, key): kind for i in range(4)
        for key, kind in (("xyz_mm", "vector3"), ("cam0_px", "vector2"), ("cam1_px", "vector2"))}},
    _COMMON_REQUIRED + [("cameras", "pyvale_csv"), ("landmarks",), ("landmarks", 3)]
    + [("landmarks", i, key) for i in range(4) for key in _LANDMARK],
    {**_COMMON_TABLES, **{("landmarks", i): set(_LANDMARK) for i in range(4)}})


def _georeg_folder(tmp_path: Path) -> Path:
    for name in ("left.tif", "right.tif", "cameras.json", "calib.csv"):
        (tmp_path / name).write_bytes(b"x")
    return tmp_path


@pytest.mark.parametrize("schema", [GEOREG_JSON_CAMERAS, GEOREG_PYVALE], ids=["json", "pyvale"])
def test_the_valid_documents_load(tmp_path, schema):
    path = _georeg_folder(tmp_path) / "config.toml"
    path.write_text(_toml(schema.doc))
    config = load_config(path)
    assert config.geometry.hole_radius_mm == 14.0 and config.method.tikhonov_length_mm == (5.0, 10.0)
    assert len(config.cameras.landmarks) == (4 if "landmarks" in schema.doc else 0)


@pytest.mark.slow
@pytest.mark.parametrize("schema", [GEOREG_JSON_CAMERAS, GEOREG_PYVALE], ids=["json", "pyvale"])
@FUZZ
@given(data=st.data())
def test_broken_georeg_config_is_one_config_error(tmp_path, schema, data):
    path = _georeg_folder(tmp_path) / "config.toml"
    path.write_text(_toml(data.draw(broken(schema))))
    _assert_one_config_error(load_config, path, tmp_path)


@FUZZ
@given(data=st.one_of(st.binary(max_size=200), _text.map(str.encode),
                      st.sampled_from([b"[images", b"= 1", b"a = [1, 2", b"\xff\xfe", b""])))
def test_any_bytes_give_a_config_error(tmp_path, data):
    path = _georeg_folder(tmp_path) / "config.toml"
    path.write_bytes(data)
    _assert_one_config_error(load_config, path, tmp_path)


# --------------------------------------------------------------------------- the example
SPECIMEN = Schema(
    {"images": {"cam0": "cam0.png", "cam1": "cam1.png"}, "cameras": {"pyvale_csv": "calib.csv"},
     "landmarks": [dict(_LANDMARK) for _ in range(4)],
     "features": [{"name": "block", "kind": "box",
                   "footprint_mm": [[0.0, 0.0], [9.0, 0.0], [9.0, 9.0], [0.0, 9.0]],
                   "height_mm": 6.0}]},
    {("images", "cam0"): "path", ("images", "cam1"): "path", ("cameras", "pyvale_csv"): "path",
     **{("landmarks", i, key): kind for i in range(4)
        for key, kind in (("xyz_mm", "vector3"), ("cam0_px", "vector2"), ("cam1_px", "vector2"))},
     ("features", 0, "name"): "string",
     ("features", 0, "kind"): _enum(challenge_config.FEATURE_KINDS),
     ("features", 0, "footprint_mm"): "corners2", ("features", 0, "height_mm"): "positive",
     ("features", 0, "half_width_mm"): "positive", ("features", 0, "radius_mm"): "positive",
     ("features", 0, "line_mm"): "segment"},
    [("images",), ("images", "cam0"), ("images", "cam1"), ("cameras",), ("cameras", "pyvale_csv"),
     ("landmarks",), ("landmarks", 3), ("features",), ("features", 0, "name"),
     ("features", 0, "kind"), ("features", 0, "footprint_mm"), ("features", 0, "height_mm")]
    + [("landmarks", i, key) for i in range(4) for key in _LANDMARK],
    {(): {"images", "cameras", "landmarks", "features"}, ("images",): {"cam0", "cam1"},
     ("cameras",): {"pyvale_csv"}, **{("landmarks", i): set(_LANDMARK) for i in range(4)},
     ("features", 0): {"name", "kind", "footprint_mm", "height_mm", "line_mm", "half_width_mm",
                       "radius_mm"}})

_BAR = {"name": "block", "axis_mm": [[0.0, 4.0, -0.2], [9.0, 4.0, -0.2]], "radius_mm": 6.0,
        "arc_deg": 80.0}
_BASE = {"corners_mm": [[0.0, 0.0, 0.0], [9.0, 0.0, 0.0], [9.0, 9.0, 0.0], [0.0, 9.0, 0.0]],
         "holes": ["block"], "hole_margin_mm": 1.0,
         "flatness_polygon_mm": [[0.0, 0.0], [9.0, 0.0], [9.0, 9.0]], "ring_feature": "block",
         "ring_mm": [1.5, 6.0]}
ANALYSIS = Schema(
    {"specimen": "specimen.toml", "base": _BASE,
     "block_top": {"corners_mm": [[1.0, 1.0, 6.0], [8.0, 1.0, 6.0], [8.0, 8.0, 6.0], [1.0, 8.0, 6.0]]},
     "bars": [_BAR]},
    {("specimen",): "path", ("base", "corners_mm"): "corners3", ("base", "holes"): "names",
     ("base", "hole_margin_mm"): "number", ("base", "flatness_polygon_mm"): "polygon",
     ("base", "ring_feature"): "feature", ("base", "ring_mm"): "number_pair",
     ("block_top", "corners_mm"): "corners3",
     ("bars", 0, "name"): "feature", ("bars", 0, "axis_mm"): "segment",
     ("bars", 0, "radius_mm"): "positive", ("bars", 0, "arc_deg"): "positive"},
    [("specimen",), ("base",), ("base", "corners_mm"), ("block_top",), ("block_top", "corners_mm"),
     ("bars", 0, "name"), ("bars", 0, "axis_mm"), ("bars", 0, "radius_mm"), ("bars", 0, "arc_deg")],
    {(): {"specimen", "base", "block_top", "bars"}, ("base",): set(_BASE), ("block_top",): {"corners_mm"},
     ("bars", 0): set(_BAR)})


def _example_folder(tmp_path: Path, analysis: dict, specimen: dict) -> Path:
    for name in ("cam0.png", "cam1.png", "calib.csv"):
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "specimen.toml").write_text(_toml(specimen))
    (tmp_path / "analysis.toml").write_text(_toml(analysis))
    return tmp_path / "analysis.toml"


def test_the_valid_example_documents_load(tmp_path):
    analysis = challenge_config.load_analysis(_example_folder(tmp_path, ANALYSIS.doc, SPECIMEN.doc))
    assert analysis.bars[0].radius_mm == 6.0 and analysis.specimen.feature("block").height_mm == 6.0
    assert challenge_config.ConfigError is ConfigError          # one validation machinery


@pytest.mark.slow
@FUZZ
@given(doc=broken(ANALYSIS))
def test_broken_example_analysis_file_is_one_config_error(tmp_path, doc):
    path = _example_folder(tmp_path, doc, SPECIMEN.doc)
    _assert_one_config_error(challenge_config.load_analysis, path, tmp_path)


@FUZZ
@given(doc=broken(SPECIMEN))
def test_broken_example_specimen_file_is_one_config_error(tmp_path, doc):
    path = _example_folder(tmp_path, ANALYSIS.doc, doc)
    _assert_one_config_error(lambda p: challenge_config.load_analysis(p.parent / "analysis.toml"),
                             path.parent / "specimen.toml", tmp_path)
