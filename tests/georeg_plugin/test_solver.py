"""GeometricRegularization: the solve hook of Eqs. 18-21 against dense linear algebra."""
import numpy as np
import pytest
import scipy.sparse as sps
from numpy.testing import assert_allclose

from georeg_plugin.operators import MultilevelSpace
from georeg_plugin.solver import GeometricRegularization, SingularProjectionError


def _random_spd(n, rng, density=0.05):
    A = sps.random(n, n, density=density, random_state=rng, format="csr")
    return sps.csr_matrix(A @ A.T + sps.identity(n) * 0.5)


def _random_full_row_rank(m, n, rng, density=0.1):
    """Sparse (m, n), m < n, full row rank: a random pattern plus a shifted identity."""
    C = sps.random(m, n, density=density, random_state=rng, format="csr")
    C = C + sps.eye(m, n, k=int(rng.integers(0, n - m)))
    C = sps.csr_matrix(C)
    assert np.linalg.matrix_rank(C.toarray()) == m
    return C


@pytest.fixture
def two_levels():
    rng = np.random.default_rng(0)
    n = 60
    C0 = _random_full_row_rank(25, n, rng)
    Cr = _random_full_row_rank(8, 25, rng)
    space = MultilevelSpace(patches=(None, None), operators=(C0, Cr @ C0),
                            refinement=(Cr,))
    return space, rng


def test_step_equals_dense_formula_eq_18_21(two_levels):
    space, rng = two_levels
    reg = GeometricRegularization(space)
    H = _random_spd(space.n_fe, rng)
    b = rng.standard_normal(space.n_fe)
    for scale in (0, 1, 5):
        s = min(scale, 1)
        C = space.operators[s].toarray()
        expected = C.T @ np.linalg.solve(C @ H.toarray() @ C.T, C @ b)
        d = reg.solve(H, b, np.zeros(space.n_fe), scale)
        assert_allclose(d, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())


def test_identity_hessian_gives_orthogonal_projection(two_levels):
    space, rng = two_levels
    reg = GeometricRegularization(space)
    b = rng.standard_normal(space.n_fe)
    d = reg.solve(sps.identity(space.n_fe, format="csr"), b, np.zeros(space.n_fe), 0)
    Ct = space.operators[0].T.toarray()
    # b - d is orthogonal to range(C^T), d lies in range(C^T), and d is idempotent
    assert_allclose(Ct.T @ (b - d), 0.0, atol=1e-10)
    coef, *_ = np.linalg.lstsq(Ct, d, rcond=None)
    assert_allclose(Ct @ coef, d, atol=1e-10)
    d2 = reg.solve(sps.identity(space.n_fe, format="csr"), d, d, 0)
    assert_allclose(d2, d, atol=1e-10)


def test_control_values_recover_q_in_range(two_levels):
    space, rng = two_levels
    reg = GeometricRegularization(space)
    for level in (0, 1):
        q_s = rng.standard_normal(space.operators[level].shape[0])
        q = reg.to_nodes(q_s, level)
        assert_allclose(reg.control_values(q, level), q_s, rtol=1e-9, atol=1e-10)


def test_control_values_is_least_squares_for_q_out_of_range(two_levels):
    space, rng = two_levels
    reg = GeometricRegularization(space)
    q = rng.standard_normal(space.n_fe)
    Ct = space.operators[1].T.toarray()
    expected, *_ = np.linalg.lstsq(Ct, q, rcond=None)
    assert_allclose(reg.control_values(q, 1), expected, rtol=1e-9, atol=1e-10)


def test_project_matches_eqs_18_19(two_levels):
    space, rng = two_levels
    reg = GeometricRegularization(space)
    H = _random_spd(space.n_fe, rng)
    b = rng.standard_normal(space.n_fe)
    H1, b1 = reg.project(H, b, 1)
    # Eq. 20: the coarse operators are the refinement of the fine spline ones
    H0, b0 = reg.project(H, b, 0)
    Cr = space.refinement[0]
    assert_allclose(H1.toarray(), (Cr @ H0 @ Cr.T).toarray(), rtol=1e-12, atol=1e-12)
    assert_allclose(b1, Cr @ b0, rtol=1e-12, atol=1e-12)


def test_schedule_maps_scale_to_level(two_levels):
    space, _ = two_levels
    assert GeometricRegularization(space).level(3) == 1
    reg = GeometricRegularization(space, schedule={0: 0, 1: 0, 2: 1})
    assert [reg.level(s) for s in (0, 1, 2)] == [0, 0, 1]
    with pytest.raises(ValueError, match="scale 3"):
        reg.level(3)
    with pytest.raises(ValueError, match="schedule"):
        GeometricRegularization(space, schedule={0: 2})


def test_singular_projection_names_the_unseen_dof(two_levels):
    space, rng = two_levels
    reg = GeometricRegularization(space)
    C = space.operators[0]
    unseen = 3
    seen_nodes = np.flatnonzero(C[unseen].toarray().ravel() == 0)
    # H that vanishes on every node where spline dof 3 lives
    mask = np.zeros(space.n_fe)
    mask[seen_nodes] = 1.0
    H = sps.diags(mask).tocsr()
    with pytest.raises(SingularProjectionError, match="level 0.*dof 3"):
        reg.solve(H, rng.standard_normal(space.n_fe), np.zeros(space.n_fe), 0)
    assert issubclass(SingularProjectionError, ValueError)


def test_rank_deficient_projection_raises(two_levels):
    space, rng = two_levels
    reg = GeometricRegularization(space)
    v = rng.standard_normal(space.n_fe)
    H = sps.csr_matrix(np.outer(v, v))  # rank one: all diagonals non zero
    with pytest.raises(SingularProjectionError, match="level 1"):
        reg.solve(H, v, np.zeros(space.n_fe), 1)


def test_mismatched_sizes_are_rejected(two_levels):
    space, _ = two_levels
    reg = GeometricRegularization(space)
    with pytest.raises(ValueError, match="do not match"):
        reg.solve(sps.identity(5, format="csr"), np.ones(5), np.zeros(5), 0)


def test_hold_unseen_keeps_unseen_dofs_and_solves_the_others(two_levels):
    space, rng = two_levels
    C = space.operators[0]
    unseen = 3
    mask = (C[unseen].toarray().ravel() == 0).astype(float)    # nodes where dof 3 does not live
    H = sps.csr_matrix(sps.diags(mask) @ _random_spd(space.n_fe, rng) @ sps.diags(mask))
    b = mask * rng.standard_normal(space.n_fe)
    d = GeometricRegularization(space, hold_unseen=True).solve(H, b, np.zeros(space.n_fe), 0)
    # the same step as the dense formula on the space without dof 3
    keep = np.arange(C.shape[0]) != unseen
    Ck = C.toarray()[keep]
    expected = Ck.T @ np.linalg.solve(Ck @ H.toarray() @ Ck.T, Ck @ b)
    assert_allclose(d, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
    # seen everywhere: identical to the default solver
    H = _random_spd(space.n_fe, rng)
    b = rng.standard_normal(space.n_fe)
    assert_allclose(GeometricRegularization(space, hold_unseen=True).solve(H, b, b, 1),
                    GeometricRegularization(space).solve(H, b, b, 1), rtol=1e-12)
