"""The ``georeg`` command line.

::

    georeg demo    [--out DIR] [--overwrite]              # embedded synthetic specimen
    georeg measure CONFIG.toml [--out DIR] [--overwrite]  # the method of [method]
    georeg compare CONFIG.toml [--out DIR] [--overwrite]  # FE, Tikhonov, georeg multi/monoscale
    georeg track   CONFIG.toml [--out DIR] [--overwrite] [--scheduler S]  # displacement series
    georeg preview CONFIG.toml [--out DIR] [--overwrite]  # the set-up at a glance, no measuring
    georeg calibrate CONFIG.toml [--out DIR] [--overwrite]  # the rig from target images

Global options: ``--quiet`` (warnings only, no progress bars), ``--verbose`` (debug log,
tracebacks on error), ``--version``. A user error (bad input: a configuration, image,
calibration, mesh or CAD file, a value that does not fit; any of
:data:`georeg_app.errors.USER_ERRORS`) prints one line ``georeg: error: <message>`` on
stderr and exits with status 1; nothing is written to the output folder then (all outputs
are staged and published together, see :mod:`georeg_app.shape.outputs`).

Exit status: 0 done; 1 user error (or every method / frame failed); 2 bad command-line
arguments (argparse); 70 a bug in georeg (any other exception: the full traceback is printed,
then a line asking to report it); 130 interrupted (Ctrl-C).

A measurement that fails its own checks (the residual against the images' noise, an
unbounded shape, no stagnation; :mod:`fesdic_core.shape.driver`) is an error of ``measure``.
``compare`` and ``demo`` mark a failed method in summary.json and the report and deliver
the others; they exit with status 1 only when every method failed. The output folder is
checked before any computing: it must be a new or empty folder, or ``--overwrite`` is
needed (its previous contents are then replaced as a whole).
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import sys
import time
import traceback
from pathlib import Path
from typing import Sequence

from georeg_app.config.measure import load_config
from georeg_app.errors import USER_ERRORS, InputError, MeasurementFailed
from georeg_app.results import SeriesRun, ShapeRun, check_output_folder
from georeg_app.version import installed_version

logger = logging.getLogger(__name__)

__all__ = ["main", "build_parser", "progress_enabled", "check_output_folder", "check_scheduler",
           "MeasurementFailed", "SCHEDULERS"]

PROG = "georeg"
DEFAULT_DEMO_OUT = "demo_out"
DEFAULT_PREVIEW_OUT = "preview_out"
EXIT_OK, EXIT_ERROR, EXIT_BUG, EXIT_INTERRUPTED = 0, 1, 70, 130   # 70: EX_SOFTWARE (sysexits.h)
EPILOG = ("exit status: 0 done, 1 user error (one line 'georeg: error: ...'), 2 bad arguments, "
          f"{EXIT_BUG} a bug in georeg (traceback; please report it), {EXIT_INTERRUPTED} interrupted")


def _common(parser: argparse.ArgumentParser, suppress: bool) -> None:
    """--quiet/--verbose, accepted before and after the sub-command."""
    default = argparse.SUPPRESS if suppress else False
    group = parser.add_mutually_exclusive_group()
    group.add_argument("-q", "--quiet", action="store_true", default=default,
                       help="warnings and errors only, no progress bars")
    group.add_argument("-v", "--verbose", action="store_true", default=default,
                       help="debug messages, and the traceback of an error")


def _config_command(sub, name: str, text: str, default_out: Path | None = None,
                    config_help: str = "configuration (TOML)") -> argparse.ArgumentParser:
    """A sub-command of one configuration file, ``--out`` and ``--overwrite``."""
    p = sub.add_parser(name, help=text)
    p.add_argument("config", type=Path, metavar="CONFIG.toml", help=config_help)
    p.add_argument("--out", type=Path, default=default_out,
                   help="output folder (default: " + (str(default_out) if default_out is not None
                                                      else "[output] dir of the configuration")
                        + ")")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the contents of a non-empty output folder")
    return p


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG, description="FE stereo-DIC shape measurement with multilevel geometric "
                               "(spline) regularization (Colantonio et al. 2020).",
        epilog=EPILOG)
    parser.add_argument("--version", action="version", version=f"%(prog)s {installed_version()}")
    _common(parser, suppress=False)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    demo = sub.add_parser("demo", help="render the embedded twisted open-hole specimen and "
                                       "compare all methods on it (no input needed)")
    demo.add_argument("--out", type=Path, default=Path(DEFAULT_DEMO_OUT),
                      help=f"output folder (default: {DEFAULT_DEMO_OUT})")
    demo.add_argument("--overwrite", action="store_true",
                      help="replace the contents of a non-empty output folder")
    for name, text in (("measure", "measure the shape with the method of the configuration"),
                       ("compare", "run all methods (FE, Tikhonov, georeg) on the same data")):
        _config_command(sub, name, text)
    track = _config_command(sub, "track", "displacement of the measured surface over a series "
                                          "of stereo pairs ([series], [displacement])")
    track.add_argument("--scheduler", default="serial",
                       help='"serial" (default, this process), "threads" or "processes" (a local '
                            'Dask cluster), or tcp://HOST:PORT (an existing Dask scheduler)')
    track.add_argument("--workers", type=int, default=None,
                       help="workers of a local Dask cluster (default: Dask's choice)")
    _config_command(sub, "preview", "the set-up at a glance, without measuring: the mesh "
                                    "projected in both images, the landmarks",
                    default_out=Path(DEFAULT_PREVIEW_OUT),
                    config_help="configuration (TOML) of measure or compare")
    _config_command(sub, "calibrate", "calibrate the stereo rig from pairs of target images "
                                      "([images], [target], [model])")
    for p in sub.choices.values():
        _common(p, suppress=True)
    return parser


#: our packages: their loggers follow --quiet/--verbose (DEBUG under --verbose)
_OURS = ("georeg_app", "fesdic_core", "georeg_plugin", "adapters", "__main__")
#: our chatty loggers (e.g. staged file names), shown from this level only, unless --verbose
_CHATTY = {"fesdic_core.fe.mesh_io": logging.WARNING, "georeg_plugin.io.spline_io": logging.WARNING}
#: third-party loggers known to flood DEBUG/INFO: kept at WARNING even under --verbose (the
#: root logger is at WARNING too, so any other third-party logger is quiet as well)
_THIRD_PARTY = ("matplotlib", "PIL", "numba", "pyxel", "urllib3", "asyncio", "distributed",
                "fsspec", "h5py", "meshio", "numexpr", "tornado", "bokeh", "dask")


def progress_enabled(quiet: bool) -> bool:
    """Progress bars only when not --quiet and stderr is a terminal (no bars in log files)."""
    if quiet:
        return False
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):        # replaced or closed stderr
        return False


def _log_levels(quiet: bool, verbose: bool) -> dict[str, int]:
    """Level of each logger we set: root and third parties at WARNING, ours at the level
    of --quiet/--verbose (our chatty ones no lower than their floor unless --verbose)."""
    level = logging.WARNING if quiet else (logging.DEBUG if verbose else logging.INFO)
    levels = {"": logging.WARNING, **{name: logging.WARNING for name in _THIRD_PARTY}}
    levels.update({name: level for name in _OURS})
    if not verbose:
        levels.update({name: max(level, floor) for name, floor in _CHATTY.items()})
    return levels


class _TimeLine(logging.Formatter):
    """Each line stamped with the seconds since the command started (a stage time line)."""

    def __init__(self, fmt: str):
        super().__init__(fmt)
        self.t0 = time.time()

    def format(self, record: logging.LogRecord) -> str:
        record.elapsed = record.created - self.t0
        return super().format(record)


@contextlib.contextmanager
def _logging_to_stderr(quiet: bool, verbose: bool):
    """Log to stderr at the level of --quiet/--verbose for the duration of a command:
    our loggers at WARNING/INFO/DEBUG, third-party loggers at WARNING in every case."""
    levels = _log_levels(quiet, verbose)
    saved = {name: logging.getLogger(name or None).level for name in levels}
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_TimeLine("%(elapsed)7.1f s %(levelname)s %(name)s: %(message)s"
                                   if verbose else f"{PROG} %(elapsed)6.1f s: %(message)s"))
    root = logging.getLogger()
    root.addHandler(handler)
    for name, lvl in levels.items():
        logging.getLogger(name or None).setLevel(lvl)
    try:
        yield
    finally:
        root.removeHandler(handler)
        for name, lvl in saved.items():
            logging.getLogger(name or None).setLevel(lvl)


def _run(args: argparse.Namespace) -> Path:
    """Run a command; return the report's path."""
    if args.command == "track":
        return _run_track(args, progress_enabled(args.quiet))
    if args.command == "preview":
        return _run_preview(args)
    if args.command == "calibrate":
        return _run_calibrate(args, progress_enabled(args.quiet))
    config = None if args.command == "demo" else load_config(args.config)   # fail fast
    out = args.out if (config is None or args.out is not None) else config.output.dir
    check_output_folder(out, args.overwrite)                                  # before computing
    from georeg_app.shape.demo import demo_config
    from georeg_app.shape.methods import default_specs, measure_specs
    from georeg_app.shape.outputs import REPORT_FILE
    from georeg_app.shape.pipeline import run_methods

    progress = progress_enabled(args.quiet)
    images = truth = None
    if config is None:
        config, images, truth = demo_config(out)
        specs = default_specs(config)
    else:
        config = config.with_output_dir(out)
        specs = default_specs(config) if args.command == "compare" else measure_specs(config)
    logger.info("%s: %d method(s): %s", args.command, len(specs), ", ".join(s.label for s in specs))
    run = ShapeRun(run_methods(config, specs, images=images, truth=truth, progress=progress),
                   command=args.command)
    for m in run.summary["methods"]:
        if m["status"] != "ok":
            if args.command != "measure":                 # (measure: the error line says it)
                logger.warning("%-24s FAILED: %s", m["label"], m["failure"])
            continue
        error = "n/a" if m["shape_rms_error_mm"] is None else f"{m['shape_rms_error_mm'] * 1e3:.2f} um"
        noise = "n/a" if m["noise_percent"] is None else f"{m['noise_percent']:.3f}%"
        logger.info("%-24s residual %.3f%% (noise floor %s), RMS dist. to BFP %.4f mm, "
                    "error vs truth %s, %d iterations, %.1f s", m["label"], m["residual_percent"],
                    noise, m["distance_to_bfp_rms_mm"], error, m["iterations"], m["time_s"])
    run.save(out, overwrite=args.overwrite)       # MeasurementFailed if it cannot be delivered
    return Path(out) / REPORT_FILE


