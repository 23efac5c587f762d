"""GeometricRegularization: the solve hook of Eqs. 18-21 against dense linear algebra, and
Eq. 20 on real spline spaces against an independently computed refinement matrix."""
import numpy as np
import pytest
import scipy.sparse as sps
from numpy.testing import assert_allclose

from scipy.interpolate import BSpline

from georeg_plugin.levels.operators import MultilevelSpace, multilevel_space
from georeg_plugin.levels.solver import GeometricRegularization, SingularProjectionError
from georeg_plugin.spline.fe_mesh import fe_mesh_from_spline
from georeg_plugin.spline.geometries import plate_with_hole, rectangle
from georeg_plugin.spline.refine import insert_knots, refine_uniform


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
    for level in (0, 1):
        H_s, b_s = reg.project(H, b, level)
        C = space.operators[level].toarray()
        assert_allclose(H_s.toarray(), C @ H.toarray() @ C.T, rtol=1e-12, atol=1e-12)  # Eq. 18
        assert_allclose(b_s, C @ b, rtol=1e-12, atol=1e-12)                            # Eq. 19


# --- Eq. 20 on real spline spaces, against a refinement matrix computed independently -----
#
# The plugin builds C_r by Boehm's knot insertion (bspline.insertion_matrix, refine.py).
# The reference below never calls it: it samples scipy's B-spline bases (coarse and dyadic
# fine knot vectors) at many points and solves R_f C_r^T = R_c (Eq. 13) by least squares;
# for NURBS the fine weights are the least-squares B-spline coefficients of the (unchanged)
# weight function W, and R = diag(w) N / W (Eq. 12).

def _dyadic(knots):
    """The knot vector with the midpoint of every non-empty span inserted once."""
    b = np.unique(knots)
    return np.sort(np.r_[knots, 0.5 * (b[:-1] + b[1:])])


def _samples(knots, per_span=5):
    b = np.unique(knots)
    return (b[:-1, None] + np.diff(b)[:, None] * (np.arange(per_span) + 0.5) / per_span).ravel()


def _tensor_bspline_basis(knots, degrees, u, v):
    """N (len(u) * len(v), nu * nv) at the grid of (u, v), dof i * nv + j."""
    Nu = BSpline.design_matrix(u, knots[0], degrees[0]).toarray()
    Nv = BSpline.design_matrix(v, knots[1], degrees[1]).toarray()
    return np.einsum("ai,bj->abij", Nu, Nv).reshape(len(u) * len(v), -1)


def _reference_refinements(coarse, n_levels):
    """C_r of each level s -> s + 1 (s = 0 the finest), by least squares on sampled bases."""
    knots = [tuple(np.asarray(k, float) for k in coarse.knots)]
    for _ in range(n_levels - 1):
        knots.append(tuple(_dyadic(k) for k in knots[-1]))
    u, v = (_samples(k) for k in knots[-1])            # points in every finest span
    N = [_tensor_bspline_basis(k, coarse.degrees, u, v) for k in knots]
    w = [coarse.homogeneous_weights]
    W = N[0] @ w[0]                                    # the weight function, Eq. 12
    for Nf in N[1:]:
        w.append(np.linalg.lstsq(Nf, W, rcond=None)[0])
    R = [Nk * wk / W[:, None] for Nk, wk in zip(N, w)]  # rational bases, coarse -> fine
    refinements = []
    for Rc, Rf in zip(R[:-1], R[1:]):
        Crt, *_ = np.linalg.lstsq(Rf, Rc, rcond=None)  # R_f C_r^T = R_c (Eq. 13)
        assert np.abs(Rf @ Crt - Rc).max() < 1e-12     # the coarse basis is in the fine span
        refinements.append(Crt.T)
    return refinements[::-1]                          # index s: level s -> s + 1


