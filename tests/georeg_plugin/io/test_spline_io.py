"""spline_io: JSON and IGES 5.3 (entity 128) round trips and the fixed-column layout."""
import json
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from georeg_plugin.io.spline_io import (read_iges, read_scalar_field, read_spline_json, write_iges,
                                        write_spline_json)
from georeg_plugin.spline.patch import SplinePatch


def _quarter_cylinder(rational=True, seed=0):
    """Degree 2 (u, exact circular arc if rational) x degree 3 (v) patch, perturbed."""
    rng = np.random.default_rng(seed)
    r = 14.0
    arc = np.array([[r, 0.0], [r, r], [0.0, r]])
    v = np.linspace(0.0, 30.0, 5)
    cp = np.zeros((3, 5, 3))
    cp[:, :, :2] = arc[:, None, :]
    cp[:, :, 2] = v[None, :]
    cp += rng.normal(scale=0.1, size=cp.shape)
    w = np.array([1.0, np.sqrt(0.5), 1.0])[:, None] * np.ones((1, 5)) if rational else None
    return SplinePatch(degrees=(2, 3),
                       knots=(np.array([0, 0, 0, 1, 1, 1.0]),
                              np.array([0, 0, 0, 0, 0.37, 1, 1, 1, 1.0])),
                       control_points=cp, weights=w)


def _random_uv(n, seed=1):
    return np.random.default_rng(seed).uniform(0.0, 1.0, size=(n, 2))


@pytest.mark.parametrize("rational", [True, False])
def test_json_round_trip_is_exact(tmp_path, rational):
    patch = _quarter_cylinder(rational)
    field = np.arange(15.0).reshape(3, 5) / 7.0
    path = tmp_path / "shape.json"
    write_spline_json(path, patch, scalar_field=field)
    back = read_spline_json(path)
    assert back.degrees == patch.degrees
    for a, b in zip(back.knots, patch.knots):
        assert_array_equal(a, b)
    assert_array_equal(back.control_points, patch.control_points)
    if rational:
        assert_array_equal(back.weights, patch.weights)
    else:
        assert back.weights is None
    assert_array_equal(read_scalar_field(path), field)
    doc = json.loads(path.read_text())
    assert doc["format"] == "georeg-spline" and doc["version"] == 1
    assert np.shape(doc["control_points"]) == (3, 5, 3)
    assert not list(tmp_path.glob(".*tmp"))  # atomic write left no temporary file


def test_json_errors_name_the_file_and_field(tmp_path):
    path = tmp_path / "bad.json"
    write_spline_json(path, _quarter_cylinder(rational=False))
    doc = json.loads(path.read_text())
    doc["control_points"] = doc["control_points"][:2]  # no longer matches the knots
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"bad\.json.*control_points"):
        read_spline_json(path)
    doc["format"] = "other"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"bad\.json.*format"):
        read_spline_json(path)
    with pytest.raises(FileNotFoundError, match="missing.json"):
        read_spline_json(tmp_path / "missing.json")
    with pytest.raises(ValueError, match="scalar_field"):
        write_spline_json(path, _quarter_cylinder(), scalar_field=np.ones(4))


@pytest.mark.parametrize("rational", [True, False])
def test_iges_round_trip_same_surface(tmp_path, rational):
    patch = _quarter_cylinder(rational)
    path = tmp_path / "shape.igs"
    write_iges(path, patch)
    back = read_iges(path)
    uv = _random_uv(500)
    assert_allclose(back.evaluate(uv), patch.evaluate(uv), rtol=0, atol=1e-9)
    assert back.degrees == patch.degrees
    assert back.is_rational == rational


