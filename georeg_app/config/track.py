"""The TOML configuration of ``georeg track``: the measure configuration plus a series.

Relative paths are resolved against the folder of the configuration file; every error
names the file, the section and the key (:class:`~georeg_app.config.toml_schema.ConfigError`).
A complete example (optional keys show their default in parentheses)::

    [images]                      # required: the REFERENCE stereo pair (frame 0)
    cam0 = "ref/left.tif"
    cam1 = "ref/right.tif"

    [cameras]                     # as `georeg measure` (required without [reference])
    [geometry]                    # as `georeg measure` (required without [reference])
    [method]                      # as `georeg measure`: the shape of the reference, and
                                  # prefilter_px / interpolation_order / normalisation of every frame

    [series]                      # required: the deformed stereo pairs, in order
    cam0 = "frames/cam0_*.tif"    # a glob (natural sort: 2 before 10) or a list of paths
    cam1 = "frames/cam1_*.tif"    # the same count as cam0

    [displacement]                # optional section
    method = "fe"                 # "fe" | "tikhonov" | "georeg"          (default "fe")
    scales = 3                    # image scales, coarse to fine           (default 3)
    incremental = true            # chain the frames: the last good one's field is a
                                  # candidate start; the reference stays frame 0 (default true)
    start = "features"            # each frame's starting field: "features": SIFT matches
                                  # of each camera's reference and deformed images,
                                  # triangulated and fitted on the mesh (large motions; with
                                  # incremental = true the better, by the residual at the
                                  # coarsest scale, of that and the last good frame's field);
                                  # "previous": the last good frame's field (zero without
                                  # incremental); "zero"                  (default "features")
    tikhonov_length_mm = "auto"   # method = "tikhonov": length (mm) on each component, or
                                  # "auto": the longest of 10 mm / sqrt(2)**k at which the
                                  # last frame measures, kept for the series (default "auto")
    levels = "auto"               # method = "georeg": spline levels per component, or
                                  # "auto": chosen on the last frame (the coarsest level
                                  # that agrees with every finer one within 2 std of their
                                  # change) and kept for the series     (default "auto")
    jacobian = "reference"        # "reference": modified Gauss-Newton, H of the reference
                                  # images built and factorized once per scale for every
                                  # iteration and frame; "current": full Gauss-Newton, H
                                  # rebuilt at each iteration      (default "reference")
    prefilter_px = 1.0            # image model of the frames and of the reference pair for
                                  # the displacement: Gaussian prefilter sigma (px); the
                                  # reference shape keeps [method] prefilter_px. 1 px reads
                                  # sub-pixel motions within 1 % where 0.5 px reads them 1.4-3 %
                                  # low (benchmarks/bench_subpixel.py)        (default 1.0)
    max_invalid_share = 0.03      # a frame fails when more of its nodes than this share are
                                  # not valid locally (residual over the local noise,
                                  # texture, conditioning, neighbours). By default 1: the
                                  # nodes' validity is written, no frame fails on it (on real
                                  # images converged frames reach 3-7 %; 0.03 catches the
                                  # local divergences of renders)            (default 1.0)
    uncertainty = true            # each node's displacement_uncertainty_mm (std and bias
                                  # indicator) for fe and georeg: 0.4 s more per georeg
                                  # frame of 320 x 240 px, 4-6 s on GT4's 1920 x 1200
                                  # (fe: 1.4 s at 320 x 240, the diagonal of H^-1)
                                  #                                            (default true)

    [reference]                   # optional: reuse a `georeg measure` output folder
    dir = "shape_out"             # (its summary.json, <method>.vtu, <method>_cameras.json,
                                  # and <method>_spline.json for method = "georeg"; a CAD
                                  # part's: nominal_spline.json, the VTU's face parameters)

    [output]
    dir = "track_out"             # (default "track_out"; `--out` overrides)
"""
from __future__ import annotations

