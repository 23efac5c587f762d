"""Knot insertion on patches: Eqs. 13-15 for B-splines and NURBS."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from georeg_plugin.spline.geometries import plate_with_hole
from georeg_plugin.spline.patch import SplinePatch
from georeg_plugin.spline.refine import (insert_knots, linear_patch, refine_to_elements,
                                         refine_uniform)


def random_patch(rng, pu, pv, rational):
    tu = np.r_[np.zeros(pu + 1), 0.4, np.ones(pu + 1)]
    tv = np.r_[np.zeros(pv + 1), np.ones(pv + 1)]
    shape = (len(tu) - pu - 1, len(tv) - pv - 1)
    cp = rng.normal(0, 5, shape + (3,))
    w = rng.uniform(0.3, 3.0, shape) if rational else None
    return SplinePatch((pu, pv), (tu, tv), cp, w)


def check_refinement(coarse, fine, C_r, rng):
    uv = rng.uniform(0, 1, (400, 2))
    uv[:4] = [[0, 0], [0, 1], [1, 0], [1, 1]]
    assert C_r.shape == (coarse.n_dofs, fine.n_dofs)
    np.testing.assert_allclose(fine.evaluate(uv), coarse.evaluate(uv), atol=1e-12 * 20)
    Rc, Rf = coarse.basis(uv).toarray(), fine.basis(uv).toarray()
    np.testing.assert_allclose(Rc, (C_r @ Rf.T).T, atol=1e-12)                # Eq. 13
    np.testing.assert_allclose(fine.control_points.reshape(-1, 3),
                               C_r.T @ coarse.control_points.reshape(-1, 3),
                               atol=1e-12 * 20)                                # Eq. 15
    np.testing.assert_allclose(C_r.sum(axis=0).A1, 1.0, atol=1e-13)


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 3), st.integers(1, 3), st.booleans(), st.integers(0, 2**31),
       st.lists(st.floats(0.05, 0.95).filter(lambda x: x != 0.4), max_size=3, unique=True),
       st.lists(st.floats(0.05, 0.95), max_size=3, unique=True))
def test_knot_insertion_leaves_surface_unchanged(pu, pv, rational, seed, new_u, new_v):
    rng = np.random.default_rng(seed)
    coarse = random_patch(rng, pu, pv, rational)
    fine, C_r = insert_knots(coarse, new_u, new_v)
    assert fine.is_rational == rational
    check_refinement(coarse, fine, C_r, rng)


def test_nurbs_weights_are_homogeneous_insertion():
    rng = np.random.default_rng(7)
    coarse = random_patch(rng, 2, 2, True)
    fine, C_r = insert_knots(coarse, [0.2, 0.7], [0.5])
    # w_f = C^T w_c with the B-spline insertion matrix C (= C_r for unit weights)
    _, C = insert_knots(SplinePatch(coarse.degrees, coarse.knots,
                                    np.zeros_like(coarse.control_points)), [0.2, 0.7], [0.5])
    np.testing.assert_allclose(fine.weights.ravel(), C.T @ coarse.weights.ravel(),
                               atol=1e-14)
    np.testing.assert_allclose(C_r.toarray(), (np.diag(coarse.weights.ravel()) @ C.toarray()
                                               @ np.diag(1 / fine.weights.ravel())),
                               atol=1e-14)


def test_refine_uniform_nesting_on_plate_with_hole():
    rng = np.random.default_rng(8)
    coarse = plate_with_hole(180.0, 50.0, 14.0)
    once, C1 = refine_uniform(coarse, 1)
    twice, C2 = refine_uniform(once, 1)
    direct, C12 = refine_uniform(coarse, 2)
    assert once.n_elements == (8, 2) and direct.n_elements == (16, 4)
    for d in range(2):
        np.testing.assert_array_equal(direct.knots[d], twice.knots[d])
    np.testing.assert_allclose(C12.toarray(), (C1 @ C2).toarray(), atol=1e-14)
    np.testing.assert_allclose(direct.control_points, twice.control_points, atol=1e-12)
    check_refinement(coarse, direct, C12, rng)


def test_refine_to_elements_counts_and_geometry():
    rng = np.random.default_rng(9)
    coarse = plate_with_hole(180.0, 50.0, 14.0)
    fine, C_r = refine_to_elements(coarse, 40, 25)
    assert fine.n_elements == (40, 25)
    for c0 in (0.25, 0.5, 0.75):  # the C0 lines stay
        assert np.sum(fine.knots[0] == c0) == 2
    check_refinement(coarse, fine, C_r, rng)
    with pytest.raises(ValueError, match="n_u"):
        refine_to_elements(coarse, 2, 4)


def test_bad_insertions_name_the_direction():
    coarse = plate_with_hole(180.0, 50.0, 14.0)
    with pytest.raises(ValueError, match="new_u.*multiplicity"):
        insert_knots(coarse, [0.25])
    with pytest.raises(ValueError, match="new_v"):
        insert_knots(coarse, (), [1.2])
    with pytest.raises(ValueError, match="times"):
        refine_uniform(coarse, -1)


@pytest.mark.parametrize("pu, pv", [(2, 2), (3, 2), (2, 1)])
def test_linear_patch_is_nested_in_every_b_spline(pu, pv):
    """The bilinear patch's basis is the patch's basis times C_r at random points (Eq. 13),
    its corners are the patch's corners, and C_r^T reproduces any bilinear function's
    control values (a plane through the dofs of the finer patch)."""
    rng = np.random.default_rng(pu * 10 + pv)
    patch = random_patch(rng, pu, pv, rational=False)
    linear, C_r = linear_patch(patch)
    assert linear.degrees == (1, 1) and C_r.shape == (4, patch.n_dofs)
    uv = rng.uniform(0, 1, (300, 2))
    np.testing.assert_allclose(linear.basis(uv).toarray(), (C_r @ patch.basis(uv).toarray().T).T,
                               atol=1e-11)
    corners = np.array([[0, 0], [0, 1], [1, 0], [1, 1.0]])
    np.testing.assert_allclose(linear.evaluate(corners), patch.evaluate(corners), atol=1e-12)
    a = rng.normal(size=4)                               # f = a0 + a1 u + a2 v + a3 u v
    f_fine = patch.basis(uv).toarray() @ (C_r.T @ a)
    assert np.allclose(f_fine, linear.basis(uv).toarray() @ a, atol=1e-11)


def test_linear_patch_refuses_nurbs():
    patch = random_patch(np.random.default_rng(0), 2, 2, rational=True)
    with pytest.raises(ValueError, match="NURBS"):
        linear_patch(patch)
