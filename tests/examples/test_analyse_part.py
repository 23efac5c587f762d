"""examples/dic_challenge/analyse_part.py on exact shapes of known dimensions.

A "measured" specimen is written as one Q9 VTU with cell data ``face`` (the output layout of
``georeg measure``), tilted and shifted off the base plane by a rigid motion: the figures
must come back as the dimensions the shapes were made with (block height, radii, crest
heights, a flat plate, the prisms' angle). ``--out`` writes the report's files, all or none.
"""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parents[2] / "examples" / "dic_challenge"
sys.path.insert(0, str(HERE))

import analyse_part                                                  # noqa: E402
from challenge.config import ConfigError, load_analysis             # noqa: E402
from fesdic_core.fe.mesh import SurfaceMesh, rectangle_mesh            # noqa: E402
from fesdic_core.fe.mesh_io import write_mesh                          # noqa: E402

HEIGHT_MM = 6.30                                 # block top above the plate
RADII_MM = {"cylinder_h": 6.25, "cylinder_v": 6.20}
AXIS_Z_MM = -0.10                                # axes below the plate: crests at r - 0.10


def _grid(u, v, nu, nv):
    """Q9 mesh of the parameter box u x v (nodes' x, y = parameters, z = 0)."""
    m = rectangle_mesh(u[1] - u[0], v[1] - v[0], nu, nv, "Q9", center=(np.mean(u), np.mean(v)))
    return m


ANALYSIS = load_analysis(HERE / "analysis.toml")


def exact_faces() -> dict:
    """name -> Q9 mesh of the exact face (world frame: plate z = 0)."""
    faces = {"base": _grid((-49.0, 49.0), (-49.0, 49.0), 40, 40)}
    top = np.asarray(ANALYSIS.block_top_mm)
    m = _grid((top[:, 0].min(), top[:, 0].max()), (top[:, 1].min(), top[:, 1].max()), 8, 8)
    faces["block_top"] = m.with_nodes(m.nodes + [0.0, 0.0, HEIGHT_MM])
    for name, r in RADII_MM.items():
        line = np.asarray(next(b for b in ANALYSIS.bars if b.name == name).axis_mm, float)
        axis = line[1] - line[0]
        length = np.linalg.norm(axis)
        axis /= length
        lateral = np.cross(axis, [0.0, 0.0, 1.0])
        lateral /= np.linalg.norm(lateral)
        m = _grid((-np.radians(45.0), np.radians(45.0)), (0.0, length), 16, 16)
        a, s = m.nodes[:, 0], m.nodes[:, 1]
        start = np.r_[line[0, :2], AXIS_Z_MM]
        X = start + s[:, None] * axis + r * (np.sin(a)[:, None] * lateral + np.cos(a)[:, None] * [0, 0, 1.0])
        faces[name] = m.with_nodes(X)
    for f in (f for f in ANALYSIS.specimen.features if f.kind == "wedge"):      # the nominal prisms
        line = np.asarray(f.line_mm, float)
        axis = line[1] - line[0]
        lateral = np.cross(axis, [0.0, 0.0, 1.0])
        lateral /= np.linalg.norm(lateral)
        for side, sign in (("a", 1.0), ("b", -1.0)):
            m = _grid((0.0, 1.0), (0.0, 1.0), 4, 8)
            w, s = m.nodes[:, 0], m.nodes[:, 1]          # down the slope, along the ridge
            foot = sign * f.half_width_mm * lateral - [0.0, 0.0, line[0, 2]]
            faces[f"{f.name}_{side}"] = m.with_nodes(line[0] + s[:, None] * axis + w[:, None] * foot)
    return faces


def _moved(X):
    """A rigid motion off the base plane (0.5 degree tilt about a skew axis, 0.3 mm shift)."""
    k = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    t = np.radians(0.5)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K
    return X @ R.T + [0.3, -0.2, 0.25]


def write_part(folder: Path, faces: dict) -> Path:
    names = list(faces)
    nodes, conn, face = [], [], []
    offset = 0
    for k, name in enumerate(names):
        m = faces[name]
        nodes.append(m.nodes)
        conn.append(m.blocks[0].connectivity + offset)
        face.append(np.full(m.n_elements, k))
        offset += m.n_nodes
    family = faces[names[0]].blocks[0].family
    from fesdic_core.fe.mesh import CellBlock
    mesh = SurfaceMesh(_moved(np.concatenate(nodes)), (CellBlock(family, np.concatenate(conn)),))
    write_mesh(folder / "georeg.vtu", mesh, cell_data={"face": np.concatenate(face).astype(np.int32)})
    (folder / "summary.json").write_text(json.dumps({"methods": [
        {"name": "georeg", "status": "ok", "mesh_file": "georeg.vtu", "time_s": 1.0}]}))
    config = folder / "part.toml"
    config.write_text("[geometry]\nfaces = [" + ", ".join(f'"{n}"' for n in names) + "]\n")
    return config


