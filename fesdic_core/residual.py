"""The gray-level residual of Eq. 3 with brightness/contrast normalisation (Remark 2).

``r(X) = f0(P0(X + S(X))) - f1(P1(X + S(X)))`` at every integration point, after each
image is brought to zero mean and unit standard deviation over each element
("element", Remark 2), over the whole region ("global"), or left raw ("none").
The normalised gradients ``grad f_c / sigma_c`` enter the Gauss-Newton operators.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np

from .quadrature import PixelQuadrature

logger = logging.getLogger(__name__)

Normalisation = Literal["element", "global", "none"]
NORMALISATIONS = ("element", "global", "none")
_SIGMA_FLOOR = 0.005  # fraction of the dynamic range below which an element is "uniform"


@dataclass(frozen=True)
class GrayLevelResidual:
    """Residual and what its derivatives need, at the integration points.

    Attributes
    ----------
    r : (g,) normalised residual of Eq. 3 (0 where ``mask`` is False)
    mask : (g,) bool, point seen inside both images
    x : tuple of (g, 2) pixel positions in each image
    grad : tuple of (g, 2) normalised image gradients ``grad f_c / sigma_c``
    jac : tuple of (g, 2, k) Jacobians of the projections (k = 3 for dX, 6 for extrinsics) or None
    sigma0 : (g,) gray-level scale of image 0 at the point (to turn r into gray levels)
    dynamic_range : float, dynamic range of image 0 (gray levels)
    """

    r: np.ndarray
    mask: np.ndarray
    x: tuple
    grad: tuple
    jac: tuple | None
    sigma0: np.ndarray
    dynamic_range: float

    @property
    def percent(self) -> np.ndarray:
        """Residual per point in percent of the dynamic range of image 0 (NaN if unseen)."""
        out = np.full(self.r.shape, np.nan)
        out[self.mask] = 100.0 * self.r[self.mask] * self.sigma0[self.mask] / self.dynamic_range
        return out

    @property
    def std_percent(self) -> float:
        """Standard deviation of the residual field in percent of the dynamic range (Fig. 11)."""
        p = self.percent[self.mask]
        return float(np.std(p)) if p.size else float("nan")

    @property
    def n_dropped(self) -> int:
        return int(np.count_nonzero(~self.mask))


def _normalise(values: np.ndarray, mask: np.ndarray, element: np.ndarray, n_elements: int,
               mode: str, dynamic_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(f - mean) / sigma`` and ``sigma`` per point (Remark 2)."""
    if mode == "none":
        return values, np.ones_like(values)
    if mode == "global":
        v = values[mask]
        mean, sigma = v.mean(), max(v.std(), _SIGMA_FLOOR * dynamic_range)
        return (values - mean) / sigma, np.full_like(values, sigma)
    w = mask.astype(float)
    count = np.bincount(element, weights=w, minlength=n_elements)
    safe = np.maximum(count, 1.0)
    mean = np.bincount(element, weights=w * values, minlength=n_elements) / safe
    var = np.bincount(element, weights=w * values ** 2, minlength=n_elements) / safe - mean ** 2
    sigma = np.maximum(np.sqrt(np.maximum(var, 0.0)), _SIGMA_FLOOR * dynamic_range)
    return (values - mean[element]) / sigma[element], sigma[element]


def gray_level_residual(X: np.ndarray, quad: PixelQuadrature, images: Sequence, cameras: Sequence,
                        normalisation: str = "element", jacobian: str | None = "point",
                        extra_mask: np.ndarray | None = None) -> GrayLevelResidual:
    """Evaluate Eq. 3 at the integration points ``X`` (g, 3) for a stereo pair.

    Parameters
    ----------
    X : (g, 3) positions of the integration points on the current surface (mm)
    quad : PixelQuadrature
    images, cameras : the two images and their cameras at the same scale
    normalisation : "element" (Remark 2), "global" or "none"
    jacobian : "point" (dx/dX, for the shape), "extrinsic" (dx/dp, for calibration) or None
    extra_mask : (g,) bool, optional, points to ignore (e.g. faces hidden from a camera)
    """
    if normalisation not in NORMALISATIONS:
        raise ValueError(f"normalisation must be one of {NORMALISATIONS}, got {normalisation!r}")
    mask = np.ones(len(X), dtype=bool) if extra_mask is None else extra_mask.copy()
    xs, jacs, vals, grads = [], [], [], []
    for image, cam in zip(images, cameras):
        if jacobian == "point":
            x, J = cam.project_jacobian(X)
        elif jacobian == "extrinsic":
            x, J = cam.extrinsic_jacobian(X)
        else:
            x, J = cam.project(X), None
        mask &= np.all(np.isfinite(x), axis=1) & image.inside(x) & cam.in_front(X)
        xs.append(x)
        jacs.append(J)
    for image, x in zip(images, xs):
        xm = np.where(mask[:, None], x, 0.0)                     # keep unseen points harmless
        f, g = image.evaluate_with_gradient(xm)
        vals.append(f)
        grads.append(g)
    dyn = float(images[0].dynamic_range)
    normed, sigmas = [], []
    for f in vals:
        fn, sigma = _normalise(f, mask, quad.element, quad.n_elements, normalisation, dyn)
        normed.append(fn)
        sigmas.append(sigma)
    r = np.where(mask, normed[0] - normed[1], 0.0)              # Eq. 3 (Remark 2)
    grad = tuple(np.where(mask[:, None], g / s[:, None], 0.0) for g, s in zip(grads, sigmas))
    return GrayLevelResidual(r=r, mask=mask, x=tuple(xs), grad=grad,
                             jac=None if jacobian is None else tuple(jacs),
                             sigma0=sigmas[0], dynamic_range=dyn)
