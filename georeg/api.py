"""``measure``, ``compare``, ``track`` and ``demo`` on Python values.

Each function builds the objects the command line builds (``Config``/``TrackConfig``,
``MethodSpec``, then :func:`~georeg_app.shape.pipeline.run_methods` or
:func:`~georeg_app.series.track.run_track`): the values are checked by the configuration's
readers before any computing (:mod:`georeg.inputs`), and the result saves the files the
command line writes (:class:`~georeg_app.results.ShapeRun`, :class:`~georeg_app.results.SeriesRun`).

Examples
--------
The demo's pair measured with three spline levels (about 40 s: not run as a doctest)::

    import georeg
    images, cameras, nominal, truth = georeg.demo()
    run = georeg.measure(images, cameras, nominal, levels=3)
    run.ok, run.residual_percent
    run.save("out")
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Callable, NamedTuple

from fesdic_core.cameras.rig import read_cameras_json

from georeg_app.config.measure import Config, OutputConfig, load_config
from georeg_app.config.track import (TrackConfig, displacement_table, reference_table, series_table,
                                     load_track_config)
from georeg_app.results import SeriesRun, ShapeRun, check_output_folder
from georeg_app.shape.demo import Truth, demo_config
from georeg_app.shape.methods import default_specs, measure_specs
from georeg_app.shape.pipeline import run_methods

from georeg.inputs import (PathLike, cameras_config, geometry_config, images_config,
                           method_config, plain)

logger = logging.getLogger(__name__)

__all__ = ["Progress", "DemoInputs", "load_config", "load_track_config", "measure", "compare",
           "track", "demo"]

#: ``progress(stage, done, total)``: after each image scale of a method (stage: its label)
#: and, in a series, after each frame (stage "frames")
Progress = Callable[[str, int, int], None]


class DemoInputs(NamedTuple):
    """The demo's rendered inputs (:func:`demo`)."""

    images: tuple           # two core Images (1224 x 816 px)
    cameras: tuple          # two core Cameras, the specimen pose off by 0.5 deg and 0.5 mm
    nominal: dict           # the [geometry] table of the plate with its hole
    truth: Truth            # the true surface and the exact cameras


def demo() -> DemoInputs:
    """The demo's specimen rendered in memory (:func:`georeg_app.shape.demo.demo_config`):
    the paper's twisted open-hole plate seen by two cameras, with its truth.

    Returns
    -------
    DemoInputs : ``(images, cameras, nominal, truth)``; ``measure(images, cameras,
        nominal, truth=truth)`` measures it as ``georeg demo`` does.
    """
    config, images, truth = demo_config(Path("demo_out"))
    geometry = config.geometry
    nominal = {"kind": geometry.kind, "length_mm": geometry.length_mm,
               "width_mm": geometry.width_mm, "hole_radius_mm": geometry.hole_radius_mm}
    cameras = tuple(read_cameras_json(config.cameras.file))
    return DemoInputs(tuple(images), cameras, nominal, truth)


def _is_toml(value: Any) -> bool:
    return isinstance(value, (str, Path)) and Path(value).suffix.lower() == ".toml"


def _progress(progress: bool | Progress | None) -> bool | Progress:
    if progress is None or progress is False:
        return False
    if progress is True or callable(progress):
        return progress
    raise ValueError(f"progress: expected True, False or a callable progress(stage, done, "
                     f"total), got {progress!r}")


def _config(name: str, images, cameras, nominal, options: dict, landmarks, source,
            out) -> tuple[Config, tuple | None]:
    """The run's Config (and loaded images) from a TOML file, a Config, or Python values."""
    given = {k: v for k, v in options.items() if v is not None}
    if _is_toml(images) or isinstance(images, Config):
        extra = [k for k, v in (("cameras", cameras), ("nominal", nominal),
                                ("landmarks", landmarks), ("source", source)) if v is not None]
        extra += [k for k in given if (k, given[k]) not in (("method", "georeg"), ("levels", "auto"))]
        if extra:
            raise TypeError(f"{name}(): {', '.join(extra)}: not used with a configuration "
                            "(give them in its TOML tables)")
        config = load_config(images) if _is_toml(images) else images
        loaded = None
    else:
        if cameras is None or nominal is None:
            missing = ", ".join(k for k, v in (("cameras", cameras), ("nominal", nominal)) if v is None)
            raise TypeError(f"{name}(): missing {missing} (or give a TOML configuration file)")
        base = Path.cwd()
        method = method_config(given)
        image_config, loaded = images_config(images, method, base)
        geometry = geometry_config(nominal, base)
        config = Config(images=image_config,
                        cameras=cameras_config(cameras, base, source, landmarks, geometry),
                        geometry=geometry, method=method,
                        output=OutputConfig(Path(out) if out is not None else Path("georeg_out")),
                        source=None)
    if out is not None:
        config = config.with_output_dir(out)
    return config, loaded


