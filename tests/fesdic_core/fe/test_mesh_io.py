"""Tests of the meshio-based mesh input/output (fesdic_core.fe.mesh_io)."""
import os

import meshio
import numpy as np
import pytest

from fesdic_core.fe.elements import FAMILIES
from fesdic_core.fe.mesh import CellBlock, SurfaceMesh, element_areas, rectangle_mesh
from fesdic_core.fe.mesh_io import read_mesh, write_mesh

FORMATS = [(".msh", None), (".msh", "gmsh22"), (".vtu", None), (".inp", None), (".vtk", None)]


def _curved(family):
    """A small non-planar mesh with distinct, non-grid coordinates (3 x 2 elements)."""
    flat = rectangle_mesh(3.0, 2.0, 3, 2, family)
    x, y = flat.nodes[:, 0], flat.nodes[:, 1]
    return flat.with_nodes(np.column_stack([x + 0.01 * y ** 2, y, 0.1 * x ** 2 - 0.05 * x * y]))


@pytest.mark.parametrize("family", ["T3", "T6", "Q4", "Q9"])
@pytest.mark.parametrize("suffix, file_format", FORMATS)
def test_round_trip_keeps_nodes_and_connectivity(tmp_path, family, suffix, file_format):
    mesh = _curved(family)
    path = tmp_path / f"plate{suffix}"
    write_mesh(path, mesh, file_format=file_format)
    back = read_mesh(path)
    assert back.name == "plate"
    np.testing.assert_array_equal(back.nodes, mesh.nodes)
    assert len(back.blocks) == 1
    assert back.blocks[0].family is FAMILIES[family]
    np.testing.assert_array_equal(back.blocks[0].connectivity, mesh.blocks[0].connectivity)
    if suffix == ".msh":
        header = path.read_bytes()[:20]
        assert (b"2.2" if file_format == "gmsh22" else b"4.1") in header
    assert sorted(os.listdir(tmp_path)) == [path.name]      # no temporary file left


def test_vtu_keeps_point_and_cell_data(tmp_path):
    mesh = rectangle_mesh(4.0, 2.0, 4, 2, "Q9")
    q = np.sin(mesh.nodes[:, 0])
    normals = np.tile([0.0, 0.0, 1.0], (mesh.n_nodes, 1))
    areas = element_areas(mesh)
    path = tmp_path / "shape.vtu"
    write_mesh(path, mesh, point_data={"q": q, "normal": normals}, cell_data={"area": areas})
    raw = meshio.read(path)
    np.testing.assert_array_equal(raw.point_data["q"], q)
    np.testing.assert_array_equal(raw.point_data["normal"], normals)
    np.testing.assert_array_equal(raw.cell_data["area"][0], areas[0])


def test_gmsh_file_written_by_hand_keeps_gmsh_order(tmp_path):
    """A gmsh 2.2 file with one Q9 and one T6 in gmsh numbering (not a meshio round
    trip): the mid-edge and centre nodes must land where our shape functions put them."""
    q9_ref = FAMILIES["Q9"].ref_nodes
    t6_ref = FAMILIES["T6"].ref_nodes + [2.0, 0.0]
    points = np.vstack([q9_ref, t6_ref])
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Nodes", str(len(points))]
    lines += [f"{i + 1} {x:.17g} {y:.17g} 0" for i, (x, y) in enumerate(points)]
    lines += ["$EndNodes", "$Elements", "3",
              "1 1 2 0 1 1 2",                                           # a line: ignored
              "2 10 2 0 1 " + " ".join(str(i + 1) for i in range(9)),    # Q9
              "3 9 2 0 1 " + " ".join(str(i + 10) for i in range(6)),    # T6
              "$EndElements"]
    path = tmp_path / "hand.msh"
    path.write_text("\n".join(lines) + "\n")
    mesh = read_mesh(path)
    assert [b.family.name for b in mesh.blocks] == ["Q9", "T6"]
    for block, ref in zip(mesh.blocks, (q9_ref, t6_ref)):
        # node k of the element sits at reference position k (identity geometry map)
        np.testing.assert_array_equal(mesh.nodes[block.connectivity[0], :2], ref)


