"""Tikhonov regularization (Eq. 10) measured on rendered images, against the true surface.

The scene (tests/conftest.py ``bump_scene``): a flat 60 x 40 mm plate carrying a Gaussian
bump of 0.3 mm (sigma 2 mm, width at half height 4.7 mm), 480 x 320 px (0.15 mm/px), noise of
2 gray levels; exact cameras, one image scale. The mesh: 24 x 16 Q9 elements of 2.5 mm, fine
enough to hold the bump. Errors: distances to the true surface after a rigid motion of at most
2 deg / 2 mm (tests/shape_truth.py).
"""
import numpy as np
import pytest

from scenes import BUMP
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.shape.driver import MeasurementSettings, measure
from fesdic_core.solve.tikhonov import TikhonovSolver, tikhonov_weight
from shape_truth import bounded_shape_error, rms


@pytest.fixture(scope="module")
def mesh():
    return rectangle_mesh(60.0, 40.0, 24, 16, family="Q9")


@pytest.fixture(scope="module")
def measured(bump_scene, mesh):
    """method -> Measurement on the bump scene (FE, Tikhonov 5 mm, Tikhonov 30 mm)."""
    images = bump_scene.images
    solvers = {"fe": None, "tikhonov 5": TikhonovSolver(mesh, 5.0),
               "tikhonov 30": TikhonovSolver(mesh, 30.0)}
    return {name: measure(mesh, images, bump_scene.cameras, solver, MeasurementSettings(scales=(0,)))
            for name, solver in solvers.items()}


def _error(bump_scene, m):
    return rms(bounded_shape_error(m.nodes, bump_scene.specimen))


def _peak(bump_scene, m, mesh):
    """Measured height at the node closest to the bump's centre, above the plate's median."""
    i = np.argmin(np.linalg.norm(mesh.nodes[:, :2] - np.asarray(BUMP["centre"]), axis=1))
    return float(m.nodes[i, 2] - np.median(m.nodes[:, 2]))


@pytest.mark.slow
def test_tikhonov_on_images_measures_the_bump_plate_better_than_fe(bump_scene, measured, mesh):
    """Tikhonov 5 mm, through driver.measure on the rendered pair: RMS error < 3 % of the bump
    (9 um) and below the unregularized FE's (whose noise it filters). The nominal flat plate
    is 20.7 um RMS from the truth. Measured: Tikhonov 5 mm 4.5 um, FE 10.8 um."""
    flat = rms(bounded_shape_error(mesh.nodes, bump_scene.specimen))
    tik, fe = _error(bump_scene, measured["tikhonov 5"]), _error(bump_scene, measured["fe"])
    assert flat > 0.015                       # the bump is there to be measured
    assert tik < 0.03 * BUMP["amplitude"], tik
    assert tik < fe, (tik, fe)
    # the bump itself comes out; FE (no bias) puts its peak within 5 % of the truth (0.291 mm
    # at the node (7.5, 5) next to the centre); measured: FE 0.295 mm, Tikhonov 5 mm 0.262 mm
    # (a 5 mm length is already as long as the bump: its peak is cut by 13 %)
    centre_node = np.argmin(np.linalg.norm(mesh.nodes[:, :2] - np.asarray(BUMP["centre"]), axis=1))
    true_peak = float(bump_scene.specimen.height(*mesh.nodes[centre_node, :2]))
    assert _peak(bump_scene, measured["fe"], mesh) == pytest.approx(true_peak, rel=0.05)
    assert 0.5 * true_peak < _peak(bump_scene, measured["tikhonov 5"], mesh) < true_peak


