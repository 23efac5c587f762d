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
from fesdic_core.displacement.strain import surface_green_lagrange
from fesdic_core.imaging.image import read_image

from georeg_app.series.reference import SeriesReference

logger = logging.getLogger(__name__)

__all__ = ["FrameResult", "measure_frame", "chained_frame", "log_frame"]


@dataclasses.dataclass(frozen=True, eq=False)
class FrameResult:
    """One deformed pair's outcome (``U``, ``strain``, ``residual_node``: None if the frame
    raised before any field; ``failure``: None for a trusted field). ``valid`` (n,) bool and
    ``residual_to_noise`` (n,): each node's local checks
    (:attr:`~fesdic_core.displacement.driver.DisplacementMeasurement.valid`), None with no field."""

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
    valid: np.ndarray | None = None
    residual_to_noise: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.failure is None

    @property
    def n_valid(self) -> int | None:
        """Number of nodes valid locally (None with no field)."""
        return None if self.valid is None else int(np.count_nonzero(self.valid))


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
        m = measure_displacement(reference.displacement, images, solver, U0)
    except (ArithmeticError, RuntimeError, ValueError, np.linalg.LinAlgError) as err:
        failure = " ".join(str(err).split()) or type(err).__name__
        logger.info("frame %d failed: %s", index, failure)
        return FrameResult(index, names[0], names[1], None, None, None, float("nan"),
                           float("nan"), 0, False, failure, time.perf_counter() - t0, start_frame)
    mesh = reference.displacement.mesh
    return FrameResult(index=index, cam0=names[0], cam1=names[1], U=m.U,
                       strain=surface_green_lagrange(mesh, m.U),
                       residual_node=m.node_residual_percent(),
                       residual_percent=float(m.residual_percent),
                       noise_percent=float(m.noise_percent), iterations=int(m.iterations),
                       converged=bool(m.converged), failure=m.failure,
                       time_s=time.perf_counter() - t0, start_frame=start_frame,
                       valid=np.asarray(m.valid, bool),
                       residual_to_noise=np.asarray(m.residual_to_noise, float))


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
