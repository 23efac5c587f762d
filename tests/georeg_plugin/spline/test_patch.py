"""SplinePatch: validation, tensor-product / NURBS basis, geometry, point inversion."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from georeg_plugin.spline.bspline import basis_matrix
from georeg_plugin.spline.geometries import plate_with_hole, rectangle
from georeg_plugin.spline.patch import SplinePatch, invert_points


def curved_patch(degrees=(2, 3), rational=False, seed=0):
    """A wavy patch over [0, 10] x [0, 8] with interior knots (one C0 knot in u if p>1)."""
    rng = np.random.default_rng(seed)
    pu, pv = degrees
    tu = np.r_[np.zeros(pu + 1), 0.3, [0.6] * max(pu - 1, 1), np.ones(pu + 1)]
    tv = np.r_[np.zeros(pv + 1), 0.5, np.ones(pv + 1)]
    nu, nv = len(tu) - pu - 1, len(tv) - pv - 1
    U, V = np.meshgrid(np.linspace(0, 10, nu), np.linspace(0, 8, nv), indexing="ij")
    cp = np.stack([U, V, rng.normal(0, 1, (nu, nv))], axis=-1)
    w = rng.uniform(0.5, 2.0, (nu, nv)) if rational else None
    return SplinePatch(degrees, (tu, tv), cp, w)


def random_uv(rng, m=500):
    uv = rng.uniform(0, 1, (m, 2))
    uv[:20, 0] = rng.integers(0, 2, 20)       # boundary u = 0, 1
    uv[20:40, 1] = rng.integers(0, 2, 20)     # boundary v = 0, 1
    uv[40:44] = [[0, 0], [0, 1], [1, 0], [1, 1]]
    return uv


@pytest.mark.parametrize("rational", [False, True])
@pytest.mark.parametrize("degrees", [(1, 1), (2, 2), (3, 2), (2, 3)])
def test_partition_of_unity_and_tensor_structure(degrees, rational):
    s = curved_patch(degrees, rational)
    uv = random_uv(np.random.default_rng(1))
    R = s.basis(uv)
    assert R.shape == (len(uv), s.n_dofs)
    np.testing.assert_allclose(R.sum(axis=1).A1, 1.0, atol=1e-14)
    Nu = basis_matrix(uv[:, 0], s.knots[0], s.degrees[0]).toarray()
    Nv = basis_matrix(uv[:, 1], s.knots[1], s.degrees[1]).toarray()
    N = (Nu[:, :, None] * Nv[:, None, :]).reshape(len(uv), -1)  # dof i * nv + j
    w = s.homogeneous_weights
    expected = N * w / (N @ w)[:, None]                        # Eq. 12
    np.testing.assert_allclose(R.toarray(), expected, atol=1e-14)
    for derivative in ("u", "v"):
        np.testing.assert_allclose(s.basis(uv, derivative).sum(axis=1).A1, 0.0,
                                   atol=1e-11)


@pytest.mark.parametrize("degrees, rational", [((1, 1), False), ((2, 2), False),
                                               ((3, 3), False), ((2, 2), True)])
def test_derivatives_match_central_differences(degrees, rational):
    s = curved_patch(degrees, rational)
    rng = np.random.default_rng(2)
    h = 1e-6
    uv = rng.uniform(2 * h, 1 - 2 * h, (400, 2))
    knots = np.unique(np.r_[s.knots[0], s.knots[1]])
    uv = uv[np.all(np.min(np.abs(uv[:, :, None] - knots), axis=2) > 2 * h, axis=1)]
    for k, derivative in enumerate(("u", "v")):
        e = np.zeros(2)
        e[k] = h
        fd = (s.basis(uv + e) - s.basis(uv - e)).toarray() / (2 * h)
        exact = s.basis(uv, derivative).toarray()
        assert np.abs(fd - exact).max() <= 1e-7 * np.abs(exact).max()
        fd_x = (s.evaluate(uv + e) - s.evaluate(uv - e)) / (2 * h)
        dS = s.derivatives(uv)[k]
        assert np.abs(fd_x - dS).max() <= 1e-7 * np.abs(dS).max()


def test_evaluate_is_basis_times_control_points_and_normals_are_unit():
    s = curved_patch((2, 3), rational=True)
    uv = random_uv(np.random.default_rng(3))
    np.testing.assert_allclose(s.evaluate(uv),
                               s.basis(uv) @ s.control_points.reshape(-1, 3), atol=1e-12)
    n = s.normals(uv)
    su, sv = s.derivatives(uv)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.sum(n * su, 1), 0.0, atol=1e-12 * np.abs(su).max())
    np.testing.assert_allclose(np.sum(n * sv, 1), 0.0, atol=1e-12 * np.abs(sv).max())


def test_control_normals_at_greville_points():
    s = curved_patch((2, 2))
    g = s.greville_points()
    assert g.shape == (s.n_dofs, 2)
    i, j = 2, 1
    assert g[i * s.shape[1] + j, 0] == pytest.approx(np.mean(s.knots[0][i + 1:i + 3]))
    np.testing.assert_allclose(s.control_normals(), s.normals(g), atol=0)
    flat = rectangle(100.0, 40.0)
    np.testing.assert_allclose(flat.control_normals(), np.tile([0, 0, 1.0], (9, 1)),
                               atol=1e-15)


def test_validation_names_the_field():
    good = curved_patch((2, 2))
    with pytest.raises(ValueError, match=r"knots\[1\]"):
        SplinePatch((2, 2), (good.knots[0], [0, 0, 1, 1]), good.control_points)
    with pytest.raises(ValueError, match="control_points"):
        SplinePatch((2, 2), good.knots, good.control_points[:-1])
    with pytest.raises(ValueError, match="weights"):
        SplinePatch((2, 2), good.knots, good.control_points,
                    -np.ones(good.control_points.shape[:2]))
    with pytest.raises(ValueError, match="degrees"):
        SplinePatch((2,), good.knots, good.control_points)
    with pytest.raises(ValueError, match="uv"):
        good.basis([[0.5, 1.5]])
    with pytest.raises(ValueError, match="derivative"):
        good.basis([[0.5, 0.5]], derivative="w")
    assert not good.is_rational and curved_patch(rational=True).is_rational
    with pytest.raises(ValueError):
        good.control_points[0, 0, 0] = 1.0  # frozen data


@pytest.mark.parametrize("make", [lambda: rectangle(120.0, 30.0, center=(5, -2)),
                                  lambda: curved_patch((2, 3)),
                                  lambda: curved_patch((3, 2), rational=True)])
def test_inversion_round_trip(make):
    s = make()
    uv = random_uv(np.random.default_rng(4), m=2000)
    uv_inv, distance = invert_points(s, s.evaluate(uv))
    np.testing.assert_allclose(uv_inv, uv, atol=1e-10)
    assert distance.max() < 1e-9


def test_inversion_round_trip_plate_with_hole():
    s = plate_with_hole(180.0, 50.0, 14.0)
    rng = np.random.default_rng(5)
    uv = random_uv(rng, m=3000)
    uv[44:80, 0] = rng.integers(0, 5, 36) / 4       # the C0 lines towards the corners
    uv_inv, distance = invert_points(s, s.evaluate(uv))
    du = np.abs(uv_inv - uv)
    du[:, 0] = np.minimum(du[:, 0], 1 - du[:, 0])  # u = 0 and u = 1 are the same seam
    assert du.max() < 1e-10
    assert distance.max() < 1e-9


@settings(max_examples=10, deadline=None)
@given(st.floats(-0.8, 0.8).filter(lambda d: abs(d) > 1e-3), st.integers(0, 2**31))
def test_points_offset_along_the_normal(d, seed):
    s = curved_patch((2, 3))
    uv = np.random.default_rng(seed).uniform(0.02, 0.98, (300, 2))
    X = s.evaluate(uv) + d * s.normals(uv)
    uv_inv, distance = invert_points(s, X)
    np.testing.assert_allclose(distance, abs(d), atol=1e-12)
    np.testing.assert_allclose(uv_inv, uv, atol=1e-10)
