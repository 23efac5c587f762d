"""The configuration of the Stereo DIC Challenge example: the specimen and its analysis.

``specimen.toml`` holds what the specimen is: the stereo pair, the pyvale calibration, the
landmarks that place it (world frame: mm, base plane z = 0; picked by pick_landmarks.py)
and the raised features' dimensions (make_specimen_cad.py builds the CAD from them).
``analysis.toml`` names the specimen file and holds where analyse_part.py takes the figures:
the base plate's region and flatness polygon, the ring around a feature that heights are
measured from, the block top's region, each bar's axis, arc and length.
Relative paths are resolved against the folder of the file. Unknown keys, wrong types and
missing keys are errors that name the file, the table and the key (:class:`ConfigError`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from georeg_app.config.toml_schema import (ConfigError, Table, array, existing_file, load_toml,
                                           number, one_of, pair, positive, string, strings, table,
                                           table_list)

__all__ = ["ConfigError", "Landmark", "Feature", "Specimen", "Plate", "Bar", "Analysis",
           "load_specimen", "load_analysis"]

FEATURE_KINDS = ("box", "wedge", "half_cylinder")


@dataclass(frozen=True, eq=False)
class Landmark:
    """A world point (mm) and where each camera sees it (px)."""

    xyz_mm: np.ndarray
    cam0_px: np.ndarray
    cam1_px: np.ndarray


@dataclass(frozen=True, eq=False)
class Feature:
    """A raised feature of the specimen as a convex solid (world frame, mm).

    kind "box": ``footprint_mm`` (4, 2) corners x [0, ``height_mm``];
    kind "wedge": ridge segment ``line_mm`` (2, 3), faces down to z = 0 at ``half_width_mm``;
    kind "half_cylinder": axis segment ``line_mm`` (2, 3) and ``radius_mm``, cut at z = 0.
    """

    name: str
    kind: str
    footprint_mm: np.ndarray | None = None
    height_mm: float | None = None
    line_mm: np.ndarray | None = None
    half_width_mm: float | None = None
    radius_mm: float | None = None


@dataclass(frozen=True)
class Specimen:
    source: Path
    cam0: Path
    cam1: Path
    pyvale_csv: Path
    landmarks: tuple[Landmark, ...]
    features: tuple[Feature, ...]

    def feature(self, name: str) -> Feature:
        for f in self.features:
            if f.name == name:
                return f
        raise ConfigError(f"{self.source}: no [[features]] named {name!r} "
                          f"(known: {', '.join(f.name for f in self.features)})")


@dataclass(frozen=True, eq=False)
class Plate:
    """Where the base plate's figures are taken: inside ``corners_mm`` (4, 3), off the
    footprints of the ``holes`` features by more than ``hole_margin_mm``; flatness in
    ``flatness_polygon_mm`` (m, 2); heights above the plate ``ring_mm`` (2,) from a footprint
    (the block's, ``ring_feature``, and each bar's)."""

    corners_mm: np.ndarray
    holes: tuple[str, ...]
    hole_margin_mm: float
    flatness_polygon_mm: np.ndarray | None
    ring_feature: str | None
    ring_mm: tuple[float, float]


@dataclass(frozen=True, eq=False)
class Bar:
    """Where a bar's figures are taken: ``arc_deg`` about the crest of the axis segment
    ``axis_mm`` (2, 3), over its length; ``radius_mm`` starts the cylinder fit. ``name`` is
    both a measured face and one of the specimen's [[features]] (its footprint: the ring)."""

    name: str
    axis_mm: np.ndarray
    radius_mm: float
    arc_deg: float


@dataclass(frozen=True, eq=False)
class Analysis:
    """The analysis configuration (``analysis.toml``): world frame, mm, base plane z = 0.

    ``block_top_mm`` (4, 3): the block top's region (inset from its edges; z the nominal
    height, which make_specimen_cad.py gives the CAD's block)."""

    source: Path
    specimen: Specimen
    plate: Plate
    block_top_mm: np.ndarray
    bars: tuple[Bar, ...]


# --------------------------------------------------------------------------- reading
# (the generic machinery, one table at a time, is georeg_app.config.toml_schema's)

def _file(table: Table, key: str, base: Path) -> Path:
    """The required existing file ``key`` (relative to ``base``), resolved."""
    value = table.take(key, string, "a file path (string)", required=True)
    return existing_file(table, key, value, base).resolve()


def _feature_name(table: Table, key: str, name: str, specimen: Specimen) -> str:
    """``name``, which must be one of the specimen's [[features]]."""
    known = [f.name for f in specimen.features]
    if name not in known:
        raise table.error(key, f"no [[features]] named {name!r} in {specimen.source.name} "
                               f"(known: {', '.join(known)})")
    return name


