"""The `cad` extra: STEP and trimmed/analytic IGES read through OpenCASCADE.

The reference files (tests/data/cad, written by OpenCASCADE's own STEP and IGES writers with
make_reference_cad.py, not by our writer): a box with a filleted edge, a solid cylinder, a
plate with a round hole. The NURBS faces must lie on the true analytic surfaces, point
outwards, and their trimming loops must map onto the true edges.
"""
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OCP")

from georeg_app.inputs import cad                                      # noqa: E402
from georeg_app.inputs.cad import (cad_faces, cad_model, cad_part, cad_triangles,  # noqa: E402
                            read_cad_faces)
from georeg_plugin.spline.geometries import cylinder                    # noqa: E402
from georeg_plugin.io.iges import read_iges_surfaces                # noqa: E402
from georeg_plugin.io.spline_io import write_iges                   # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "data" / "cad"
PLATE_AREA = 60.0 * 40.0 - np.pi * 8.0 ** 2


def _grid(patch, n=9):
    lo, hi = patch.bounds
    s = np.linspace(0, 1, n)
    U, V = np.meshgrid(lo[0] + s * (hi[0] - lo[0]), lo[1] + s * (hi[1] - lo[1]), indexing="ij")
    return np.column_stack([U.ravel(), V.ravel()])


def _areas(tri):
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


@pytest.mark.parametrize("suffix", [".step", ".igs"])
def test_cylinder_faces_lie_on_the_cylinder_and_its_discs_and_point_outwards(suffix):
    faces = read_cad_faces(DATA / f"cylinder{suffix}")
    assert len(faces) == 3
    lateral = [f for f in faces if f.patch.is_rational]
    assert len(lateral) == 1 and not lateral[0].trimmed
    uv = _grid(lateral[0].patch)
    x = lateral[0].patch.evaluate(uv)
    np.testing.assert_allclose(np.hypot(x[:, 0], x[:, 1]), 10.0, atol=1e-6)
    assert x[:, 2].min() == pytest.approx(0, abs=1e-9) and x[:, 2].max() == pytest.approx(20)
    n = lateral[0].patch.normals(uv[(uv[:, 0] > 0) & (uv[:, 0] < uv[:, 0].max())])
    x = lateral[0].patch.evaluate(uv[(uv[:, 0] > 0) & (uv[:, 0] < uv[:, 0].max())])
    np.testing.assert_allclose(n[:, :2], x[:, :2] / 10.0, atol=1e-6)   # radial, outwards
    discs = sorted((f for f in faces if not f.patch.is_rational),
                   key=lambda f: f.patch.evaluate(np.mean(f.patch.bounds, 0)[None])[0, 2])
    for disc, z in zip(discs, (0.0, 20.0)):
        assert disc.trimmed and len(disc.loops) == 1 and min(disc.patch.degrees) >= 2
        np.testing.assert_allclose(disc.patch.evaluate(_grid(disc.patch))[:, 2], z, atol=1e-9)
        np.testing.assert_allclose(disc.patch.normals(_grid(disc.patch, 3)),
                                   np.tile([0, 0, 1 if z else -1], (9, 1)), atol=1e-12)
        edge = disc.patch.evaluate(disc.loops[0])                # the loop: the rim circle
        np.testing.assert_allclose(np.hypot(edge[:, 0], edge[:, 1]), 10.0, atol=1e-6)


def test_box_with_fillet_has_seven_faces_on_their_planes_and_the_fillet_radius():
    faces = read_cad_faces(DATA / "box_fillet.step")
    assert len(faces) == 7
    fillet = [f for f in faces if f.patch.is_rational]
    assert len(fillet) == 1
    x = fillet[0].patch.evaluate(_grid(fillet[0].patch))
    np.testing.assert_allclose(np.hypot(x[:, 0] - 17.0, x[:, 1] - 7.0), 3.0, atol=1e-6)
    centre = np.array([10.0, 5.0, 4.0])
    for f in faces:
        uv = _grid(f.patch, 5)
        x, n = f.patch.evaluate(uv), f.patch.normals(uv)
        assert np.all(np.sum(n * (x - centre), axis=1) > 0), f.name          # outwards
        if not f.patch.is_rational:                          # a plane: one coordinate fixed
            axis = int(np.argmax(np.abs(n[0])))
            np.testing.assert_allclose(np.abs(n[:, axis]), 1.0, atol=1e-12)
            assert np.ptp(x[:, axis]) < 1e-9 and round(x[0, axis], 9) in (0, 8, 10, 20)