def test_tikhonov_longer_than_the_feature_flattens_it(bump_scene, measured, mesh):
    """Over-regularization bias: a Tikhonov length (30 mm) far longer than the bump (4.7 mm at
    half height) flattens it: more than twice the error of a 5 mm length, and a peak cut by
    more than half. Measured: error 15.8 um (30 mm) vs 4.5 um (5 mm); peak 0.059 mm vs
    0.262 mm (truth 0.291 mm at that node); residual 1.594 % vs 1.329 %."""
    short, long = measured["tikhonov 5"], measured["tikhonov 30"]
    assert _error(bump_scene, long) > 2.0 * _error(bump_scene, short)
    assert _peak(bump_scene, long, mesh) < 0.5 * _peak(bump_scene, short, mesh)
    # a bias, not noise: the long length fits the images worse (its residual is higher)
    assert long.residual_percent > short.residual_percent


class _NoiseModel:
    """Duck-typed noise model (the solver reads ``variance`` only)."""

    def __init__(self, scale, variance):
        self.scale, self.variance = scale, variance


def _kappa(m):
    """``kappa`` with ``Cov(b) ~= kappa H`` from a converged residual: with independent point
    residuals of variance sigma^2, ``Cov(b) = sigma^2 sum w^2 phi phi^T``, so for (nearly)
    uniform weights ``kappa = sum w^2 r^2 / sum w``."""
    r, w = m.residual.r[m.residual.mask], m.quadrature.weight_mm2[m.residual.mask]
    return float(np.sum(w * w * r * r) / np.sum(w))


@pytest.mark.slow
def test_automatic_length_on_images_is_as_good_as_the_best_fixed_one(bump_scene, measured, mesh):
    """length_mm="auto" with the noise of the FE fit's residual: the Cp choice measures the
    bump as well as the better fixed length (5 mm, error within 1.3 x) and better than FE and
    the 30 mm length. Measured: it chooses 5 mm (the grid's shortest, 2 elements), 4.5 um."""
    solver = TikhonovSolver(mesh, "auto")
    solver.start_scale(0, _NoiseModel(0, _kappa(measured["fe"])))
    auto = measure(mesh, bump_scene.images, bump_scene.cameras, solver,
                   MeasurementSettings(scales=(0,)))
    error = _error(bump_scene, auto)
    assert error <= 1.3 * _error(bump_scene, measured["tikhonov 5"]), error
    assert error < _error(bump_scene, measured["fe"])
    assert error < 0.5 * _error(bump_scene, measured["tikhonov 30"])
    assert set(solver.lambdas) == {0} and solver.chosen_lengths_mm[0] in solver.grid_mm


class _Spy(TikhonovSolver):
    """Records the weight of every step and the H of the first step of each scale."""

    def __init__(self, *args):
        super().__init__(*args)
        self.steps, self.first_H = [], {}

    def solve(self, H, b, q, scale):
        self.first_H.setdefault(scale, H.copy())
        d = super().solve(H, b, q, scale)
        self.steps.append((scale, self.last_lambda))
        return d


@pytest.mark.slow
def test_multiscale_weight_is_fixed_per_scale_and_weakens_on_finer_images(bump_scene, mesh):
    """Through driver.measure with scales (1, 0) and a 5 mm length: every step of a scale
    uses that scale's weight, the cosine-probe weight of 10 mm (scale 1) and 5 mm (scale 0)
    from the scale's first H (Remark 3)."""
    solver = _Spy(mesh, 5.0)
    m = measure(mesh, bump_scene.images, bump_scene.cameras, solver,
                MeasurementSettings(scales=(1, 0)))
    assert m.ok, m.failure
    assert solver.chosen_lengths_mm == {1: 10.0, 0: 5.0}
    for s in (1, 0):
        weights = {lam for scale, lam in solver.steps if scale == s}
        assert weights == {solver.lambdas[s]}
        assert solver.lambdas[s] == pytest.approx(
            tikhonov_weight(solver.first_H[s], solver.A, mesh.nodes, 5.0 * 2 ** s), rel=1e-12)
    assert all(sum(1 for scale, _ in solver.steps if scale == s) >= 2 for s in (1, 0))
