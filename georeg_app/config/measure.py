"""The TOML configuration of ``georeg measure`` and ``georeg compare``.

Relative paths are resolved against the folder of the configuration file. Unknown keys
(at any level), wrong types, missing required keys and missing files are errors
(:class:`ConfigError`) that name the file, the section and the key, e.g.::

    ConfigError: config.toml: [method] levels: expected an integer or "auto", got "three"
    ConfigError: config.toml: [geometry] radius: unknown key (did you mean hole_radius_mm?)

A complete example (every key; optional keys show their default in parentheses)::

    [images]                      # required: the stereo pair (any format OpenCV reads)
    cam0 = "images/left.tif"
    cam1 = "images/right.tif"

    [cameras]                     # required: exactly one of file, pyvale_csv, opencv, vic3d, dice
    file = "cameras.json"         # the core's JSON camera file (intrinsics + poses)
    # pyvale_csv = "calib.csv"    # a pyvale stereo calibration CSV (cam0 at the origin)
    # opencv = "stereo.yml"       # OpenCV FileStorage (.yml/.xml/.json): K1 D1 K2 D2 R T
    # vic3d = "project.z3d"       # VIC-3D project (.z3d zip or its project.xml)
    # dice = "cal.xml"            # DICe camera-system XML
                                  # all but `file`: >= 4 landmarks pose the specimen (not
                                  # kind "roi", nor "cad" with a pose):
    # [[landmarks]]               # one table per landmark (also accepted: [[cameras.landmarks]])
    # xyz_mm = [-50.0, -25.0, 0.0]   # world point on the specimen (mm)
    # cam0_px = [812.3, 1040.8]      # where camera 0 sees it (x = column, y = row, px)
    # cam1_px = [640.1, 1032.5]      # where camera 1 sees it

    [geometry]                    # required: the nominal surface
    kind = "plate_with_hole"      # "rectangle" | "plate_with_hole" | "mesh" | "cad" | "roi"
    length_mm = 100.0             # along x; rectangle and plate_with_hole
    width_mm = 50.0               # along y; rectangle and plate_with_hole
    hole_radius_mm = 14.0         # plate_with_hole only (0 < r < width/2)
    # file = "specimen.msh"       # kind = "mesh": any surface mesh meshio reads;
                                  # kind = "cad": the part's IGES file (.igs, .iges:
                                  # untrimmed B-spline faces, entity 128) or, with the
                                  # optional 'cad' extra, STEP (.step, .stp) or trimmed IGES
    # faces = [0, "lid"]          # kind = "cad" only: faces by index or name (default all)
    # pose = "auto"               # "cad" without landmarks: ICP of the rig's triangulated
                                  # matches onto the faces, from their principal axes, or
    # pose = {rotation_deg = [180, 0, 0], translation_mm = [0, 0, 400]}   # from a rough
                                  # pose X_cam0 = R X_cad + t (R: rotation vector, deg)
    # polygon_px = [[420, 310], [1500, 300], [1510, 900]]   # kind = "roi": the specimen on
                                  # camera 0's image, [x, y] px (x = column), no landmarks
    # exclude_px = [[[900, 500], [1000, 500], [1000, 600]]]   # "roi": holes (default none)
    # mask = "roi.png"            # "roi": instead of the polygons, nonzero = specimen
    # surface = "plane"           # "roi": "plane" | "quadric" (z = f(x, y)) (default "plane")
    elements = 400                # approximate number of FE elements (default: chosen by the method)
                                  # (plates are centred at the world origin in the z = 0 plane)

    [method]                      # optional section
    name = "georeg"               # "fe" | "tikhonov" | "georeg"       (default "georeg")
    levels = "auto"               # georeg spline levels: "auto" (chosen from the data by an
                                  # information criterion, docs "Level choice") or an integer
                                  # (the paper's fixed levels)          (default "auto")
    start_levels = 3              # levels of the coarse-to-fine start of "auto" (default 3)
    scales = 3                    # image scales, coarse to fine       (default 3)
    tikhonov_length_mm = [5.0, 10.0, 20.0, "auto"]   # numbers (mm) and/or "auto"
                                  # (chosen from the data)   (default [5, 10, 20, "auto"])
    calibrate = true              # calibrate the poses with the shape (default true),
    keep_stereo = true            # keeping the stereo relation (default true)
    coupling = "joint"            # "joint" (one Gauss-Newton) | "alternate" (fixed point)
    normalisation = "element"     # brightness/contrast: "element" | "global" | "none"
    max_fixed_point = 10          # per scale, coupling = "alternate"  (default 10)
    prefilter_px = 0.5            # image model: Gaussian prefilter sigma (px) before the
                                  # B-spline, >= 0, 0 = none (default 0.5, DEFAULT_PREFILTER_PX)
    interpolation_order = 3       # image model: B-spline order after the prefilter, 3 (cubic)
                                  # | 5 (quintic) (default 3, imaging.image.DEFAULT_ORDER)
    edge_margin_px = 2.0          # leave out the points within this many px of the mesh's
                                  # projected boundary, >= 0, 0 = none (default 2, the core's
                                  # fesdic_core.residual.edges.DEFAULT_EDGE_MARGIN_PX)
    self_occlusion = true         # leave out the points the surface itself hides from a camera,
                                  # recomputed on the current shape at every scale (default true)
    max_view_angle_deg = 70.0     # leave out the points seen at more than this angle from their
                                  # normal, in (0, 90], 90 = no cut-off (default 70, the core's
                                  # fesdic_core.residual.visibility.DEFAULT_MAX_VIEW_ANGLE_DEG)

    [output]                      # optional section
    dir = "georeg_out"            # output folder (default "georeg_out"; `--out` overrides)
"""
from __future__ import annotations

