"""fe_mesh: Q9/Q4 meshes made from a spline (Eq. 17): nodes on the surface, order, area."""
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from georeg_plugin.spline.fe_mesh import (ElementDegreeError, check_element_degree,
                                          fe_mesh_from_spline)
from georeg_plugin.spline.geometries import cylinder, plate_with_hole, quadrilateral, rectangle
from georeg_plugin.spline.patch import invert_points
from georeg_plugin.spline.refine import insert_knots, refine_uniform

L, W, R = 100.0, 50.0, 14.0
# gmsh Q9 reference nodes on [-1, 1]^2: corners ccw, mid-edges 01 12 23 30, centre
Q9_REF = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1],
                   [0, -1], [1, 0], [0, 1], [-1, 0], [0, 0]], dtype=float)


def _lagrange_1d(x):
    """Quadratic Lagrange basis on nodes -1, 0, 1 and derivatives, each (m, 3)."""
    x = x[:, None]
    values = np.hstack([0.5 * x * (x - 1), 1 - x ** 2, 0.5 * x * (x + 1)])
    derivs = np.hstack([x - 0.5, -2 * x, x + 0.5])
    return values, derivs


def q9_shape(xi):
    """Q9 shape functions (m, 9) and derivatives (m, 9, 2) in gmsh order."""
    a = (Q9_REF[:, 0] + 1).astype(int)
    b = (Q9_REF[:, 1] + 1).astype(int)
    Nx, dNx = _lagrange_1d(xi[:, 0])
    Ny, dNy = _lagrange_1d(xi[:, 1])
    N = Nx[:, a] * Ny[:, b]
    dN = np.stack([dNx[:, a] * Ny[:, b], Nx[:, a] * dNy[:, b]], axis=-1)
    return N, dN


def q9_area(mesh):
    """Area of the Q9 isoparametric surface by 3x3 Gauss quadrature."""
    g, w = np.polynomial.legendre.leggauss(3)
    xi = np.array([[a, b] for a in g for b in g])
    wg = np.array([wa * wb for wa in w for wb in w])
    _, dN = q9_shape(xi)
    X = mesh.nodes[mesh.connectivity]                     # (ne, 9, 3)
    J = np.einsum("gnk,enc->egck", dN, X)                 # (ne, g, 3, 2)
    dA = np.linalg.norm(np.cross(J[..., 0], J[..., 1]), axis=-1)
    return float(np.sum(dA * wg))


def test_q9_nodes_lie_on_the_spline_and_hole_is_exact():
    patch, _ = refine_uniform(plate_with_hole(L, W, R), 2)
    mesh = fe_mesh_from_spline(patch, "Q9", weld=False)
    nu_el, nv_el = patch.n_elements
    assert mesh.cell_type == "quad9"
    assert mesh.connectivity.shape == (nu_el * nv_el, 9)
    assert mesh.nodes.shape == ((2 * nu_el + 1) * (2 * nv_el + 1), 3)
    assert len(np.unique(mesh.connectivity)) == mesh.n_nodes  # every node used
    # independent check: the hole nodes are on the circle, the outer ones on the box
    hole = mesh.uv[:, 1] == 0.0
    assert_allclose(np.linalg.norm(mesh.nodes[hole, :2], axis=1), R, rtol=1e-13)
    outer = mesh.uv[:, 1] == 1.0
    on_box = np.isclose(np.abs(mesh.nodes[outer, 0]), L / 2, rtol=1e-13) | \
        np.isclose(np.abs(mesh.nodes[outer, 1]), W / 2, rtol=1e-13)
    assert on_box.all()
    # point inversion finds every node on the coarse nominal surface
    _, distance = invert_points(plate_with_hole(L, W, R), mesh.nodes)
    assert distance.max() < 1e-9


def test_q9_node_order_follows_gmsh_in_parameter_space():
    patch, _ = refine_uniform(plate_with_hole(L, W, R), 1)
    mesh = fe_mesh_from_spline(patch, "Q9", weld=False)
    uv = mesh.uv[mesh.connectivity]                       # (ne, 9, 2)
    centre = uv[:, 8:9, :]
    half = 0.5 * (uv[:, 2:3, :] - uv[:, 0:1, :])
    assert np.all(half > 0)
    assert_allclose((uv - centre) / half, np.broadcast_to(Q9_REF, uv.shape), atol=1e-12)


@pytest.mark.parametrize("make", [lambda: plate_with_hole(L, W, R),
                                  lambda: cylinder(20.0, 60.0, 150.0)])
def test_fe_normal_equals_spline_normal(make):
    patch, _ = refine_uniform(make(), 2)
    mesh = fe_mesh_from_spline(patch, "Q9")
    _, dN = q9_shape(np.zeros((1, 2)))
    J = np.einsum("nk,enc->eck", dN[0], mesh.nodes[mesh.connectivity])
    n_fe = np.cross(J[..., 0], J[..., 1])
    n_fe /= np.linalg.norm(n_fe, axis=1, keepdims=True)
    n_spline = patch.normals(mesh.uv[mesh.connectivity[:, 8]])
    cosine = np.einsum("ec,ec->e", n_fe, n_spline)
    assert cosine.min() > 0.999


def test_q9_area_converges_to_plate_with_hole_area():
    exact = L * W - np.pi * R ** 2
    coarse = plate_with_hole(L, W, R)
    h, errors = [], []
    for times in range(1, 5):
        patch, _ = refine_uniform(coarse, times)
        errors.append(abs(q9_area(fe_mesh_from_spline(patch, "Q9")) - exact) / exact)
        h.append(2.0 ** -times)
    rate = np.polyfit(np.log(h), np.log(errors), 1)[0]
    assert np.all(np.diff(errors) < 0)
    # quadratic interpolation of the hole arcs: area error O(h^4)
    assert rate > 3.5, (errors, rate)
    assert errors[-1] < 1e-6