@pytest.mark.parametrize("suffix", [".step", ".igs"])
def test_plate_hole_loops_map_onto_the_rectangle_and_the_hole_circle(suffix):
    (face,) = read_cad_faces(DATA / f"plate_hole{suffix}")
    assert face.trimmed and len(face.loops) == 2
    outer, hole = (face.patch.evaluate(loop) for loop in face.loops)
    np.testing.assert_allclose(np.hypot(hole[:, 0], hole[:, 1]), 8.0, atol=1e-6)
    np.testing.assert_allclose(np.r_[outer[:, 2], hole[:, 2]], 0.0, atol=1e-12)
    on_side = np.isclose(np.abs(outer[:, 0]), 30) | np.isclose(np.abs(outer[:, 1]), 20)
    assert on_side.all() and np.abs(outer[:, :2]).max(0) == pytest.approx([30, 20])
    assert np.allclose(face.patch.normals(_grid(face.patch, 3)), [0, 0, 1])


def test_trimmed_plate_mesh_area_converges_to_plate_minus_hole():
    lost = []
    for elements in (256, 1024, 4096):
        model = cad_model(DATA / "plate_hole.step", None, elements, 2)
        assert model.is_part and model.face_names == ("face0",)
        x = model.mesh.nodes[model.mesh.blocks[0].connectivity[:, :4]]
        area = np.sum(np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 3] - x[:, 0]), axis=1))
        h = np.hypot(60, 40) / np.sqrt(elements)              # element diagonal
        lost.append(PLATE_AREA - area)
        assert 0 <= lost[-1] <= np.pi * ((8 + h) ** 2 - 8 ** 2)
        assert np.min(np.hypot(model.mesh.nodes[:, 0], model.mesh.nodes[:, 1])) >= 8 - 1e-9
    assert lost[0] > lost[1] > lost[2] > 0


@pytest.mark.parametrize("name, exact", [("plate_hole.step", PLATE_AREA),
                                         ("cylinder.step", 2 * np.pi * 10 * 20 + 2 * np.pi * 100),
                                         ("cylinder.igs", 2 * np.pi * 10 * 20 + 2 * np.pi * 100)])
def test_cad_triangles_cover_every_face_inside_its_loops(name, exact):
    deflection = 0.01
    tri = cad_triangles(DATA / name, deflection)
    assert tri.ndim == 3 and tri.shape[1:] == (3, 3)
    # chords deviate at most `deflection` from the curved edges: the rims' band bounds the error
    rims = 2 * np.pi * 8 if name.startswith("plate") else 2 * 2 * np.pi * 10 * 2
    assert abs(_areas(tri).sum() - exact) <= deflection * rims


def test_cad_triangles_of_an_untrimmed_iges_without_the_kernel(tmp_path, monkeypatch):
    """The base path (grid triangles), the same with the kernel hidden."""
    path = tmp_path / "panel.igs"
    write_iges(path, [cylinder(50.0, 30.0, 60.0)], names=["panel"])
    monkeypatch.setattr(cad, "kernel_available", lambda: False)
    area = _areas(cad_triangles(path)).sum()
    exact = 50.0 * np.radians(60.0) * 30.0
    step = np.radians(60.0) / 16                      # 16 cells per knot span: chords
    assert 0 < exact - area <= exact * step ** 2 / 20  # strip of width 2 R sin(step / 2)


def test_untrimmed_iges_keeps_the_base_reader(tmp_path):
    path = tmp_path / "panel.igs"
    write_iges(path, [cylinder(50.0, 30.0, 60.0)], names=["panel"])
    (surface,) = read_iges_surfaces(path)
    patches, names = cad_faces(path)
    assert names == ("panel",)
    np.testing.assert_array_equal(patches[0].control_points, surface.patch.control_points)
    np.testing.assert_array_equal(patches[0].weights, surface.patch.weights)


def test_step_face_names_are_read_and_selectable(tmp_path):
    text = (DATA / "plate_hole.step").read_text()
    assert text.count("ADVANCED_FACE(''") == 1
    path = tmp_path / "named.stp"
    path.write_text(text.replace("ADVANCED_FACE(''", "ADVANCED_FACE('top'"))
    (face,) = cad_part(path, ["top"])
    assert face.name == "top"
    with pytest.raises(ValueError, match=r"named\.stp: no face named 'lid'; its faces: 0 'top'"):
        cad_part(path, ["lid"])