def _feature(item: Any, i: int, source: Path) -> Feature:
    t = Table(item, f"[[features]][{i}]", source)
    name = t.take("name", string, "a string", required=True)
    kind = t.take("kind", one_of(FEATURE_KINDS), f"one of {', '.join(FEATURE_KINDS)}",
                  required=True)
    required = {"box": ("footprint_mm", "height_mm"), "wedge": ("line_mm", "half_width_mm"),
                "half_cylinder": ("line_mm", "radius_mm")}[kind]
    values = {key: t.take(key, conv, what) for key, conv, what in (
        ("footprint_mm", array((4, 2)), "4 corners [x, y] (mm)"),
        ("height_mm", positive, "a number > 0 (mm)"),
        ("line_mm", array((2, 3)), "2 points [x, y, z] (mm)"),
        ("half_width_mm", positive, "a number > 0 (mm)"),
        ("radius_mm", positive, "a number > 0 (mm)"))}
    t.finish()
    for key in required:
        if values[key] is None:
            raise t.error(key, f"missing required key (kind = {kind!r})")
    for key, value in values.items():
        if value is not None and key not in required:
            raise t.error(key, f"not used with kind = {kind!r}")
    return Feature(name=name, kind=kind, **values)


def load_specimen(path: str | Path) -> Specimen:
    """Read ``specimen.toml`` (images, calibration, landmarks, features)."""
    source = Path(path).resolve()
    top = Table(load_toml(source), "", source)
    base = source.parent
    images = Table(top.take("images", table, "a table", required=True), "[images]", source)
    cam0, cam1 = _file(images, "cam0", base), _file(images, "cam1", base)
    images.finish()
    cameras = Table(top.take("cameras", table, "a table", required=True), "[cameras]", source)
    csv = _file(cameras, "pyvale_csv", base)
    cameras.finish()
    landmarks = []
    for i, item in enumerate(top.take("landmarks", table_list, "[[landmarks]]", required=True)):
        t = Table(item, f"[[landmarks]][{i}]", source)
        landmarks.append(Landmark(t.take("xyz_mm", array((3,)), "3 numbers (mm)", required=True),
                                  t.take("cam0_px", array((2,)), "2 numbers (px)", required=True),
                                  t.take("cam1_px", array((2,)), "2 numbers (px)", required=True)))
        t.finish()
    if len(landmarks) < 4:
        raise ConfigError(f"{source}: [[landmarks]]: at least 4 are needed, got {len(landmarks)}")
    features = tuple(_feature(item, i, source) for i, item in enumerate(
        top.take("features", table_list, "[[features]]", required=True)))
    top.finish()
    return Specimen(source, cam0, cam1, csv, tuple(landmarks), features)


def _bar(item: Any, i: int, source: Path, specimen: Specimen) -> Bar:
    t = Table(item, f"[[bars]][{i}]", source)
    bar = Bar(name=_feature_name(t, "name", t.take("name", string, "a string", required=True), specimen),
              axis_mm=t.take("axis_mm", array((2, 3)), "2 points [x, y, z] (mm)", required=True),
              radius_mm=t.take("radius_mm", positive, "a number > 0 (mm)", required=True),
              arc_deg=t.take("arc_deg", positive, "a number > 0 (degrees)", required=True))
    t.finish()
    return bar


def load_analysis(path: str | Path) -> Analysis:
    """Read the analysis file and the specimen file it names."""
    source = Path(path).resolve()
    top = Table(load_toml(source), "", source)
    specimen = load_specimen(_file(top, "specimen", source.parent))
    b = Table(top.take("base", table, "a table", required=True), "[base]", source)
    plate = Plate(
        corners_mm=b.take("corners_mm", array((4, 3)), "4 corners [x, y, z] (mm)", required=True),
        holes=b.take("holes", strings, "a list of feature names", default=()),
        hole_margin_mm=b.take("hole_margin_mm", number, "a number (mm)", default=1.0),
        flatness_polygon_mm=b.take("flatness_polygon_mm", lambda v: array((len(v), 2))(v),
                                   "a list of [x, y] (mm)"),
        ring_feature=b.take("ring_feature", string, "a feature name"),
        ring_mm=b.take("ring_mm", pair(number), "2 numbers (mm)", default=(1.5, 6.0)))
    b.finish()
    for name in plate.holes:
        _feature_name(b, "holes", name, specimen)
    if plate.ring_feature is not None:
        _feature_name(b, "ring_feature", plate.ring_feature, specimen)
    t = Table(top.take("block_top", table, "a table", required=True), "[block_top]", source)
    block_top = t.take("corners_mm", array((4, 3)), "4 corners [x, y, z] (mm)", required=True)
    t.finish()
    bars = tuple(_bar(item, i, source, specimen) for i, item in enumerate(
        top.take("bars", table_list, "[[bars]]", default=[])))
    top.finish()
    return Analysis(source, specimen, plate, block_top, bars)
