"""Tests of the Lagrange element families (fesdic_core.fe.elements)."""
import numpy as np
import pytest

from fesdic_core.fe.elements import FAMILIES, centroid, family_from_meshio, gauss_rule

NAMES = sorted(FAMILIES)


def _random_points(family, m=50, seed=0):
    """Random parametric points inside the reference element, (m, 2)."""
    rng = np.random.default_rng(seed)
    if family.reference == "quad":
        return rng.uniform(-1.0, 1.0, size=(m, 2))
    u = rng.uniform(0.0, 1.0, size=(m, 2))
    flip = u.sum(axis=1) > 1.0
    u[flip] = 1.0 - u[flip]
    return u


@pytest.mark.parametrize("name", NAMES)
def test_nodality(name):
    family = FAMILIES[name]
    N = family.shape_functions(family.ref_nodes)
    np.testing.assert_allclose(N, np.eye(family.n_nodes), atol=1e-13)


@pytest.mark.parametrize("name", NAMES)
def test_partition_of_unity_and_zero_derivative_sum(name):
    family = FAMILIES[name]
    xi = _random_points(family)
    np.testing.assert_allclose(family.shape_functions(xi).sum(axis=1), 1.0, atol=1e-13)
    np.testing.assert_allclose(family.shape_derivatives(xi).sum(axis=1), 0.0, atol=1e-12)


@pytest.mark.parametrize("name", NAMES)
def test_derivatives_match_central_finite_differences(name):
    family = FAMILIES[name]
    xi = _random_points(family, seed=1)
    h = 1e-6
    dN = family.shape_derivatives(xi)
    assert dN.shape == (len(xi), family.n_nodes, 2)
    for a in range(2):
        step = np.zeros(2)
        step[a] = h
        fd = (family.shape_functions(xi + step) - family.shape_functions(xi - step)) / (2 * h)
        np.testing.assert_allclose(dN[:, :, a], fd, atol=1e-8)


@pytest.mark.parametrize("name", NAMES)
def test_reproduces_complete_polynomials_of_its_degree(name):
    family = FAMILIES[name]
    rng = np.random.default_rng(2)
    xi = _random_points(family, seed=3)
    # a random complete polynomial of total degree `family.degree`
    terms = [(a, b) for a in range(family.degree + 1) for b in range(family.degree + 1)
             if a + b <= family.degree]
    coef = rng.normal(size=len(terms))

    def field(p):
        return sum(c * p[:, 0] ** a * p[:, 1] ** b for c, (a, b) in zip(coef, terms))

    def gradient(p):
        gx = sum(c * a * p[:, 0] ** max(a - 1, 0) * p[:, 1] ** b for c, (a, b) in zip(coef, terms))
        gy = sum(c * b * p[:, 0] ** a * p[:, 1] ** max(b - 1, 0) for c, (a, b) in zip(coef, terms))
        return np.column_stack([gx, gy])

    nodal = field(family.ref_nodes)
    np.testing.assert_allclose(family.shape_functions(xi) @ nodal, field(xi), atol=1e-12)
    np.testing.assert_allclose(np.einsum("mia,i->ma", family.shape_derivatives(xi), nodal),
                               gradient(xi), atol=1e-11)


def test_q9_reproduces_biquadratic_field():
    family = FAMILIES["Q9"]
    xi = _random_points(family, seed=4)
    f = lambda p: (p[:, 0] ** 2) * (p[:, 1] ** 2) - 3 * p[:, 0] ** 2 * p[:, 1]  # noqa: E731
    np.testing.assert_allclose(family.shape_functions(xi) @ f(family.ref_nodes), f(xi),
                               atol=1e-12)


def test_linear_families_match_textbook_formulas():
    xi = _random_points(FAMILIES["Q4"], seed=5)
    s, t = xi[:, 0], xi[:, 1]
    q4 = 0.25 * np.column_stack([(1 - s) * (1 - t), (1 + s) * (1 - t),
                                 (1 + s) * (1 + t), (1 - s) * (1 + t)])
    np.testing.assert_allclose(FAMILIES["Q4"].shape_functions(xi), q4, atol=1e-14)
    xi = _random_points(FAMILIES["T3"], seed=6)
    t3 = np.column_stack([1 - xi[:, 0] - xi[:, 1], xi[:, 0], xi[:, 1]])
    np.testing.assert_allclose(FAMILIES["T3"].shape_functions(xi), t3, atol=1e-14)


@pytest.mark.parametrize("name", NAMES)
def test_gmsh_node_order(name):
    """Corners first (counter-clockwise), then the mid-edge nodes of the edges in order."""
    family = FAMILIES[name]
    corners = family.ref_nodes[: 3 if family.reference == "triangle" else 4]
    closed = np.vstack([corners, corners[:1]])
    signed_area = 0.5 * np.sum(closed[:-1, 0] * closed[1:, 1] - closed[1:, 0] * closed[:-1, 1])
    assert signed_area > 0
    if family.degree == 2:
        for edge in family.edges:
            np.testing.assert_allclose(family.ref_nodes[edge[2]],
                                       family.ref_nodes[edge[:2]].mean(axis=0))


@pytest.mark.parametrize("name", NAMES)
def test_centroid_is_mean_of_corners(name):
    family = FAMILIES[name]
    corners = family.ref_nodes[: 3 if family.reference == "triangle" else 4]
    np.testing.assert_allclose(centroid(family), corners.mean(axis=0), atol=1e-15)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("n_points", [1, 2, 3, 4])
def test_gauss_rule_is_exact_for_its_degree(name, n_points):
    family = FAMILIES[name]
    xi, w = gauss_rule(family, n_points)
    rng = np.random.default_rng(n_points)
    a, b = rng.integers(0, 2 * n_points - 1, size=2)
    if family.reference == "quad":
        # integral over [-1,1]^2 of x^a y^b
        one_d = lambda k: 0.0 if k % 2 else 2.0 / (k + 1)  # noqa: E731
        exact = one_d(a) * one_d(b)
    else:
        # total degree <= 2 n - 2; integral over the unit triangle = a! b! / (a + b + 2)!
        from math import factorial
        b = min(b, 2 * n_points - 2 - a) if a <= 2 * n_points - 2 else 0
        a = min(a, 2 * n_points - 2)
        exact = factorial(a) * factorial(b) / factorial(a + b + 2)
    np.testing.assert_allclose(np.sum(w * xi[:, 0] ** a * xi[:, 1] ** b), exact, rtol=1e-13)


def test_family_from_meshio_and_error():
    for family in FAMILIES.values():
        assert family_from_meshio(family.meshio_type) is family
    assert [FAMILIES[n].gmsh_type for n in ("T3", "T6", "Q4", "Q9")] == [2, 9, 3, 10]
    with pytest.raises(ValueError, match="quad8"):
        family_from_meshio("quad8")


def test_bad_points_shape_names_xi():
    with pytest.raises(ValueError, match="xi"):
        FAMILIES["Q4"].shape_functions(np.zeros(3))