def _check(figures):
    assert figures["block"]["height_mm"] == pytest.approx(HEIGHT_MM, abs=1e-5)
    assert figures["block"]["top_rms_plane_um"] < 1e-3
    assert figures["base"]["plane_rms_um"] < 1e-3
    for name, r in RADII_MM.items():
        assert figures[name]["radius_mm"] == pytest.approx(r, abs=1e-5), name
        assert figures[name]["crest_above_ring_mm"] == pytest.approx(r + AXIS_Z_MM, abs=1e-5), name
        assert figures[name]["fit_rms_um"] < 0.1
    for name in ("prism_h", "prism_v"):
        prism = figures["prisms"][name]
        assert prism["included_angle_deg"] == pytest.approx(prism["nominal_angle_deg"], abs=1e-6)
        assert prism["nominal_angle_deg"] == pytest.approx(2 * np.degrees(np.arctan(6.4 / 6.9)), abs=1e-9)
        assert max(prism["rms_plane_um"].values()) < 1e-3
        ridge = ANALYSIS.specimen.feature(name).line_mm[0][2]          # 6.9 mm, the ridge line's z
        assert prism["ridge_height_mm"] == pytest.approx(ridge, abs=1e-5)


def test_part_vtu_gives_the_exact_dimensions(tmp_path, capsys):
    config = write_part(tmp_path, exact_faces())
    out = tmp_path / "figures.json"
    assert analyse_part.main([str(tmp_path), "--config", str(config), "--json", str(out)]) == 0
    _check(json.loads(out.read_text()))
    assert "block height above the plate ring" in capsys.readouterr().out


@pytest.mark.slow
def test_report_folder_holds_the_figures_and_the_targets(tmp_path, capsys):
    """--out: summary.json (the same figures as --json), the PNGs and report.html; the targets
    printed. The exact block is 6.30 mm high: 0.06 mm off the laser's 6.36 mm, a FAIL."""
    config = write_part(tmp_path, exact_faces())
    report = tmp_path / "report"
    assert analyse_part.main([str(tmp_path), "--config", str(config), "--out", str(report)]) == 0
    names = sorted(p.name for p in report.iterdir())
    assert names == ["cylinder_profiles.png", "overview.png", "report.html", "shape_maps.png", "summary.json"]
    summary = json.loads((report / "summary.json").read_text())
    _check(summary)
    targets = {t["claim"]: t["passed"] for t in summary["targets"]}
    assert targets["block height within 0.03 mm of 6.36 mm"] is False
    assert targets["base plate: RMS to the best-fit quadric < 3.6 um (pyvale)"] is True
    assert targets["the part measured in < 300 s"] is None           # not the specimen's images
    out = capsys.readouterr().out
    assert "FAIL  block height within 0.03 mm of 6.36 mm: 6.3000 mm" in out
    page = (report / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 3 and "6.3000" in page


def test_bad_analysis_config_is_one_line_naming_file_and_key(tmp_path, capsys):
    config = write_part(tmp_path, exact_faces())
    text = (HERE / "analysis.toml").read_text().replace('specimen = "specimen.toml"',
                                                       f'specimen = "{HERE / "specimen.toml"}"')
    bad = tmp_path / "analysis.toml"
    for broken, words in ((text.replace("arc_deg = 80.0", "arc_deg = 80.0\narc_dgr = 2", 1),
                           r"analysis.toml: \[\[bars\]\]\[0\] arc_dgr: unknown key \(did you mean arc_deg"),
                          (text.replace('name = "cylinder_h"', 'name = "cylinder_x"'),
                           r"analysis.toml: \[\[bars\]\]\[0\] name: no \[\[features\]\] named 'cylinder_x'"),
                          (text.replace('ring_feature = "block"', "ring_feature = 3"),
                           r"analysis.toml: \[base\] ring_feature"),
                          (text.replace("[block_top]", "[block_tops]"), r"analysis.toml: .*block_top")):
        bad.write_text(broken)
        with pytest.raises(ConfigError, match=words):
            load_analysis(bad)
        assert analyse_part.main([str(tmp_path), "--config", str(config), "--analysis", str(bad),
                                  "--out", str(tmp_path / "report")]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("analyse_part.py: error: ") and "analysis.toml" in err[0], err
        assert not (tmp_path / "report").exists()


def test_missing_face_data_is_an_error_naming_the_file(tmp_path, capsys):
    config = write_part(tmp_path, exact_faces())
    m = exact_faces()["block_top"]
    write_mesh(tmp_path / "georeg.vtu", m)                       # no cell data `face`
    assert analyse_part.main([str(tmp_path), "--config", str(config), "--out", str(tmp_path / "report")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "georeg.vtu" in err[0] and "face" in err[0], err
    assert not (tmp_path / "report").exists()
