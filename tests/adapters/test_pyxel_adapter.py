"""The pyxel-dic adapter: reduced basis, projection, and a spline-regularized FE-DIC.

A synthetic speckle pair with a known smooth displacement (made here with
scipy.ndimage.map_coordinates, plus Gaussian noise) is correlated by pyxel on its own
Q4 and Q9 meshes, with and without the spline basis.
"""
import logging
import sys

import numpy as np
import pytest
import scipy.ndimage as ndi
import scipy.sparse as sps

from adapters import pyxel as adapter
from adapters.protocol import Adapter

SIZE = 256  # px
ROI = np.array([[40, 40], [216, 216]])  # (x, y) px corners of the meshed region
NOISE = 3.0  # gray levels


def true_displacement(x, y):
    """A smooth field of a few px (x = column, y = row), quadratic in the image."""
    xh, yh = (x - SIZE / 2) / (SIZE / 2), (y - SIZE / 2) / (SIZE / 2)
    return 1.5 + 2.0 * xh ** 2 - 1.0 * xh * yh, -1.0 + 1.5 * yh ** 2 + 0.8 * xh


@pytest.fixture(scope="module")
def speckle_pair():
    """(f, g) pyxel images: g(x + u(x)) = f(x), both with Gaussian noise."""
    pyxel = pytest.importorskip("pyxel")
    rng = np.random.default_rng(7)
    texture = ndi.gaussian_filter(rng.standard_normal((SIZE + 40, SIZE + 40)), 1.5)[20:-20, 20:-20]
    texture = 20 + 200 * (texture - texture.min()) / np.ptp(texture)
    rows, cols = np.mgrid[0:SIZE, 0:SIZE].astype(float)
    x, y = cols.copy(), rows.copy()
    for _ in range(30):  # fixed point for the inverse map x = y_img - u(x)
        ux, uy = true_displacement(x, y)
        x, y = cols - ux, rows - uy
    warped = ndi.map_coordinates(texture, [y, x], order=3, mode="nearest")
    f, g = pyxel.Image("f"), pyxel.Image("g")
    f.pix = texture + NOISE * rng.standard_normal(texture.shape)
    g.pix = warped + NOISE * rng.standard_normal(texture.shape)
    return f, g


def roi_mesh(typel):
    """pyxel's own structured mesh of the ROI (Q4: typel 3, Q9: typel 10), node spacing 8 px."""
    pyxel = pytest.importorskip("pyxel")
    m, cam = pyxel.MeshFromROI(ROI, [8, 8] if typel == 3 else [16, 16], typel=typel)
    m.Connectivity()
    return m, cam


def nodal_truth(m):
    """The true displacement as a pyxel dof vector (pyxel's mesh y axis points up)."""
    ux, uy = true_displacement(m.n[:, 0], -m.n[:, 1])
    return m.Nodes2DOF(np.c_[ux, -uy])


def rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


def test_missing_pyxel_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyxel", None)  # makes "import pyxel" fail
    with pytest.raises(ImportError, match=r"\.\[pyxel\]"):
        adapter.import_pyxel()


@pytest.mark.parametrize("typel", [3, 10])
def test_basis_reproduces_the_node_coordinates(typel):
    """B [x_J; y_J] = node coordinates: the affine spline field of its own control
    points, placed by point inversion in pyxel's dof numbering (C^T = R_J(xi_I))."""
    m, _ = roi_mesh(typel)
    patch = adapter.spline_for_mesh(m, margin=3.0, degree=2, elements=(2, 3))
    from georeg_plugin.levels.operators import multilevel_space
    nodes = np.c_[m.n, np.zeros(len(m.n))]
    C = multilevel_space(patch, 2, nodes).operators[0]
    B = adapter.pyxel_basis(m, C)
    assert B.shape == (m.ndof, 2 * C.shape[0])
    fine = multilevel_space(patch, 2, nodes).patch(0)
    P = fine.control_points.reshape(-1, 3)
    X = m.DOF2Nodes(B @ np.r_[P[:, 0], P[:, 1]])
    np.testing.assert_allclose(X, m.n, atol=1e-9 * np.ptp(m.n))


