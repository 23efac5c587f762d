"""The step solvers' factorize-once path and the cache that reuses it (CachedFactorization)."""
import copy
import pickle

import numpy as np
import pytest
import scipy.sparse as sps

from fesdic_core.solve.solvers import (CachedFactorization, DirectSolver, SingularSystemError,
                                       sparse_factor, sparse_solve)


def _spd(n, seed=0):
    rng = np.random.default_rng(seed)
    A = sps.random(n, n, density=0.05, random_state=rng, format="csr")
    return sps.csr_matrix(A @ A.T + 0.5 * sps.identity(n)), rng


def test_sparse_factor_solves_as_the_dense_inverse():
    H, rng = _spd(80)
    b = rng.standard_normal(80)
    expected = np.linalg.solve(H.toarray(), b)
    np.testing.assert_allclose(sparse_factor(H)(b), expected, rtol=1e-10)
    np.testing.assert_allclose(sparse_solve(H, b), expected, rtol=1e-10)


def test_sparse_factor_names_an_empty_row():
    H, _ = _spd(10)
    H = sps.lil_matrix(H)
    H[4, :] = 0.0
    H[:, 4] = 0.0
    with pytest.raises(SingularSystemError, match="first: dof 4"):
        sparse_factor(H, "H")


class _CountingSolver(DirectSolver):
    def __init__(self):
        self.factorizations = 0

    def factorize(self, H, scale):
        self.factorizations += 1
        return super().factorize(H, scale)


def test_the_cache_factorizes_each_matrix_once_and_gives_the_fresh_step():
    """Same H object: one factorization, and every step identical (bit for bit) to a fresh
    factorization's; another object (even equal) or another scale: a new factorization."""
    H, rng = _spd(60)
    inner = _CountingSolver()
    solver = CachedFactorization(inner)
    for _ in range(4):
        b = rng.standard_normal(60)
        assert np.array_equal(solver.solve(H, b, b, 0), sparse_factor(H)(b))
    assert inner.factorizations == 1
    solver.solve(H, b, b, 1)
    solver.solve(H.copy(), b, b, 0)
    assert inner.factorizations == 3
    # deepcopy (a frame's copy of the series' solver) shares the factors; pickling drops them
    assert copy.deepcopy(solver) is solver
    again = pickle.loads(pickle.dumps(solver))
    assert again._steps == {} and isinstance(again.solver, _CountingSolver)
    np.testing.assert_array_equal(again.solve(H, b, b, 0), solver.solve(H, b, b, 0))


def test_the_cache_keeps_at_most_its_entries_and_passes_solvers_without_factorize():
    H, rng = _spd(30)
    inner = _CountingSolver()
    solver = CachedFactorization(inner, max_entries=2)
    matrices = [H + k * sps.identity(30) for k in range(3)]
    b = rng.standard_normal(30)
    for M in matrices:
        solver.solve(M, b, b, 0)
    assert len(solver._steps) == 2 and inner.factorizations == 3
    solver.solve(matrices[2], b, b, 0)                       # the newest stays
    assert inner.factorizations == 3

    class Plain:
        def solve(self, H, b, q, scale):
            return 2.0 * b
    np.testing.assert_array_equal(CachedFactorization(Plain()).solve(H, b, b, 0), 2.0 * b)
