import numpy as np
import pytest

from fesdic_core.fe.mesh import element_areas, rectangle_mesh
from fesdic_core.fe.quadrature import _subcell_centres, pixel_quadrature, subdivisions
from fesdic_core.synthetic.render import demo_cameras


@pytest.fixture(scope="module")
def cameras():
    return demo_cameras(image_size=(640, 480), field_mm=72.0)


@pytest.mark.parametrize("family", ["T3", "T6", "Q4", "Q9"])
def test_weights_sum_to_the_mesh_area(family, cameras):
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, family=family)
    quad = pixel_quadrature(mesh, cameras)
    np.testing.assert_allclose(quad.weight_mm2.sum(), 60.0 * 40.0, rtol=1e-12)
    per_element = np.bincount(quad.element, weights=quad.weight_mm2)
    np.testing.assert_allclose(per_element, np.concatenate(element_areas(mesh)), rtol=1e-10)


@pytest.mark.parametrize("family", ["T3", "T6", "Q4", "Q9"])
def test_about_one_point_per_pixel(family, cameras):
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, family=family)
    quad = pixel_quadrature(mesh, cameras)
    corners = np.array([[-30, -20, 0], [30, -20, 0], [30, 20, 0], [-30, 20, 0]], float)
    area_px = max(_polygon_area(cam.project(corners)) for cam in cameras)
    # at least one point per pixel of the larger view, and not more than ~2 per pixel
    assert area_px <= quad.n_points <= 2.0 * area_px


def _polygon_area(x):
    return 0.5 * abs(np.dot(x[:, 0], np.roll(x[:, 1], -1)) - np.dot(x[:, 1], np.roll(x[:, 0], -1)))


def test_shape_functions_interpolate_the_points(cameras):
    mesh = rectangle_mesh(60.0, 40.0, 3, 2, family="Q9")
    quad = pixel_quadrature(mesh, cameras, points_per_px=0.2)
    np.testing.assert_allclose(quad.L.sum(axis=1).A1, 1.0, atol=1e-12)
    X = quad.points(mesh.nodes)
    assert np.all(np.abs(X[:, 0]) <= 30.0) and np.all(np.abs(X[:, 1]) <= 20.0)
    # points of an element lie inside that element's box (structured mesh: 20 x 20 mm cells)
    ix = np.floor((X[:, 0] + 30.0) / 20.0).astype(int)
    iy = np.floor((X[:, 1] + 20.0) / 20.0).astype(int)
    conn = mesh.blocks[0].connectivity
    centres = mesh.nodes[conn[:, :4]].mean(axis=1)
    cx = np.floor((centres[quad.element, 0] + 30.0) / 20.0).astype(int)
    cy = np.floor((centres[quad.element, 1] + 20.0) / 20.0).astype(int)
    assert np.array_equal(ix, cx) and np.array_equal(iy, cy)


@pytest.mark.parametrize("reference,n", [("triangle", (1, 1)), ("triangle", (4, 4)), ("quad", (3, 5))])
def test_subcells_tile_the_reference_element(reference, n):
    xi, area = _subcell_centres(reference, n)
    assert np.isclose(area.sum(), 0.5 if reference == "triangle" else 4.0)
    if reference == "triangle":
        assert np.all(xi > 0) and np.all(xi.sum(axis=1) < 1)
    assert len(np.unique(np.round(xi, 12), axis=0)) == len(xi)


def test_subdivisions_follow_the_projected_size(cameras):
    mesh = rectangle_mesh(60.0, 30.0, 3, 1, family="Q4")          # 20 x 30 mm elements
    n = subdivisions(mesh.nodes, mesh.blocks[0].connectivity, "quad", cameras)
    px_per_mm = cameras[0].K[0, 0] / 400.0
    assert np.all(np.abs(n[:, 0] / (20.0 * px_per_mm) - 1) < 0.15)
    assert np.all(np.abs(n[:, 1] / (30.0 * px_per_mm) - 1) < 0.15)


@pytest.mark.parametrize("family", ["T6", "Q9"])
def test_element_groups_agree_with_the_sparse_operator(family, cameras):
    mesh = rectangle_mesh(60.0, 40.0, 5, 3, family=family)
    quad = pixel_quadrature(mesh, cameras, points_per_px=0.3)
    rng = np.random.default_rng(0)
    nodes = rng.standard_normal((mesh.n_nodes, 3))
    np.testing.assert_allclose(quad.points(nodes), quad.L @ nodes, rtol=0, atol=1e-12)
    np.testing.assert_allclose(quad.points(nodes[:, 0]), quad.L @ nodes[:, 0], rtol=0, atol=1e-12)
    v = rng.standard_normal(quad.n_points)
    np.testing.assert_allclose(quad.to_nodes(v), quad.L.T @ v, rtol=0, atol=1e-10)
    covered = np.zeros(quad.n_points, int)
    for group in quad.groups:                      # groups tile the points, element by element
        covered[group.span] += 1
        np.testing.assert_array_equal(quad.element[group.span],
                                      np.repeat(group.elements, group.points_per_element))
    assert np.all(covered == 1)