def _shape_run(command: str, images, cameras, nominal, *, options: dict, landmarks, source,
               truth, out, overwrite, progress) -> ShapeRun:
    progress = _progress(progress)
    config, loaded = _config(command, images, cameras, nominal, options, landmarks, source, out)
    if out is not None:
        check_output_folder(out, overwrite, option="overwrite=True")   # before computing
    specs = measure_specs(config) if command == "measure" else default_specs(config)
    logger.info("%s: %d method(s): %s", command, len(specs), ", ".join(s.label for s in specs))
    result = ShapeRun(run_methods(config, specs, images=loaded, truth=truth, progress=progress),
                      command=command)
    if out is not None:
        result.save(out, overwrite=overwrite)
    return result


def measure(images, cameras=None, nominal=None, *, method: str = "georeg",
            levels: int | str = "auto", scales: int | None = None,
            tikhonov_length_mm: float | str | list | None = None,
            landmarks: list[dict] | None = None, source: str | None = None,
            truth: Truth | None = None, out: PathLike | None = None, overwrite: bool = False,
            progress: bool | Progress = False, **method_options) -> ShapeRun:
    """Measure a shape, as ``georeg measure``.

    Parameters
    ----------
    images : two image files, two 2-D arrays (h, w) of gray levels, or two core
        ``Image`` objects; or a TOML configuration file (``"run.toml"``) or a ``Config``, then
        without ``cameras``, ``nominal`` and method options (its ``[method]`` holds them).
    cameras : a calibration file (the project's JSON, OpenCV FileStorage, VIC-3D, DICe,
        pyvale CSV; recognised from the file, or named by ``source``), or two core Cameras.
    nominal : a dict like the TOML ``[geometry]`` table (``{"kind": "plate_with_hole",
        "length_mm": 100, "width_mm": 50, "hole_radius_mm": 14}``), a ``GeometryConfig``,
        or a mesh or CAD (IGES, STEP) file.
    method, levels, scales, tikhonov_length_mm, **method_options : the ``[method]`` table
        (``"fe"``, ``"tikhonov"`` or ``"georeg"``; any other key of ``[method]``, e.g.
        ``calibrate=False``, ``prefilter_px=0.7``).
    landmarks : the ``[[landmarks]]`` (``xyz_mm``, ``cam0_px``, ``cam1_px``) that pose
        another tool's calibration (at least 4).
    source : the ``[cameras]`` key of ``cameras`` (``"file"``, ``"opencv"``, ...).
    truth : the true surface of a synthetic scene (:func:`demo`): errors in the summary.
    out, overwrite : save the outputs there (checked before computing; see ``ShapeRun.save``).
    progress : True for progress bars, or a callable ``progress(stage, done, total)``.

    Returns
    -------
    ShapeRun : ``ok``, ``failure``, ``nodes`` (n, 3), ``shape_std_mm`` (n,),
        ``residual_percent``, ``summary``, ``save(folder)``, ``to_meshio()``.

    Raises
    ------
    ConfigError, ConfigFileNotFoundError, ValueError
        Before any computing, naming the argument and the value at fault.
    """
    options = dict(method_options, name=method, levels=levels, scales=scales,
                   tikhonov_length_mm=tikhonov_length_mm)
    if _is_toml(images) or isinstance(images, Config):
        options = dict(method_options, method=method, levels=levels, scales=scales,
                       tikhonov_length_mm=tikhonov_length_mm)
    return _shape_run("measure", images, cameras, nominal, options=options, landmarks=landmarks,
                      source=source, truth=truth, out=out, overwrite=overwrite, progress=progress)


def compare(images, cameras=None, nominal=None, *, levels: int | str = "auto",
            scales: int | None = None, tikhonov_length_mm: float | str | list | None = None,
            landmarks: list[dict] | None = None, source: str | None = None,
            truth: Truth | None = None, out: PathLike | None = None, overwrite: bool = False,
            progress: bool | Progress = False, **method_options) -> ShapeRun:
    """Measure the shape with every method on the same images, as ``georeg compare``: FE,
    Tikhonov at each ``tikhonov_length_mm``, georeg with ``levels`` (multiscale, and
    monoscale). Arguments as :func:`measure`; the ``ShapeRun``'s chosen method is the
    first georeg one (``run.result(label)`` gives any other)."""
    options = dict(method_options, levels=levels, scales=scales,
                   tikhonov_length_mm=tikhonov_length_mm)
    return _shape_run("compare", images, cameras, nominal, options=options, landmarks=landmarks,
                      source=source, truth=truth, out=out, overwrite=overwrite, progress=progress)


