"""The ladder of nested spline levels and the pieces of the level search (no images)."""
import numpy as np
import pytest
import scipy.sparse as sps

from adapters.fesdic_core import multilevel_for_mesh, nominal_model
from adapters.level_search import _move_to, below_nominal, ladder
from georeg_plugin.levels.selection import (information_criterion, noise_gain, penalty_per_dof,
                                            predicted_fit)
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.spline.geometries import plate_with_hole, rectangle


def test_ladder_of_a_dyadic_mesh_is_the_paper_space_plus_nothing():
    """plate_with_hole refined 3 times: the ladder is the 4 dyadic levels of Eq. 28, the
    finest one the FE mesh's own spline (the knot spans are the elements)."""
    model = nominal_model(plate_with_hole(100.0, 50.0, 14.0), 3, "Q9")
    space = ladder(model)
    paper = multilevel_for_mesh(model, 4)
    assert space.n_levels == 4
    for C, D in zip(space.operators, paper.operators):
        assert C.shape == D.shape and abs(C - D).max() < 1e-12


def test_ladder_ends_on_the_spline_of_a_non_dyadic_mesh():
    """24 x 16 elements on a one-element rectangle: from the spline of the elements down by
    halving, 24 x 16, 12 x 8, 6 x 4, 3 x 2, 2 x 1 (u knots 0, 2/3, 1) spans and the nominal;
    every level nested in the next (Eq. 13: the coarse operator is a refinement of the fine
    one, C_c = C_r C_f)."""
    model = nominal_model(rectangle(60.0, 40.0), (24, 16), "Q9")
    space = ladder(model)
    dofs = [C.shape[0] for C in space.operators]
    assert dofs == [26 * 18, 14 * 10, 8 * 6, 5 * 4, 4 * 3, 3 * 3]
    assert np.allclose(space.patch(4).breaks[0], [0.0, 2.0 / 3.0, 1.0])
    for s in range(space.n_levels - 1):                  # C_{s+1} = C_r C_s (Eq. 28)
        Cr = space.refinement[s]
        assert abs(Cr @ space.operators[s] - space.operators[s + 1]).max() < 1e-12
    # the finest level reproduces any quadratic spline of the mesh's knots at the nodes
    x, y = model.mesh.nodes[:, 0], model.mesh.nodes[:, 1]
    q = 0.01 * x * y + 0.002 * x ** 2
    solver = GeometricRegularization(space)
    assert np.max(np.abs(solver.to_nodes(solver.control_values(q, 0), 0) - q)) < 1e-10


def test_the_search_ladder_has_a_bilinear_level_below_the_nominal():
    """``linear=True``: the same levels plus one below the nominal, the bilinear patch (4
    dofs), nested in the nominal (C_lin = C_r C_nominal, Eq. 28) and holding a plane's
    rigid normal motions (1, x, y) at the nodes; none below a NURBS nominal."""
    model = nominal_model(rectangle(60.0, 40.0), (24, 16), "Q9")
    plain, space = ladder(model), ladder(model, linear=True)
    assert space.n_levels == plain.n_levels + 1 and below_nominal(space, model) == 1
    assert below_nominal(plain, model) == 0
    for C, D in zip(space.operators, plain.operators):
        assert abs(C - D).max() < 1e-12
    coarsest = space.operators[-1]
    assert coarsest.shape[0] == 4
    assert abs(space.refinement[-1] @ space.operators[-2] - coarsest).max() < 1e-12
    x, y = model.mesh.nodes[:, 0], model.mesh.nodes[:, 1]
    for q in (np.ones_like(x), x, y):
        a, *_ = np.linalg.lstsq(coarsest.T.toarray(), q, rcond=None)
        assert np.abs(coarsest.T @ a - q).max() < 1e-9
    hole = nominal_model(plate_with_hole(100.0, 50.0, 14.0), 1, "Q9")
    assert ladder(hole, linear=True).n_levels == ladder(hole).n_levels


def test_predicted_fit_is_exact_for_a_linear_problem():
    """c(q + d) = |r + Phi^T d|^2 equals c - b.d for the Gauss-Newton step d = G b of any level."""
    model = nominal_model(rectangle(30.0, 20.0), (6, 4), "Q9")
    space = ladder(model)
    rng = np.random.default_rng(0)
    n = model.mesh.n_nodes
    Phi = rng.standard_normal((n, 600))                 # 600 "points", a dense design
    r = rng.standard_normal(600)
    H, b = sps.csr_matrix(Phi @ Phi.T), -Phi @ r
    c = float(r @ r)
    for level in range(space.n_levels):
        d = GeometricRegularization(space, {0: level}).solve(H, b, np.zeros(n), 0)
        assert predicted_fit(c, b, d) == pytest.approx(float(np.sum((r + Phi.T @ d) ** 2)), rel=1e-10)