SCHEDULERS = ("serial", "threads", "processes")


def check_scheduler(scheduler: str) -> str:
    """The scheduler, checked before any computing (Dask installed for all but "serial")."""
    if scheduler not in SCHEDULERS and not scheduler.startswith("tcp://"):
        raise InputError(f"--scheduler {scheduler!r}: expected one of {', '.join(SCHEDULERS)} or "
                         "tcp://HOST:PORT")
    if scheduler != "serial":
        try:
            importlib.import_module("distributed")
        except ImportError:
            raise InputError(f"--scheduler {scheduler}: Dask is not installed (pip install "
                             "\"dask[distributed]\"); use --scheduler serial") from None
    return scheduler


def _run_track(args: argparse.Namespace, progress: bool) -> Path:
    """Run ``georeg track``; returns the path of the report written.

    Bad input (a frame of another size, counts that differ between the cameras, a missing
    file, a reference folder that lacks a file) is one error line naming it, exit status 1 and
    nothing written. A frame that fails its checks is marked in summary.json and left out of
    ``displacement.pvd``; the command fails (status 1) only when every frame failed, and then
    writes the outputs all the same, for inspection.
    """
    from georeg_app.series.outputs import REPORT_FILE, SUMMARY_FILE
    from georeg_app.series.track import run_track

    scheduler = check_scheduler(args.scheduler)
    from georeg_app.config.track import load_track_config
    config = load_track_config(args.config)                                   # fail fast
    out = args.out if args.out is not None else config.output.dir
    check_output_folder(out, args.overwrite)                                  # before computing
    config = config.with_output_dir(out)
    run = SeriesRun(run_track(config, scheduler, progress, workers=args.workers))
    failed = [f for f in run.frames if not f.ok]
    if failed:
        logger.warning("%d of %d frames failed (marked in %s): %s", len(failed), len(run.frames),
                       SUMMARY_FILE, ", ".join(f"{f.index} ({Path(f.cam0).name})" for f in failed))
    run.save(out, overwrite=args.overwrite)       # failed frames too: something to inspect
    try:
        run.check()                               # MeasurementFailed: every frame failed
    except MeasurementFailed as err:
        raise MeasurementFailed(f"{err} (the failed frames are written to {out})") from None
    return Path(out) / REPORT_FILE


