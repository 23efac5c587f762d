import numpy as np
import pytest
import scipy.sparse as sps

from fesdic_core.mesh import rectangle_mesh
from fesdic_core.tikhonov import TikhonovSolver, surface_gradient_operator, tikhonov_weight


@pytest.mark.parametrize("family", ["T3", "T6", "Q4", "Q9"])
def test_gradient_operator_energy_of_linear_fields(family):
    """q^T A q = int |grad S|^2: zero for constants, |a|^2 * area for S = a . x."""
    mesh = rectangle_mesh(30.0, 20.0, 5, 4, family=family)
    A = surface_gradient_operator(mesh)
    one = np.ones(mesh.n_nodes)
    np.testing.assert_allclose(A @ one, 0.0, atol=1e-10)
    a = np.array([0.3, -0.7])
    q = mesh.nodes[:, :2] @ a
    np.testing.assert_allclose(q @ (A @ q), (a @ a) * 600.0, rtol=1e-10)
    assert abs(A - A.T).max() < 1e-12


def test_gradient_operator_on_a_curved_surface():
    """On a cylinder of radius R, S = R * theta has |grad_s S| = 1: energy = area."""
    R = 10.0
    mesh = rectangle_mesh(np.pi * R / 2, 20.0, 16, 4, family="Q9")
    theta = mesh.nodes[:, 0] / R
    nodes = np.column_stack([R * np.sin(theta), mesh.nodes[:, 1], R * np.cos(theta)])
    curved = mesh.with_nodes(nodes)
    A = surface_gradient_operator(curved)
    S = R * theta
    np.testing.assert_allclose(S @ (A @ S), np.pi * R / 2 * 20.0, rtol=1e-4)


def test_tikhonov_weight_balances_a_cosine_of_the_given_wavelength():
    mesh = rectangle_mesh(60.0, 40.0, 60, 40, family="Q4")
    A = surface_gradient_operator(mesh)
    H = sps.identity(mesh.n_nodes, format="csr")
    lam_short = tikhonov_weight(H, A, mesh.nodes, 10.0)
    lam_long = tikhonov_weight(H, A, mesh.nodes, 20.0)
    # the cosine energy scales like (2 pi / l)^2: lam grows like l^2
    assert lam_long / lam_short == pytest.approx(4.0, rel=0.1)


def test_tikhonov_step_solves_eq_10():
    mesh = rectangle_mesh(20.0, 10.0, 4, 2, family="Q4")
    rng = np.random.default_rng(1)
    M = sps.random(mesh.n_nodes, mesh.n_nodes, density=0.3, random_state=2)
    H = (M @ M.T + sps.identity(mesh.n_nodes)).tocsr()
    b, q = rng.standard_normal(mesh.n_nodes), rng.standard_normal(mesh.n_nodes)
    solver = TikhonovSolver(mesh, length_mm=8.0)
    d = solver.solve(H, b, q, 0)
    lam, A = solver.last_lambda, solver.A
    np.testing.assert_allclose((H + lam * A) @ d, b - lam * (A @ q), atol=1e-9)


def test_bad_length_is_named():
    mesh = rectangle_mesh(20.0, 10.0, 2, 1)
    with pytest.raises(ValueError, match="tikhonov_length_mm"):
        TikhonovSolver(mesh, length_mm=-1.0)
