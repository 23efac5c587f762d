"""Univariate B-spline basis: validation, values, derivatives, Greville, insertion."""
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

from georeg_plugin.spline.bspline import basis_matrix, greville, insertion_matrix, validate_knots


@st.composite
def knot_vectors(draw, degrees=(1, 4)):
    """Random valid open knot vector on a random interval, with its degree."""
    p = draw(st.integers(*degrees))
    a = draw(st.floats(-5, 5))
    length = draw(st.floats(0.5, 10))
    n_int = draw(st.integers(0, 5))
    cuts = np.sort(draw(st.lists(st.floats(0.05, 0.95), min_size=n_int, max_size=n_int,
                                 unique=True)))
    values = np.unique(a + length * cuts)          # distinct after rounding too
    mult = draw(st.lists(st.integers(1, p), min_size=values.size, max_size=values.size))
    interior = np.repeat(values, mult)
    t = np.r_[np.full(p + 1, a), interior, np.full(p + 1, a + length)]
    return t, p


def _points(t, rng, m=200):
    """Random points, every knot and both ends."""
    return np.r_[rng.uniform(t[0], t[-1], m), np.unique(t)]


def _reference(x, t, p, nu=0):
    """Each basis function as a scipy BSpline with a unit coefficient vector."""
    n = len(t) - p - 1
    return np.stack([BSpline(t, np.eye(n)[i], p)(x, nu=nu) for i in range(n)], axis=1)


@settings(max_examples=40, deadline=None)
@given(knot_vectors(), st.integers(0, 2**31))
def test_partition_of_unity_and_scipy_reference(tp, seed):
    t, p = tp
    x = _points(t, np.random.default_rng(seed))
    N = basis_matrix(x, t, p)
    assert N.shape == (len(x), len(t) - p - 1)
    np.testing.assert_allclose(N.sum(axis=1).A1, 1.0, atol=1e-13)
    np.testing.assert_allclose(N.toarray(), _reference(x, t, p), atol=1e-13)
    # right end: the last function is one there
    assert basis_matrix([t[-1]], t, p).toarray()[0, -1] == pytest.approx(1.0, abs=1e-14)


@settings(max_examples=40, deadline=None)
@given(knot_vectors(degrees=(1, 3)), st.integers(0, 2**31))
@example(tp=(np.array([0.0, 0.0, 0.0, 0.0, 0.389, 0.391, 0.391, 1.0, 1.0, 1.0, 1.0]), 3), seed=0)
def test_first_derivative_matches_central_differences(tp, seed):
    t, p = tp
    rng = np.random.default_rng(seed)
    # the step scales with the shortest knot span: the central difference errs by about
    # (h / span)^2 of the derivative inside a span (its third derivative ~ 1 / span^2), which
    # an absolute step made 1e-7 of it on spans of 0.002 (hypothesis found one)
    h = 1e-4 * np.diff(np.unique(t)).min()
    x = rng.uniform(t[0], t[-1], 300)
    x = x[np.min(np.abs(x[:, None] - np.unique(t)[None, :]), axis=1) > 2 * h]
    fd = (basis_matrix(x + h, t, p) - basis_matrix(x - h, t, p)).toarray() / (2 * h)
    dN = basis_matrix(x, t, p, derivative=1).toarray()
    scale = np.abs(dN).max()
    assert np.abs(fd - dN).max() <= 1e-7 * scale
    np.testing.assert_allclose(dN.sum(axis=1), 0.0, atol=1e-11 * scale)


@settings(max_examples=30, deadline=None)
@given(knot_vectors(degrees=(1, 4)), st.integers(0, 2**31))
def test_higher_derivatives_match_scipy_including_right_end(tp, seed):
    t, p = tp
    x = _points(t, np.random.default_rng(seed), m=50)
    for d in range(1, p + 2):
        ref = _reference(x, t, p, nu=d) if d <= p else np.zeros((len(x), len(t) - p - 1))
        got = basis_matrix(x, t, p, derivative=d).toarray()
        assert np.abs(got - ref).max() <= 1e-10 * max(1.0, np.abs(ref).max())


@settings(max_examples=40, deadline=None)
@given(knot_vectors(), st.integers(0, 2**31))
def test_greville_linear_precision(tp, seed):
    t, p = tp
    x = _points(t, np.random.default_rng(seed))
    np.testing.assert_allclose(basis_matrix(x, t, p) @ greville(t, p), x,
                               atol=1e-12 * np.abs(t).max())


@settings(max_examples=40, deadline=None)
@given(knot_vectors(), st.integers(0, 2**31), st.lists(st.floats(0.01, 0.99), max_size=6))
def test_insertion_matrix_reproduces_coarse_basis(tp, seed, cuts):
    t, p = tp
    new = t[0] + (t[-1] - t[0]) * np.asarray(cuts)
    merged = np.sort(np.r_[t, new])
    _, counts = np.unique(merged[p + 1:-p - 1], return_counts=True)
    if counts.size and counts.max() > p:
        with pytest.raises(ValueError, match="multiplicity"):
            insertion_matrix(t, p, new)
        return
    C, tf = insertion_matrix(t, p, new)
    np.testing.assert_array_equal(tf, merged)
    assert C.shape == (len(t) - p - 1, len(tf) - p - 1)
    x = _points(tf, np.random.default_rng(seed))
    Nc = basis_matrix(x, t, p).toarray()
    Nf = basis_matrix(x, tf, p).toarray()
    np.testing.assert_allclose(Nc, Nf @ C.T.toarray(), atol=1e-13)  # Eq. 13
    np.testing.assert_allclose(C.sum(axis=0).A1, 1.0, atol=1e-13)


def test_insertion_is_composable():
    t = np.r_[0, 0, 0, 0.5, 1, 1, 1.0]
    C1, t1 = insertion_matrix(t, 2, [0.25])
    C2, t2 = insertion_matrix(t1, 2, [0.75])
    C, tf = insertion_matrix(t, 2, [0.75, 0.25])
    np.testing.assert_array_equal(tf, t2)
    np.testing.assert_allclose((C1 @ C2).toarray(), C.toarray(), atol=1e-15)


@pytest.mark.parametrize("knots, degree, match", [
    ([0, 0, 1, 1], -1, "degree"),
    ([0, 0, 1, 1], 1.5, "degree"),
    ([0, 0, 0, 1, 1], 1, "index 0"),
    ([0, 0, 0.5, 0.2, 1, 1], 1, "index 3"),
    ([0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1], 2, "multiplicity 3"),
    ([0, 0, 0, 1, 1], 2, "degree\\+1"),
    ([0, 0, np.nan, 1, 1], 1, "index 2"),
    ([[0, 0], [1, 1]], 1, "1-D"),
    ([1, 1, 1, 1], 1, "empty"),
])
def test_invalid_knots_raise_naming_the_fault(knots, degree, match):
    with pytest.raises(ValueError, match=match) as err:
        validate_knots(knots, degree, name="knots_u")
    assert "knots_u" in str(err.value)


def test_points_outside_and_bad_insertions_raise():
    t = np.r_[0, 0, 0, 1, 1, 1.0]
    with pytest.raises(ValueError, match="x: parameter value 1.5"):
        basis_matrix([0.5, 1.5], t, 2)
    with pytest.raises(ValueError, match="new_knots"):
        insertion_matrix(t, 2, [1.0])
    with pytest.raises(ValueError, match="derivative"):
        basis_matrix([0.5], t, 2, derivative=-1)
