"""The displacement's uncertainty (fesdic_core.displacement.uncertainty) against the truth of
a rendered pair (tests/scenes.py ``twist_wave_pair``: the flat plate, then the same paint
twisted and wavy, 2 gray levels of noise) and against repeated noise draws."""
import numpy as np
import pytest

from adapters.fesdic_core import nominal_model
from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                             measure_displacement)
from fesdic_core.imaging.image import Image
from georeg_app.series.reference import displacement_solver
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.spline.geometries import rectangle
from adapters.fesdic_core import displacement_space


@pytest.fixture(scope="module")
def plate(twist_wave_pair):
    model = nominal_model(rectangle(44.0, 30.0), (24, 16), "Q9")
    reference = displacement_reference(model.mesh, twist_wave_pair.reference,
                                       twist_wave_pair.cameras, DisplacementSettings(scales=(1, 0)))
    return model, reference


def _coverage(m, truth):
    """Share of the (node, component) pairs within two uncertainties of the truth."""
    return float(np.mean(np.abs(m.U - truth) <= 2.0 * m.uncertainty.uncertainty_mm))


@pytest.mark.parametrize("method, levels", [("fe", 2), ("georeg", 2)])
def test_two_uncertainties_cover_the_error_at_most_nodes(plate, twist_wave_pair, method, levels):
    """Measured on the twisted and wavy plate (scales 1, 0): plain FE 90.3 % of the (node,
    component) pairs within two standard deviations (it has no bias); georeg with 2 levels
    94.3 % within two combined uncertainties (the bias indicator less its noise; 97.8 % with
    the raw indicator), and fewer within two standard deviations alone (the estimated bias
    holds the rest). Asserted: 88-99 % combined; for georeg the standard
    deviation alone covers at least 2 points less."""
    model, reference = plate
    m = measure_displacement(reference, twist_wave_pair.deformed,
                             displacement_solver(method, model.mesh, model, 10.0, levels))
    assert m.ok, m.failure
    truth = twist_wave_pair.motion(model.mesh.nodes)
    u = m.uncertainty
    assert u.std_mm.shape == u.uncertainty_mm.shape == (model.mesh.n_nodes, 3)
    coverage = _coverage(m, truth)
    print(method, "coverage", coverage)                                 # pytest -s shows it
    assert 0.88 <= coverage <= 0.99
    std_only = float(np.mean(np.abs(m.U - truth) <= 2.0 * u.std_mm))
    if method == "fe":
        assert std_only == coverage          # FE has no regularization: its bias is zero...
        assert np.all(u.bias_mm < 0.1 * u.std_mm)       # ...up to the last step's remainder
    else:
        assert std_only < coverage - 0.02


def test_the_standard_deviation_is_that_of_repeated_noise(plate, twist_wave_pair):
    """No motion, the deformed pair the reference pair plus a fresh draw of 2 gray levels of
    noise (so the residual is that draw alone), four draws: the spread of the measured fields
    over the draws, per node and component, against the predicted standard deviation.

    The prediction is the linearised response to the noise. The converged fields spread 7 %
    more than the first Gauss-Newton step from the truth (which the linear model reproduces
    to 0.5 %: the noise's own gradient enters the later steps, a second-order effect), and
    the fit absorbs more of the noise than the linear model does (the residual ratio 0.72
    where the draws' amplitudes give 0.78): at 2 gray levels on this contrast the predicted
    std is 8-21 % low (measured 1.21 / 1.08 / 1.10 for x / y / z). Asserted: low by 0-25 %."""
    model, _ = plate
    reference = displacement_reference(model.mesh, twist_wave_pair.reference,
                                       twist_wave_pair.cameras, DisplacementSettings(scales=(0,)))
    solver = displacement_solver("fe", model.mesh, model)
    rng = np.random.default_rng(5)
    fields, predicted = [], []
    for _ in range(4):
        noisy = [Image.from_array(im.values + rng.normal(0.0, 2.0, im.shape), im.source)
                 for im in twist_wave_pair.reference]
        m = measure_displacement(reference, noisy, solver)
        assert m.ok, m.failure
        fields.append(m.U)
        predicted.append(m.uncertainty.std_mm)
    spread = np.std(np.array(fields), axis=0, ddof=1)                  # (n, 3)
    ratio = np.sqrt(np.mean(spread ** 2, axis=0) / np.mean(np.mean(predicted, axis=0) ** 2, axis=0))
    print("spread over predicted std per component", ratio)
    assert np.all((ratio >= 1.0) & (ratio <= 1.25)), ratio


def test_the_finer_ladder_solves_the_same_level_and_gives_its_bias(plate, twist_wave_pair):
    """The georeg solver of a series holds one level finer than it solves with: its step is
    that of the coarser ladder's finest level (the levels are nested and the same, Eq. 13),
    to rounding, and its bias indicator is the next finer level's change, not the FE step."""
    model, reference = plate
    held = displacement_solver("georeg", model.mesh, model, 10.0, 2)
    plain = GeometricRegularization(displacement_space(model, 2))
    assert held.n_levels == 3 and plain.n_levels == 2
    a = measure_displacement(reference, twist_wave_pair.deformed, held)
    b = measure_displacement(reference, twist_wave_pair.deformed, plain)
    assert np.max(np.abs(a.U - b.U)) < 1e-9
    # the plain ladder's bias is the unregularized step: every FE dof's noise, larger
    assert np.median(a.uncertainty.bias_mm) < 0.5 * np.median(b.uncertainty.bias_mm)


def test_an_uncertainty_that_cannot_be_computed_leaves_the_field_trusted(plate, twist_wave_pair,
                                                                          caplog):
    """A solver whose step covariance fails (here: it raises) gives the same trusted field,
    with no uncertainty and a warning that says why."""
    model, reference = plate

    class Failing(GeometricRegularization):
        def step_covariance(self, H, scale):
            raise ValueError("no covariance here")

    solver = Failing(displacement_space(model, 2))
    with caplog.at_level("WARNING"):
        m = measure_displacement(reference, twist_wave_pair.deformed, solver)
    assert m.ok and m.uncertainty is None
    assert "no covariance here" in caplog.text
    plain = measure_displacement(reference, twist_wave_pair.deformed,
                                 GeometricRegularization(displacement_space(model, 2)))
    np.testing.assert_array_equal(m.U, plain.U)
