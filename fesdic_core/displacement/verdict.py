"""Whether a displacement can be trusted: the residual against the images' noise, texture,
divergence, stagnation and the nodes' local checks (the verdict of
:func:`~fesdic_core.displacement.driver.measure_displacement`)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from fesdic_core.displacement.residual import DisplacementResidual, ReferenceView
from fesdic_core.displacement.settings import DisplacementSettings
from fesdic_core.imaging.noise import MIN_TEXTURE_RATIO, residual_noise_floor
from fesdic_core.residual.validity import NodeValidity
from fesdic_core.shape.settings import ScaleReport
from fesdic_core.shape.verdict import judge

__all__ = ["noise_floor", "displacement_verdict"]


def noise_floor(ref: ReferenceView, res: DisplacementResidual, images: Sequence):
    """Per camera, the residual the two images' noise explains (percent of the reference
    range; :func:`residual_noise_floor` of the pair (reference, deformed) of one camera),
    pooled over the cameras as the residual is; the deformed images' texture ratios; and each
    camera's contrast ratio (reference over deformed, over the region)."""
    percents, counts, ratios, contrast = [], [], [], []
    for c in range(2):
        floor = residual_noise_floor(ref.X, res.mask[c], [ref.images[c], images[c]],
                                     [ref.cameras[c], ref.cameras[c]])
        percents.append(floor.percent)
        counts.append(np.count_nonzero(res.mask[c]))
        ratios.append(floor.texture_ratio()[1])
        contrast.append(floor.contrast[0] / floor.contrast[1] if floor.contrast[1] > 0 else 1.0)
    n = sum(counts)
    pooled = float(np.sqrt(np.dot(counts, np.square(percents)) / n)) if n else float("nan")
    return pooled, ratios, contrast


def displacement_verdict(residual_percent: float, noise_percent: float, U: np.ndarray,
                         nodes: np.ndarray, texture_ratios: Sequence[float], sources: Sequence[str],
                         finest: ScaleReport, settings: DisplacementSettings,
                         validity: NodeValidity | None = None) -> str | None:
    """Why a displacement cannot be trusted, or None: no texture in a deformed image, a
    diverged field (``U``: the Gauss-Newton's change from its start), then :func:`driver.judge`
    (residual against the noise floor, stagnation), then the local checks (``validity``: more
    than ``settings.max_invalid_share`` of the nodes invalid, the worst named)."""
    for ratio, source in zip(texture_ratios, sources):
        if not ratio >= MIN_TEXTURE_RATIO:
            return (f"{source}: no texture to correlate over the specimen (contrast over noise "
                    f"{ratio:.3g}, at least {MIN_TEXTURE_RATIO:g} needed): a uniform or "
                    "pure-noise image, or the wrong image")
    size = float(np.linalg.norm(np.ptp(nodes, axis=0)))
    largest = float(np.max(np.linalg.norm(U, axis=1))) if U.size else 0.0
    if not np.isfinite(largest) or largest > settings.max_shape_fraction * size:
        return (f"the displacement diverged: {largest:.3g} mm at a node, more than "
                f"{settings.max_shape_fraction:g} of the surface's size ({size:.3g} mm)")
    failure = judge(residual_percent, noise_percent, np.zeros(len(nodes)), nodes, finest, settings)
    if failure is None and validity is not None:
        failure = validity.failure(nodes, settings.max_invalid_share)
    return failure