def _run_preview(args: argparse.Namespace) -> Path:
    """Run ``georeg preview``; returns the path of the picture written."""
    from georeg_app.inputs.preview import preview, preview_summary, write_preview

    config = load_config(args.config)                                         # fail fast
    check_output_folder(args.out, args.overwrite)
    p = preview(config)
    summary = preview_summary(p)
    seen = summary["elements_seen_fraction"]
    logger.info("%s mesh, %d %s elements, %d nodes: cam0 sees %.0f %%, cam1 %.0f %%, both %.0f %% "
                "of the elements", summary["geometry"], summary["mesh"]["n_elements"],
                summary["mesh"]["family"], summary["mesh"]["n_nodes"], 100 * seen["cam0"],
                100 * seen["cam1"], 100 * seen["both"])
    if summary["landmark_error_max_px"] is not None:
        logger.info("landmarks: largest reprojection error %.2f px", summary["landmark_error_max_px"])
    if seen["both"] < 1.0:
        logger.warning("%.0f %% of the elements are not seen by both cameras (see preview.png)",
                       100 * (1.0 - seen["both"]))
    write_preview(args.out, p, overwrite=args.overwrite)
    return Path(args.out) / "preview.png"


def _run_calibrate(args: argparse.Namespace, progress: bool) -> Path:
    """Run ``georeg calibrate``; returns the path of the report written."""
    from georeg_app.calibrate import load_calibrate_config, run_calibration, write_calibration
    from georeg_app.calibrate.outputs import REPORT_FILE

    config = load_calibrate_config(args.config)                               # fail fast
    out = args.out if args.out is not None else config.output.dir
    check_output_folder(out, args.overwrite)                                  # before computing
    run = run_calibration(config.with_output_dir(out), progress)
    cal = run.calibration
    used = sum(v.status == "used" for v in cal.views)
    for v in cal.views:
        if v.status != "used":
            logger.warning("view %d (%s) left out: %s", v.index, Path(v.sources[0]).name, v.status)
    logger.info("calibrated from %d of %d views: reprojection RMS %.4f px, baseline %.4f mm, "
                "stereo angle %.4f deg", used, len(cal.views), cal.rms_px, cal.baseline_mm,
                cal.stereo_angle_deg)
    write_calibration(out, run, overwrite=args.overwrite)
    return Path(out) / REPORT_FILE


