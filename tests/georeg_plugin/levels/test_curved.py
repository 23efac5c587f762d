"""curved: vector control displacements seen along the node normals (nested, rigid-complete)."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from georeg_plugin.levels.curved import (is_flat, range_basis, vector_extraction, vector_gluing,
                                         vector_level)
from georeg_plugin.levels.operators import extraction_operator, multilevel_space
from georeg_plugin.spline.fe_mesh import fe_mesh_from_spline
from georeg_plugin.spline.geometries import cylinder, plate_with_hole, rectangle
from georeg_plugin.spline.patch import SplinePatch
from georeg_plugin.spline.refine import refine_uniform


def dome():
    """Doubly curved bi-quadratic B-spline (an elliptic paraboloid with a twist), 40 x 30 mm."""
    U, V = np.meshgrid(np.linspace(-20, 20, 3), np.linspace(-15, 15, 3), indexing="ij")
    cp = np.stack([U, V, 0.004 * U ** 2 + 0.006 * V ** 2 + 0.002 * U * V], -1)
    k = np.array([0, 0, 0, 1, 1, 1.0])
    return SplinePatch((2, 2), (k, k), cp)


def panel():
    """Cylindrical NURBS panel, R 100 mm, 30 degrees, 40 mm long."""
    return cylinder(100.0, 40.0, 30.0)


def _space(coarse, n_levels=4):
    fine, _ = refine_uniform(coarse, n_levels)
    mesh = fe_mesh_from_spline(fine, "Q9")
    normals = fine.normals(mesh.uv)
    return mesh, normals, multilevel_space(coarse, n_levels, mesh.nodes, node_normals=normals,
                                           uv=mesh.uv)


def rigid_normal_modes(nodes, normals):
    """(n, 6) normal parts ``n_I . (a + w x X_I)`` of the unit translations and rotations."""
    return np.column_stack([normals[:, k] for k in range(3)] +
                           [np.einsum("kd,kd->k", normals, np.cross(np.eye(3)[k], nodes))
                            for k in range(3)])


@pytest.mark.slow
@pytest.mark.parametrize("make", [panel, dome], ids=["cylinder", "dome"])
def test_vector_levels_are_nested_and_hold_the_rigid_modes(make):
    mesh, normals, space = _space(make())
    rigid = rigid_normal_modes(mesh.nodes, normals)
    for s in range(space.n_levels):
        C = space.operators[s].toarray()
        assert_allclose(C @ C.T, np.eye(C.shape[0]), atol=1e-12)          # orthonormal rows
        residual = rigid - C.T @ (C @ rigid)
        assert np.abs(residual).max() < 1e-12 * np.abs(rigid).max()       # rigid in range
        if s + 1 < space.n_levels:                                          # Eq. 13: nested
            coarse = space.operators[s + 1].toarray()
            assert np.abs(coarse.T - C.T @ (C @ coarse.T)).max() < 1e-10


def test_the_normal_n_dot_n_formula_is_not_nested_but_the_vector_one_is():
    """The first formula tried, R_J(xi_I) (n_I . n_J), leaves the coarse level out of the fine."""
    coarse = panel()
    mesh, normals, space = _space(coarse, 3)
    ops = [extraction_operator(p, mesh.uv, normals).toarray() for p in reversed(space.patches)]
    Q, _ = np.linalg.qr(ops[0].T)
    miss = ops[1].T - Q @ (Q.T @ ops[1].T)
    assert np.abs(miss).max() > 1e-4 * np.abs(ops[1]).max()
    C, Cc = space.operators[0].toarray(), space.operators[1].toarray()
    assert np.abs(Cc.T - C.T @ (C @ Cc.T)).max() < 1e-10


def test_on_a_flat_plate_the_range_is_the_scalar_one():
    coarse = plate_with_hole(100.0, 50.0, 14.0)
    fine, _ = refine_uniform(coarse, 2)
    mesh = fe_mesh_from_spline(fine, "Q9")
    normals = np.tile([0.0, 0.0, 1.0], (mesh.n_nodes, 1))
    vector = multilevel_space(coarse, 2, mesh.nodes, node_normals=normals, uv=mesh.uv)
    scalar = multilevel_space(coarse, 2, mesh.nodes, uv=mesh.uv)
    for s in range(2):
        C = vector.operators[s].toarray()
        S = scalar.operators[s].toarray()
        assert C.shape[0] == np.linalg.matrix_rank(S) == np.linalg.matrix_rank(C)  # same dim.
        inside, *_ = np.linalg.lstsq(C.T, S.T, rcond=None)                   # same range
        assert np.abs(S.T - C.T @ inside).max() < 1e-12 * np.abs(S).max()


def test_control_vectors_reproduce_the_nodal_field_and_make_the_measured_nurbs():
    """d = T q_s: the moved NURBS P_J + d_J has the normal displacement C^T q_s at the nodes."""
    coarse = panel()
    mesh, normals, space = _space(coarse, 2)
    rng = np.random.default_rng(3)
    level = 1
    q_s = rng.standard_normal(space.operators[level].shape[0])
    d = space.control_vectors(q_s, level)
    patch = space.patch(level)
    A = vector_extraction(patch, mesh.uv, normals)
    assert_allclose(A @ d.ravel(), space.operators[level].T @ q_s, atol=1e-10)
    # linear in d: the moved patch's points differ from the nominal by u(xi)
    moved = SplinePatch(patch.degrees, patch.knots,
                        patch.control_points + 1e-3 * d.reshape(patch.control_points.shape),
                        patch.weights)
    shift = moved.evaluate(mesh.uv) - patch.evaluate(mesh.uv)
    assert_allclose(np.einsum("kd,kd->k", shift, normals), 1e-3 * space.operators[level].T @ q_s,
                    atol=1e-12)


def test_a_closed_patch_glues_its_seam_vectors():
    coarse = plate_with_hole(100.0, 50.0, 14.0)
    G = vector_gluing([coarse])
    assert G.shape == (coarse.n_dofs - 3, coarse.n_dofs)
    fine, _ = refine_uniform(coarse, 1)
    mesh = fe_mesh_from_spline(fine, "Q9")
    tilted = np.tile(np.array([0.1, 0.0, 1.0]) / np.hypot(0.1, 1.0), (mesh.n_nodes, 1))
    level = vector_level([coarse], [np.arange(mesh.n_nodes)], [mesh.uv], tilted, mesh.n_nodes)
    d = level.control_vectors(np.ones(level.operator.shape[0]))
    cp = coarse.control_points.reshape(-1, 3)
    same = np.flatnonzero(np.all(np.abs(cp[:, None] - cp[None]) < 1e-9, axis=2).sum(1) > 1)
    for j in same:                                   # coincident points move together
        twins = np.flatnonzero(np.all(np.abs(cp - cp[j]) < 1e-9, axis=1))
        assert_allclose(d[twins], np.broadcast_to(d[j], d[twins].shape), atol=1e-12)


def test_flatness_and_rank_inputs():
    assert is_flat([rectangle(10.0, 5.0)]) and is_flat([plate_with_hole(100.0, 50.0, 14.0)])
    assert not is_flat([panel()]) and not is_flat([dome()])
    with pytest.raises(ValueError, match="zero"):
        range_basis(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="node_normals"):
        vector_extraction(panel(), np.zeros((4, 2)), np.zeros((3, 3)))