def test_abaqus_file_written_by_hand(tmp_path):
    """Abaqus S9R5 / STRI65 use corners, mid-edges, centre: the gmsh order."""
    q9_ref = FAMILIES["Q9"].ref_nodes
    nodes = "\n".join(f"{i + 1}, {x:.17g}, {y:.17g}, 0.0" for i, (x, y) in enumerate(q9_ref))
    text = ("*NODE\n" + nodes + "\n*ELEMENT, TYPE=S9R5, ELSET=plate\n"
            "1, " + ", ".join(str(i + 1) for i in range(9)) + "\n")
    path = tmp_path / "hand.inp"
    path.write_text(text)
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.nodes[mesh.blocks[0].connectivity[0], :2], q9_ref)


def test_two_dimensional_points_get_z_zero_and_lines_are_ignored(tmp_path):
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    raw = meshio.Mesh(points, [("line", np.array([[0, 1]])), ("quad", np.array([[0, 1, 2, 3]])),
                               ("vertex", np.array([[0]]))])
    path = tmp_path / "flat.vtu"
    raw.write(path)
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.nodes[:, 2], 0.0)
    np.testing.assert_array_equal(mesh.nodes[:, :2], points)
    assert [b.family.name for b in mesh.blocks] == ["Q4"]


def test_blocks_of_the_same_type_are_merged(tmp_path):
    mesh = rectangle_mesh(2.0, 1.0, 2, 1, "T3")
    conn = mesh.blocks[0].connectivity
    t3 = FAMILIES["T3"]
    split = SurfaceMesh(mesh.nodes, (CellBlock(t3, conn[:1]), CellBlock(t3, conn[1:])))
    path = tmp_path / "split.vtu"
    write_mesh(path, split)
    back = read_mesh(path)
    assert len(back.blocks) == 1
    np.testing.assert_array_equal(back.blocks[0].connectivity, conn)


def test_errors_name_the_file(tmp_path):
    missing = tmp_path / "nowhere.msh"
    with pytest.raises(FileNotFoundError, match="nowhere.msh"):
        read_mesh(missing)
    garbage = tmp_path / "garbage.msh"
    garbage.write_text("not a mesh\n")
    with pytest.raises(ValueError, match="garbage.msh"):
        read_mesh(garbage)
    lines_only = tmp_path / "wire.vtu"
    meshio.Mesh(np.eye(3), [("line", np.array([[0, 1], [1, 2]]))]).write(lines_only)
    with pytest.raises(ValueError, match="wire.vtu.*no surface cell"):
        read_mesh(lines_only)
    quad8 = tmp_path / "serendipity.vtu"
    meshio.Mesh(np.random.default_rng(0).random((8, 3)),
                [("quad8", np.arange(8)[None])]).write(quad8)
    with pytest.raises(ValueError, match="serendipity.vtu.*quad8"):
        read_mesh(quad8)
    mesh = rectangle_mesh(1.0, 1.0, 1, 1)
    with pytest.raises(ValueError, match="point_data\\['q'\\]"):
        write_mesh(tmp_path / "x.vtu", mesh, point_data={"q": np.zeros(3)})
    with pytest.raises(FileNotFoundError, match="missing_dir"):
        write_mesh(tmp_path / "missing_dir" / "x.vtu", mesh)


def test_interrupted_write_leaves_no_file(tmp_path, monkeypatch):
    mesh = rectangle_mesh(1.0, 1.0, 2, 2, "Q9")
    seen = []

    def broken_write(filename, *args, **kwargs):
        seen.append(str(filename))
        with open(filename, "w") as f:      # half-written temporary file
            f.write("partial")
        raise RuntimeError("disk full")

    monkeypatch.setattr(meshio, "write", broken_write)
    with pytest.raises(RuntimeError, match="disk full"):
        write_mesh(tmp_path / "out.vtu", mesh)
    assert seen and seen[0].endswith(".vtu") and os.path.dirname(seen[0]) == str(tmp_path)
    assert os.listdir(tmp_path) == []


def test_failed_write_keeps_previous_file(tmp_path, monkeypatch):
    path = tmp_path / "out.vtu"
    first = rectangle_mesh(1.0, 1.0, 2, 2, "Q4")
    write_mesh(path, first)
    monkeypatch.setattr(meshio, "write", lambda *a, **k: (_ for _ in ()).throw(OSError("boom")))
    with pytest.raises(OSError):
        write_mesh(path, rectangle_mesh(5.0, 5.0, 3, 3, "Q4"))
    monkeypatch.undo()
    np.testing.assert_array_equal(read_mesh(path).nodes, first.nodes)
    assert os.listdir(tmp_path) == ["out.vtu"]
