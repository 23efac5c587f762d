"""The displacement's step solvers on the node-major dofs: the factorize-once path."""
import numpy as np
import scipy.sparse as sps

from fesdic_core.displacement.solvers import ComponentTikhonovSolver
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.solve.solvers import CachedFactorization


def _hessian(n, rng):
    """A symmetric positive definite (n, n) with a weaker third component, as a stereo rig's."""
    A = sps.random(n, n, density=0.05, random_state=rng, format="csr")
    weight = np.tile([1.0, 1.0, 0.2], n // 3)
    return sps.csr_matrix(sps.diags(weight) @ (A @ A.T + sps.identity(n)) @ sps.diags(weight))


def test_tikhonov_factorize_is_its_solve_and_the_cache_keeps_its_weights():
    """``factorize(H, s)(b, q)`` equals ``solve(H, b, q, s)`` (Eq. 10, ``q`` moves the
    right-hand side) for several right-hand sides; through the cache the weights of a scale
    are chosen once from the H of the scale."""
    mesh = rectangle_mesh(40.0, 30.0, 8, 6, family="Q4")
    n = 3 * mesh.n_nodes
    rng = np.random.default_rng(2)
    H = _hessian(n, rng)
    solver = ComponentTikhonovSolver(mesh, 20.0)
    cached = CachedFactorization(ComponentTikhonovSolver(mesh, 20.0))
    for _ in range(3):
        b, q = rng.standard_normal(n), rng.standard_normal(n)
        step = solver.solve(H, b, q, 0)
        np.testing.assert_allclose(solver.factorize(H, 0)(b, q), step, rtol=1e-10,
                                   atol=1e-12 * np.abs(step).max())
        np.testing.assert_allclose(cached.solve(H, b, q, 0), step, rtol=1e-10,
                                   atol=1e-12 * np.abs(step).max())
    np.testing.assert_array_equal(cached.solver.component_lambdas[0], solver.component_lambdas[0])
    assert cached.solver.component_lambdas[0][2] < solver.component_lambdas[0][0]
