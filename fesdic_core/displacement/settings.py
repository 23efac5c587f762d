"""How to measure a displacement: :class:`DisplacementSettings` and the defaults of a series.

The settings of :func:`fesdic_core.displacement.driver.measure_displacement` (image scales,
stopping rules, the verdict's factors, the Jacobian of the Gauss-Newton, the share of invalid
nodes that fails a frame), and the image model a series' frames are read with.
"""
from __future__ import annotations

from dataclasses import dataclass

from fesdic_core.imaging.noise import CONSISTENCY_FACTOR
from fesdic_core.shape.settings import MeasurementSettings

__all__ = ["JACOBIANS", "DISPLACEMENT_PREFILTER_PX", "DISPLACEMENT_MAX_INVALID_SHARE",
           "DisplacementSettings"]

#: the Gaussian prefilter (px) of a series' images: 1 px reads sub-pixel motions of an aliased
#: speckle within 1 %, the shape's 0.5 px 1.4-3 % low (interpolation bias;
#: benchmarks/bench_subpixel.py, tests/fesdic_core/displacement/test_subpixel.py)
DISPLACEMENT_PREFILTER_PX = 1.0

#: the default share of invalid nodes that fails a frame: 1, i.e. the nodes' validity is
#: reported but fails no frame by default. On renders the diverging fields have 2.2-12 % (and
#: :data:`~fesdic_core.residual.validity.DEFAULT_MAX_INVALID_SHARE`, 3 %, catches them), but
#: on the real GT4 series the converged frames 0004, 0110 and 0129 have 3.1, 4.3 and 6.5 %
#: (residuals 4 times below a noise floor that the images' estimate overstates about 4 times
#: there, so the median rule of the local residual flags nodes that are 0.55 of their floor):
#: no share separates the two yet (benchmarks/bench_real_series.py, bench_validity.py)
DISPLACEMENT_MAX_INVALID_SHARE = 1.0

#: the Jacobian of the displacement's Gauss-Newton: the reference images' (modified
#: Gauss-Newton, H once per scale) or the deformed images' at the current state (full)
JACOBIANS = ("reference", "current")


@dataclass(frozen=True)
class DisplacementSettings:
    """How to measure a displacement.

    scales : image scales coarse to fine, e.g. (2, 1, 0).
    tol_mm : stagnation of U at scale 0 (largest component of a step, mm; ``* 2**s`` at s).
    residual_rtol : at a coarse scale the Gauss-Newton also hands over when the residual
        falls by less than this fraction in a step (a coarse scale only starts the next).
    consistency_factor : the final residual may be at most this many times the noise floor.
    max_shape_fraction : the displacement may reach at most this fraction of the reference
        surface's diagonal (the name :func:`driver.judge` reads); more is a divergence.
    jacobian : "reference" (default): the modified Gauss-Newton, the Jacobian of the reference
        images at the reference points, so ``H`` is built and factorized once per scale and
        serves every iteration of every frame; "current": the full Gauss-Newton, the
        deformed images' Jacobian at the current state, ``H`` rebuilt at every iteration.
        With "reference" the full Gauss-Newton goes on at the finest scale from the modified
        one's end (the modified one's fixed point is the residual's minimum only at small
        displacement gradients; :mod:`fesdic_core.displacement.driver`).
    max_invalid_share : fail when more than this share of the seen nodes fail their local checks
        (:mod:`fesdic_core.displacement.validity`; default measured in :mod:`~fesdic_core.residual.validity`).
    uncertainty : estimate each node's standard deviation and bias indicator at the end
        (:mod:`fesdic_core.displacement.uncertainty`: one residual with its derivative, one noise
        draw and the step's covariance, for a trusted frame).
    """

    scales: tuple[int, ...] = (0,)
    normalisation: str = "element"
    max_iter: int = 30
    tol_mm: float = 1e-4
    residual_rtol: float = 1e-4
    max_damping: int = 8
    points_per_px: float = 1.0
    consistency_factor: float = CONSISTENCY_FACTOR
    max_shape_fraction: float = 0.25
    jacobian: str = "reference"
    max_invalid_share: float = DISPLACEMENT_MAX_INVALID_SHARE
    uncertainty: bool = True

    def __post_init__(self):
        # the shape's checks of the scales and the normalisation (ValueError naming them)
        MeasurementSettings(scales=self.scales, normalisation=self.normalisation)
        if self.jacobian not in JACOBIANS:
            raise ValueError(f"jacobian must be one of {JACOBIANS}, got {self.jacobian!r}")
        if isinstance(self.max_invalid_share, str) or not 0.0 <= self.max_invalid_share <= 1.0:
            raise ValueError(f"max_invalid_share must be a share in [0, 1], got {self.max_invalid_share!r}")
