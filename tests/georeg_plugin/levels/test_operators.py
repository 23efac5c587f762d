"""operators: C_s by node evaluation (Remark 6, Eqs. 26-28), exactness, nesting, legacy meshes."""
import logging

import meshio
import numpy as np
import pytest
import scipy.sparse as sps
from numpy.testing import assert_allclose
from scipy.interpolate import NdBSpline
from scipy.spatial import Delaunay

from georeg_plugin.levels.operators import (NodesOutsidePatchError, extraction_operator,
                                            multilevel_space, node_parameters)
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.spline.fe_mesh import ElementDegreeError, fe_mesh_from_spline
from georeg_plugin.spline.geometries import cylinder, plate_with_hole, quadrilateral, rectangle
from georeg_plugin.spline.patch import SplinePatch
from georeg_plugin.spline.refine import insert_knots, refine_uniform

L, W, R = 100.0, 50.0, 14.0
Q9_REF = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1],
                   [0, -1], [1, 0], [0, 1], [-1, 0], [0, 0]], dtype=float)


def q9_shape(xi):
    """Q9 shape functions in gmsh order at reference points (m, 2) -> (m, 9)."""
    def lag(x):
        x = x[:, None]
        return np.hstack([0.5 * x * (x - 1), 1 - x ** 2, 0.5 * x * (x + 1)])
    a = (Q9_REF[:, 0] + 1).astype(int)
    b = (Q9_REF[:, 1] + 1).astype(int)
    return lag(xi[:, 0])[:, a] * lag(xi[:, 1])[:, b]


def fe_interpolant_at_random_points(mesh, nodal, rng, per_element=4):
    """Q9 interpolation of nodal values at random points inside every element.

    Returns the values (ne*k,) and the parameters uv (ne*k, 2) of those points
    (the element map is affine in parameter space).
    """
    ne = mesh.n_elements
    xi = rng.uniform(-1, 1, size=(ne, per_element, 2))
    N = q9_shape(xi.reshape(-1, 2)).reshape(ne, per_element, 9)
    values = np.einsum("ekn,en->ek", N, nodal[mesh.connectivity])
    uv_e = mesh.uv[mesh.connectivity]
    centre, half = uv_e[:, 8, :], 0.5 * (uv_e[:, 2, :] - uv_e[:, 0, :])
    uv = centre[:, None, :] + half[:, None, :] * xi
    return values.ravel(), uv.reshape(-1, 2)


def _bumpy_bspline_rectangle():
    """A flat B-spline rectangle with non-uniform knots (degrees 2, 2)."""
    patch, _ = insert_knots(rectangle(L, W), [0.3], [0.55])
    return patch


@pytest.fixture(scope="module")
def flat_bspline_space():
    coarse = _bumpy_bspline_rectangle()
    fine, _ = refine_uniform(coarse, 3)
    mesh = fe_mesh_from_spline(fine, "Q9")
    return coarse, mesh, multilevel_space(coarse, 3, mesh.nodes, uv=mesh.uv, glue=False)


def test_node_evaluation_equals_product_form_eq_28(flat_bspline_space):
    _, _, space = flat_bspline_space
    assert space.n_levels == 3
    for s in range(space.n_levels - 1):
        product = space.refinement[s] @ space.operators[s]        # Eq. 28
        diff = abs(product - space.operators[s + 1])
        assert diff.max() < 1e-12
    sizes = [C.shape[0] for C in space.operators]
    assert sizes == sorted(sizes, reverse=True)                  # s = 0 is the finest
    assert space.patch(0) is space.patches[-1]


def test_product_form_also_holds_for_nurbs():
    coarse = plate_with_hole(L, W, R)
    fine, _ = refine_uniform(coarse, 3)
    mesh = fe_mesh_from_spline(fine, "Q9")
    space = multilevel_space(coarse, 3, mesh.nodes, uv=mesh.uv, glue=False)
    for s in range(2):
        diff = abs(space.refinement[s] @ space.operators[s] - space.operators[s + 1])
        assert diff.max() < 1e-12