def test_projection_is_the_least_squares_one():
    rng = np.random.default_rng(1)
    B = sps.random(60, 8, density=0.3, random_state=2, format="csr") + sps.eye(60, 8)
    a = rng.standard_normal(8)
    np.testing.assert_allclose(adapter.project_on_basis(B, B @ a), B @ a, atol=1e-10)
    U = rng.standard_normal(60)
    P = adapter.project_on_basis(B, U)
    np.testing.assert_allclose(B.T @ (U - P), 0.0, atol=1e-9)  # normal equations
    with pytest.raises(ValueError, match="shape"):
        adapter.project_on_basis(B, U[:-1])


def test_spline_for_mesh_covers_the_mesh():
    class Nodes:  # any object with node coordinates n
        n = np.array([[1.0, -2.0], [5.0, 4.0], [3.0, 0.0]])
    patch = adapter.spline_for_mesh(Nodes, margin=0.5, degree=3, elements=(2, 1))
    corners = patch.evaluate(np.array([[0.0, 0.0], [1.0, 1.0], [0.25, 0.5]]))
    np.testing.assert_allclose(corners[:, :2], [[0.5, -2.5], [5.5, 4.5], [1.75, 1.0]], atol=1e-12)
    np.testing.assert_allclose(corners[:, 2], 0.0)
    with pytest.raises(ValueError, match="margin"):
        adapter.spline_for_mesh(Nodes, margin=-1.0)


@pytest.mark.slow
@pytest.mark.parametrize("typel", [3, 10])
def test_spline_regularization_beats_plain_pyxel_on_noisy_images(speckle_pair, typel):
    f, g = speckle_pair
    m, cam = roi_mesh(typel)
    U_true = nodal_truth(m)
    U_fe, std_fe = adapter.correlate_fe(f, g, m, cam, init_scales=(2, 1))
    m, cam = roi_mesh(typel)
    patch = adapter.spline_for_mesh(m, degree=2)
    U_s, std_s, history = adapter.correlate_multilevel(f, g, m, cam, patch, n_levels=3)
    err_fe, err_s = rms(U_fe - U_true), rms(U_s - U_true)
    print(f"typel {typel}: rms error plain {err_fe:.4f} px, spline {err_s:.4f} px; "
          f"residual std {std_fe:.3f} / {std_s:.3f} gl")
    assert err_s < err_fe, (err_s, err_fe)
    # coarse to fine: spline levels 2, 1, 0 on image scales 2, 1, 0, bases growing
    assert [h.level for h in history] == [2, 1, 0]
    assert [h.image_scale for h in history] == [2, 1, 0]
    assert history[0].n_basis < history[1].n_basis < history[2].n_basis
    # the true field lies in the spline space: the converged fit cannot do worse
    host = adapter.PyxelAdapter(f, g, m, cam)
    assert isinstance(host, Adapter) and host.n_dof == m.ndof
    std_true = host.residual_std(U_true)
    print(f"residual std at the true field {std_true:.4f} gl")
    assert std_s <= std_true * (1.0 + 1e-3)


def test_dependent_columns_are_dropped_and_the_range_kept():
    rng = np.random.default_rng(3)
    B0 = sps.random(40, 6, density=0.5, random_state=4, format="csr") + sps.eye(40, 6)
    mix = sps.csr_matrix(rng.standard_normal((6, 3)))
    B = sps.hstack([B0, B0 @ mix]).tocsr()  # 9 columns, rank 6
    keep = adapter.independent_columns(B)
    assert keep.size == 6 and np.linalg.matrix_rank(B[:, keep].toarray()) == 6
    for column in B.T.toarray():  # every original column is in the kept range
        np.testing.assert_allclose(adapter.project_on_basis(B[:, keep], column), column,
                                   atol=1e-8)
    np.testing.assert_array_equal(adapter.independent_columns(B0), np.arange(6))


def graded_strip():
    """A pyxel Q4 strip of eight 4 x 20 px columns then two 40 x 20 px ones (2 rows)."""
    pyxel = pytest.importorskip("pyxel")
    xb = np.r_[np.arange(0, 33, 4), 72, 112] + 20.0
    yb = np.array([20.0, 40.0, 60.0])
    X, Y = np.meshgrid(xb, yb, indexing="ij")
    ny = yb.size
    conn = np.array([[i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1]
                     for i in range(xb.size - 1) for j in range(ny - 1)])
    m = pyxel.Mesh({3: conn}, np.c_[X.ravel(), -Y.ravel()], 2)  # pyxel's y axis points up
    rng = np.random.default_rng(0)
    f, g = pyxel.Image("f"), pyxel.Image("g")
    f.pix = 200.0 * rng.random((96, 160))
    g.pix = f.pix.copy()
    return f, g, m, pyxel.Camera(2), xb, yb


