"""``[displacement] tikhonov_length_mm = "auto"``: the series' Tikhonov length chosen on its
last frame.

The length of Eq. 10 on each displacement component
(:class:`~fesdic_core.displacement.solvers.ComponentTikhonovSolver`, ``length * 2**s`` at
image scale ``s``) is a prior on the field's smoothness. Too long, and a field with strain
gradients is not held: the Gauss-Newton stops far from the images' minimum (GT4's
``large_motion``: 10 mm leaves a residual 4.3 times the noise floor, 5 mm does not converge
in 30 iterations, 3 mm measures it). The choice is the discrepancy principle on a geometric
ladder: the longest of :data:`~georeg_app.series.reference.START_LENGTH_MM` (10 mm) divided by
:data:`LADDER_RATIO` again and again, down to two element sizes, at which the series' last (most
loaded) frame measures, by the measurement's own verdict (its residual explained by the image
noise, its invalid share under the threshold). Every frame is then measured at that length.
If no length measures the frame, the frame and not the prior is wrong: the start length is
kept, and the frame fails in the series as it would.
"""
from __future__ import annotations

import dataclasses
import logging

import numpy as np

from fesdic_core.displacement.driver import measure_displacement
from fesdic_core.imaging.image import read_image
from fesdic_core.solve.solvers import CachedFactorization
from fesdic_core.solve.tikhonov_choice import element_size

from georeg_app.config.measure import AUTO
from georeg_app.config.track import TrackConfig
from georeg_app.series.frames import frame_start
from georeg_app.series.reference import (START_LENGTH_MM, SeriesReference,
                                         displacement_solver)

logger = logging.getLogger(__name__)

__all__ = ["LADDER_RATIO", "TikhonovLength", "length_ladder", "with_chosen_length"]

#: the ratio of two lengths of the ladder: two steps halve the length (the weight, ~ l**2, by 4)
LADDER_RATIO = float(np.sqrt(2.0))


@dataclasses.dataclass(frozen=True)
class TikhonovLength:
    """The record of a Tikhonov length's choice.

    length_mm : the chosen length (mm) at the finest image scale.
    tried_mm, residual_percent : (k,) the lengths measured, longest first, and the residual
        each left (%); the last one measured the frame, unless none did.
    measured : whether a length measured the frame (False: the start length was kept).
    frame : the frame the choice was made on (its cam0 file).
    """

    length_mm: float
    tried_mm: tuple
    residual_percent: tuple
    measured: bool
    frame: str

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def length_ladder(mesh, start_mm: float = START_LENGTH_MM) -> list[float]:
    """``start_mm`` divided by :data:`LADDER_RATIO` while the length stays at least two element
    sizes (mm), longest first (at least ``start_mm`` itself)."""
    shortest = 2.0 * element_size(mesh)
    lengths = [float(start_mm)]
    while lengths[-1] / LADDER_RATIO >= shortest:
        lengths.append(lengths[-1] / LADDER_RATIO)
    return lengths


def with_chosen_length(reference: SeriesReference, config: TrackConfig) -> SeriesReference:
    """``reference`` with its Tikhonov solver at the length chosen on the last frame (the
    record in ``tikhonov_length``); unchanged unless ``method = "tikhonov"`` and
    ``tikhonov_length_mm = "auto"``. A frame that raises while measured keeps the start."""
    d = config.displacement
    if d.method != "tikhonov" or d.tikhonov_length_mm != AUTO or not config.series.cam0:
        return reference
    paths = (config.series.cam0[-1], config.series.cam1[-1])
    images = [read_image(p, prefilter_px=reference.prefilter_px,
                         order=reference.interpolation_order) for p in paths]
    mesh = reference.displacement.mesh
    quick = dataclasses.replace(reference.displacement, settings=dataclasses.replace(
        reference.displacement.settings, uncertainty=False))
    tried, residuals, chosen = [], [], None
    try:
        U0, _ = frame_start(reference, len(config.series.cam0), images, None)
        for length in length_ladder(mesh):
            m = measure_displacement(quick, images, displacement_solver("tikhonov", mesh, None,
                                                                        length), U0)
            tried.append(length)
            residuals.append(float(m.residual_percent))
            if m.ok:
                chosen = length
                break
            logger.info("tikhonov length: %.4g mm does not measure %s (%s)", length, paths[0],
                        m.failure)
    except (ArithmeticError, RuntimeError, ValueError, np.linalg.LinAlgError) as err:
        # as measure_frame: an error in the measurement is that frame's failure, not the run's
        logger.warning("tikhonov length: %s failed: %s", paths[0],
                       " ".join(str(err).split()) or type(err).__name__)
    record = TikhonovLength(START_LENGTH_MM if chosen is None else chosen, tuple(tried),
                            tuple(residuals), chosen is not None, str(paths[0]))
    if chosen is None:
        logger.warning("tikhonov length: no length down to %.3g mm measures %s: kept %.4g mm",
                       tried[-1] if tried else START_LENGTH_MM, paths[0], START_LENGTH_MM)
    else:
        logger.info("displacement: tikhonov length %.4g mm, chosen on %s (tried %s mm)",
                    chosen, paths[0], ", ".join(f"{x:.4g}" for x in tried))
    solver = displacement_solver("tikhonov", mesh, None, record.length_mm)
    if d.jacobian == "reference":
        solver = CachedFactorization(solver)
    return dataclasses.replace(reference, solver=solver, tikhonov_length=record)
