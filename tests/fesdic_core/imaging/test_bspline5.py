"""Tests of the quintic B-spline of the image model (fesdic_core.imaging.bspline5): weights, and the
compiled 6x6 kernel against its numpy twin. Values against scipy's order-5 map_coordinates,
gradients against finite differences: tests/fesdic_core/test_image.py."""
import numpy as np
import pytest

from fesdic_core import parallel
from fesdic_core.imaging import bspline5
from fesdic_core.imaging.image import Image


def test_quintic_weights_are_the_b_spline():
    """Partition of unity, reproduction of x (sum_a (a - 2) w_a = t), derivative by difference."""
    t = np.linspace(0.0, 1.0, 101)
    w, dw = bspline5.weights(t)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(w @ np.arange(-2, 4), t, atol=1e-15)
    np.testing.assert_allclose(dw.sum(axis=1), 0.0, atol=1e-14)
    h = 1e-6
    fd = (bspline5.weights(t + h)[0] - bspline5.weights(t - h)[0]) / (2 * h)
    np.testing.assert_allclose(dw, fd, atol=1e-9)
    np.testing.assert_allclose(w[0], [1, 26, 66, 26, 1, 0] / np.float64(120), atol=1e-16)   # b5 at nodes


@pytest.mark.skipif(not bspline5.COMPILED, reason="installed without the C kernel")
@pytest.mark.parametrize("shape", [(37, 53), (1, 9), (2, 3), (200, 150)])
def test_compiled_quintic_kernel_equals_its_numpy_twin(shape):
    image = Image.from_array(np.random.default_rng(3).uniform(0.0, 255.0, size=shape), order=5)
    rng = np.random.default_rng(4)
    h, w = image.shape
    xy = np.column_stack([rng.uniform(-40.5, w + 39.5, 200_000),      # mirror folds included
                          rng.uniform(-40.5, h + 39.5, 200_000)])
    xy[::997] = np.nan
    xy[1::1009, 0] = np.inf
    with parallel.threads(2):                                       # threaded split
        compiled = image.evaluate_with_gradient(xy)
    value, grad = np.empty(len(xy)), np.empty((len(xy), 2))
    bspline5.evaluate_numpy(image._padded, h, w, xy, value, grad)
    for a, b in zip(compiled, (value, grad)):
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * image.dynamic_range, equal_nan=True)
