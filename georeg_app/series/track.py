"""The science of ``georeg track``: a displacement field per deformed stereo pair.

The reference (:mod:`georeg_app.series.reference`) is built once; each frame of
``[series]`` is then correlated with the reference pair (:mod:`georeg_app.series.frames`),
in this process or on Dask (:mod:`georeg_app.series.dask`). With ``incremental = true`` a
frame starts from the field of the last frame that succeeded (the reference stays frame 0);
a frame that fails its checks is marked and the series goes on from the last good frame.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from tqdm.auto import tqdm

from fesdic_core.fe.mesh import SurfaceMesh

from georeg_app.config.track import TrackConfig
from georeg_app.series.dask import run_series_dask
from georeg_app.series.frames import FrameResult, chained_frame, log_frame, measure_frame
from georeg_app.series.levels import with_chosen_levels
from georeg_app.series.reference import SeriesReference, check_frames, series_reference
from georeg_app.series.tikhonov_length import with_chosen_length

logger = logging.getLogger(__name__)

__all__ = ["TrackRun", "run_series", "run_track"]


@dataclasses.dataclass(frozen=True, eq=False)
class TrackRun:
    config: TrackConfig
    mesh: SurfaceMesh
    frames: tuple
    reference_label: str
    scheduler: str
    time_s: float
    element_face: np.ndarray | None = None       # a CAD part's face of each element
    levels: object | None = None     # levels = "auto": the choice's DisplacementLevels
    tikhonov_length: object | None = None   # tikhonov_length_mm = "auto": its TikhonovLength


def run_series(reference: SeriesReference, frames: Sequence[tuple[Path, Path]],
               incremental: bool, on_frame: Callable[[FrameResult], None] | None = None
               ) -> list[FrameResult]:
    """The frames in order, in this process. ``incremental``: each frame starts from the
    field of the last frame that succeeded (frame 0, the reference: zero)."""
    results, previous = [], None
    for index, paths in enumerate(frames, start=1):
        if incremental:
            previous = chained_frame(reference, index, paths, previous)
            frame = previous[0]
        else:
            frame = measure_frame(reference, index, paths, None, 0)
        results.append(frame)
        if on_frame is not None:
            on_frame(frame)
    return results


def run_track(config: TrackConfig, scheduler: str = "serial",
              progress: bool | Callable[[str, int, int], None] = False,
              workers: int | None = None) -> TrackRun:
    """Run the whole series: reference, frames (serially or over Dask), in order.

    ``progress``: True for progress bars (tqdm), or a callable ``progress(stage, done,
    total)`` called after each scale of the reference shape (stage: its method's label)
    and after each frame (stage ``"frames"``).
    """
    t0 = time.perf_counter()
    reference = series_reference(config, progress)
    check_frames(config, reference.displacement.images[0].shape)
    reference = with_chosen_length(with_chosen_levels(reference, config), config)
    frames = list(zip(config.series.cam0, config.series.cam1))
    logger.info("reference: %s; %d nodes; %d frames, displacement method %s, scales %s, %s",
                reference.label, reference.displacement.mesh.n_nodes, len(frames),
                config.displacement.method, config.displacement.scale_sequence,
                "incremental" if config.displacement.incremental else "each from rest")
    with tqdm(total=len(frames), desc="frames", unit="frame", disable=progress is not True) as bar:
        done = []
        def on_frame(frame: FrameResult) -> None:
            log_frame(frame, len(frames))
            bar.update(1)
            done.append(frame.index)
            if callable(progress):
                progress("frames", len(done), len(frames))
        if scheduler == "serial":
            results = run_series(reference, frames, config.displacement.incremental, on_frame)
        else:
            results = run_series_dask(reference, frames, config.displacement.incremental,
                                      scheduler, on_frame, workers=workers)
    return TrackRun(config=config, mesh=reference.displacement.mesh, frames=tuple(results),
                    reference_label=reference.label, scheduler=scheduler,
                    time_s=time.perf_counter() - t0, element_face=reference.element_face,
                    levels=reference.levels, tikhonov_length=reference.tikhonov_length)
