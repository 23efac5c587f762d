"""The damped Gauss-Newton loop shared by the shape and the displacement, on small least
squares problems with a known minimum."""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps

from fesdic_core.solve.gauss_newton import damped_gauss_newton, predicted_change
from fesdic_core.solve.solvers import CachedFactorization, DirectSolver


@dataclass(frozen=True)
class _Residual:
    r: np.ndarray

    @property
    def std_percent(self) -> float:
        return float(np.std(self.r))


def _problem(cubic: float, seed: int = 0, n: int = 40, m: int = 6):
    """r(q) = A (q + cubic q**3) - y, noise of 0.01 on y; the linear part's H = A^T A."""
    rng = np.random.default_rng(seed)
    A = sps.csr_matrix(rng.standard_normal((n, m)))
    q_true = rng.standard_normal(m)
    y = A @ (q_true + cubic * q_true ** 3) + 0.01 * rng.standard_normal(n)
    H = sps.csr_matrix(A.T @ A)

    def evaluate(q):
        return _Residual(A @ (q + cubic * q ** 3) - y)

    return A, H, y, evaluate, q_true


def _chi_square(res):
    return float(res.r @ res.r), len(res.r)


def test_a_linear_problem_takes_one_step_and_stops_on_the_next_plain_step():
    """Linear: the first Gauss-Newton step is the least-squares solution; the next plain step
    is zero (stagnant, not taken, not counted)."""
    A, H, y, evaluate, _ = _problem(cubic=0.0)
    q = np.zeros(H.shape[0])
    out = damped_gauss_newton(q, evaluate(q), evaluate, lambda res: (H, -(A.T @ res.r)),
                              lambda H, b, q: DirectSolver().solve(H, b, q, 0), _chi_square,
                              tol=1e-9, max_iter=10, max_damping=4)
    expected = np.linalg.lstsq(A.toarray(), y, rcond=None)[0]
    np.testing.assert_allclose(out.q, expected, rtol=1e-10)
    assert out.converged and out.iterations == 1 and out.stop in ("step", "noise")


def test_a_constant_hessian_is_factorized_once_and_reaches_the_minimum():
    """The modified Gauss-Newton on a nonlinear problem: H of the linear part at every
    iteration (the same object): each matrix (H, and H + mu diag H of each damping used)
    factorized once over all the iterations, and the minimum of the full problem reached
    (where its gradient J^T r vanishes)."""
    A, H, y, evaluate, q_true = _problem(cubic=0.05)
    calls = []

    class Counting(DirectSolver):
        def factorize(self, H, scale):
            calls.append(H)
            return super().factorize(H, scale)

    solver = CachedFactorization(Counting())
    q = np.zeros(H.shape[0])
    out = damped_gauss_newton(q, evaluate(q), evaluate, lambda res: (H, -(A.T @ res.r)),
                              lambda H, b, q: solver.solve(H, b, q, 0), _chi_square,
                              tol=1e-12, max_iter=50, max_damping=4)
    assert out.iterations > len(calls) > 1                      # damped steps were needed
    assert sum(M is H for M in calls) == 1 and len({id(M) for M in calls}) == len(calls)
    J = A.toarray() * (1.0 + 3 * 0.05 * out.q ** 2)                  # dr/dq
    gradient = J.T @ evaluate(out.q).r
    assert np.linalg.norm(gradient) < 1e-2 * np.linalg.norm(A.T @ evaluate(q).r)


def test_predicted_change_is_the_linear_models_fall():
    A, H, y, evaluate, _ = _problem(cubic=0.0)
    q = np.zeros(H.shape[0])
    res = evaluate(q)
    b = -(A.T @ res.r)
    d = np.linalg.solve(H.toarray(), b)
    c, n = _chi_square(res)
    after = _chi_square(evaluate(q + d))[0]
    np.testing.assert_allclose(predicted_change(H, b, d, (c, n)), (c - after) * n / c, rtol=1e-9)