import dataclasses
import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fesdic_core.imaging.image import DEFAULT_ORDER, DEFAULT_PREFILTER_PX, ORDERS
from fesdic_core.residual.edges import DEFAULT_EDGE_MARGIN_PX
from fesdic_core.residual.visibility import DEFAULT_MAX_VIEW_ANGLE_DEG
from fesdic_core.shape.joint import COUPLINGS

from georeg_app.config.cad import RoughPose, cad_file, take_cad
from georeg_app.config.roi import RoiConfig, take_roi
from georeg_app.config.toml_schema import (ConfigError, ConfigFileNotFoundError, Table, boolean,
                                           check, existing_file, integer, load_toml, number,
                                           resolve_path, show, string, vector)

logger = logging.getLogger(__name__)

__all__ = ["METHOD_NAMES", "AUTO", "integer_or_auto", "lengths_or_auto", "GEOMETRY_KINDS",
           "NORMALISATIONS", "DEFAULT_TIKHONOV_LENGTHS_MM", "DEFAULT_OUTPUT_DIR",
           "ImagesConfig", "Landmark", "CAMERA_SOURCES", "CamerasConfig", "GeometryConfig",
           "MethodConfig", "OutputConfig", "Config", "load_config",
           "ConfigError", "ConfigFileNotFoundError", "images_table", "cameras_table",
           "geometry_table", "method_table", "output_table", "placed"]

METHOD_NAMES = ("fe", "tikhonov", "georeg")
#: the value of ``levels`` and of a Tikhonov length chosen from the data
AUTO = "auto"


def integer_or_auto(value: Any) -> int | str:
    """An integer (not a boolean) or the string "auto"."""
    return value if value == AUTO else integer(value)


def lengths_or_auto(value: Any) -> tuple:
    """One length (mm) or "auto", or a non-empty list of them."""
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ValueError
    return tuple(v if v == AUTO else number(v) for v in values)
GEOMETRY_KINDS = ("rectangle", "plate_with_hole", "mesh", "cad", "roi")
NORMALISATIONS = ("element", "global", "none")
DEFAULT_TIKHONOV_LENGTHS_MM = (5.0, 10.0, 20.0, "auto")
DEFAULT_OUTPUT_DIR = "georeg_out"


@dataclass(frozen=True)
class ImagesConfig:
    cam0: Path
    cam1: Path


@dataclass(frozen=True, eq=False)
class Landmark:
    """A world point seen in both images: ``xyz_mm`` (3,), ``cam0_px`` (2,), ``cam1_px`` (2,)."""

    xyz_mm: np.ndarray
    cam0_px: np.ndarray
    cam1_px: np.ndarray


CAMERA_SOURCES = ("file", "pyvale_csv", "opencv", "vic3d", "dice")


@dataclass(frozen=True)
class CamerasConfig:
    """Exactly one camera source: ``file`` (JSON cameras) or a calibration of another tool
    (``pyvale_csv``, ``opencv``, ``vic3d``, ``dice``, each + >= 4 landmarks)."""

    file: Path | None = None
    pyvale_csv: Path | None = None
    landmarks: tuple[Landmark, ...] = ()
    opencv: Path | None = None
    vic3d: Path | None = None
    dice: Path | None = None

    @property
    def source(self) -> str:
        """The key of the camera source given (one of :data:`CAMERA_SOURCES`)."""
        return next(k for k in CAMERA_SOURCES if getattr(self, k) is not None)


