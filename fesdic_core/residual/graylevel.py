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

from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.parallel import for_each_span

logger = logging.getLogger(__name__)

__all__ = ["NORMALISATIONS", "GrayLevelResidual", "gray_level_residual"]

Normalisation = Literal["element", "global", "none"]
NORMALISATIONS = ("element", "global", "none")
_SIGMA_FLOOR = 0.005  # fraction of the dynamic range below which an element is "uniform"
_BLOCK = 1 << 14      # points per block: the temporaries of a block stay in cache, and the
                      # thin (block, 3) @ (3, k) products stay below the size at which
                      # OpenBLAS shares one out over its own threads (oversubscribed inside
                      # the core's threads: 4x slower on the loaded 2-core benchmark machine)


@dataclass(frozen=True, eq=False)
class GrayLevelResidual:
    """Residual and its derivatives at the integration points.

    Attributes
    ----------
    r : (g,) normalised residual of Eq. 3 (0 where ``mask`` is False)
    mask : (g,) bool, point seen inside both images (and kept by the extra mask)
    dr_dX : (g, 3) ``dr/dX = J0^T grad f0 - J1^T grad f1`` (normalised gradients), or None
    dr_dp : (g, 12) ``dr/dp`` for the extrinsics ``[p0, p1]`` of the two cameras, or None
    sigma0 : (g,) gray-level scale of image 0 at the point (to turn r into gray levels)
    dynamic_range : float, dynamic range of image 0 (gray levels)
    std_percent : standard deviation of :attr:`percent` over the mask (Fig. 11; NaN if empty)
    """

    r: np.ndarray
    mask: np.ndarray
    dr_dX: np.ndarray | None
    dr_dp: np.ndarray | None
    sigma0: np.ndarray
    dynamic_range: float
    std_percent: float

    @property
    def percent(self) -> np.ndarray:
        """Residual per point in percent of the dynamic range of image 0 (NaN if unseen)."""
        out = np.full(self.r.shape, np.nan)
        out[self.mask] = 100.0 * self.r[self.mask] * self.sigma0[self.mask] / self.dynamic_range
        return out

    @property
    def n_dropped(self) -> int:
        return int(np.count_nonzero(~self.mask))


