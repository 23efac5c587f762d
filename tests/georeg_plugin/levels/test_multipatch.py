"""multipatch: one FE mesh over several faces, glued vector levels, creases, conformity."""
import logging

import numpy as np
import pytest
from numpy.testing import assert_allclose

from georeg_plugin.levels.multipatch import (NonConformingFacesError, part_component_space,
                                             part_mesh, part_space)
from georeg_plugin.spline.fe_mesh import fe_mesh_from_spline
from georeg_plugin.spline.geometries import cylinder, quadrilateral
from georeg_plugin.spline.patch import SplinePatch
from georeg_plugin.spline.refine import refine_to_elements, refine_uniform
from level_checks import assert_in_range, assert_nested, assert_nested_with_rigid_modes

SLOPE = 0.1


def folded_faces(degrees=(2, 2)):
    """Two 30 x 40 mm flat faces meeting at a crease along x = 0 (z = -SLOPE |x|)."""
    z = -SLOPE * 30.0
    left = quadrilateral([[-30, -20, z], [0, -20, 0], [0, 20, 0], [-30, 20, z]], degrees)
    right = quadrilateral([[0, -20, 0], [30, -20, z], [30, 20, z], [0, 20, 0]], degrees)
    return [left, right]


def two_faces(shape):
    """The folded plate, or a 120 degree cylinder cut at its C0 knot into 2 faces."""
    if shape == "folded":
        return folded_faces()
    p = cylinder(50.0, 40.0, 120.0)
    cp, w, k = p.control_points, p.weights, np.array([0, 0, 0, 1, 1, 1.0])
    return [SplinePatch((2, 2), (k, p.knots[1]), cp[:3], w[:3]),
            SplinePatch((2, 2), (k, p.knots[1]), cp[2:], w[2:])]


def face_normals(mesh, faces):
    """Unit normals of each node on its own face, and the mean of both faces on the crease."""
    n = np.vstack([faces[f].normals(mesh.uv[[i]]) for i, f in enumerate(mesh.node_face)])
    crease = np.abs(mesh.nodes[:, 0]) < 1e-9
    mean = faces[0].normals([[1.0, 0.5]]) + faces[1].normals([[0.0, 0.5]])
    n[crease] = mean / np.linalg.norm(mean)
    return n


def test_two_faces_share_their_edge_nodes_and_carry_a_face_index():
    faces = [refine_uniform(f, 2)[0] for f in folded_faces()]
    mesh = part_mesh(faces, names=("left", "right"))
    single = fe_mesh_from_spline(faces[0], "Q9")
    assert len(mesh.nodes) == 2 * single.n_nodes - 9           # 4 x 4 Q9: 9 nodes on the crease
    assert np.bincount(mesh.element_face).tolist() == [16, 16]
    crease = np.flatnonzero(np.abs(mesh.nodes[:, 0]) < 1e-9)
    assert crease.size == 9 and np.all(mesh.node_face[crease] == 0)
    for k, f in enumerate(faces):                              # each node's uv is on its face
        rows = mesh.node_face == k
        assert_allclose(f.evaluate(mesh.uv[rows]), mesh.nodes[rows], atol=1e-12)
    # both faces' elements use the crease nodes: the mesh is conforming
    used = [np.intersect1d(mesh.connectivity[mesh.element_face == k], crease) for k in (0, 1)]
    assert used[0].size == used[1].size == 9


def test_a_non_conforming_edge_is_named():
    left, right = folded_faces()
    faces = [refine_to_elements(left, 4, 4)[0], refine_to_elements(right, 4, 3)[0]]
    with pytest.raises(NonConformingFacesError, match=r"face 0 \('left'\) and face 1 \('right'\)"):
        part_mesh(faces, names=("left", "right"))


def test_a_bicubic_face_is_meshed_on_the_surface(caplog):
    faces = [refine_uniform(f, 1)[0] for f in folded_faces((3, 3))]
    with caplog.at_level(logging.WARNING, logger="georeg_plugin.levels.multipatch"):
        mesh = part_mesh(faces)
    assert "only approximately" in caplog.text and not mesh.exact
    assert_allclose(faces[1].evaluate(mesh.uv[mesh.node_face == 1]),
                    mesh.nodes[mesh.node_face == 1], atol=1e-12)