@dataclass(frozen=True)
class GeometryConfig:
    """Nominal surface; plates are centred at the origin in z = 0, x along the length."""

    kind: str
    length_mm: float | None = None
    width_mm: float | None = None
    hole_radius_mm: float | None = None
    file: Path | None = None
    elements: int | None = None
    faces: tuple | None = None
    polygon_px: tuple | None = None
    exclude_px: tuple | None = None
    mask: Path | None = None
    surface: str | None = None        # kind = "roi": "plane" (its default) or "quadric"
    pose: str | RoughPose | None = None   # kind = "cad": "auto" or a rough pose (no landmarks)

    @property
    def roi(self) -> RoiConfig | None:  # the region of interest of kind = "roi" (arrays)
        return RoiConfig.of(self) if self.kind == "roi" else None


@dataclass(frozen=True)
class MethodConfig:
    name: str = "georeg"
    levels: int | str = "auto"
    start_levels: int = 3
    scales: int = 3
    tikhonov_length_mm: tuple[float | str, ...] = DEFAULT_TIKHONOV_LENGTHS_MM
    calibrate: bool = True
    keep_stereo: bool = True
    coupling: str = "joint"
    normalisation: str = "element"
    max_fixed_point: int = 10
    prefilter_px: float = DEFAULT_PREFILTER_PX
    edge_margin_px: float = DEFAULT_EDGE_MARGIN_PX
    interpolation_order: int = DEFAULT_ORDER
    self_occlusion: bool = True
    max_view_angle_deg: float = DEFAULT_MAX_VIEW_ANGLE_DEG

    @property
    def fixed_levels(self) -> int:
        """The levels of the coarse-to-fine run: ``levels``, or ``start_levels`` if "auto"."""
        return self.start_levels if self.levels == AUTO else int(self.levels)

    @property
    def scale_sequence(self) -> tuple[int, ...]:
        """Image scales coarse to fine, e.g. ``(2, 1, 0)`` for ``scales = 3``."""
        return tuple(range(self.scales - 1, -1, -1))


@dataclass(frozen=True)
class OutputConfig:
    dir: Path


@dataclass(frozen=True)
class Config:
    images: ImagesConfig
    cameras: CamerasConfig
    geometry: GeometryConfig
    method: MethodConfig
    output: OutputConfig
    source: Path

    def with_output_dir(self, out_dir: str | os.PathLike) -> Config:
        """The same configuration writing to ``out_dir``."""
        return dataclasses.replace(self, output=OutputConfig(Path(out_dir)))


# --------------------------------------------------------------------------- sections

def images_table(data: Any, source: Path, base: Path) -> ImagesConfig:
    """The ``[images]`` table ``data`` (read from ``source``, paths relative to ``base``), checked."""
    t = Table(data, "[images]", source)
    cam0 = t.take("cam0", string, "a file path (string)", required=True)
    cam1 = t.take("cam1", string, "a file path (string)", required=True)
    t.finish()
    return ImagesConfig(existing_file(t, "cam0", cam0, base), existing_file(t, "cam1", cam1, base))


def _landmarks(data: Any, where: str, source: Path) -> tuple[Landmark, ...]:
    if not isinstance(data, list):
        raise ConfigError(f"{source}: {where}: expected an array of tables ([[landmarks]]), "
                          f"got {show(data)}")
    out = []
    for i, item in enumerate(data):
        t = Table(item, f"{where}[{i}]", source)
        xyz = t.take("xyz_mm", vector(3), "a list of 3 numbers", required=True)
        p0 = t.take("cam0_px", vector(2), "a list of 2 numbers", required=True)
        p1 = t.take("cam1_px", vector(2), "a list of 2 numbers", required=True)
        t.finish()
        out.append(Landmark(xyz, p0, p1))
    return tuple(out)


