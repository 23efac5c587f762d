"""The shape uncertainty (fesdic_core.shape.uncertainty): linear algebra identities, and the
predicted standard deviation against the empirical one over noise draws on a render."""
import numpy as np
import pytest
import scipy.sparse as sps

from fesdic_core.fe.mesh import nodal_areas, rectangle_mesh
from fesdic_core.imaging.image import Image
from fesdic_core.shape.driver import MeasurementSettings, measure
from fesdic_core.shape.gauge import rigid_normal_modes
from fesdic_core.shape.uncertainty import shape_std
from fesdic_core.solve.solvers import DirectSolver, inverse_covariance
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from scenes import bump_specimen


def _spd(n, seed=0):
    rng = np.random.default_rng(seed)
    M = sps.random(n, n, density=0.2, random_state=seed) + sps.identity(n)
    return sps.csr_matrix(M @ M.T + 0.1 * sps.identity(n)), rng


def test_inverse_covariance_is_the_inverse():
    H, rng = _spd(40)
    diag, apply = inverse_covariance(H)
    inverse = np.linalg.inv(H.toarray())
    np.testing.assert_allclose(diag, np.diag(inverse), rtol=1e-10)
    V = rng.standard_normal((40, 3))
    np.testing.assert_allclose(apply(V), inverse @ V, rtol=1e-9, atol=1e-12)


def test_inverse_diagonal_of_an_fe_matrix_matches_the_dense_inverse():
    """Takahashi's recurrence on the banded (RCM) Cholesky factor of a Q9 mesh's matrix."""
    from fesdic_core.solve.solvers import inverse_diagonal
    from fesdic_core.solve.tikhonov import surface_gradient_operator
    mesh = rectangle_mesh(40.0, 20.0, 10, 5, family="Q9")
    H = sps.csr_matrix(surface_gradient_operator(mesh) + 0.05 * sps.identity(mesh.n_nodes))
    rng = np.random.default_rng(2)
    shuffle = rng.permutation(mesh.n_nodes)               # a bad numbering: RCM must fix it
    H = H[shuffle][:, shuffle]
    np.testing.assert_allclose(inverse_diagonal(H), np.diag(np.linalg.inv(H.toarray())), rtol=1e-9)


def test_shape_std_projects_out_the_rigid_modes():
    """diag(P C P^T) of shape_std against the dense product, P the weighted projection."""
    mesh = rectangle_mesh(30.0, 20.0, 4, 3, family="Q4")
    n = mesh.n_nodes
    H, _ = _spd(n, seed=3)
    normals = np.tile([0.0, 0.0, 1.0], (n, 1))
    modes, _ = rigid_normal_modes(mesh.nodes, normals)
    w = nodal_areas(mesh)
    std = shape_std(H, 2.0, DirectSolver(), 0, modes, w)
    C = 2.0 * np.linalg.inv(H.toarray())
    W = np.diag(w)
    keep = modes[:, [2, 3, 4]]                     # z offset and two tilts span the normal modes
    P = np.eye(n) - keep @ np.linalg.solve(keep.T @ W @ keep, keep.T @ W)
    np.testing.assert_allclose(std, np.sqrt(np.diag(P @ C @ P.T)), rtol=1e-8)
    assert shape_std(H, 2.0, object(), 0) is None              # no hook, no uncertainty


@pytest.fixture(scope="module")
def noisy_bump_pairs():
    cameras = demo_cameras(image_size=(360, 240), field_mm=72.0)
    specimen = bump_specimen(speckle_mm_for(cameras[0], 4.0))
    clean = render_stereo(specimen, cameras, supersample=3, noise_std=0.0, seed=2, progress=False)
    return cameras, clean


@pytest.mark.slow
def test_predicted_std_matches_the_spread_over_noise_draws(noisy_bump_pairs):
    """FE on a 12 x 8 Q9 mesh 2 mm inside the plate's edges, 8 draws of 2 gray levels of
    noise: the median over the nodes of predicted / empirical std lies in [0.8, 1.3] (the
    empirical std of 8 draws is itself ~25 % uncertain per node; the median over 425 nodes
    is not). A prediction from the images' Immerkaer sigma alone would be about 2 times too
    large on this 4 px speckle. (A mesh that reaches the plate's edge takes background
    pixels into its boundary elements, a misfit that the noise model counts as noise: the
    ratio then rises to about 1.3, benchmarks/bench_uncertainty.py --margin-mm 0.)"""
    cameras, clean = noisy_bump_pairs
    mesh = rectangle_mesh(56.0, 36.0, 12, 8, family="Q9")
    qs, stds = [], []
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        images = [Image.from_array(a + rng.normal(0.0, 2.0, a.shape), f"cam{k}")
                  for k, a in enumerate(clean)]
        m = measure(mesh, images, cameras, None, MeasurementSettings(scales=(0,)))
        assert m.ok, m.failure
        qs.append(m.q)
        stds.append(m.shape_std_mm)
    empirical = np.std(qs, axis=0, ddof=1)
    ratio = np.median(np.median(stds, axis=0) / empirical)
    assert 0.8 <= ratio <= 1.3, ratio


def test_tikhonov_step_covariance_with_the_gauge_projection():
    """shape_std through TikhonovSolver.step_covariance against the dense
    P G H G P^T, G = (H + lam A)^-1 (its weight chosen by a first solve of scale 0)."""
    from fesdic_core.solve.tikhonov import TikhonovSolver
    mesh = rectangle_mesh(30.0, 20.0, 4, 3, family="Q9")
    n = mesh.n_nodes
    H, rng = _spd(n, seed=5)
    solver = TikhonovSolver(mesh, 12.0)
    solver.solve(H, rng.standard_normal(n), np.zeros(n), 0)
    normals = np.tile([0.0, 0.0, 1.0], (n, 1))
    modes, _ = rigid_normal_modes(mesh.nodes, normals)
    w = nodal_areas(mesh)
    std = shape_std(H, 0.5, solver, 0, modes, w)
    G = np.linalg.inv(H.toarray() + solver.lambdas[0] * solver.A.toarray())
    C = 0.5 * G @ H.toarray() @ G
    keep = modes[:, [2, 3, 4]]
    W = np.diag(w)
    P = np.eye(n) - keep @ np.linalg.solve(keep.T @ W @ keep, keep.T @ W)
    np.testing.assert_allclose(std, np.sqrt(np.diag(P @ C @ P.T)), rtol=1e-8)


def test_shape_std_refuses_rigid_modes_without_their_weights():
    """The modes are projected out in the nodal weights' metric: modes alone are refused
    (a ValueError naming them, not numpy's TypeError on None)."""
    H = sps.identity(4, format="csr") * 2.0
    with pytest.raises(ValueError, match="rigid normal modes .* nodal weights"):
        shape_std(H, 1.0, DirectSolver(), modes=np.ones((4, 1)))
