"""conforming: faces meeting along an edge given the same knots there (knot insertion), so
that the part's mesh conforms and its vector levels glue (issue 11, item 2: a coupling where
two faces' knot spans do not match)."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from georeg_plugin.levels.multipatch import NonConformingFacesError, part_mesh, part_space
from georeg_plugin.spline.conforming import conforming_faces
from georeg_plugin.spline.geometries import quadrilateral
from georeg_plugin.spline.refine import refine_to_elements, refine_uniform
from level_checks import assert_nested_with_rigid_modes

#: a long face A (x 0..40 along the fold y = 0) meeting two faces B (x 0..25) and C (25..40)
A = quadrilateral([[0, 0, 0], [40, 0, 0], [40, 20, 4], [0, 20, 4]])
B = quadrilateral([[0, -15, -3], [25, -15, -3], [25, 0, 0], [0, 0, 0]])
C = quadrilateral([[25, -15, -3], [40, -15, -3], [40, 0, 0], [25, 0, 0]])


def _same_surface(before, after):
    rng = np.random.default_rng(0)
    for f, g in zip(before, after):
        uv = np.column_stack([rng.uniform(*f.knots[d][[0, -1]], 300) for d in (0, 1)])
        assert_allclose(g.evaluate(uv), f.evaluate(uv), atol=1e-12)


def test_knot_spans_that_differ_along_an_edge_are_unified():
    """The folded plate split 4 x 4 and 4 x 3 (refused as it is): the union of both edges'
    knots on both faces, the same surfaces, a conforming mesh."""
    left, right = (quadrilateral(c) for c in ([[-30, -20, -3], [0, -20, 0], [0, 20, 0], [-30, 20, -3]],
                                              [[0, -20, 0], [30, -20, -3], [30, 20, -3], [0, 20, 0]]))
    faces = [refine_to_elements(left, 4, 4)[0], refine_to_elements(right, 4, 3)[0]]
    with pytest.raises(NonConformingFacesError):
        part_mesh(faces)
    fixed = conforming_faces(faces, ["left", "right"])
    _same_surface(faces, fixed)
    union = np.unique(np.r_[faces[0].knots[1], faces[1].knots[1]])
    for f in fixed:
        assert_allclose(np.unique(f.knots[1]), union, atol=1e-12)
    mesh = part_mesh(fixed)
    crease = np.abs(mesh.nodes[:, 0]) < 1e-9
    assert np.count_nonzero(crease) == 2 * (union.size - 1) + 1       # one node each, welded


@pytest.mark.slow
def test_an_edge_that_meets_two_faces_is_split_where_they_meet():
    """A's edge meets B and C: A gets a C0 knot (multiplicity p = 2) at x = 25; the levels built
    on the conforming faces are nested, glued (the correction continuous across both edges)
    and hold the rigid motions."""
    coarse = conforming_faces([A, B, C], ["A", "B", "C"])
    _same_surface([A, B, C], coarse)
    assert_allclose(coarse[0].knots[0], [0, 0, 0, 0.625, 0.625, 1, 1, 1], atol=1e-12)
    for f, g in zip((B, C), coarse[1:]):                               # nothing to insert
        assert all(np.array_equal(a, b) for a, b in zip(f.knots, g.knots))
    with pytest.raises(NonConformingFacesError):                       # without the coupling
        part_mesh([refine_uniform(f, 2)[0] for f in (A, B, C)])
    n_levels = 3
    fine = [refine_uniform(f, n_levels - 1)[0] for f in coarse]
    mesh = part_mesh(fine)
    normals = np.vstack([fine[f].normals(mesh.uv[[i]]) for i, f in enumerate(mesh.node_face)])
    space = part_space(coarse, n_levels, mesh.uv, mesh.node_face, normals)
    assert_nested_with_rigid_modes(space, normals, mesh.nodes, rtol=1e-11)
    rng = np.random.default_rng(1)
    for level in range(space.n_levels):
        d = space.control_vectors(rng.standard_normal(space.operators[level].shape[0]), level)
        faces = space.patch(level)
        parts = np.split(d, np.cumsum([f.n_dofs for f in faces])[:-1])
        for k, (x0, x1) in ((1, (0.0, 25.0)), (2, (25.0, 40.0))):      # along y = 0
            t = np.linspace(0.0, 1.0, 9)
            on_a = np.column_stack([(x0 + t * (x1 - x0)) / 40.0, np.zeros(9)])
            on_k = np.column_stack([t, np.ones(9)])
            assert_allclose(faces[0].basis(on_a) @ parts[0], faces[k].basis(on_k) @ parts[k],
                            atol=1e-12)


def test_a_feature_inside_a_face_adds_no_knot():
    """A face standing on another's interior (not on its parameter box's edge) changes nothing:
    they meet along a trimming loop, not along an edge."""
    plate = quadrilateral([[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]])
    wall = quadrilateral([[-10, 0, 0], [10, 0, 0], [10, 0, 5], [-10, 0, 5]])
    out = conforming_faces([plate, wall])
    for f, g in zip((plate, wall), out):
        assert all(np.array_equal(a, b) for a, b in zip(f.knots, g.knots))


def test_a_circle_touching_a_square_adds_no_knot():
    """A cylinder's rim (breakpoints every 90 degrees) touches the square end plate's edges at
    four points, its breakpoints: touching is not sharing a stretch of edge (the spans next to
    the breakpoints run inside the square), so neither face gets a knot. (Without that test
    the square took C0 lines through the tangent points: cylinder.step's discs did.)"""
    from georeg_plugin.spline.geometries import cylinder
    tube = cylinder(10.0, 5.0, 360.0)                        # axis x, rims at x = -2.5, 2.5
    plate = quadrilateral([[-2.5, -10, -10], [-2.5, 10, -10], [-2.5, 10, 10], [-2.5, -10, 10]])
    out = conforming_faces([plate, tube])
    for f, g in zip((plate, tube), out):
        assert all(np.array_equal(a, b) for a, b in zip(f.knots, g.knots))



@pytest.mark.slow
def test_the_split_keeps_the_neighbour_s_continuity_in_the_target_s_degree():
    """A bicubic A against the biquadratic B and C: where they meet (x = 25, C0 between B and
    C) A gets a triple knot, C0 in degree 3; its surface unchanged; the FE mesh conforms."""
    cubic = quadrilateral([[0, 0, 0], [40, 0, 0], [40, 20, 4], [0, 20, 4]], (3, 3))
    out = conforming_faces([cubic, B, C])
    _same_surface([cubic, B, C], out)
    assert np.count_nonzero(np.isclose(out[0].knots[0], 0.625)) == 3
    part_mesh([refine_uniform(f, 2)[0] for f in out])            # no NonConformingFacesError
