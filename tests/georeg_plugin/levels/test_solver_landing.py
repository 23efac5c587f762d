"""The step of the schedule's finest level lands in its span (georeg_plugin.levels.solver).

From a state ``q`` off the span (a start interpolated from matched features), the step of
Eq. 21 alone keeps for ever the part of ``q`` that no step in the span changes. At the finest
level of the schedule the step is ``d = G_s (b + H q) - q``, ``G_s = C_s^T (C_s H C_s^T)^-1 C_s``
(the optimum of the Gauss-Newton model over the level's dofs), on the FE dofs some integration
point sees; for ``q`` in the span it is Eq. 21's ``G_s b``.
"""
import numpy as np
import scipy.sparse as sps
from numpy.testing import assert_allclose

from georeg_plugin.levels.operators import MultilevelSpace
from georeg_plugin.levels.solver import GeometricRegularization

N_FE, M_FINE, M_COARSE, UNSEEN = 14, 6, 3, 2


def _case(seed=3):
    """Two nested levels (C_1 = R C_0), an SPD H whose last UNSEEN FE dofs no point sees."""
    rng = np.random.default_rng(seed)
    C0 = rng.standard_normal((M_FINE, N_FE))
    C1 = rng.standard_normal((M_COARSE, M_FINE)) @ C0                       # nested (Eq. 13)
    A = rng.standard_normal((N_FE - UNSEEN, N_FE - UNSEEN))
    H = np.zeros((N_FE, N_FE))
    H[:-UNSEEN, :-UNSEEN] = A @ A.T + np.eye(N_FE - UNSEEN)
    space = MultilevelSpace(patches=(None, None), operators=(sps.csr_matrix(C0),
                                                             sps.csr_matrix(C1)))
    return space, C0, sps.csr_matrix(H), rng.standard_normal(N_FE), rng


def _g(C, H, v):
    """G v = C^T (C H C^T)^-1 C v, dense."""
    H = H.toarray()
    return C.T @ np.linalg.solve(C @ H @ C.T, C @ v)


def test_from_off_the_span_the_step_lands_on_the_level_s_optimum():
    space, C0, H, b, rng = _case()
    reg = GeometricRegularization(space)                  # schedule: scale s -> level s
    assert reg.landing_level == 0
    q = rng.standard_normal(N_FE)                         # off the 6-dimensional span
    d = reg.solve(H, b, q, 0)
    seen = np.arange(N_FE) < N_FE - UNSEEN
    assert_allclose((q + d)[seen], _g(C0, H, b + H @ q)[seen], rtol=1e-9, atol=1e-10)
    # the landed state is a spline field: C_0^T a for some a (on the seen dofs)
    a, *_ = np.linalg.lstsq(C0.T[seen], (q + d)[seen], rcond=None)
    assert np.linalg.norm(C0.T[seen] @ a - (q + d)[seen]) < 1e-9 * np.linalg.norm(q)
    # the step of Eq. 21 alone does not land: q's part off the span stays
    plain = q + _g(C0, H, b)
    a, *_ = np.linalg.lstsq(C0.T[seen], plain[seen], rcond=None)
    assert np.linalg.norm(C0.T[seen] @ a - plain[seen]) > 0.1 * np.linalg.norm(q)
    # the dofs no point sees keep their value: there the step is Eq. 21's
    assert_allclose(d[~seen], _g(C0, H, b)[~seen], rtol=1e-9, atol=1e-10)


def test_in_the_span_the_step_is_eq_21():
    space, C0, H, b, rng = _case(5)
    reg = GeometricRegularization(space)
    q = C0.T @ rng.standard_normal(M_FINE)                # a spline field of the level
    assert_allclose(reg.solve(H, b, q, 0), _g(C0, H, b), rtol=1e-8, atol=1e-10)
    assert_allclose(reg.solve(H, b, np.zeros(N_FE), 0), _g(C0, H, b), rtol=1e-9, atol=1e-12)


def test_a_coarser_level_keeps_the_detail_of_the_state():
    """Scale 1 solves on level 1, coarser than the landing level: Eq. 21, whatever q."""
    space, C0, H, b, rng = _case(7)
    reg = GeometricRegularization(space)
    C1 = space.operators[1].toarray()
    for q in (np.zeros(N_FE), rng.standard_normal(N_FE)):
        assert_allclose(reg.solve(H, b, q, 1), _g(C1, H, b), rtol=1e-9, atol=1e-10)


def test_the_landing_level_is_the_finest_of_the_schedule():
    space, C0, H, b, rng = _case(9)
    coarse_only = GeometricRegularization(space, {2: 1, 3: 1})
    assert coarse_only.landing_level == 1
    C1 = space.operators[1].toarray()
    q = rng.standard_normal(N_FE)
    seen = np.arange(N_FE) < N_FE - UNSEEN
    d = coarse_only.solve(H, b, q, 2)
    assert_allclose((q + d)[seen], _g(C1, H, b + H @ q)[seen], rtol=1e-9, atol=1e-10)
    # the factorized map (a Gauss-Newton with a constant H) is the same step
    assert_allclose(coarse_only.factorize(H, 3)(b, q), d, rtol=1e-12, atol=1e-12)