import dataclasses
import glob
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fesdic_core.displacement.driver import (DISPLACEMENT_MAX_INVALID_SHARE,
                                             DISPLACEMENT_PREFILTER_PX, JACOBIANS)

from georeg_app.config.measure import (AUTO, CamerasConfig, GeometryConfig, ImagesConfig,
                                       MethodConfig, OutputConfig, cameras_table, geometry_table,
                                       images_table, integer_or_auto, method_table, placed)
from georeg_app.config.toml_schema import (ConfigFileNotFoundError, Table, boolean, check, integer,
                                           load_toml, number, resolve_path, show, show_path, string)

__all__ = ["SeriesConfig", "DisplacementConfig", "ReferenceConfig", "TrackConfig",
           "load_track_config", "natural_key", "DISPLACEMENT_METHODS", "START_MODES",
           "REFERENCE_SUMMARY", "REFERENCE_NOMINAL", "series_table", "displacement_table",
           "reference_table"]

DISPLACEMENT_METHODS = ("fe", "tikhonov", "georeg")
#: the starting field of each frame (``[displacement] start``)
START_MODES = ("features", "previous", "zero")
DEFAULT_TRACK_DIR = "track_out"
REFERENCE_SUMMARY = "summary.json"
#: a CAD part's nominal faces in a `georeg measure` folder (georeg_app.shape.outputs.NOMINAL_FILE)
REFERENCE_NOMINAL = "nominal_spline.json"


@dataclass(frozen=True)
class SeriesConfig:
    """The deformed stereo pairs, in order: ``cam0[k]`` with ``cam1[k]``."""

    cam0: tuple[Path, ...]
    cam1: tuple[Path, ...]

    def __len__(self) -> int:
        return len(self.cam0)


@dataclass(frozen=True)
class DisplacementConfig:
    method: str = "fe"
    scales: int = 3
    incremental: bool = True
    tikhonov_length_mm: float | str = AUTO
    levels: int | str = AUTO
    jacobian: str = "reference"
    start: str = "features"
    prefilter_px: float = DISPLACEMENT_PREFILTER_PX
    max_invalid_share: float = DISPLACEMENT_MAX_INVALID_SHARE
    uncertainty: bool = True

    @property
    def scale_sequence(self) -> tuple[int, ...]:
        return tuple(range(self.scales - 1, -1, -1))


@dataclass(frozen=True)
class ReferenceConfig:
    """A `georeg measure` output folder and the files of its (first trusted) method;
    ``nominal``: a CAD part's nominal faces (:data:`REFERENCE_NOMINAL`), None for one patch."""

    dir: Path
    mesh: Path
    cameras: Path
    spline: Path | None
    label: str
    nominal: Path | None = None


@dataclass(frozen=True)
class TrackConfig:
    images: ImagesConfig
    cameras: CamerasConfig | None
    geometry: GeometryConfig | None
    method: MethodConfig
    series: SeriesConfig
    displacement: DisplacementConfig
    reference: ReferenceConfig | None
    output: OutputConfig
    source: Path

    def with_output_dir(self, out_dir: str | os.PathLike) -> TrackConfig:
        return dataclasses.replace(self, output=OutputConfig(Path(out_dir)))


def natural_key(path: str | Path) -> list:
    """Sort key with the digit runs compared as numbers (``img_2`` before ``img_10``)."""
    return [int(part) if part.isdigit() else part.lower()
            for part in re.split(r"(\d+)", str(path))]


def _frames(t: Table, key: str, value: Any, base: Path) -> tuple[Path, ...]:
    """A glob (natural sort, at least one match) or a non-empty list of existing files."""
    if isinstance(value, str):
        pattern = resolve_path(value, base)
        found = sorted((Path(p) for p in glob.glob(str(pattern)) if Path(p).is_file()),
                       key=natural_key)
        if not found:
            raise t.error(key, f"no file matches {show_path(pattern)}", ConfigFileNotFoundError)
        return tuple(found)
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise t.error(key, f"expected a glob (string) or a non-empty list of file paths, got "
                           f"{show(value)}")
    paths = []
    for i, item in enumerate(value):
        path = resolve_path(item, base)
        if not path.is_file():
            raise t.error(key, f"file not found: {show_path(path)} (item {i + 1} of {len(value)})",
                          ConfigFileNotFoundError)
        paths.append(path)
    return tuple(paths)


