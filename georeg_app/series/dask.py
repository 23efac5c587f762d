"""The frames of ``georeg track`` over Dask (``--scheduler``).

The reference state (:class:`~georeg_app.series.track.SeriesReference`: reference pyramids and
quadratures, cameras, the step solver's operators) is scattered to every worker once
(``Client.scatter(..., broadcast=True)``); each frame is one task that receives it by
reference and reads its own two images on the worker. Given the reference the frames are
independent (``incremental = false``: all submitted at once, as many running as there are
workers); with ``incremental = true`` each task also takes the previous task's outcome (the
field of the last frame that succeeded) and the frames form a chain, run in order, still on
the cluster. Results are gathered in frame order; the outputs are written by the client.

Schedulers: ``"threads"`` (a local cluster in this process: one worker of ``workers``
threads), ``"processes"`` (a local cluster of ``workers`` processes of one task thread
each, the core's own thread pool of each sized to its share of the machine's cores),
``tcp://HOST:PORT`` (an existing scheduler, e.g. started by ``dask scheduler`` and
``dask worker`` on a cluster's nodes; the workers need this package installed and read the
frame images from the same paths, a shared file system).
"""
from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path
from typing import Callable, Sequence

from georeg_app.errors import InputError
from georeg_app.series.frames import FrameResult, chained_frame, measure_frame
from georeg_app.series.reference import SeriesReference

logger = logging.getLogger(__name__)

__all__ = ["run_series_dask", "dask_client"]


@contextlib.contextmanager
def dask_client(scheduler: str, workers: int | None = None):
    """A ``distributed.Client`` for ``scheduler`` ("threads", "processes" or tcp://...),
    closed (with its local cluster) on exit."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError(f"--scheduler {scheduler}: Dask is not installed (pip install "
                         "\"dask[distributed]\"), use --scheduler serial") from None
    _quiet_dask_loggers()
    if scheduler.startswith("tcp://"):
        with Client(scheduler) as client:
            yield client
        return
    cores = os.cpu_count() or 1
    if scheduler == "threads":
        cluster = LocalCluster(n_workers=1, threads_per_worker=workers or cores, processes=False,
                               dashboard_address=None, silence_logs=logging.WARNING)
    elif scheduler == "processes":
        n = workers or cores
        threads = str(max(1, cores // n))          # the core's thread pool of each worker
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.WARNING,
                               env={"FESDIC_THREADS": threads})
    else:
        raise ValueError(f"unknown scheduler {scheduler!r}")
    with cluster, Client(cluster) as client:
        yield client


def _quiet_dask_loggers() -> None:
    """Dask's own loggers (set to INFO by its configuration when imported) at WARNING unless
    ours are at DEBUG (--verbose): a cluster's start and stop are not the user's business."""
    level = logging.DEBUG if logger.isEnabledFor(logging.DEBUG) else logging.WARNING
    for name in list(logging.root.manager.loggerDict):
        if name.split(".")[0] in ("distributed", "dask", "tornado", "bokeh"):
            logging.getLogger(name).setLevel(max(level, logging.getLogger(name).level))


def _frame_of(outcome: tuple) -> FrameResult:
    return outcome[0]


def run_series_dask(reference: SeriesReference, frames: Sequence[tuple[Path, Path]],
                    incremental: bool, scheduler: str,
                    on_frame: Callable[[FrameResult], None] | None = None,
                    workers: int | None = None) -> list[FrameResult]:
    """The frames on a Dask cluster, results in frame order (as :func:`georeg_app.series.track.run_series`)."""
    with dask_client(scheduler, workers) as client:
        shared = client.scatter(reference, broadcast=True)       # the reference, shipped once
        logger.info("Dask: %s, %d workers; the reference scattered once", scheduler,
                    len(client.scheduler_info()["workers"]))
        futures = []
        previous = None
        for index, paths in enumerate(frames, start=1):
            if incremental:
                previous = client.submit(chained_frame, shared, index, list(paths), previous,
                                         key=f"frame-{index}-{os.getpid()}-{id(frames)}")
                futures.append(client.submit(_frame_of, previous, pure=False))
            else:
                futures.append(client.submit(measure_frame, shared, index, list(paths), None, 0,
                                             key=f"frame-{index}-{os.getpid()}-{id(frames)}"))
        results = []
        for future in futures:                                    # in frame order
            frame = future.result()
            results.append(frame)
            if on_frame is not None:
                on_frame(frame)
    return results

