"""How large the gray-level residual of Eq. 3 may be: the images' own noise.

At the true shape and poses the residual is not zero: each camera adds its sensor noise,
and the interpolant misses the finest texture (sub-pixel speckle detail), differently in
the two views. Both are estimated from each image alone with Immerkaer's operator
(J. Immerkaer, "Fast noise variance estimation", CVIU 64(2), 1996)::

    N = [[1, -2, 1], [-2, 4, -2], [1, -2, 1]],     sigma = sqrt(pi / 2) * mean |N * f| / 6,

the difference of two Laplacians, blind to the image's smooth content (every quadratic
in x and y) and answering to white noise with ``6 sigma`` standard deviation. It is taken
over the pixels that the integration points fall on (the region of interest), not over
the background. On a noise-free rendered speckle it gives the texture's fine content,
which is the part the interpolation cannot follow; with noise it adds in quadrature.

The residual compares the images through their image model (:mod:`fesdic_core.imaging.image`):
a Gaussian prefilter of the raw pixels, then the spline. The prefilter lowers the noise in
the residual by the model's white-noise gain ``k_c`` (:attr:`Image.noise_gain`: the
standard deviation of the prefiltered values per unit of white noise in the raw pixels,
0.64 at 0.5 px), while sigma is estimated on the RAW values (Immerkaer's operator assumes
white noise). A residual consistent with the images then has a standard deviation (in
gray levels of image 0, as :attr:`GrayLevelResidual.std_percent`) of about
``sqrt((k_0 sigma_0)**2 + (s_0 / s_1)**2 (k_1 sigma_1)**2)`` where ``s_c`` is the contrast
of image ``c`` over the region (the residual compares normalised gray levels, Remark 2).
Measured on renders with known truth (``benchmarks/bench_verdict.py``, the default model,
prefilter 0.5 px), the converged residual is 0.48 times this figure without noise and 0.63
with 2 gray levels, and 19-25 times it for swapped images or a camera turned by 10
degrees (without prefilter: 0.43, 0.58 and 13-17): :data:`CONSISTENCY_FACTOR` lies between.
The texture check (:meth:`NoiseFloor.texture_ratio`) keeps the raw sigma: it is about the
image, not its model.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

__all__ = ["CONSISTENCY_FACTOR", "MIN_TEXTURE_RATIO", "NoiseFloor", "immerkaer_sigma",
           "immerkaer_response", "residual_noise_floor"]

#: a residual more than this many times the noise floor is not explained by the images
CONSISTENCY_FACTOR = 3.0
#: an image whose contrast over the region is below this many times its noise shows no
#: texture to correlate (white noise has a ratio of 1; a 4 px speckle about 20)
MIN_TEXTURE_RATIO = 2.0

_IMMERKAER = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])


def immerkaer_response(values: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Immerkaer's noise estimate at each pixel nearest to ``xy`` (m, 2) (x = column):
    ``sqrt(pi / 2) |N * f| / 6`` (m,) gray levels, whose mean over a region is
    :func:`immerkaer_sigma` there; its mean over a node's support is that node's local noise
    (:mod:`fesdic_core.residual.validity`)."""
    values = np.asarray(values, dtype=np.float64)
    h, w = values.shape
    if h < 3 or w < 3:
        raise ValueError(f"an image of {w} x {h} px is too small to estimate its noise")
    response = np.abs(cv2.filter2D(values, -1, _IMMERKAER, borderType=cv2.BORDER_REFLECT))
    col = np.clip(np.rint(np.nan_to_num(xy[:, 0])).astype(np.int64), 1, w - 2)
    row = np.clip(np.rint(np.nan_to_num(xy[:, 1])).astype(np.int64), 1, h - 2)
    return np.sqrt(np.pi / 2.0) * response[row, col] / 6.0


def immerkaer_sigma(values: np.ndarray, xy: np.ndarray | None = None) -> float:
    """Noise standard deviation (gray levels) of an image by Immerkaer's operator.

    Parameters
    ----------
    values : (h, w) gray levels
    xy : (m, 2) optional pixel coordinates (x = column) of the region of interest; the
        operator's response is averaged over the pixels nearest to them (default: every
        pixel whose 3 x 3 neighbourhood lies inside the image)
    """
    values = np.asarray(values, dtype=np.float64)
    h, w = values.shape
    if h < 3 or w < 3:
        raise ValueError(f"an image of {w} x {h} px is too small to estimate its noise")
    if xy is not None:
        inner = immerkaer_response(values, xy)
        return float(np.mean(inner)) if inner.size else float("nan")
    response = np.abs(cv2.filter2D(values, -1, _IMMERKAER, borderType=cv2.BORDER_REFLECT))
    inner = response[1:-1, 1:-1]
    return float(np.sqrt(np.pi / 2.0) * np.mean(inner) / 6.0)


@dataclass(frozen=True)
class NoiseFloor:
    """The residual the images explain at one scale.

    Attributes
    ----------
    sigma_gray : (2,) Immerkaer's sigma of each image's RAW values over the region (gray levels)
    contrast : (2,) standard deviation of each image's gray levels over the region
    percent : the residual's expected standard deviation, in percent of the dynamic range
        of image 0 (the unit of ``std_percent``), with each sigma times its image model's
        white-noise gain
    """

    sigma_gray: tuple[float, float]
    contrast: tuple[float, float]
    percent: float

    def texture_ratio(self) -> tuple[float, ...]:
        """Contrast over noise of each image (how much texture stands above the noise)."""
        return tuple(c / s if s > 0 else (np.inf if c > 0 else 0.0)
                     for c, s in zip(self.contrast, self.sigma_gray))


def residual_noise_floor(X: np.ndarray, mask: np.ndarray, images: Sequence, cameras: Sequence
                         ) -> NoiseFloor:
    """Noise floor of the residual for the integration points ``X`` (g, 3) seen (``mask``).

    ``images`` and ``cameras`` at the same scale (:class:`~fesdic_core.imaging.image.Image`,
    :class:`~fesdic_core.cameras.camera.Camera`).
    """
    seen = X[np.asarray(mask, bool)]
    sigma, contrast = [], []
    for image, camera in zip(images, cameras):
        xy = camera.project(seen) if len(seen) else np.empty((0, 2))
        sigma.append(immerkaer_sigma(image.values, xy))
        if len(xy):
            col = np.clip(np.rint(xy[:, 0]).astype(np.int64), 0, image.shape[1] - 1)
            row = np.clip(np.rint(xy[:, 1]).astype(np.int64), 0, image.shape[0] - 1)
            contrast.append(float(np.std(image.values[row, col])))
        else:
            contrast.append(float("nan"))
    ratio = contrast[0] / contrast[1] if contrast[1] > 0 else 1.0
    gain = [float(getattr(image, "noise_gain", 1.0)) for image in images]
    gray = np.hypot(gain[0] * sigma[0], ratio * gain[1] * sigma[1])
    dyn = float(images[0].dynamic_range)
    percent = 100.0 * gray / dyn if dyn > 0 else float("nan")
    return NoiseFloor(sigma_gray=(sigma[0], sigma[1]), contrast=(contrast[0], contrast[1]),
                      percent=float(percent))
