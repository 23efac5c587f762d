"""Trimmed faces: elements kept inside the loops (staircase area bound, convergence), nodes
keep their (u, v), the part mesh of a trimmed face, grid triangles' area."""
import numpy as np
import pytest

from georeg_plugin.levels.multipatch import part_mesh
from georeg_plugin.spline.fe_mesh import fe_mesh_from_spline
from georeg_plugin.spline.geometries import cylinder, quadrilateral
from georeg_plugin.spline.refine import refine_uniform
from georeg_plugin.spline.trimmed import grid_triangles, inside_loops, trim_mesh

L, W, R = 60.0, 40.0, 8.0


def _plate():
    """A flat 60 x 40 mm face, parameters (0..1)^2, degree 2 (elevated bilinear)."""
    a, b = 0.5 * L, 0.5 * W
    return quadrilateral([[-a, -b, 0], [a, -b, 0], [a, b, 0], [-a, b, 0]])


def _loops(patch, n=400):
    """Outer loop: the parameter box; hole: the circle of radius R at the centre, in (u, v)."""
    lo, hi = patch.bounds
    box = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    hole = np.column_stack([0.5 + R * np.cos(t) / L, 0.5 + R * np.sin(t) / W])
    return box, hole


def _area(mesh) -> float:
    x = mesh.nodes[mesh.connectivity[:, :4]]                     # flat rectangles
    return float(np.sum(np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 3] - x[:, 0]), axis=1)))


def test_inside_loops_is_inside_the_outer_and_outside_the_holes():
    box, hole = _loops(_plate())
    uv = np.array([[0.1, 0.1], [0.5, 0.5], [1.5, 0.5], [0.5 + 0.9 * R / L, 0.5],
                   [0.5 + 1.1 * R / L, 0.5]])
    assert inside_loops(uv, [box, hole]).tolist() == [True, False, False, False, True]
    with pytest.raises(ValueError, match=r"loops\[1\]: expected a finite closed polyline"):
        inside_loops(uv, [box, np.zeros((2, 2))])


def test_trimmed_plate_area_is_plate_minus_hole_within_the_staircase_band_and_converges():
    plate = _plate()
    exact = L * W - np.pi * R ** 2
    lost = []
    for k in (3, 4, 5):
        mesh = fe_mesh_from_spline(refine_uniform(plate, k)[0], "Q9")
        trimmed = trim_mesh(mesh, _loops(plate))
        h = np.hypot(L, W) / 2 ** k                             # an element's diagonal
        lost.append(exact - _area(trimmed))
        # only elements cut by the circle are lost: a band of one diagonal outside it
        assert 0 <= lost[-1] <= np.pi * ((R + h) ** 2 - R ** 2), (k, lost[-1])
        # every kept element's nine nodes are outside the hole, every node keeps its (u, v)
        np.testing.assert_allclose(trimmed.nodes, plate.evaluate(trimmed.uv), atol=1e-12)
        assert np.min(np.linalg.norm(trimmed.nodes[:, :2], axis=1)) >= R - 1e-9   # hole at 0
        assert trimmed.n_nodes == len(np.unique(trimmed.connectivity))
    assert lost[0] > lost[1] > lost[2] > 0
    assert lost[2] < 0.6 * lost[1] < 0.36 * lost[0]               # about halves with h


def test_a_face_with_no_element_inside_its_loops_is_named():
    plate = _plate()
    tiny = np.array([[0.4, 0.4], [0.45, 0.4], [0.45, 0.45]])
    with pytest.raises(ValueError, match=r"face 'lid': none of its 1 FE elements lies inside"):
        trim_mesh(fe_mesh_from_spline(plate, "Q9"), [tiny], "face 'lid'")


def test_part_mesh_of_a_trimmed_face_next_to_an_untrimmed_one_welds_their_edge():
    """A trimmed plate (hole) and a flat neighbour sharing its edge x = 30 mm: one mesh."""
    plate = _plate()
    a, b = 0.5 * L, 0.5 * W
    right = quadrilateral([[a, -b, 0], [a + 20, -b, 0], [a + 20, b, 0], [a, b, 0]])
    fine = [refine_uniform(plate, 4)[0], refine_uniform(right, 4)[0]]
    part = part_mesh(fine, ["plate", "right"], loops=[_loops(plate), None])
    kept = trim_mesh(fe_mesh_from_spline(fine[0], "Q9"), _loops(plate))
    right_mesh = fe_mesh_from_spline(fine[1], "Q9")
    assert len(part.connectivity) == kept.n_elements + right_mesh.n_elements
    assert part.nodes.shape[0] == kept.n_nodes + right_mesh.n_nodes - 33   # 33 welded Q9 nodes
    for f, face in enumerate(fine):
        rows = part.node_face == f
        np.testing.assert_allclose(part.nodes[rows], face.evaluate(part.uv[rows]), atol=1e-12)


def test_grid_triangles_area_of_a_cylinder_panel_and_of_a_trimmed_plate():
    radius, length, angle = 50.0, 30.0, 60.0
    panel = cylinder(radius, length, angle)
    tri = grid_triangles(panel, per_span=32)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    exact = radius * np.radians(angle) * length
    assert abs(area.sum() - exact) < 1e-3 * exact               # chords: O(h^2)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    uv_normals = panel.normals(np.full((1, 2), 0.5))[0]
    assert np.all(normal @ uv_normals > 0)                      # ordered along S_u x S_v
    plate = _plate()
    tri = grid_triangles(plate, _loops(plate), per_span=64)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    h = np.hypot(L, W) / 64
    exact = L * W - np.pi * R ** 2
    assert 0 <= exact - area.sum() <= np.pi * ((R + h) ** 2 - R ** 2)
