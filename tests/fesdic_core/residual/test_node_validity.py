"""The node checks of fesdic_core.residual.validity on fields and images made to order."""
import numpy as np
import pytest

from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.imaging.noise import immerkaer_response, immerkaer_sigma
from fesdic_core.residual.validity import (EXPLAINED_RESIDUAL_TO_NOISE, MAX_NEIGHBOUR_RATIO,
                                           MAX_RESIDUAL_TO_NOISE, RESIDUAL_FACTOR,
                                           block_conditioning, neighbour_ratio, node_neighbours,
                                           node_validity, residual_limit)


def _neighbours(mesh):
    return node_neighbours([b.connectivity for b in mesh.blocks], mesh.n_nodes)


@pytest.mark.parametrize("family", ["Q4", "Q9", "T3", "T6"])
def test_neighbours_share_an_element_and_are_symmetric(family):
    mesh = rectangle_mesh(4.0, 3.0, 4, 3, family=family)
    A = _neighbours(mesh)
    assert (A != A.T).nnz == 0 and A.diagonal().sum() == 0
    for block in mesh.blocks:
        for element in block.connectivity[:3]:
            i, j = element[0], element[-1]
            assert A[i, j] and A[j, i]


@pytest.mark.parametrize("family", ["Q4", "Q9", "T3", "T6"])
def test_a_smooth_field_is_consistent_with_its_neighbours_at_every_node(family):
    """An affine field and a quadratic one (the twist k x y plus a bowl), noise-free: every
    node, boundary and corner ones included, within the threshold of its neighbours."""
    mesh = rectangle_mesh(44.0, 30.0, 11, 8, family=family)
    x, y = mesh.nodes[:, 0], mesh.nodes[:, 1]
    A = _neighbours(mesh)
    for field in (np.column_stack([0.01 * x + 0.3, -0.02 * y, 0.005 * (x + y)]),
                  np.column_stack([x * y / 600.0, (x ** 2 + y ** 2) / 2000.0, 0 * x])):
        ratio = neighbour_ratio(A, mesh.nodes, field, np.zeros_like(field))
        assert ratio.max() < 0.5 * MAX_NEIGHBOUR_RATIO, ratio.max()


def test_a_node_off_its_neighbours_stands_out():
    """One node 0.5 mm off a graded field (the twist, up to 0.07 mm between neighbours) with
    noise of 2 um: its ratio (6: the neighbours' range is the allowance) is twice the
    threshold; it is the only node beyond it (the spike widens its neighbours' range)."""
    mesh = rectangle_mesh(44.0, 30.0, 22, 15, family="Q4")
    rng = np.random.default_rng(0)
    field = np.column_stack([0.01 * mesh.nodes[:, 0], 0 * mesh.nodes[:, 0],
                             mesh.nodes[:, 0] * mesh.nodes[:, 1] / 600.0])
    field += 0.002 * rng.standard_normal(field.shape)
    i = 200
    field[i, 2] += 0.5
    A = _neighbours(mesh)
    ratio = neighbour_ratio(A, mesh.nodes, field, np.full(field.shape, 0.002))
    assert ratio[i] > 1.8 * MAX_NEIGHBOUR_RATIO
    assert np.all(ratio[A[i].indices] < MAX_NEIGHBOUR_RATIO)
    assert np.sum(ratio > MAX_NEIGHBOUR_RATIO) == 1


def test_conditioning_is_relative_to_the_median_node_per_unit_area():
    """Blocks proportional to their areas have conditioning 1; a node with a rank-deficient
    block (seen along one direction only) 0; a node without area 0."""
    rng = np.random.default_rng(1)
    area = rng.uniform(0.2, 1.0, 6)
    blocks = np.array([a * np.diag([3.0, 2.0, 1.0]) for a in area])
    blocks[2] = np.diag([5.0, 5.0, 0.0])
    area[4] = 0.0
    c = block_conditioning(blocks, area)
    np.testing.assert_allclose(c[[0, 1, 3, 5]], 1.0)
    assert c[2] == 0.0 and c[4] == 0.0
    np.testing.assert_allclose(block_conditioning(area * 2.0, area)[area > 0], 1.0)  # scalar


