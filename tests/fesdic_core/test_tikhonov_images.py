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
from fesdic_core.driver import MeasurementSettings, measure
from fesdic_core.mesh import rectangle_mesh
from fesdic_core.tikhonov import TikhonovSolver
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
