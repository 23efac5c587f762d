"""The committed CAD of the Stereo DIC Challenge specimen (data/dic_challenge_stereo/specimen.step).

Read back with OpenCASCADE (skipped without it): the 16 named faces in order, each face's
area against the hand formula from the features of specimen.toml, the cylinders' radii
and the prisms' slopes at points sampled on the faces, the base's footprints trimmed out
(points classified against the face), and the file is what make_specimen_cad.py builds.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OCP")

ROOT = Path(__file__).resolve().parents[2]
HERE = ROOT / "examples" / "dic_challenge"
sys.path.insert(0, str(HERE))

import make_specimen_cad as cad                                      # noqa: E402
from challenge.config import load_analysis                          # noqa: E402

STEP = ROOT / "data" / "dic_challenge_stereo" / "specimen.step"
ANALYSIS = load_analysis(HERE / "analysis.toml")
SPECIMEN = ANALYSIS.specimen
HEIGHT = float(np.mean(ANALYSIS.block_top_mm[:, 2]))


@pytest.fixture(scope="module")
def faces():
    return cad.read_step_faces(STEP)


def test_the_file_holds_the_twelve_named_faces_in_order(faces):
    assert list(faces) == list(cad.FACE_NAMES)
    assert STEP.stat().st_size < 100_000


def test_each_face_area_matches_the_hand_formula(faces):
    expected = cad.expected_areas(SPECIMEN.features, HEIGHT)
    for name, face in faces.items():
        assert cad.face_area(face) == pytest.approx(expected[name], rel=1e-9), name


def test_surfaces_lie_where_the_features_put_them(faces):
    base = cad.face_points(faces["base"])
    top = cad.face_points(faces["block_top"])
    np.testing.assert_allclose(base[:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(top[:, 2], HEIGHT, atol=1e-9)
    for f in SPECIMEN.features:
        line = np.asarray(f.line_mm) if f.line_mm is not None else None
        if f.kind == "half_cylinder":
            P = cad.face_points(faces[f.name])                   # the crest face
            assert len(P) > 20
            np.testing.assert_allclose(cad.distance_to_line(P, line), f.radius_mm, atol=1e-7)
            crest = line[0, 2] + f.radius_mm                     # sampled within the 0.05 mm deflection
            assert crest - 0.05 < P[:, 2].max() <= crest + 1e-9
            low = line[0, 2] + f.radius_mm * np.cos(np.radians(cad.CREST_DEG))
            assert P[:, 2].min() == pytest.approx(low, abs=1e-7)          # +-40 deg about the top
            for side in ("a", "b"):
                F = cad.face_points(faces[f"{f.name}_flank_{side}"])
                np.testing.assert_allclose(cad.distance_to_line(F, line), f.radius_mm, atol=1e-7)
                assert F[:, 2].min() == pytest.approx(0.0, abs=1e-7)      # down to the plate
                assert F[:, 2].max() == pytest.approx(low, abs=1e-7)
        elif f.kind == "wedge":
            ridge = line.copy()
            for side in [n for n in cad.FACE_NAMES if n.startswith(f.name)]:
                P = cad.face_points(faces[side])
                # horizontal distance to the ridge d: height 6.9 (1 - d / half width)
                flat = np.c_[P[:, :2], np.full(len(P), ridge[0, 2])]
                d = cad.distance_to_line(flat, ridge)
                np.testing.assert_allclose(P[:, 2], ridge[0, 2] * (1 - d / f.half_width_mm), atol=1e-7)


def test_base_has_the_footprints_trimmed_out(faces):
    from OCP.BRepClass import BRepClass_FaceClassifier
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_IN, TopAbs_OUT, TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.gp import gp_Pnt

    def state(x, y):
        return BRepClass_FaceClassifier(faces["base"], gp_Pnt(x, y, 0.0), 1e-7).State()

    wires = 0
    explorer = TopExp_Explorer(faces["base"], TopAbs_WIRE)
    while explorer.More():
        wires, _ = wires + 1, explorer.Next()
    assert wires == 1 + len(SPECIMEN.features)                 # outer + one per footprint
    assert BRepTools.OuterWire_s(faces["base"]) is not None
    for f in SPECIMEN.features:
        centre = (np.mean(f.footprint_mm, axis=0) if f.kind == "box"
                  else np.mean(np.asarray(f.line_mm)[:, :2], axis=0))
        assert state(*centre) == TopAbs_OUT, f.name
    for x, y in [(0.0, 0.0), (45.0, -45.0), (-45.0, 27.0), (28.0, 40.0)]:   # landmarks on the plate
        assert state(x, y) == TopAbs_IN
    assert state(0.0, 51.0) == TopAbs_OUT                       # off the 101.6 mm plate


def test_the_committed_file_is_what_the_script_builds(tmp_path):
    out = tmp_path / "specimen.step"
    cad.build(out)
    assert out.read_bytes() == STEP.read_bytes()