def series_table(data: Any, source: Path, base: Path) -> SeriesConfig:
    """The ``[series]`` table: the deformed pairs (globs or lists), checked."""
    t = Table(data, "[series]", source)
    raw0 = t.take("cam0", lambda v: v, "a glob or a list of paths", required=True)
    raw1 = t.take("cam1", lambda v: v, "a glob or a list of paths", required=True)
    t.finish()
    cam0, cam1 = _frames(t, "cam0", raw0, base), _frames(t, "cam1", raw1, base)
    if len(cam0) != len(cam1):
        raise t.error(None, f"cam0 has {len(cam0)} frames but cam1 has {len(cam1)} "
                            "(a stereo pair per frame)")
    return SeriesConfig(cam0, cam1)


def _number_or_auto(value: Any) -> float | str:
    """A finite number (not a boolean) or the string "auto"."""
    return value if value == AUTO else number(value)


def displacement_table(data: Any, source: Path) -> DisplacementConfig:
    """The ``[displacement]`` table, checked (defaults for the keys it lacks)."""
    t = Table(data, "[displacement]", source)
    d = DisplacementConfig()
    c = DisplacementConfig(
        method=t.take("method", string, "a string", default=d.method),
        scales=t.take("scales", integer, "an integer", default=d.scales),
        incremental=t.take("incremental", boolean, "true or false", default=d.incremental),
        tikhonov_length_mm=t.take("tikhonov_length_mm", _number_or_auto,
                                  'a number (mm) or "auto"', default=d.tikhonov_length_mm),
        levels=t.take("levels", integer_or_auto, 'an integer or "auto"', default=d.levels),
        jacobian=t.take("jacobian", string, "a string", default=d.jacobian),
        start=t.take("start", string, "a string", default=d.start),
        prefilter_px=t.take("prefilter_px", number, "a number (px)", default=d.prefilter_px),
        max_invalid_share=t.take("max_invalid_share", number, "a number (a share, 0 to 1)",
                                 default=d.max_invalid_share),
        uncertainty=t.take("uncertainty", boolean, "true or false", default=d.uncertainty))
    t.finish()
    check(t, "method", c.method, c.method in DISPLACEMENT_METHODS,
          "one of " + ", ".join(map(json.dumps, DISPLACEMENT_METHODS)))
    check(t, "scales", c.scales, c.scales >= 1, ">= 1")
    check(t, "tikhonov_length_mm", c.tikhonov_length_mm,
          c.tikhonov_length_mm == AUTO or c.tikhonov_length_mm > 0, '> 0 (mm) or "auto"')
    check(t, "levels", c.levels, c.levels == AUTO or c.levels >= 1, '>= 1 or "auto"')
    check(t, "jacobian", c.jacobian, c.jacobian in JACOBIANS,
          "one of " + ", ".join(map(json.dumps, JACOBIANS)))
    check(t, "prefilter_px", c.prefilter_px, c.prefilter_px >= 0, ">= 0 (px; 0 = no prefilter)")
    check(t, "start", c.start, c.start in START_MODES,
          "one of " + ", ".join(map(json.dumps, START_MODES)))
    check(t, "max_invalid_share", c.max_invalid_share, 0.0 <= c.max_invalid_share <= 1.0,
          "a share in [0, 1]")
    return c