def test_levels_are_nested(flat_bspline_space):
    _, _, space = flat_bspline_space
    for s in range(space.n_levels - 1):
        fine_t = space.operators[s].T.toarray()
        coarse_t = space.operators[s + 1].T.toarray()
        coef, *_ = np.linalg.lstsq(fine_t, coarse_t, rcond=None)
        residual = np.abs(fine_t @ coef - coarse_t).max()
        assert residual < 1e-12


def test_bspline_operator_is_exact(flat_bspline_space):
    """C_s^T q_s is the spline field at the nodes, and its Q9 interpolant is the field."""
    _, mesh, space = flat_bspline_space
    rng = np.random.default_rng(3)
    for s in range(space.n_levels):
        patch = space.patch(s)
        q_s = rng.standard_normal(patch.n_dofs)
        field = NdBSpline(patch.knots, q_s.reshape(patch.shape), patch.degrees)
        nodal = space.operators[s].T @ q_s
        assert_allclose(nodal, field(mesh.uv), atol=1e-12)
        values, uv = fe_interpolant_at_random_points(mesh, nodal, rng)
        assert_allclose(values, field(uv), atol=1e-12)


def test_operator_shape_and_no_explicit_zeros(flat_bspline_space):
    _, mesh, space = flat_bspline_space
    for C, patch in zip(space.operators, reversed(space.patches)):
        assert isinstance(C, sps.csr_matrix)
        assert C.shape == (patch.n_dofs, mesh.n_nodes)
        assert np.all(C.data != 0)
        assert_allclose(np.asarray(C.sum(axis=0)).ravel(), 1.0, atol=1e-13)  # unity


def _nurbs_interpolation_error(times, rng):
    """Max error of Eq. 27 (Q9 interpolant of C^T q vs R^T q), last level refined."""
    coarse = plate_with_hole(L, W, R)
    fine, C_r = refine_uniform(coarse, times)
    mesh = fe_mesh_from_spline(fine, "Q9", weld=False)
    C = extraction_operator(fine, mesh.uv)
    q_c = np.sin(np.arange(coarse.n_dofs))          # one fixed smooth field...
    q_f = C_r.T @ q_c                                # ...on the refined level (Eq. 15)
    values, uv = fe_interpolant_at_random_points(mesh, C.T @ q_f, rng)
    exact = coarse.basis(uv) @ q_c                   # R_c^T q_c = R_f^T q_f
    return np.abs(values - exact).max(), 2.0 ** -times


def test_nurbs_eq_27_error_falls_with_refinement():
    rng = np.random.default_rng(5)
    errors, h = zip(*[_nurbs_interpolation_error(t, rng) for t in (1, 2, 3, 4)])
    rate = np.polyfit(np.log(h), np.log(errors), 1)[0]
    logging.getLogger(__name__).info("Eq. 27 error %s, rate %.2f", errors, rate)
    assert np.all(np.diff(errors) < 0)
    assert rate > 2.5, (errors, rate)  # quadratic interpolation of a smooth field: h^3


def _legacy_plate_nodes(n_target, rng):
    """Nodes of an unstructured T3 mesh of the plate with hole, written/read by meshio."""
    h = np.sqrt((L * W - np.pi * R ** 2) / n_target)
    nx, ny = int(L / h), int(W / h)
    x, y = np.linspace(-L / 2, L / 2, nx + 1), np.linspace(-W / 2, W / 2, ny + 1)[1:-1]
    box = np.r_[np.column_stack([x, np.full(x.size, -W / 2)]),
                np.column_stack([x, np.full(x.size, W / 2)]),
                np.column_stack([np.full(y.size, -L / 2), y]),
                np.column_stack([np.full(y.size, L / 2), y])]
    n_hole = int(2 * np.pi * R / h)
    t = np.linspace(0, 2 * np.pi, n_hole, endpoint=False)
    hole = R * np.column_stack([np.cos(t), np.sin(t)])
    inner = rng.uniform([-L / 2, -W / 2], [L / 2, W / 2], size=(3 * n_target, 2))
    inner = inner[np.linalg.norm(inner, axis=1) > R + 0.3 * h][:n_target]
    points = np.r_[box, hole, inner]
    tri = Delaunay(points).simplices
    tri = tri[np.linalg.norm(points[tri].mean(axis=1), axis=1) > R]
    return np.column_stack([points, np.zeros(len(points))]), tri