def cameras_table(data: Any, top_landmarks: Any, source: Path, base: Path,
                  roi: bool = False, pose: bool = False) -> CamerasConfig:
    """The ``[cameras]`` table (and the top-level ``[[landmarks]]``), checked: one calibration
    source (``roi``: for ``[geometry] kind = "roi"``, ``pose``: for a CAD part with a
    ``pose``; no landmarks for either)."""
    t = Table(data, "[cameras]", source)
    paths = {key: t.take(key, string, "a file path (string)") for key in CAMERA_SOURCES}
    nested = t.take("landmarks", lambda v: v, "an array of tables")
    t.finish()
    given = [key for key, value in paths.items() if value is not None]
    if len(given) != 1:
        raise t.error(None, f"give exactly one of {', '.join(f'`{k}`' for k in CAMERA_SOURCES)}, "
                            f"got {len(given)}" + (f" ({', '.join(given)})" if given else ""))
    if nested is not None and top_landmarks is not None:
        raise t.error("landmarks", "given both as [[landmarks]] and [[cameras.landmarks]]; keep one")
    raw = nested if nested is not None else top_landmarks
    where = "[[cameras.landmarks]]" if nested is not None else "[[landmarks]]"
    landmarks = _landmarks(raw, where, source) if raw is not None else ()
    if (roi or pose) and landmarks:
        used = 'kind = "roi"' if roi else "pose"
        raise t.error("landmarks", f"not used with [geometry] {used} (the rig's triangulation "
                                   "places the specimen); remove them")
    if given[0] != "file" and len(landmarks) < 4 and not (roi or pose):
        raise t.error(given[0], f"needs at least 4 [[landmarks]] to place the specimen, got "
                                f'{len(landmarks)} (or [geometry] kind = "roi", or kind = "cad" '
                                'with pose = "auto" or a rough pose)')
    return CamerasConfig(landmarks=landmarks,
                         **{key: existing_file(t, key, value, base) for key, value in paths.items()})


_GEOMETRY_KEYS = {"rectangle": {"length_mm", "width_mm"},
                  "plate_with_hole": {"length_mm", "width_mm", "hole_radius_mm"},
                  "mesh": {"file"}, "cad": {"file"}, "roi": set()}


def geometry_table(data: Any, source: Path, base: Path) -> GeometryConfig:
    """The ``[geometry]`` table, checked against its ``kind``'s keys."""
    t = Table(data, "[geometry]", source)
    kind = t.take("kind", string, "a string", required=True)
    if kind not in GEOMETRY_KINDS:
        raise t.error("kind", f"expected one of {', '.join(map(json.dumps, GEOMETRY_KINDS))}, "
                              f"got {show(kind)}")
    given = set(t.data)
    values = {"length_mm": t.take("length_mm", number, "a number (mm)"),
              "width_mm": t.take("width_mm", number, "a number (mm)"),
              "hole_radius_mm": t.take("hole_radius_mm", number, "a number (mm)"),
              "file": t.take("file", string, "a file path (string)")}
    elements = t.take("elements", integer, "an integer")
    cad = take_cad(t, kind)
    roi = take_roi(t, kind, base)
    t.finish()
    for key in sorted(_GEOMETRY_KEYS[kind] - given):
        raise t.error(key, f"missing required key (for kind = {json.dumps(kind)})")
    for key in sorted((given & set(values)) - _GEOMETRY_KEYS[kind]):
        raise t.error(key, f"not used with kind = {json.dumps(kind)}; remove it")
    length, width, radius = values["length_mm"], values["width_mm"], values["hole_radius_mm"]
    check(t, "length_mm", length, length is not None and length > 0, "> 0")
    check(t, "width_mm", width, width is not None and width > 0, "> 0")
    check(t, "hole_radius_mm", radius, radius is not None and width is not None
           and 0 < radius < 0.5 * width, f"> 0 and < width_mm / 2 = {0.5 * (width or 0):g}")
    check(t, "elements", elements, elements is not None and elements >= 1, ">= 1")
    path = (cad_file(t, values["file"], base, cad["faces"]) if kind == "cad"
            else existing_file(t, "file", values["file"], base))
    return GeometryConfig(kind, length, width, radius, path, elements, **cad, **roi)


