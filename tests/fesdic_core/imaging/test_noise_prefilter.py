"""The noise floor of the residual through the image model's prefilter (fesdic_core.imaging.noise)."""
import numpy as np
import pytest

from fesdic_core.imaging.image import Image
from fesdic_core.imaging.noise import residual_noise_floor


class _PixelCamera:
    """A camera that sees the world point (x, y, z) at the pixel (x, y)."""

    def project(self, X):
        return np.asarray(X)[:, :2]


@pytest.mark.parametrize("sigma", [0.5, 0.9, 1.2])
def test_noise_gain_is_the_models_white_noise_gain(sigma):
    """The model's values at the pixel centres (the spline interpolates the prefiltered
    values there) of white noise of std 10 have std ``10 * noise_gain``; measured to 2 %
    on 300 x 300 px (the estimate's own scatter is about 0.5 %)."""
    noise = np.random.default_rng(3).normal(0.0, 10.0, size=(300, 300))
    image = Image.from_array(noise, prefilter_px=sigma)
    yy, xx = np.mgrid[20:280, 20:280]
    model = image.evaluate(np.column_stack([xx.ravel(), yy.ravel()]).astype(float))
    assert np.std(model) == pytest.approx(10.0 * image.noise_gain, rel=0.02)
    assert Image.from_array(noise, prefilter_px=0.0).noise_gain == 1.0


def test_floor_scales_by_the_gain_and_the_texture_check_keeps_the_raw_sigma():
    rng = np.random.default_rng(4)
    a, b = (rng.uniform(0, 255, size=(60, 80)) for _ in range(2))
    yy, xx = np.mgrid[5:55, 5:75]
    X = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)]).astype(float)
    mask = np.ones(len(X), bool)
    cams = (_PixelCamera(), _PixelCamera())
    raw = residual_noise_floor(X, mask, [Image.from_array(v, prefilter_px=0.0) for v in (a, b)], cams)
    smooth_images = [Image.from_array(v, prefilter_px=0.7) for v in (a, b)]
    smooth = residual_noise_floor(X, mask, smooth_images, cams)
    assert smooth.sigma_gray == raw.sigma_gray and smooth.contrast == raw.contrast
    assert smooth.texture_ratio() == raw.texture_ratio()
    assert smooth.percent == pytest.approx(smooth_images[0].noise_gain * raw.percent, rel=1e-12)
    assert smooth.percent < 0.5 * raw.percent