def test_legacy_mesh_reproduces_a_smooth_offset_better_with_refinement(tmp_path):
    rng = np.random.default_rng(11)
    coarse = plate_with_hole(L, W, R)

    def offset(X):
        return 0.2 * np.sin(X[:, 0] / 15.0) * np.cos(X[:, 1] / 9.0) + 0.01 * X[:, 0]

    errors = []
    for n_nodes, levels in ((300, 2), (1200, 3), (4800, 4)):
        nodes, tri = _legacy_plate_nodes(n_nodes, rng)
        path = tmp_path / f"legacy_{n_nodes}.vtu"
        meshio.write(path, meshio.Mesh(nodes, [("triangle", tri)]))
        nodes = meshio.read(path).points
        uv, distance = node_parameters(coarse, nodes)
        assert distance.max() < 1e-8
        space = multilevel_space(coarse, levels, nodes, uv=uv, glue=False)
        reg = GeometricRegularization(space)
        q = offset(nodes)
        q_s = reg.control_values(q, 0)                  # least squares in range(C^T)
        errors.append(np.abs(reg.to_nodes(q_s, 0) - q).max())
    assert errors[1] < 0.5 * errors[0] and errors[2] < 0.5 * errors[1], errors


def test_node_parameters_rejects_nodes_outside_and_warns_off_surface(caplog):
    patch = plate_with_hole(L, W, R)
    nodes = np.array([[30.0, 10.0, 0.0], [0.0, 20.0, 0.0], [L / 2 + 2.0, 0.0, 0.0],
                      [0.0, W / 2 + 5.0, 0.0], [0.0, 0.0, 0.0]])
    with pytest.raises(NodesOutsidePatchError, match=r"3 of 5 FE nodes.*worst: node 4"):
        node_parameters(patch, nodes)
    with caplog.at_level(logging.WARNING, logger="georeg_plugin.levels.operators"):
        uv, distance = node_parameters(patch, np.array([[30.0, 10.0, 0.5],
                                                        [0.0, 20.0, 0.0]]))
    assert "1 of 2 FE nodes" in caplog.text
    assert_allclose(distance, [0.5, 0.0], atol=1e-9)
    assert_allclose(patch.evaluate(uv), [[30.0, 10.0, 0.0], [0.0, 20.0, 0.0]], atol=1e-9)


def test_curved_operator_is_the_normal_motion_of_control_points():
    """C^T[I, J] = R_J(xi_I) (n_I . n_J): move dof J along n_J, read along n_I."""
    patch, _ = refine_uniform(cylinder(20.0, 60.0, 150.0), 1)
    mesh = fe_mesh_from_spline(refine_uniform(patch, 1)[0], "Q9")
    n_nodes = patch.normals(mesh.uv)
    C = extraction_operator(patch, mesh.uv, node_normals=n_nodes)
    rng = np.random.default_rng(2)
    q = rng.standard_normal(patch.n_dofs)
    n_cp = patch.control_normals()
    moved = SplinePatch(patch.degrees, patch.knots,
                        patch.control_points + (q[:, None] * n_cp).reshape(patch.shape + (3,)),
                        patch.weights)
    shift = moved.evaluate(mesh.uv) - patch.evaluate(mesh.uv)   # exact: linear in x_J
    assert_allclose(C.T @ q, np.einsum("kc,kc->k", shift, n_nodes), atol=1e-12)
    # on a flat plate the normals change nothing
    flat = plate_with_hole(L, W, R)
    uv = fe_mesh_from_spline(flat, "Q9").uv
    diff = extraction_operator(flat, uv, flat.normals(uv)) - extraction_operator(flat, uv)
    assert abs(diff).max() < 1e-15