def test_rectangle_area_is_exact_and_nodes_are_linear_in_uv():
    patch, _ = refine_uniform(rectangle(L, W), 2)
    mesh = fe_mesh_from_spline(patch, "Q9")
    assert_allclose(q9_area(mesh), L * W, rtol=1e-13)
    assert_allclose(mesh.nodes[:, 0], -L / 2 + L * mesh.uv[:, 0], atol=1e-12)
    assert_allclose(mesh.nodes[:, 1], -W / 2 + W * mesh.uv[:, 1], atol=1e-12)


def _bilinear_patch(times=1):
    """A degree-(1, 1) B-spline of a skew flat quadrilateral, non-uniform knots."""
    corners = [[0.0, 0.0, 0.0], [L, 5.0, 0.0], [L + 8.0, W, 0.0], [-4.0, W - 3.0, 0.0]]
    patch, _ = insert_knots(quadrilateral(corners, degrees=(1, 1)), [0.3], [0.6])
    return refine_uniform(patch, times)[0]


def test_q4_mesh_has_the_q9_corners():
    patch = _bilinear_patch()
    q9 = fe_mesh_from_spline(patch, "Q9", weld=False)
    q4 = fe_mesh_from_spline(patch, "Q4", weld=False)
    nu_el, nv_el = patch.n_elements
    assert q4.cell_type == "quad"
    assert q4.nodes.shape == ((nu_el + 1) * (nv_el + 1), 3)
    assert_array_equal(q4.nodes[q4.connectivity], q9.nodes[q9.connectivity[:, :4]])


def test_mesh_is_frozen_and_bad_family_rejected():
    mesh = fe_mesh_from_spline(rectangle(L, W), "Q9")
    with pytest.raises(ValueError):
        mesh.nodes[0, 0] = 1.0
    with pytest.raises(ValueError, match="family"):
        fe_mesh_from_spline(rectangle(L, W), "T6")
    m = mesh.to_meshio()
    assert m.cells[0].type == "quad9" and m.points.shape == mesh.nodes.shape


def test_seam_of_the_closed_plate_is_welded():
    """u = 0 and u = 1 are the same line: welding merges exactly those nodes (conforming mesh)."""
    patch, _ = refine_uniform(plate_with_hole(L, W, R), 2)
    open_mesh = fe_mesh_from_spline(patch, "Q9", weld=False)
    welded = fe_mesh_from_spline(patch, "Q9")
    seam = np.count_nonzero(open_mesh.uv[:, 0] == 1.0)
    assert welded.n_nodes == open_mesh.n_nodes - seam
    assert_allclose(welded.nodes[welded.connectivity], open_mesh.nodes[open_mesh.connectivity], atol=1e-12)
    # no two nodes coincide any more, and every node is used
    d = np.linalg.norm(welded.nodes[:, None] - welded.nodes[None], axis=-1) + np.eye(welded.n_nodes)
    assert d.min() > 1e-6
    assert np.array_equal(np.unique(welded.connectivity), np.arange(welded.n_nodes))


@pytest.mark.parametrize("degrees,family", [((3, 3), "Q9"), ((2, 3), "Q9"), ((2, 2), "Q4"),
                                            ((1, 2), "Q4")])
def test_spline_degree_above_the_element_degree_is_refused(degrees, family):
    """Eq. 16 needs spline degree <= element degree: the error names both."""
    corners = [[0.0, 0.0, 0.0], [L, 0.0, 0.0], [L, W, 0.0], [0.0, W, 0.0]]
    patch = refine_uniform(quadrilateral(corners, degrees=degrees), 1)[0]
    with pytest.raises(ElementDegreeError,
                       match=rf"degree \({degrees[0]}, {degrees[1]}\).*{family} elements.*Eq. 16"):
        fe_mesh_from_spline(patch, family)


def test_q4_mesh_of_a_bilinear_spline_reproduces_it():
    """Degree 1 on Q4 (Eq. 16 holds): the bilinear interpolant of the nodal values of a
    spline function is that function, at random points of every element."""
    patch = _bilinear_patch(2)
    mesh = fe_mesh_from_spline(patch, "Q4", weld=False)
    rng = np.random.default_rng(2)
    c = rng.standard_normal(patch.n_dofs)
    nodal = patch.basis(mesh.uv) @ c
    s, t = rng.uniform(0.0, 1.0, (2, mesh.n_elements, 5))
    corners = mesh.connectivity                                 # (u, v) corners ccw
    weights = np.stack([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t], -1)
    values = np.einsum("ekc,ec->ek", weights, nodal[corners])
    uv = np.einsum("ekc,ecd->ekd", weights, mesh.uv[corners]).reshape(-1, 2)
    assert_allclose(values.ravel(), patch.basis(uv) @ c, atol=1e-12)
    assert_allclose(np.einsum("ekc,ecd->ekd", weights, mesh.nodes[corners]).reshape(-1, 3),
                    patch.evaluate(uv), atol=1e-10)


def test_triangles_need_the_total_degree():
    """u^p_u v^p_v has total degree p_u + p_v: a bilinear spline fits T6, not T3."""
    check_element_degree((1, 1), "T6")
    check_element_degree((1, 0), "T3")
    with pytest.raises(ElementDegreeError, match=r"degree \(1, 1\).*T3 elements.*total degree"):
        check_element_degree((1, 1), "T3")
    with pytest.raises(ElementDegreeError, match=r"degree \(2, 1\).*T6 elements"):
        check_element_degree((2, 1), "T6")