def _track_config(images, cameras, nominal, series, displacement, reference, options: dict,
                  landmarks, source, out) -> TrackConfig:
    if _is_toml(images) or isinstance(images, TrackConfig):
        extra = [k for k, v in (("cameras", cameras), ("nominal", nominal), ("series", series),
                                ("displacement", displacement), ("reference", reference),
                                ("landmarks", landmarks), ("source", source)) if v is not None]
        extra += [k for k, v in options.items() if v is not None]
        if extra:
            raise TypeError(f"track(): {', '.join(extra)}: not used with a configuration "
                            "(give them in its TOML tables)")
        config = load_track_config(images) if _is_toml(images) else images
        return config if out is None else config.with_output_dir(out)
    base = Path.cwd()
    if series is None:
        raise TypeError("track(): missing series=(cam0 frames, cam1 frames): two globs or lists")
    if not isinstance(series, (list, tuple)) or len(series) != 2:
        raise ValueError(f"series: expected (cam0 frames, cam1 frames), two globs or lists of "
                         f"files, got {series!r}")
    frames = series_table(plain({"cam0": series[0], "cam1": series[1]}), Path("series"), base)
    table = displacement if isinstance(displacement, dict) else {"method": displacement or "fe"}
    disp = displacement_table(plain(table), Path("displacement"))
    method = method_config(options)
    image_config, loaded = images_config(images, method, base)
    if loaded is not None:
        raise ValueError("images: the reference pair of a series must be two image files "
                         "(the frames are read from files too)")
    if reference is not None:
        if cameras is not None or nominal is not None:
            raise TypeError("track(): cameras and nominal are not used with reference= (the "
                            "reference folder holds the calibrated cameras and the surface)")
        ref = reference_table(plain({"dir": reference}), Path("reference"), base, disp.method)
        cams = geometry = None
    else:
        if cameras is None or nominal is None:
            raise TypeError("track(): give cameras and nominal, or reference= a `georeg "
                            "measure` output folder")
        geometry, ref = geometry_config(nominal, base), None
        cams = cameras_config(cameras, base, source, landmarks, geometry)
    return TrackConfig(images=image_config, cameras=cams, geometry=geometry, method=method,
                       series=frames, displacement=disp, reference=ref,
                       output=OutputConfig(Path(out) if out is not None else Path("track_out")),
                       source=None)


def track(images, cameras=None, nominal=None, *, series=None, displacement: str | dict | None = None,
          reference: PathLike | None = None, method: str | None = None,
          levels: int | str | None = None, scales: int | None = None,
          landmarks: list[dict] | None = None, source: str | None = None,
          scheduler: str = "serial", workers: int | None = None, out: PathLike | None = None,
          overwrite: bool = False, progress: bool | Progress = False,
          **method_options) -> SeriesRun:
    """The displacement of the measured surface over a series of stereo pairs, as
    ``georeg track``.

    Parameters
    ----------
    images : the reference pair (two image files), or a TOML file / ``TrackConfig``.
    cameras, nominal, landmarks, source : as :func:`measure` (the reference shape is
        measured first), or None with ``reference``.
    series : ``(cam0, cam1)``: the deformed pairs, each a glob or a list of files.
    displacement : the displacement method ("fe", "tikhonov", "georeg") or a dict like the
        ``[displacement]`` table.
    reference : a ``georeg measure`` output folder (``ShapeRun.save``) to start from.
    method, levels, scales, **method_options : the reference shape's ``[method]``.
    scheduler, workers : "serial", "threads", "processes" or tcp://HOST:PORT (Dask).
    out, overwrite, progress : as :func:`measure`.

    Returns
    -------
    SeriesRun : ``ok``, ``failure``, ``frames``, ``summary``, ``save(folder)``,
        ``to_meshio(frame)``.
    """
    from georeg_app.cli import check_scheduler         # the command line's own check
    from georeg_app.series.track import run_track
    progress = _progress(progress)
    scheduler = check_scheduler(scheduler)
    options = dict(method_options, name=method, levels=levels, scales=scales)
    config = _track_config(images, cameras, nominal, series, displacement, reference, options,
                           landmarks, source, out)
    if out is not None:
        check_output_folder(out, overwrite, option="overwrite=True")   # before computing
    result = SeriesRun(run_track(config, scheduler, progress, workers=workers))
    if out is not None:
        result.save(out, overwrite=overwrite)
    return result