def test_iges_fixed_column_layout(tmp_path):
    patch = _quarter_cylinder()
    path = tmp_path / "layout.igs"
    write_iges(path, patch)
    lines = path.read_text(encoding="ascii").split("\n")
    assert lines[-1] == ""
    lines = lines[:-1]
    assert all(len(line) == 80 for line in lines)
    letters = "".join(line[72] for line in lines)
    assert re.fullmatch(r"S+G+D+P+T", letters), letters
    for letter in "SGDPT":
        seq = [int(line[73:80]) for line in lines if line[72] == letter]
        assert seq == list(range(1, len(seq) + 1)), letter
    sec = {c: [line for line in lines if line[72] == c] for c in "SGDPT"}
    # Terminate: counts of each section in 8-column fields
    t = sec["T"][0]
    assert [t[i * 8] for i in range(4)] == list("SGDP")
    assert [int(t[i * 8 + 1:i * 8 + 8]) for i in range(4)] == \
        [len(sec[c]) for c in "SGDP"]
    # Global: delimiters, units mm (flag 2, name MM), IGES 5.3 version flag 11
    g = "".join(line[:72] for line in sec["G"])
    assert g.startswith("1H,,1H;,")
    fields = g.rstrip().rstrip(";").split(",")
    assert fields[14] == "2" and fields[15] == "2HMM"  # (offset 1 for the '1H,' split)
    assert g.rstrip().endswith(";")
    # Directory entry: two lines of 8-column right-justified fields
    d1, d2 = sec["D"]
    assert int(d1[0:8]) == 128 and int(d2[0:8]) == 128
    assert all(re.fullmatch(r" *\d+", d1[i:i + 8]) for i in range(0, 64, 8))
    pointer, count = int(d1[8:16]), int(d2[24:32])
    assert pointer == 1 and count == len(sec["P"])
    assert int(d1[48:56]) == 0  # no transformation matrix
    de_sequence = int(d1[73:80])
    # Parameter data: data in 1-64, the D pointer in 65-72 on every line
    assert all(int(line[64:72]) == de_sequence for line in sec["P"])
    data = "".join(line[:64] for line in sec["P"])
    assert data.startswith("128,") and data.rstrip().endswith(";")
    values = [v.strip() for v in data.rstrip().rstrip(";").split(",")]
    nu, nv = patch.shape
    (p, q), n_knots = patch.degrees, [len(k) for k in patch.knots]
    assert [int(v) for v in values[:10]] == [128, nu - 1, nv - 1, p, q, 0, 0, 0, 0, 0]
    assert len(values) == 10 + sum(n_knots) + 4 * nu * nv + 4
    # every number parses as an IGES real/integer and no token is split across lines
    assert all(re.fullmatch(r"-?\d+(\.\d*)?(E-?\d+)?", v) for v in values), values
    for line in sec["P"]:
        assert line[:64].rstrip()[-1] in ",;"


def test_iges_reader_converts_units_and_rejects_bad_files(tmp_path):
    patch = _quarter_cylinder()
    path = tmp_path / "inch.igs"
    write_iges(path, patch)
    text = path.read_text()
    text = text.replace(",2,2HMM,", ",1,2HIN,")  # same numbers, now in inches
    path.write_text(text)
    back = read_iges(path)
    assert_allclose(back.control_points, 25.4 * patch.control_points, rtol=1e-14)
    with pytest.raises(FileNotFoundError, match="nothing.igs"):
        read_iges(tmp_path / "nothing.igs")
    bad = tmp_path / "bad.igs"
    bad.write_text("not an iges file\n")
    with pytest.raises(ValueError, match="bad.igs"):
        read_iges(bad)
    with pytest.raises(ValueError, match="entity index 1"):
        read_iges(path, entity=1)


def test_iges_read_by_independent_reader_pyiges(tmp_path):
    pyiges = pytest.importorskip("pyiges")
    patch = _quarter_cylinder()
    path = tmp_path / "shape.igs"
    write_iges(path, patch)
    surfaces = pyiges.read(str(path)).bspline_surfaces()
    assert len(surfaces) == 1
    s = surfaces[0]
    nu, nv = patch.shape
    assert (s.k1, s.k2, s.m1, s.m2) == (nu - 1, nv - 1, 2, 3)
    assert_allclose(s.knot1, patch.knots[0], rtol=0, atol=0)
    assert_allclose(s.knot2, patch.knots[1], rtol=0, atol=0)
    assert_allclose(s.weights, patch.weights.ravel(order="F"), rtol=1e-15)
    assert_allclose(s.control_points(),
                    patch.control_points.transpose(1, 0, 2).reshape(-1, 3), rtol=1e-15)


def test_written_files_have_a_new_files_permissions_without_touching_the_umask(tmp_path,
                                                                               monkeypatch):
    import os
    import stat
    real_umask = os.umask
    old = real_umask(0o027)
    calls = []
    monkeypatch.setattr(os, "umask", lambda mask: calls.append(mask) or real_umask(mask))
    try:
        write_spline_json(tmp_path / "s.json", _quarter_cylinder())
        write_iges(tmp_path / "s.igs", _quarter_cylinder())
    finally:
        real_umask(old)
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in tmp_path.iterdir()}
    assert modes == {"s.json": 0o640, "s.igs": 0o640}             # 0666 less umask, no leftovers
    assert calls == []


def test_spline_json_carries_the_std_of_the_control_values(tmp_path):
    """scalar_field_std (the measured control values' standard deviation) is written beside
    scalar_field, one value per control point; a wrong size is refused, naming the field."""
    import json
    from georeg_plugin.io.spline_io import write_spline_json
    from georeg_plugin.spline.geometries import rectangle
    patch = rectangle(60.0, 40.0)
    n = int(np.prod(patch.control_points.shape[:2]))
    path = tmp_path / "s.json"
    write_spline_json(path, patch, scalar_field=np.arange(n, dtype=float),
                      scalar_field_std=np.full(n, 0.002))
    doc = json.loads(path.read_text())
    assert np.allclose(doc["scalar_field_std"], 0.002) and np.size(doc["scalar_field_std"]) == n
    with pytest.raises(ValueError, match="scalar_field_std has 2 values"):
        write_spline_json(path, patch, scalar_field_std=np.ones(2))
