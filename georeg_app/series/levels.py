"""``[displacement] levels = "auto"``: the series' spline levels chosen on its last frame.

In a loading series the last frame is the most loaded, the one whose field has the most
detail (chosen on the first frames of GT4, a sub-pixel motion where every level agrees with
the noise, the choice fell to the coarsest level, 36 dofs). It is measured from its usual
start (:func:`~georeg_app.series.frames.frame_start`) with
:data:`~georeg_app.series.reference.START_LEVELS` levels, and the level is chosen from that
measurement's Gauss-Newton system (:mod:`adapters.displacement_levels`); every frame of the
series, that one included, is then measured on that one space.
"""
from __future__ import annotations

import dataclasses
import logging

import numpy as np

from adapters.displacement_levels import DisplacementLevels, choose_displacement_levels
from fesdic_core.imaging.image import read_image
from fesdic_core.solve.solvers import CachedFactorization

from georeg_app.config.track import TrackConfig
from georeg_app.series.frames import frame_start
from georeg_app.series.reference import START_LEVELS, SeriesReference, displacement_solver

logger = logging.getLogger(__name__)

__all__ = ["with_chosen_levels"]


def with_chosen_levels(reference: SeriesReference, config: TrackConfig) -> SeriesReference:
    """``reference`` with its georeg solver on the levels chosen on the last frame (the
    record in ``levels``); unchanged when its levels are fixed (no ``levels_model``).

    An unreadable frame raises as the frame would (``check_frames`` runs first); a frame
    that fails to measure, or raises while measured, keeps the start levels (logged)."""
    model = reference.levels_model
    if model is None or not config.series.cam0:
        return dataclasses.replace(reference, levels_model=None)
    paths = (config.series.cam0[-1], config.series.cam1[-1])
    images = [read_image(p, prefilter_px=reference.prefilter_px,
                         order=reference.interpolation_order) for p in paths]
    try:
        U0, _ = frame_start(reference, len(config.series.cam0), images, None)
        record = choose_displacement_levels(model, reference.displacement, images, START_LEVELS,
                                            frame=str(paths[0]), U0=U0)
    except (ArithmeticError, RuntimeError, ValueError, np.linalg.LinAlgError) as err:
        # as measure_frame: an error in the measurement is that frame's failure, not the run's
        logger.warning("displacement levels: kept %d (%s failed: %s)", START_LEVELS, paths[0],
                       " ".join(str(err).split()) or type(err).__name__)
        record = DisplacementLevels(START_LEVELS, START_LEVELS, (), (), (), (), float("nan"),
                                    str(paths[0]))
    d = config.displacement
    solver = displacement_solver(d.method, reference.displacement.mesh, model,
                                 levels=record.levels)
    if d.jacobian == "reference":
        solver = CachedFactorization(solver)
    logger.info("displacement: %d spline levels per component, chosen on %s", record.levels,
                paths[0])
    return dataclasses.replace(reference, solver=solver, levels=record,
                               levels_model=None)
