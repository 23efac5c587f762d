"""One deformed stereo pair of a series against the reference: a frame.

:func:`measure_frame` is a plain function of picklable arguments (a Dask task): it reads the
frame's two images, correlates them with the reference pair
(:func:`fesdic_core.displacement.driver.measure_displacement`) and returns the displacement
of every node of the reference surface, its surface Green-Lagrange strain and the residual;
an error inside the measurement marks the frame failed instead of raising.
"""
from __future__ import annotations

import copy
import dataclasses
import logging
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from fesdic_core.displacement.driver import measure_displacement
from fesdic_core.displacement.start import (coarse_noise_percent, feature_start,
                                            image_shift_px, start_residual_percent)
from fesdic_core.displacement.strain import surface_green_lagrange
from fesdic_core.displacement.uncertainty import DisplacementUncertainty
from fesdic_core.imaging.image import read_image

from georeg_app.series.reference import SeriesReference

logger = logging.getLogger(__name__)

__all__ = ["FrameResult", "measure_frame", "frame_start", "chained_frame", "log_frame"]


@dataclasses.dataclass(frozen=True, eq=False)
class FrameResult:
    """One deformed pair's outcome (``U``, ``strain``, ``residual_node``: None if the frame
    raised before any field; ``failure``: None for a trusted field). ``valid`` (n,) bool and
    ``residual_to_noise`` (n,): each node's local checks
    (:attr:`~fesdic_core.displacement.driver.DisplacementMeasurement.valid`), None with no field.
    ``uncertainty``: the field's standard deviation and bias indicator per node and component
    (:class:`~fesdic_core.displacement.uncertainty.DisplacementUncertainty`), None for a failed
    frame."""

    index: int
    cam0: str
    cam1: str
    U: np.ndarray | None
    strain: np.ndarray | None
    residual_node: np.ndarray | None
    residual_percent: float
    noise_percent: float
    iterations: int
    converged: bool
    failure: str | None
    time_s: float
    start_frame: int
    start: str = ""                 # where the starting field came from (:func:`frame_start`)
    valid: np.ndarray | None = None
    residual_to_noise: np.ndarray | None = None
    uncertainty: DisplacementUncertainty | None = None

    @property
    def ok(self) -> bool:
        return self.failure is None

    @property
    def n_valid(self) -> int | None:
        """Number of nodes valid locally (None with no field)."""
        return None if self.valid is None else int(np.count_nonzero(self.valid))

    def uncertainty_summary(self) -> dict | None:
        """``{"median": (3,), "max": (3,)}``: the median and the largest uncertainty of each
        component (mm) over the valid nodes, or None without one."""
        u = None if self.uncertainty is None else self.uncertainty.uncertainty_mm
        if u is None:
            return None
        u = u if self.valid is None else u[np.asarray(self.valid, bool)]
        return {"median": np.median(u, axis=0), "max": np.max(u, axis=0)} if len(u) else None


def measure_frame(reference: SeriesReference, index: int, paths: Sequence[Path],
                  U0: np.ndarray | None, start_frame: int) -> FrameResult:
    """Measure one deformed pair (a plain function of picklable arguments: a Dask task).
    An error inside the measurement marks the frame failed instead of raising."""
    t0 = time.perf_counter()
    names = [str(p) for p in paths]
    try:
        images = [read_image(p, prefilter_px=reference.prefilter_px, order=reference.interpolation_order)
                  for p in paths]
        solver = copy.deepcopy(reference.solver)
        U0, start = frame_start(reference, index, images, U0)
        m = measure_displacement(reference.displacement, images, solver, U0)
    except (ArithmeticError, RuntimeError, ValueError, np.linalg.LinAlgError) as err:
        failure = " ".join(str(err).split()) or type(err).__name__
        logger.info("frame %d failed: %s", index, failure)
        return FrameResult(index, names[0], names[1], None, None, None, float("nan"),
                           float("nan"), 0, False, failure, time.perf_counter() - t0, start_frame,
                           reference.start)
    mesh = reference.displacement.mesh
    return FrameResult(index=index, cam0=names[0], cam1=names[1], U=m.U,
                       strain=surface_green_lagrange(mesh, m.U),
                       residual_node=m.node_residual_percent(),
                       residual_percent=float(m.residual_percent),
                       noise_percent=float(m.noise_percent), iterations=int(m.iterations),
                       converged=bool(m.converged), failure=m.failure,
                       time_s=time.perf_counter() - t0, start_frame=start_frame, start=start,
                       valid=np.asarray(m.valid, bool),
                       residual_to_noise=np.asarray(m.residual_to_noise, float),
                       uncertainty=m.uncertainty)