def _scale_of(moments: np.ndarray, dynamic_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean and scale (floored) from the moments ``[count, sum f, sum f^2]`` (3, m)."""
    count = np.maximum(moments[0], 1.0)
    mean = moments[1] / count
    var = np.maximum(moments[2] / count - mean ** 2, 0.0)
    return mean, np.maximum(np.sqrt(var), _SIGMA_FLOOR * dynamic_range)


def _project_and_sample(X: np.ndarray, images: Sequence, cameras: Sequence, jacobian: str | None,
                        mask: np.ndarray, f: np.ndarray, pull: np.ndarray) -> None:
    """One block of points: project into both views, sample ``f_c``, pull ``grad f_c`` back.

    Writes the block's mask (in place), gray levels ``f`` (2, b) and pulled-back gradients
    ``J_c^T grad f_c`` (2, b, k) (not yet normalised).
    """
    views = []
    for image, cam in zip(images, cameras):
        x, lin = cam.linearise(X)
        with np.errstate(invalid="ignore"):
            mask &= (lin.inv_z > 0.0) & image.inside(x)                 # inside() is False for NaN
        views.append((x, lin))
    for c, (image, (x, lin)) in enumerate(zip(images, views)):
        x[~mask] = 0.0                                                 # keep unseen points harmless
        value, grad = image.evaluate_with_gradient(x)
        f[c] = value
        if jacobian == "point":
            pull[c] = lin.pull_point(grad)                             # J_c^T grad f_c
        elif jacobian == "extrinsic":
            pull[c] = lin.pull_extrinsic(grad)


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
    jacobian : "point" (``dr/dX``, for the shape), "extrinsic" (``dr/dp``, for calibration)
        or None
    extra_mask : (g,) bool, optional, points to ignore (e.g. faces hidden from a camera)

    Two passes over cache-sized blocks of whole elements, shared out over threads (numpy
    and the interpolation kernel release the GIL): sampling and the gray-level moments of
    each element, then the normalised residual, its derivative and its moments.
    """
    if normalisation not in NORMALISATIONS:
        raise ValueError(f"normalisation must be one of {NORMALISATIONS}, got {normalisation!r}")
    if jacobian not in (None, "point", "extrinsic"):
        raise ValueError(f"jacobian must be None, 'point' or 'extrinsic', got {jacobian!r}")
    X = np.ascontiguousarray(X, dtype=np.float64)
    g = len(X)
    mask = np.ones(g, dtype=bool) if extra_mask is None else np.array(extra_mask, dtype=bool)
    f = np.empty((2, g))
    k = {"point": 3, "extrinsic": 6, None: 0}[jacobian]
    if jacobian == "extrinsic":                       # pull[c] (g, k); dr_dp (g, 2k) = [p0, p1]
        pull = np.empty((g, 2, k)).transpose(1, 0, 2)
    else:                                             # dr_dX = pull[0], contiguous
        pull = np.empty((2, g, k))
    blocks = quad.element_blocks(_BLOCK)
    run_starts, run_element = quad.element_runs
    moments = np.zeros((2, 3, len(run_starts)))       # per camera, per element run: n, sum, sum^2

    def sample(i: int) -> None:
        b, runs = blocks[i]
        _project_and_sample(X[b], images, cameras, jacobian, mask[b], f[:, b], pull[:, b])
        seen = mask[b].astype(float)
        starts = run_starts[runs] - b.start
        for c in range(2):
            fm = f[c, b] * seen
            moments[c, :, runs] = [np.add.reduceat(seen, starts), np.add.reduceat(fm, starts),
                                   np.add.reduceat(fm * fm, starts)]

    for_each_span(sample, len(blocks))
    dyn = float(images[0].dynamic_range)
    n_elements = quad.n_elements
    stats = []                                        # mean and sigma per element (Remark 2)
    for c in range(2):
        if normalisation == "none":
            mean, sigma = np.zeros(n_elements), np.ones(n_elements)
        else:
            m = moments[c].sum(axis=1, keepdims=True) if normalisation == "global" else moments[c]
            mean_r, sigma_r = _scale_of(m, dyn)
            mean, sigma = np.empty(n_elements), np.empty(n_elements)
            mean[run_element], sigma[run_element] = mean_r, sigma_r
        stats.append((mean, sigma))
    (mean0, sigma0), (mean1, sigma1) = stats
    r, s0 = np.empty(g), np.empty(g)
    residual_moments = np.zeros((len(blocks), 3))     # n, mean, M2 of r * sigma0 per block

    def normalise(i: int) -> None:                                      # Remark 2, then Eq. 3
        b = blocks[i][0]
        e, seen = quad.element[b], mask[b]
        s0[b], s1 = sigma0[e], sigma1[e]
        r[b] = np.where(seen, (f[0, b] - mean0[e]) / s0[b] - (f[1, b] - mean1[e]) / s1, 0.0)
        pull[0, b] *= np.where(seen, 1.0 / s0[b], 0.0)[:, None]
        pull[1, b] *= np.where(seen, -1.0 / s1, 0.0)[:, None]
        if jacobian == "point":
            pull[0, b] += pull[1, b]                                    # J0^T df0 - J1^T df1
        gray = (r[b] * s0[b])[seen]
        if gray.size:
            residual_moments[i] = gray.size, gray.mean(), np.sum((gray - gray.mean()) ** 2)

    for_each_span(normalise, len(blocks))
    return GrayLevelResidual(r=r, mask=mask, dr_dX=pull[0] if jacobian == "point" else None,
                             dr_dp=pull.transpose(1, 0, 2).reshape(g, 2 * k)
                             if jacobian == "extrinsic" else None,
                             sigma0=s0, dynamic_range=dyn,
                             std_percent=100.0 * _pooled_std(residual_moments) / dyn)


def _pooled_std(moments: np.ndarray) -> float:
    """Standard deviation of the union of groups given by (count, mean, M2) rows (Chan et al.)."""
    n = moments[:, 0].sum()
    if n == 0:
        return float("nan")
    mean = np.dot(moments[:, 0], moments[:, 1]) / n
    m2 = moments[:, 2].sum() + np.dot(moments[:, 0], (moments[:, 1] - mean) ** 2)
    return float(np.sqrt(m2 / n))