def test_the_residual_limit_follows_the_median_node_within_bounds():
    assert residual_limit(np.array([0.4, 0.5, 0.45, 9.0])) == pytest.approx(RESIDUAL_FACTOR * 0.475)
    assert residual_limit(np.zeros(5)) == EXPLAINED_RESIDUAL_TO_NOISE        # identical images
    assert residual_limit(np.full(5, 4.0)) == MAX_RESIDUAL_TO_NOISE
    assert residual_limit(np.array([np.nan, 0.5, 0.5])) == pytest.approx(1.0)


def test_a_node_is_valid_when_every_check_passes_and_the_failure_names_the_worst():
    n = 40
    ok = dict(residual_to_noise=np.full(n, 0.5), texture_ratio=np.full(n, 10.0),
              conditioning=np.ones(n), neighbour=np.full(n, 0.5))
    assert node_validity(**ok).valid.all()
    for name, bad in (("residual_to_noise", 1.2), ("texture_ratio", 1.0), ("conditioning", 0.001),
                      ("neighbour", 4.0), ("residual_to_noise", np.nan)):
        values = {k: v.copy() for k, v in ok.items()}
        values[name][7] = bad
        v = node_validity(**values)
        assert np.flatnonzero(~v.valid).tolist() == [7], name
    values = {k: v.copy() for k, v in ok.items()}
    values["residual_to_noise"][[3, 9]] = [1.5, 6.0]
    v = node_validity(**values)
    nodes = np.column_stack([np.arange(n), np.zeros(n), np.zeros(n)]).astype(float)
    assert v.invalid_share == pytest.approx(0.05)
    assert v.failure(nodes, 0.05) is None
    line = v.failure(nodes, 0.04)
    assert line.startswith("2 of 40 nodes (5.0 %, at most 4 %) are not valid locally")
    assert "node 9 at (9, 0, 0) mm" in line and "residual 6 times" in line


def test_the_local_noise_estimate_is_immerkaer_s_pixel_by_pixel():
    """The mean of the per-pixel response is immerkaer_sigma over the same pixels; on white
    noise of 3 gray levels over a smooth ramp it is 3 (to the estimate's scatter)."""
    rng = np.random.default_rng(2)
    h, w = 200, 300
    ramp = np.add.outer(0.3 * np.arange(h), 0.2 * np.arange(w))
    values = ramp + rng.normal(0.0, 3.0, (h, w))
    xy = np.column_stack([rng.uniform(5, w - 5, 5000), rng.uniform(5, h - 5, 5000)])
    response = immerkaer_response(values, xy)
    assert response.shape == (5000,)
    assert np.mean(response) == pytest.approx(immerkaer_sigma(values, xy), rel=1e-12)
    assert np.mean(response) == pytest.approx(3.0, rel=0.05)


@pytest.mark.parametrize("family", ["Q4", "Q9", "T3", "T6"])
def test_support_sums_weigh_the_points_by_the_squared_shape_functions(family):
    """Support.total is (L**2)^T v for one and several components, group by group."""
    from fesdic_core.fe.quadrature import pixel_quadrature
    from fesdic_core.residual.validity import Support
    from fesdic_core.synthetic.render import demo_cameras
    mesh = rectangle_mesh(30.0, 20.0, 3, 2, family=family)
    quad = pixel_quadrature(mesh, demo_cameras(image_size=(160, 120), field_mm=48.0))
    rng = np.random.default_rng(3)
    v = rng.standard_normal((quad.n_points, 4))
    L2 = quad.L.multiply(quad.L).toarray()
    support = Support(quad)
    np.testing.assert_allclose(support.total(v), L2.T @ v, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(support.total(v[:, 0]), L2.T @ v[:, 0], rtol=1e-12, atol=1e-12)
    w = rng.uniform(0.0, 1.0, quad.n_points)
    np.testing.assert_allclose(support.mean(v[:, 1], w), (L2.T @ (w * v[:, 1])) / (L2.T @ w))