@pytest.mark.parametrize("shape", ["folded", "cylinder"])
def test_part_levels_are_nested_glued_and_hold_the_rigid_modes(shape):
    coarse = two_faces(shape)
    n_levels = 3
    fine = [refine_uniform(f, n_levels)[0] for f in coarse]
    mesh = part_mesh(fine)
    normals = face_normals(mesh, fine) if shape == "folded" else \
        np.vstack([fine[f].normals(mesh.uv[[i]]) for i, f in enumerate(mesh.node_face)])
    space = part_space(coarse, n_levels, mesh.uv, mesh.node_face, normals)
    assert_nested_with_rigid_modes(space, normals, mesh.nodes)
    # the correction is continuous across the shared edge: both faces give the same vector
    rng = np.random.default_rng(1)
    level = 1
    d = space.control_vectors(rng.standard_normal(space.operators[level].shape[0]), level)
    faces = space.patch(level)
    split = np.cumsum([f.n_dofs for f in faces])[:-1]
    parts = np.split(d, split)
    v = np.linspace(0, 1, 7)
    a, b = np.column_stack([np.ones(7), v]), np.column_stack([np.zeros(7), v])  # u = 1 | u = 0
    ua = faces[0].basis(a) @ parts[0]
    ub = faces[1].basis(b) @ parts[1]
    assert_allclose(ua, ub, atol=1e-12)


@pytest.mark.parametrize("shape", ["folded", "cylinder"])
def test_part_component_levels_are_glued_nested_and_hold_the_part_s_affine_fields(shape):
    """The scalar levels of a component (a displacement's): one dof where faces share a
    control point (one row of points fewer), a field that is one affine function of X on
    the whole part (a rigid translation, a homogeneous strain's component) is in every
    level's range, and the levels are nested (Eq. 13)."""
    coarse = two_faces(shape)
    n_levels = 3
    fine = [refine_uniform(f, n_levels - 1)[0] for f in coarse]
    mesh = part_mesh(fine)
    space = part_component_space(coarse, n_levels, mesh.uv, mesh.node_face)
    assert space.n_levels == n_levels
    glued = sum(f.n_dofs for f in coarse) - space.operators[-1].shape[0]
    assert glued == coarse[0].control_points.shape[1]          # one shared row of points
    X = mesh.nodes
    fields = np.column_stack([np.ones(len(X)), X])   # 1 and X: in every NURBS's span (Eq. 16)
    for s in range(n_levels):
        assert_in_range(space.operators[s].toarray(), fields, 1e-10)
    assert_nested(space)


@pytest.mark.slow
def test_a_lone_face_may_take_the_scalar_space_and_the_part_stays_nested_and_rigid():
    """The folded plate (two glued faces: vector) and a cylinder panel apart from it (no
    shared control point: `isolated_faces`) in one part; with `scalar` the panel gets its
    scalar space `R_J(xi_I)` (one dof per control point), the glued faces keep the vector
    formulation whatever they are asked: every level holds the part's rigid normal motions
    and is nested in the next finer one (Eq. 13)."""
    from georeg_plugin.levels.multipatch import isolated_faces
    from georeg_plugin.spline.geometries import transformed
    panel = transformed(cylinder(100.0, 40.0, 30.0), translation=(0.0, 0.0, 40.0))
    coarse = folded_faces() + [panel]
    assert isolated_faces(coarse).tolist() == [False, False, True]
    n_levels = 3
    fine = [refine_uniform(f, n_levels)[0] for f in coarse]
    mesh = part_mesh(fine)
    normals = face_normals(mesh, fine)
    on_panel = mesh.node_face == 2
    normals[on_panel] = fine[2].normals(mesh.uv[on_panel])
    vector = part_space(coarse, n_levels, mesh.uv, mesh.node_face, normals)
    mixed = part_space(coarse, n_levels, mesh.uv, mesh.node_face, normals, scalar=[True] * 3)
    X = mesh.nodes
    rigid = np.column_stack([normals] + [np.einsum("kd,kd->k", normals, np.cross(e, X))
                                         for e in np.eye(3)])
    for s in range(n_levels):
        C, V = mixed.operators[s].toarray(), vector.operators[s].toarray()
        n_panel = mixed.patch(s)[2].n_dofs
        panel_rows = np.abs(C[:, ~on_panel]).sum(axis=1) == 0
        assert panel_rows.sum() == n_panel                      # one dof per control point
        assert (np.abs(V[:, ~on_panel]).sum(axis=1) == 0).sum() > n_panel   # vector: more
        assert (~panel_rows).sum() == (np.abs(V[:, ~on_panel]).sum(axis=1) > 0).sum()
        assert_in_range(C, rigid, 1e-9)
    assert_nested(mixed)