def test_bad_inputs_are_rejected():
    patch = rectangle(L, W)
    with pytest.raises(ValueError, match="uv"):
        extraction_operator(patch, np.zeros((4, 3)))
    with pytest.raises(ValueError, match="node_normals"):
        extraction_operator(patch, np.zeros((4, 2)), node_normals=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="n_levels"):
        multilevel_space(patch, 0, np.zeros((4, 3)))


def test_glued_levels_are_continuous_across_the_seam_and_nested():
    """Closed plate: coincident control points share a dof; levels stay nested."""
    coarse = plate_with_hole(L, W, R)
    fine, _ = refine_uniform(coarse, 3)
    mesh = fe_mesh_from_spline(fine, "Q9")                     # welded seam
    space = multilevel_space(coarse, 3, mesh.nodes, uv=mesh.uv)
    assert space.gluing and space.gluing[-1].shape == (coarse.n_dofs - 3, coarse.n_dofs)
    for s in range(space.n_levels - 1):
        fine_op, coarse_op = space.operators[s], space.operators[s + 1]
        X, *_ = np.linalg.lstsq(fine_op.T.toarray(), coarse_op.T.toarray(), rcond=None)
        assert np.abs(fine_op.T @ X - coarse_op.T).max() < 1e-10
    # a glued field evaluated on both sides of the seam (u = 0 and u = 1) agrees
    rng = np.random.default_rng(2)
    q_s = rng.standard_normal(space.operators[-1].shape[0])
    ctrl = space.control_point_values(q_s, space.n_levels - 1)
    v = rng.uniform(0, 1, 20)
    left = coarse.basis(np.column_stack([np.zeros(20), v])) @ ctrl
    right = coarse.basis(np.column_stack([np.ones(20), v])) @ ctrl
    assert_allclose(left, right, atol=1e-12)


def _cubic_rectangle():
    corners = [[-L / 2, -W / 2, 0.0], [L / 2, -W / 2, 0.0], [L / 2, W / 2, 0.0], [-L / 2, W / 2, 0.0]]
    return quadrilateral(corners, degrees=(3, 3))


def test_multilevel_space_refuses_a_spline_degree_above_the_element_degree():
    """A Q9 mesh made from the spline claims Eq. 16, which a degree-3 spline breaks."""
    mesh = fe_mesh_from_spline(refine_uniform(rectangle(L, W), 2)[0], "Q9")
    with pytest.raises(ElementDegreeError, match=r"coarse_patch: degree \(3, 3\).*Q9 elements"):
        multilevel_space(_cubic_rectangle(), 2, mesh.nodes, uv=mesh.uv, family="Q9")
    with pytest.raises(ElementDegreeError, match=r"degree \(2, 2\).*Q4 elements"):
        multilevel_space(rectangle(L, W), 2, mesh.nodes, uv=mesh.uv, family="Q4")
    multilevel_space(rectangle(L, W), 2, mesh.nodes, uv=mesh.uv, family="Q9")      # accepted


def test_degree_3_spline_on_a_legacy_q9_mesh_interpolates_at_the_nodes_only():
    """Point inversion (no family, Eq. 16 not claimed): C^T q_s is the cubic spline at the
    nodes exactly; between them the Q9 interpolant converges (h^3), it is not exact."""
    coarse = _cubic_rectangle()
    rng = np.random.default_rng(4)
    errors = []
    for times in (2, 3):
        mesh = fe_mesh_from_spline(refine_uniform(rectangle(L, W), times)[0], "Q9")  # another spline's mesh
        space = multilevel_space(coarse, 2, mesh.nodes)                               # point inversion
        patch = space.patch(0)
        q_s = np.cos(np.arange(patch.n_dofs))                   # one fixed field of level 0
        field = NdBSpline(patch.knots, q_s.reshape(patch.shape), patch.degrees)
        uv_nodes = (mesh.nodes[:, :2] + [L / 2, W / 2]) / [L, W]       # the flat map is affine
        assert_allclose(space.operators[0].T @ q_s, field(uv_nodes), atol=1e-12)
        values, uv = fe_interpolant_at_random_points(mesh, space.operators[0].T @ q_s, rng)
        errors.append(np.abs(values - field(uv)).max())
    assert errors[0] > 1e-6 and errors[1] < errors[0] / 4, errors