def test_move_to_any_level_is_exact_for_a_linear_problem():
    """From the optimum of a middle level, the predicted optimum of every level, coarser or
    finer, is the true least-squares optimum on that level (compared with a dense lstsq), and
    the predicted cost c - 2 b.d + d^T H d is its true cost."""
    model = nominal_model(rectangle(30.0, 20.0), (6, 4), "Q9")
    space = ladder(model)
    rng = np.random.default_rng(3)
    n = model.mesh.n_nodes
    Phi = rng.standard_normal((n, 600))
    r0 = rng.standard_normal(600)
    H = sps.csr_matrix(Phi @ Phi.T)

    def cost(q):                                         # c(q) = |r0 + Phi^T q|^2, b = -Phi r
        return float(np.sum((r0 + Phi.T @ q) ** 2))

    middle = space.n_levels // 2
    q = _move_to(space, middle, H, -Phi @ r0, np.zeros(n), 0)       # the middle level's optimum
    r = r0 + Phi.T @ q
    b, c = -Phi @ r, float(r @ r)
    for level in range(space.n_levels):
        d = _move_to(space, level, H, b, q, 0)
        CT = space.operators[level].T.toarray()
        a, *_ = np.linalg.lstsq(Phi.T @ CT, -r0, rcond=None)         # min |r0 + Phi^T C^T a|
        assert np.allclose(q + d, CT @ a, atol=1e-9 * np.abs(CT @ a).max())
        assert predicted_fit(c, b, d, H) == pytest.approx(cost(q + d), rel=1e-10)
        assert (cost(q + d) >= c - 1e-9 * c) == (level >= middle)  # nested: coarser fits worse


def test_criterion_and_gain():
    assert information_criterion(10.0, 5, 0.5, 1000) == pytest.approx(10.0 + 2.5 * 2 * np.log(np.log(1000)))
    assert penalty_per_dof(10 ** 6) == pytest.approx(5.2516, abs=1e-4)     # 2 ln ln N, a megapixel pair
    assert noise_gain(10.0, 4, 7.0, 7, 0.5) == pytest.approx(2.0)      # (10 - 7) / (0.5 * 3)
    assert np.isnan(noise_gain(10.0, 4, 7.0, 4, 0.5))
    assert noise_gain(7.0, 7, 10.0, 4, 0.5) == pytest.approx(2.0)      # coarser: rise per removed dof


def test_noise_alone_never_passes_the_criterion():
    """Pure noise of variance kappa on a linear problem: the gain per added dof is ~1, so
    the criterion (threshold 2 ln ln N = 4.2 here) keeps the coarse level in every draw."""
    model = nominal_model(rectangle(30.0, 20.0), (8, 8), "Q9")
    space = ladder(model)
    rng = np.random.default_rng(1)
    n = model.mesh.n_nodes
    Phi = rng.standard_normal((n, 3000)) / np.sqrt(3000)
    H = sps.csr_matrix(Phi @ Phi.T)
    kept, gains = 0, []
    for _ in range(40):
        r = rng.standard_normal(3000)                    # kappa = 1: Cov(b) = H
        b = -Phi @ r
        coarse = GeometricRegularization(space, {0: space.n_levels - 2}).solve(H, b, np.zeros(n), 0)
        fine = GeometricRegularization(space, {0: space.n_levels - 3}).solve(H, b, np.zeros(n), 0)
        c = float(r @ r)
        c0, c1 = predicted_fit(c, b, coarse), predicted_fit(c, b, fine)
        m0, m1 = space.operators[-2].shape[0], space.operators[-3].shape[0]
        gains.append(noise_gain(c0, m0, c1, m1, 1.0))
        kept += information_criterion(c0, m0, 1.0, 3000) <= information_criterion(c1, m1, 1.0, 3000)
    assert 0.7 < np.mean(gains) < 1.3
    assert kept == 40


def test_ladder_takes_the_formulation_of_the_nominal():
    """On a dyadic mesh the search's ladder is the fixed-level space, formulation included:
    the scalar space on a cylinder (it holds the rigid normal motions), the vector one on a
    doubly curved face (the scalar space misses them by 7e-4): equal operators level by
    level, and the rigid normal modes inside every level of the doubly curved ladder."""
    from fesdic_core.fe.mesh import node_normals
    from fesdic_core.shape.gauge import rigid_normal_modes
    from georeg_plugin.spline.geometries import cylinder
    from georeg_plugin.spline.patch import SplinePatch
    U, V = np.meshgrid(np.linspace(-20, 20, 3), np.linspace(-15, 15, 3), indexing="ij")
    k = np.array([0, 0, 0, 1, 1, 1.0])                           # an elliptic paraboloid, twisted
    dome = SplinePatch((2, 2), (k, k), np.stack([U, V, 0.004 * U ** 2 + 0.006 * V ** 2
                                                 + 0.002 * U * V], -1))
    for patch, vector in ((cylinder(100.0, 40.0, 30.0), False), (dome, True)):
        model = nominal_model(patch, 2, "Q9")
        space, fixed = ladder(model), multilevel_for_mesh(model, 3, curved=None)
        assert bool(space.vector) == vector and space.n_levels == 3
        for C, D in zip(space.operators, fixed.operators):
            assert C.shape == D.shape and abs(C - D).max() < 1e-10
    rigid, _ = rigid_normal_modes(model.mesh.nodes, node_normals(model.mesh))
    for C in space.operators:
        C = C.toarray()
        coeffs, *_ = np.linalg.lstsq(C.T, rigid, rcond=None)
        assert np.abs(rigid - C.T @ coeffs).max() < 1e-10 * np.abs(rigid).max()