def frame_start(reference: SeriesReference, index: int, images: Sequence,
                U_previous: np.ndarray | None) -> tuple[np.ndarray | None, str]:
    """The starting field (n, 3) of a frame (None: zero) and where it comes from.

    ``reference.start``: "zero"; "previous": ``U_previous`` (the last good frame's field in an
    incremental series, else None); "features": the feature start
    (:func:`~fesdic_core.displacement.start.feature_start`) where it helps. The fallback is
    ``U_previous`` (zero when None); it is kept when its residual at the coarsest scale is
    within the images' noise there (no features computed), when no features match, when the
    features' field is within a pixel of the coarsest scale of it, or when the features' has
    the higher residual at that scale.
    """
    if reference.start == "zero":
        return None, "zero"
    fallback = "previous" if U_previous is not None else "zero"
    if reference.start == "previous" or reference.features is None:
        return U_previous, fallback
    displacement, coarsest = reference.displacement, reference.displacement.settings.scales[0]
    other = np.zeros((displacement.mesh.n_nodes, 3)) if U_previous is None else U_previous
    r_other = start_residual_percent(displacement, images, [other])[0]
    noise = coarse_noise_percent(displacement, images)
    # (GT4 0129, scale 2: the residual crosses this noise floor, 5.9 %, at a start 3.4 px
    # from the field, about one pixel of that scale: the Gauss-Newton's reach)
    if r_other <= noise:
        logger.info("frame %d start: %s matches the images at scale %d within their noise "
                    "(residual %.3f%%, noise floor %.3f%%): no features needed", index, fallback,
                    coarsest, r_other, noise)
        return U_previous, fallback
    found = feature_start(reference.features, images, displacement.cameras)
    if found.U is None:
        logger.warning("frame %d start: %s; starting from %s", index, found.report.describe(),
                       fallback)
        return U_previous, fallback
    shift = image_shift_px(displacement, found.U, other)
    if shift < 2.0 ** coarsest:
        # within a pixel of the coarsest scale, the Gauss-Newton's own reach: the fallback
        # (zero, or a correlated field) has no matching noise
        logger.info("frame %d start: features: %s; within %.2g px of %s (90 %% of the nodes): "
                    "starting from %s", index, found.report.describe(), shift, fallback, fallback)
        return U_previous, fallback
    r_features = start_residual_percent(displacement, images, [found.U])[0]
    chosen = "features" if not r_other < r_features else fallback
    logger.info("frame %d start: features: %s; %.2g px from %s, residual at scale %d %.3f%% "
                "(%s %.3f%%, noise floor %.3f%%): starting from %s", index,
                found.report.describe(), shift, fallback, coarsest, r_features, fallback,
                r_other, noise, chosen)
    return (found.U, chosen) if chosen == "features" else (U_previous, chosen)


def log_frame(frame: FrameResult, total: int) -> None:
    if frame.ok:
        mean = np.mean(frame.U, axis=0) * 1e3
        logger.info("frame %d of %d: residual %.3f%% (noise floor %.3f%%), mean displacement "
                    "(%.1f, %.1f, %.1f) um, %s of %d nodes valid, %d iterations, %.1f s",
                    frame.index, total, frame.residual_percent, frame.noise_percent, *mean,
                    frame.n_valid, len(frame.U), frame.iterations, frame.time_s)
    else:
        logger.warning("frame %d of %d FAILED: %s", frame.index, total, frame.failure)


def chained_frame(reference: SeriesReference, index: int, paths: Sequence[Path],
                  previous: tuple | None) -> tuple:
    """One frame of an incremental series: ``previous`` = (frame, last good U, its index), the
    outcome of the frame before (None for the first); returns this frame's outcome.

    The frame starts from the field of the last frame that succeeded (frame 0, the reference:
    zero) and, if it succeeds, becomes that frame. The one chaining of frames, serial
    (:func:`georeg_app.series.track.run_series`) and on Dask
    (:func:`georeg_app.series.dask.run_series_dask`).
    """
    U0, start = (None, 0) if previous is None else previous[1:]
    frame = measure_frame(reference, index, paths, U0, start)
    if frame.ok:
        return frame, frame.U, index
    return frame, U0, start