@pytest.mark.parametrize("geometry", ["bspline", "nurbs"])
def test_eq_20_against_an_independent_refinement_matrix(geometry):
    """multilevel_space's C_s satisfy C_{s+1} = C_r C_s (Eqs. 13, 28) and the projected
    operators H_{s+1} = C_r H_s C_r^T, b_{s+1} = C_r b_s (Eq. 20), with the reference C_r."""
    if geometry == "bspline":
        coarse, _ = insert_knots(rectangle(100.0, 50.0), [0.3], [0.55])   # non-uniform knots
    else:
        coarse = plate_with_hole(100.0, 50.0, 14.0)                       # one NURBS patch
    n_levels = 3
    mesh = fe_mesh_from_spline(refine_uniform(coarse, n_levels - 1)[0], "Q9")
    space = multilevel_space(coarse, n_levels, mesh.nodes, uv=mesh.uv, glue=False, family="Q9")
    reference = _reference_refinements(coarse, n_levels)
    reg = GeometricRegularization(space)
    rng = np.random.default_rng(7)
    H = _random_spd(space.n_fe, rng)
    b = rng.standard_normal(space.n_fe)
    for s, Cr in enumerate(reference):
        assert_allclose(space.refinement[s].toarray(), Cr, atol=1e-11)
        C_fine, C_coarse = space.operators[s].toarray(), space.operators[s + 1].toarray()
        assert_allclose(C_coarse, Cr @ C_fine, atol=1e-11)                  # Eqs. 13, 28
        H_f, b_f = reg.project(H, b, s)
        H_c, b_c = reg.project(H, b, s + 1)
        scale = np.abs(H_c.toarray()).max()
        assert_allclose(H_c.toarray(), Cr @ H_f.toarray() @ Cr.T, atol=1e-11 * scale)  # Eq. 20
        assert_allclose(b_c, Cr @ b_f, atol=1e-11 * np.abs(b_c).max())


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
    """Strict mode (``hold_unseen=False``): an unseen dof is an error naming it."""
    space, rng = two_levels
    reg = GeometricRegularization(space, hold_unseen=False)
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


def test_factorize_gives_the_step_of_solve_for_every_right_hand_side(two_levels):
    """``factorize(H, scale)`` (C_s H C_s^T factorized once) is the map of ``solve``: the same
    step, to round-off, for several right-hand sides and both levels."""
    space, rng = two_levels
    reg = GeometricRegularization(space)
    H = _random_spd(space.n_fe, rng)
    for scale in (0, 1):
        step = reg.factorize(H, scale)
        for _ in range(3):
            b = rng.standard_normal(space.n_fe)
            q = rng.standard_normal(space.n_fe)
            assert_allclose(step(b, q), reg.solve(H, b, q, scale), rtol=1e-12,
                            atol=1e-14 * np.abs(b).max())
    with pytest.raises(ValueError, match="does not match"):
        reg.factorize(H, 0)(np.ones(5), np.zeros(5))


def test_weaker_is_the_next_finer_level_and_its_change_has_the_covariance_difference(two_levels):
    """``weaker(scale)``: the next finer level (None at the finest); its step is the bias
    step; for nested levels the change ``(G' - G) b`` under ``Cov(b) = H`` has the covariance
    ``G' H G' - G H G`` (the cross terms are ``G``: ``G H G' = G``), checked densely."""
    space, rng = two_levels
    reg = GeometricRegularization(space)
    assert reg.weaker(0) is None and reg.weaker(1).level(1) == 0
    H = _random_spd(space.n_fe, rng)
    b = rng.standard_normal(space.n_fe)
    q = np.zeros(space.n_fe)
    assert_allclose(reg.weaker(1).solve(H, b, q, 1), reg.bias_step(H, b, q, 1), atol=1e-12)
    Hd = H.toarray()
    G = {s: space.operators[s].toarray().T @ np.linalg.solve(
        space.operators[s].toarray() @ Hd @ space.operators[s].toarray().T,
        space.operators[s].toarray()) for s in (0, 1)}
    D = G[0] - G[1]
    assert_allclose(G[1] @ Hd @ G[0], G[1], atol=1e-10)
    assert_allclose(D @ Hd @ D.T, G[0] @ Hd @ G[0] - G[1] @ Hd @ G[1], atol=1e-10)
    diag_f, _ = reg.weaker(1).step_covariance(H, 1)
    diag_s, _ = reg.step_covariance(H, 1)
    assert_allclose(diag_f - diag_s, np.diag(D @ Hd @ D.T), atol=1e-10)