def reference_table(data: Any, source: Path, base: Path, method: str) -> ReferenceConfig:
    """The reference folder and the files of its first method that is "ok"."""
    t = Table(data, "[reference]", source)
    folder = resolve_path(t.take("dir", string, "a folder path (string)", required=True), base)
    t.finish()
    if not folder.is_dir():
        raise t.error("dir", f"folder not found: {show_path(folder)}", ConfigFileNotFoundError)
    summary_path = folder / REFERENCE_SUMMARY
    if not summary_path.is_file():
        raise t.error("dir", f"{show_path(folder)} lacks {REFERENCE_SUMMARY} (not a `georeg "
                             "measure` output folder?)", ConfigFileNotFoundError)
    try:
        methods = json.loads(summary_path.read_text())["methods"]
        entry = next(m for m in methods if m.get("status") == "ok" and m.get("mesh_file"))
    except (ValueError, KeyError, TypeError):
        raise t.error("dir", f"{show_path(summary_path)} is not a `georeg measure` summary") from None
    except StopIteration:
        raise t.error("dir", f"{show_path(summary_path)}: no method measured the shape "
                             "successfully (every one failed)") from None
    stem = Path(entry["mesh_file"]).stem
    files = {"mesh": folder / entry["mesh_file"], "cameras": folder / f"{stem}_cameras.json"}
    if method == "georeg":
        files["spline"] = folder / f"{stem}_spline.json"
    for what, path in files.items():
        if not path.is_file():
            why = " (the georeg displacement needs the measured spline: measure the reference " \
                  "with [method] name = \"georeg\")" if what == "spline" else ""
            raise t.error("dir", f"{show_path(folder)} lacks {path.name}{why}",
                          ConfigFileNotFoundError)
    nominal = folder / REFERENCE_NOMINAL
    return ReferenceConfig(dir=folder, mesh=files["mesh"], cameras=files["cameras"],
                           spline=files.get("spline"), label=str(entry.get("label", stem)),
                           nominal=nominal if nominal.is_file() else None)


def load_track_config(path: str | os.PathLike) -> TrackConfig:
    """Read and check a ``georeg track`` configuration (schema in the module docstring)."""
    source = Path(path)
    data = load_toml(source)
    base = source.resolve().parent
    top = Table(data, "", source)
    images = top.take("images", lambda v: v, "a table", required=True)
    cameras = top.take("cameras", lambda v: v, "a table")
    landmarks = top.take("landmarks", lambda v: v, "an array of tables")
    geometry = top.take("geometry", lambda v: v, "a table")
    method = top.take("method", lambda v: v, "a table", default={})
    series = top.take("series", lambda v: v, "a table", required=True)
    displacement = top.take("displacement", lambda v: v, "a table", default={})
    reference = top.take("reference", lambda v: v, "a table")
    output = top.take("output", lambda v: v, "a table", default={})
    top.finish()
    disp = displacement_table(displacement, source)
    if reference is None:
        for key, value in (("cameras", cameras), ("geometry", geometry)):
            if value is None:
                raise top.error(key, "missing required section (or give [reference] dir = a "
                                     "`georeg measure` output folder)")
        cams = cameras_table(cameras, landmarks, source, base, **placed(geometry))
        geom, ref = geometry_table(geometry, source, base), None
    else:
        for key, value in (("cameras", cameras), ("geometry", geometry), ("landmarks", landmarks)):
            if value is not None:
                raise top.error(key, "not used with [reference] (the reference folder holds the "
                                     "calibrated cameras and the measured surface); remove it")
        cams = geom = None
        ref = reference_table(reference, source, base, disp.method)
    out_table = Table(output, "[output]", source)
    out = out_table.take("dir", string, "a folder path (string)", default=DEFAULT_TRACK_DIR)
    out_table.finish()
    return TrackConfig(images=images_table(images, source, base), cameras=cams, geometry=geom,
                       method=method_table(method, source), series=series_table(series, source, base),
                       displacement=disp, reference=ref,
                       output=OutputConfig(resolve_path(out, base)), source=source.resolve())