def test_large_elements_of_a_graded_mesh_get_a_point_per_pixel_at_coarse_scales():
    """Regression: MultiscaleInit's n x n rule (n from the mean element size) gave the
    large elements of pyxel's composite mesh 2 x 2 points at scale 1 and the spline dofs
    there drifted by ~30 px; the default pixel rule samples every element by its area."""
    f, g, m, cam, xb, yb = graded_strip()
    area_px = np.diff(xb) * (yb[-1] - yb[0])  # per column of elements, scale 0
    density = {}
    for rule in ("pixel", "fast"):
        host = adapter.PyxelAdapter(f, g, m, cam, integration=rule)
        _, _, m_s, _, _, _ = host._scale(1)
        column = np.searchsorted(xb, np.asarray(m_s.pgx)) - 1
        density[rule] = np.bincount(column, minlength=xb.size - 1) / (area_px / 4)
    assert np.all((density["pixel"] > 0.5) & (density["pixel"] < 2.0)), density["pixel"]
    assert density["fast"][-1] < 0.5 * density["fast"][0]  # what went wrong before


def test_unknown_integration_rule_is_refused():
    f, g, m, cam, _, _ = graded_strip()
    with pytest.raises(ValueError, match="integration"):
        adapter.PyxelAdapter(f, g, m, cam, integration="gauss")


def test_iteration_count_is_the_one_pyxel_prints(speckle_pair, caplog):
    """The count comes from the engine's ComputeRHS calls; pyxel's own "Iter #" lines
    (captured into the debug log) must agree, on a run that converges before maxiter."""
    f, g = speckle_pair
    m, cam = roi_mesh(3)
    host = adapter.PyxelAdapter(f, g, m, cam, eps=1e-3, maxiter=30)
    with caplog.at_level(logging.DEBUG, logger=adapter.__name__):
        _, _, n_iterations = host.correlate(None, None, 1)
    printed = sum(r.getMessage().count("Iter #") for r in caplog.records)
    assert 1 < n_iterations < 30
    assert n_iterations == printed


def test_iteration_count_is_maxiter_when_convergence_is_impossible(speckle_pair, caplog):
    f, g = speckle_pair
    m, cam = roi_mesh(3)
    host = adapter.PyxelAdapter(f, g, m, cam, eps=0.0, maxiter=4)   # |dU|/|U| < 0: never
    with caplog.at_level(logging.WARNING, logger=adapter.__name__):
        _, _, n_iterations = host.correlate(None, None, 1)
    assert n_iterations == 4
    assert any("maxiter = 4" in r.getMessage() for r in caplog.records)


def test_basis_columns_no_data_sees_are_dropped():
    """B = C_s^T restricted to the outline: a column zero on the mesh (a spline function
    outside it) goes whatever H; with H, a column that no integration point sees goes too."""
    rng = np.random.default_rng(8)
    B = sps.random(30, 8, density=0.4, random_state=9, format="lil")
    B[:, 2] = 0.0                                      # outside the mesh
    B[:, 5] = 0.0
    B[25:, 5] = 1.0                                    # lives on dofs 25-29 only
    B = sps.csr_matrix(B)
    kept, dropped = adapter.seen_columns(B)
    assert kept.shape == (30, 7) and dropped == 1
    w = np.r_[np.ones(25), np.zeros(5)]                # no point sees dofs 25-29
    A = rng.standard_normal((30, 30))
    H = sps.csr_matrix(np.diag(w) @ (A @ A.T) @ np.diag(w))
    kept, dropped = adapter.seen_columns(B, H)
    expected = [c for c in range(8) if np.abs(B[:25, c].toarray()).sum() > 0]
    assert dropped == 8 - len(expected) >= 2
    np.testing.assert_array_equal(kept.toarray(), B[:, expected].toarray())