def _error_line(err: BaseException) -> str:
    if isinstance(err, FileNotFoundError) and err.filename:
        message = f"file not found: {err.filename}"
    else:
        message = str(err) or type(err).__name__
    return " ".join(message.split())          # one line


def _report_bug(argv: Sequence[str] | None) -> None:
    """Print the traceback of the exception being handled, then ask to report it."""
    traceback.print_exc(file=sys.stderr)
    command = " ".join([PROG, *(sys.argv[1:] if argv is None else argv)])
    sys.stderr.write(f"{PROG}: this is a bug in georeg (version {installed_version()}), not an "
                     "error in your input; please report it to the georeg developers with the "
                     f"traceback above and the command: {command}\n")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``georeg``; returns the exit status.

    0 done, 1 a user error (one of :data:`~georeg_app.errors.USER_ERRORS`: one line, the
    traceback too under ``--verbose``), 70 a bug (any other exception: the traceback and a
    request to report it), 130 interrupted. argparse exits with status 2 on bad arguments.
    """
    args = build_parser().parse_args(argv)
    with _logging_to_stderr(args.quiet, args.verbose):
        t0 = time.perf_counter()
        try:
            report = _run(args)
        except KeyboardInterrupt:
            sys.stderr.write(f"{PROG}: error: interrupted (nothing written)\n")
            return EXIT_INTERRUPTED
        except USER_ERRORS as err:
            if args.verbose:
                traceback.print_exc(file=sys.stderr)
            sys.stderr.write(f"{PROG}: error: {_error_line(err)}\n")
            return EXIT_ERROR
        except Exception:                       # noqa: BLE001 - anything else is a bug
            _report_bug(argv)
            return EXIT_BUG
        logger.info("done in %.1f s; report: %s", time.perf_counter() - t0, report.resolve())
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
