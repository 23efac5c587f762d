"""shape_error_to_surface on a surface with a LOCALIZED feature (a 0.3 mm bump, tests/scenes.py).

The accuracy of every synthetic test rests on this function: it must not report a flat shape
as exact when the truth has a bump.
"""
import numpy as np
import pytest

from fesdic_core.synthetic.accuracy import shape_error_to_surface
from scenes import bump_specimen
from shape_truth import bounded_shape_error, rms


def _flat_grid():
    x, y = np.meshgrid(np.linspace(-30.0, 30.0, 49), np.linspace(-20.0, 20.0, 33))
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


def test_bounded_alignment_sees_the_bump():
    """The test helper (rigid motion <= 2 deg, 2 mm): the flat grid is 20.7 um RMS off the
    bumped plate (21.2 um without any alignment; a best plane takes little of a bump)."""
    specimen, flat = bump_specimen(), _flat_grid()
    raw = rms(specimen.height(flat[:, 0], flat[:, 1]))
    assert raw > 0.02
    assert 0.9 * raw < rms(bounded_shape_error(flat, specimen)) <= raw


@pytest.mark.slow
def test_shape_error_to_surface_does_not_dodge_a_localized_feature():
    specimen, flat = bump_specimen(), _flat_grid()
    raw = rms(specimen.height(flat[:, 0], flat[:, 1]))
    assert rms(shape_error_to_surface(flat, specimen)) > 0.9 * raw
