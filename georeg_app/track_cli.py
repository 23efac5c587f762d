"""``georeg track CONFIG.toml``: the command (configuration, run, outputs, exit status).

Bad input (a frame of another size, counts that differ between the cameras, a missing
file, a reference folder that lacks a file) is one error line naming it, exit status 1 and
nothing written. A frame that fails its checks is marked in summary.json and left out of
``displacement.pvd``; the command fails (status 1, nothing written) only when every frame
failed.
"""
from __future__ import annotations

import argparse
import importlib
import logging
from pathlib import Path
from typing import Callable

from georeg_app.config.track import load_track_config

logger = logging.getLogger(__name__)

SCHEDULERS = ("serial", "threads", "processes")


def check_scheduler(scheduler: str) -> str:
    """The scheduler, checked before any computing (Dask installed for all but "serial")."""
    if scheduler not in SCHEDULERS and not scheduler.startswith("tcp://"):
        raise ValueError(f"--scheduler {scheduler!r}: expected one of {', '.join(SCHEDULERS)} or "
                         "tcp://HOST:PORT")
    if scheduler != "serial":
        try:
            importlib.import_module("distributed")
        except ImportError:
            raise RuntimeError(f"--scheduler {scheduler}: Dask is not installed (pip install "
                               "\"dask[distributed]\"); use --scheduler serial") from None
    return scheduler


def run_track_command(args: argparse.Namespace, check_output_folder: Callable,
                      progress: bool) -> Path:
    """Run ``georeg track``; returns the path of the report written."""
    from georeg_app.cli import MeasurementFailed
    from georeg_app.series.track import run_track
    from georeg_app.series.outputs import REPORT_FILE, SUMMARY_FILE, write_track

    scheduler = check_scheduler(args.scheduler)
    config = load_track_config(args.config)                                   # fail fast
    out = args.out if args.out is not None else config.output.dir
    check_output_folder(out, args.overwrite)                                  # before computing
    config = config.with_output_dir(out)
    run = run_track(config, scheduler, progress, workers=args.workers)
    failed = [f for f in run.frames if not f.ok]
    if failed and len(failed) == len(run.frames):
        raise MeasurementFailed("every frame failed: " + "; ".join(
            f"frame {f.index}: {f.failure}" for f in failed[:3]) + (" ..." if len(failed) > 3 else ""))
    if failed:
        logger.warning("%d of %d frames failed (marked in %s): %s", len(failed), len(run.frames),
                       SUMMARY_FILE, ", ".join(str(f.index) for f in failed))
    write_track(out, run, overwrite=args.overwrite)
    return Path(out) / REPORT_FILE
