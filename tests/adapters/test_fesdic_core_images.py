"""The plugin through the core's adapter on rendered images, against the true surface.

- the paper's NURBS plate with a hole (``plate_with_hole``, one patch) measured on the demo's
  twisted open-hole plate (tests/scenes.py ``small_demo_scene``: 1 mm twist + 0.2 mm waviness,
  500 x 333 px, noise 2 gray levels), exact cameras;
- the bias of a FIXED set of coarse spline levels on a feature shorter than their knot spans
  (``bump_scene``: a 0.3 mm Gaussian bump, sigma 2 mm, on a flat 60 x 40 mm plate).
"""
import numpy as np
import pytest

from adapters.fesdic_core import georeg_solver, nominal_model
from adapters.level_search import measure_auto_levels
from fesdic_core.shape.driver import MeasurementSettings, measure
from georeg_plugin.spline.geometries import plate_with_hole, rectangle
from shape_truth import bounded_shape_error, rms


@pytest.mark.slow
def test_nurbs_plate_with_hole_measures_the_twisted_open_hole_plate(small_demo_scene):
    """plate_with_hole (100 x 50 mm, r = 14 mm), 256 Q9 elements, 3 spline levels on image
    scales (2, 1, 0): RMS error to the true surface < 5 um (0.5 % of the 1 mm twist, 0.02 px)
    and <= 0.3 x the unregularized FE's on the same mesh. Measured: 3.0 um; FE 17.8 um."""
    scene = small_demo_scene
    model = nominal_model(plate_with_hole(100.0, 50.0, 14.0), 3, "Q9")
    images = scene.images
    geo = measure(model.mesh, images, scene.cameras, georeg_solver(model, 3),
                  MeasurementSettings(scales=(2, 1, 0)))
    fe = measure(model.mesh, images, scene.cameras, None, MeasurementSettings(scales=(1, 0)))
    nominal = rms(bounded_shape_error(model.mesh.nodes, scene.specimen))
    geo_error = rms(bounded_shape_error(geo.nodes, scene.specimen))
    fe_error = rms(bounded_shape_error(fe.nodes, scene.specimen))
    assert nominal > 0.2                                  # the flat nominal is 0.24 mm off
    assert geo_error < 0.005, geo_error
    assert geo_error <= 0.3 * fe_error, (geo_error, fe_error)
    # no node of the hole's edge or of the C0 lines runs away: worst node < 25 um
    assert abs(bounded_shape_error(geo.nodes, scene.specimen)).max() < 0.025


@pytest.mark.slow
def test_georeg_with_fixed_coarse_levels_is_worse_than_fe_on_a_short_feature(bump_scene):
    """The bias that the level search removes: with 2 FIXED spline levels of the plate
    (finest knot spans 30 x 20 mm) a 0.3 mm bump of sigma 2 mm is not in the spline space;
    georeg flattens it. Measured: 19.0 um against FE's 10.8 um on the same 24 x 16 Q9 mesh."""
    model = nominal_model(rectangle(60.0, 40.0), (24, 16), "Q9")
    images = bump_scene.images
    settings = MeasurementSettings(scales=(0,))
    geo = measure(model.mesh, images, bump_scene.cameras, georeg_solver(model, 2), settings)
    fe = measure(model.mesh, images, bump_scene.cameras, None, settings)
    geo_error = rms(bounded_shape_error(geo.nodes, bump_scene.specimen))
    fe_error = rms(bounded_shape_error(fe.nodes, bump_scene.specimen))
    assert geo_error > 1.5 * fe_error, (geo_error, fe_error)
    # the verdict (residual <= 3 x the images' noise floor) does not catch this bias (1.68 %
    # against a 1.9 % floor): only the level search's statistic does, below
    assert geo.ok


@pytest.mark.slow
def test_automatic_level_is_not_worse_than_fe_on_a_short_feature(bump_scene):
    """The same start (2 levels), then the level search: it climbs the ladder to the
    spline of the FE mesh (26 x 18 = 468 dofs) and beats FE. Measured: 7.3 um, FE 11.1 um."""
    model = nominal_model(rectangle(60.0, 40.0), (24, 16), "Q9")
    images = bump_scene.images
    settings = MeasurementSettings(scales=(0,))
    geo, solver, search = measure_auto_levels(model, images, bump_scene.cameras, settings,
                                              start_levels=2)
    fe = measure(model.mesh, images, bump_scene.cameras, None, settings)
    geo_error = rms(bounded_shape_error(geo.nodes, bump_scene.specimen))
    fe_error = rms(bounded_shape_error(fe.nodes, bump_scene.specimen))
    assert geo.ok, geo.failure
    assert search.chosen < search.start and solver.level(0) == search.chosen
    assert geo_error <= fe_error, (geo_error, fe_error)
    # the measurement at the chosen level carries the core's verdict and uncertainty
    assert geo.converged and geo.scales[-1].residual_percent == pytest.approx(geo.residual_percent)
    assert geo.shape_std_mm is not None and np.all(np.isfinite(geo.shape_std_mm))
    assert geo.state.H.shape == (model.mesh.n_nodes,) * 2 and geo.noise.variance > 0
    # the search chose by its estimate of the shape error (bias and noise at the nodes):
    # the chosen level's estimate is that of an error of the measured size
    chosen = [t for t in search.trials if t.chosen]
    assert len(chosen) == 1 and chosen[0].level == search.chosen
    assert 0.0 < chosen[0].std_mm <= chosen[0].error_mm
    assert 0.5 * geo_error <= chosen[0].error_mm <= 2.0 * geo_error, (chosen[0], geo_error)
    # its combined uncertainty covers the error at most nodes (|error| <= 2 uncertainty)
    covered = np.abs(bounded_shape_error(geo.nodes, bump_scene.specimen)) <= 2 * geo.shape_uncertainty_mm
    assert covered.mean() >= 0.9, covered.mean()