def method_table(data: Any, source: Path) -> MethodConfig:
    """The ``[method]`` table, checked (defaults for the keys it lacks)."""
    t = Table(data, "[method]", source)
    d = MethodConfig()
    m = MethodConfig(
        name=t.take("name", string, "a string", default=d.name),
        levels=t.take("levels", integer_or_auto, 'an integer or "auto"', default=d.levels),
        start_levels=t.take("start_levels", integer, "an integer", default=d.start_levels),
        scales=t.take("scales", integer, "an integer", default=d.scales),
        tikhonov_length_mm=t.take("tikhonov_length_mm", lengths_or_auto,
                                  'a number, "auto" or a list of them (mm)',
                                  default=d.tikhonov_length_mm),
        calibrate=t.take("calibrate", boolean, "true or false", default=d.calibrate),
        keep_stereo=t.take("keep_stereo", boolean, "true or false", default=d.keep_stereo),
        coupling=t.take("coupling", string, "a string", default=d.coupling),
        normalisation=t.take("normalisation", string, "a string", default=d.normalisation),
        max_fixed_point=t.take("max_fixed_point", integer, "an integer", default=d.max_fixed_point),
        prefilter_px=t.take("prefilter_px", number, "a number (px)", default=d.prefilter_px),
        edge_margin_px=t.take("edge_margin_px", number, "a number (px)", default=d.edge_margin_px),
        interpolation_order=t.take("interpolation_order", integer, "an integer (3 or 5)",
                                   default=d.interpolation_order),
        self_occlusion=t.take("self_occlusion", boolean, "true or false", default=d.self_occlusion),
        max_view_angle_deg=t.take("max_view_angle_deg", number, "a number (deg)",
                                  default=d.max_view_angle_deg))
    t.finish()
    check(t, "name", m.name, m.name in METHOD_NAMES, "one of " + ", ".join(map(json.dumps, METHOD_NAMES)))
    check(t, "levels", m.levels, m.levels == AUTO or m.levels >= 1, '>= 1 or "auto"')
    check(t, "start_levels", m.start_levels, m.start_levels >= 1, ">= 1")
    check(t, "scales", m.scales, m.scales >= 1, ">= 1")
    check(t, "tikhonov_length_mm", list(m.tikhonov_length_mm),
           all(v == AUTO or v > 0 for v in m.tikhonov_length_mm), '> 0 or "auto"')
    check(t, "normalisation", m.normalisation, m.normalisation in NORMALISATIONS,
           "one of " + ", ".join(map(json.dumps, NORMALISATIONS)))
    check(t, "coupling", m.coupling, m.coupling in COUPLINGS, " or ".join(map(json.dumps, COUPLINGS)))
    check(t, "max_fixed_point", m.max_fixed_point, m.max_fixed_point >= 1, ">= 1")
    check(t, "prefilter_px", m.prefilter_px, m.prefilter_px >= 0, ">= 0 (px; 0 = no prefilter)")
    check(t, "edge_margin_px", m.edge_margin_px, m.edge_margin_px >= 0, ">= 0 (px; 0 = no margin)")
    check(t, "interpolation_order", m.interpolation_order, m.interpolation_order in ORDERS,
          " or ".join(map(str, ORDERS)) + " (3 = cubic, 5 = quintic B-spline)")
    check(t, "max_view_angle_deg", m.max_view_angle_deg, 0 < m.max_view_angle_deg <= 90,
          "in (0, 90] (deg; 90 = no cut-off)")
    return m


def placed(geometry: Any) -> dict:
    """The keyword arguments ``roi`` and ``pose`` of :func:`cameras_table` for the raw
    ``[geometry]`` table: does it place the specimen without landmarks?"""
    kind = geometry.get("kind") if isinstance(geometry, dict) else None
    return {"roi": kind == "roi", "pose": kind == "cad" and geometry.get("pose") is not None}


def output_table(data: Any, source: Path, base: Path) -> OutputConfig:
    """The ``[output]`` table, checked (``dir`` relative to ``base``)."""
    t = Table(data, "[output]", source)
    out = t.take("dir", string, "a folder path (string)", default=DEFAULT_OUTPUT_DIR)
    t.finish()
    return OutputConfig(resolve_path(out, base))


def load_config(path: str | os.PathLike) -> Config:
    """Read and check a TOML configuration (schema in the module docstring).

    Raises
    ------
    ConfigFileNotFoundError
        If the configuration or a file it references does not exist (names the key).
    ConfigError
        On a TOML syntax error, an unknown key, a wrong type or value, a missing key.
    """
    source = Path(path)
    data = load_toml(source)
    base = source.resolve().parent
    top = Table(data, "", source)
    images = top.take("images", lambda v: v, "a table", required=True)
    cameras = top.take("cameras", lambda v: v, "a table", required=True)
    landmarks = top.take("landmarks", lambda v: v, "an array of tables")
    geometry = top.take("geometry", lambda v: v, "a table", required=True)
    method = top.take("method", lambda v: v, "a table", default={})
    output = top.take("output", lambda v: v, "a table", default={})
    top.finish()
    config = Config(images=images_table(images, source, base),
                    cameras=cameras_table(cameras, landmarks, source, base, **placed(geometry)),
                    geometry=geometry_table(geometry, source, base),
                    method=method_table(method, source),
                    output=output_table(output, source, base),
                    source=source.resolve())
    logger.debug("configuration %s: %s", source, config)
    return config