def test_errors_name_the_file_and_the_missing_extra(tmp_path, monkeypatch):
    bad = tmp_path / "broken.step"
    bad.write_text("ISO-10303-21;\nnot a step file\n")
    with pytest.raises(ValueError, match=r"broken\.step: unreadable STEP file"):
        read_cad_faces(bad)
    with pytest.raises(ValueError, match=r"box_fillet\.step: face 9 is out of range "
                                         r"\(the file has 7: 0 'face0'"):
        cad_part(DATA / "box_fillet.step", [9])
    monkeypatch.setattr(cad, "kernel_available", lambda: False)
    with pytest.raises(ValueError, match=r"cylinder\.step: STEP files need a CAD kernel: "
                                         r"install the optional 'cad' extra"):
        read_cad_faces(DATA / "cylinder.step")
    with pytest.raises(ValueError, match=r"plate_hole\.igs: 1 surface\(s\) needs a CAD kernel.*"
                                         r"entity 144 trimmed surface.*install the optional "
                                         r"'cad' extra"):
        read_cad_faces(DATA / "plate_hole.igs")


def test_a_file_without_faces_is_named(tmp_path):
    """A STEP file holding only a wire (OpenCASCADE's writer): no face to measure."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
    from OCP.gp import gp_Pnt
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer
    writer = STEPControl_Writer()
    writer.Transfer(BRepBuilderAPI_MakeEdge(gp_Pnt(0, 0, 0), gp_Pnt(10, 0, 0)).Edge(),
                    STEPControl_AsIs)
    path = tmp_path / "wire.step"
    writer.Write(str(path))
    with pytest.raises(ValueError, match=r"wire\.step: no face \(surface\) in the file"):
        read_cad_faces(path)


@pytest.mark.slow
def test_the_whole_cylinder_is_one_part_with_trimmed_discs_and_glued_levels():
    """Three faces, one mesh: each face refined for elements of about one size (by its
    area), the discs (trimmed) keep their elements inside the rim, not welded to the lateral
    face there (the staircase); the spline levels build."""
    from adapters.fesdic_core import multilevel_for_mesh
    from georeg_app.inputs.cad import cad_part, face_refinements
    model = cad_model(DATA / "cylinder.step", None, 300, 2)
    counts = np.bincount(model.element_face)
    lateral = int(np.flatnonzero([f.is_rational for f in model.faces])[0])
    k = face_refinements(cad_part(DATA / "cylinder.step"), 300, 2)   # by area: 200 / 50 / 50
    assert k[lateral] == 4 and sorted(k) == [3, 3, 4]
    assert counts[lateral] == np.prod(model.faces[lateral].n_elements) * 4 ** 4
    connectivity = model.mesh.blocks[0].connectivity
    for f, face in enumerate(model.faces):
        x = model.mesh.nodes[np.unique(connectivity[model.element_face == f])]
        r = np.hypot(x[:, 0], x[:, 1])
        if f == lateral:
            np.testing.assert_allclose(r, 10.0, atol=1e-9)
            continue
        assert np.ptp(x[:, 2]) < 1e-9 and r.max() <= 10.0 + 1e-9
        corners = model.mesh.nodes[connectivity[model.element_face == f][:, :4]]
        area = np.sum(np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                              corners[:, 3] - corners[:, 0]), axis=1))
        h = 20.0 * np.sqrt(2) / 2 ** 3                            # element diagonal
        assert np.pi * (10 - h) ** 2 <= area < np.pi * 100
    space = multilevel_for_mesh(model, 2, None)
    assert len(space.operators) == 2
    assert all(op.shape[1] == model.mesh.nodes.shape[0] for op in space.operators)


@pytest.mark.parametrize("suffix", [".step", ".igs"])
def test_a_located_face_is_placed(tmp_path, monkeypatch, suffix):
    """The plate moved by a rotation about x and a translation (a TopLoc location written by
    OpenCASCADE): its NURBS and its hole land where the motion puts them."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt, gp_Trsf, gp_Vec
    monkeypatch.syspath_prepend(str(DATA))
    import make_reference_cad
    monkeypatch.setattr(make_reference_cad, "HERE", tmp_path)
    rotation, translation = gp_Trsf(), gp_Trsf()
    rotation.SetRotation(gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(1, 0, 0)), np.radians(30.0))
    translation.SetTranslation(gp_Vec(5.0, -2.0, 3.0))
    moved = BRepBuilderAPI_Transform(make_reference_cad.plate_hole(),
                                     translation.Multiplied(rotation), False).Shape()
    make_reference_cad.write(moved, "plate")
    (face,) = read_cad_faces(tmp_path / f"plate{suffix}")
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    hole = face.patch.evaluate(face.loops[1]) - [5.0, -2.0, 3.0]
    local = hole @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]]).T     # undo the rotation
    np.testing.assert_allclose(np.hypot(local[:, 0], local[:, 1]), 8.0, atol=1e-6)
    np.testing.assert_allclose(local[:, 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(face.patch.normals(_grid(face.patch, 3)),
                               np.tile([0, -s, c], (9, 1)), atol=1e-9)


def test_a_trimmed_face_still_needs_its_elements_to_refine_the_finest_level():
    """The trimmed plate keeps fewer elements than 4^k per knot span; the check of Eq. 16's
    nesting counts the spacing of its element centres: 16 per span passes 3 levels, not 4."""
    from adapters.fesdic_core import multilevel_for_mesh
    model = cad_model(DATA / "plate_hole.step", None, 16, 3)
    assert model.mesh.n_elements < 16
    assert len(multilevel_for_mesh(model, 3).operators) == 3
    with pytest.raises(ValueError, match=r"face 0 has 16 FE elements per knot span, fewer "
                                         r"than the 64"):
        multilevel_for_mesh(model, 4)


def test_step_lengths_are_converted_to_mm(tmp_path):
    """The plate's file with its length unit declared in metres instead of millimetres:
    OpenCASCADE converts to mm, the hole's radius reads 8000 mm."""
    text = (DATA / "plate_hole.step").read_text()
    assert text.count("SI_UNIT(.MILLI.,.METRE.)") == 1
    path = tmp_path / "plate_m.step"
    path.write_text(text.replace("SI_UNIT(.MILLI.,.METRE.)", "SI_UNIT($,.METRE.)"))
    (face,) = read_cad_faces(path)
    hole = face.patch.evaluate(face.loops[1])
    np.testing.assert_allclose(np.hypot(hole[:, 0], hole[:, 1]), 8000.0, rtol=1e-9)


def test_the_faces_not_measured_are_the_occluders():
    """`cad_occluders`: the triangles of the faces the selection leaves out (the cylinder's
    two discs when its lateral face is measured: their area, on two planes 20 mm apart),
    None when every face is measured."""
    from georeg_app.inputs.cad import cad_occluders, read_cad_faces
    faces = read_cad_faces(DATA / "cylinder.step")
    lateral = next(k for k, f in enumerate(faces) if f.patch.is_rational)
    t = cad_occluders(DATA / "cylinder.step", [lateral])
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    assert abs(area - 2 * np.pi * 10.0 ** 2) < 0.01 * 2 * np.pi * 10.0 ** 2
    heights = np.unique(np.round(t[..., 2], 6))
    assert heights.size == 2 and np.isclose(np.ptp(heights), 20.0)
    assert cad_occluders(DATA / "cylinder.step", None) is None


@pytest.mark.slow
def test_box_with_fillet_is_one_part_welded_everywhere_but_along_the_trimmed_arcs():
    """Its faces split their shared edges differently (the 20 mm side against the 17 mm face
    beside the fillet, ...): the common refinement (georeg_plugin.spline.conforming) gives them the
    same knots, the surfaces unchanged, and the 7 faces mesh as one part (before: refused,
    NonConformingFacesError). The mesh's free edges are only where the trimmed end faces meet
    the fillet along their trimming arc (a staircase, not welded), within two elements of it."""
    from fesdic_core.fe.mesh import boundary_nodes
    from georeg_plugin.spline.patch import invert_points
    read = read_cad_faces(DATA / "box_fillet.step")
    part = cad_part(DATA / "box_fillet.step")
    for f, g in zip(read, part):
        uv = _grid(f.patch, 7)
        np.testing.assert_allclose(g.patch.evaluate(uv), f.patch.evaluate(uv), atol=1e-12)
    assert sum(g.patch.n_dofs > f.patch.n_dofs for f, g in zip(read, part)) >= 2
    model = cad_model(DATA / "box_fillet.step", None, 500, 2)
    mesh = model.mesh
    assert sorted(set(model.element_face.tolist())) == list(range(7))
    free = boundary_nodes(mesh)
    fillet = next(g.patch for g in part if g.patch.is_rational)
    _, distance = invert_points(fillet, mesh.nodes[free])
    h = max(np.ptp(mesh.nodes[c], axis=0).max() for c in mesh.blocks[0].connectivity[:50])
    assert free.size > 0 and distance.max() < 2 * h, (distance.max(), h)
