"""The configuration of the Stereo DIC Challenge example: the specimen and one file per face.

``specimen.toml`` holds what the faces share: the stereo pair, the pyvale calibration, the
landmarks that place the specimen (world frame: mm, base plane z = 0) and the raised
features (the solids that hide parts of the base from a camera). Each face file
(``base.toml``, ``block_top.toml``, ``cylinder_h.toml``, ``cylinder_v.toml``) names its
nominal surface(s), the features that may hide it, the method and the analysis region.
Relative paths are resolved against the folder of the file. Unknown keys, wrong types and
missing keys are errors that name the file, the table and the key (:class:`ConfigError`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from georeg_app.toml_schema import (ConfigError, Table, array, count, existing_file, integer,
                                    load_toml, number, one_of, pair, positive, string, strings,
                                    table, table_list)

__all__ = ["ConfigError", "MAX_LEVELS", "Landmark", "Feature", "Specimen", "Nominal", "Method",
           "Analysis", "Face", "load_specimen", "load_face"]

FEATURE_KINDS = ("box", "wedge", "half_cylinder")
NOMINAL_KINDS = ("quadrilateral", "cylinder")
#: spline levels of a nominal at most (each one doubles the spline elements)
MAX_LEVELS = 20


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
class Nominal:
    """One nominal surface of a face: a quadrilateral (4 corners) or a cylinder (axis, radius).

    ``elements`` are the FE elements (Q9) along (u, v); ``spline_elements`` the elements of
    the coarsest spline level; ``levels`` the number of spline levels (each one refines the
    previous one dyadically). ``holes`` are features cut out of the FE mesh.
    """

    name: str
    kind: str
    elements: tuple[int, int]
    spline_elements: tuple[int, int]
    levels: int
    corners_mm: np.ndarray | None = None
    line_mm: np.ndarray | None = None
    radius_mm: float | None = None
    arc_deg: float | None = None
    holes: tuple[str, ...] = ()
    hole_margin_mm: float = 1.0


@dataclass(frozen=True)
class Method:
    scales: tuple[int, ...] = (3, 2, 1, 0)
    max_fixed_point: int = 6
    max_iter: int = 20
    points_per_px: float = 1.0
    visibility_margin_mm: float = 0.5


@dataclass(frozen=True, eq=False)
class Analysis:
    """Where the figures of merit are taken (world frame, mm)."""

    flatness_polygon_mm: np.ndarray | None = None
    ring_feature: str | None = None
    ring_mm: tuple[float, float] = (1.5, 6.0)
    edge_margin_mm: float = 0.0


@dataclass(frozen=True)
class Face:
    source: Path
    name: str
    specimen: Specimen
    occluders: tuple[str, ...]
    nominals: tuple[Nominal, ...]
    method: Method
    analysis: Analysis


# --------------------------------------------------------------------------- reading
# (the generic machinery, one table at a time, is georeg_app.toml_schema's)

def _scales(v: Any) -> tuple[int, ...]:
    """A non-empty list of integers >= 0."""
    if not isinstance(v, list) or not v or any(integer(x) < 0 for x in v):
        raise TypeError
    return tuple(v)


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


def _nominal(item: Any, i: int, source: Path, specimen: Specimen) -> Nominal:
    t = Table(item, f"[[nominal]][{i}]", source)
    name = t.take("name", string, "a string", required=True)
    kind = t.take("kind", one_of(NOMINAL_KINDS), f"one of {', '.join(NOMINAL_KINDS)}",
                  required=True)
    nominal = Nominal(
        name=name, kind=kind,
        elements=t.take("elements", pair(count), "2 integers >= 1", required=True),
        spline_elements=t.take("spline_elements", pair(count), "2 integers >= 1", default=(1, 1)),
        levels=t.take("levels", count, "an integer >= 1", default=3),
        corners_mm=t.take("corners_mm", array((4, 3)), "4 corners [x, y, z] (mm)"),
        line_mm=t.take("axis_mm", array((2, 3)), "2 points [x, y, z] (mm)"),
        radius_mm=t.take("radius_mm", positive, "a number > 0 (mm)"),
        arc_deg=t.take("arc_deg", positive, "a number > 0 (degrees)"),
        holes=t.take("holes", strings, "a list of feature names", default=()),
        hole_margin_mm=t.take("hole_margin_mm", number, "a number (mm)", default=1.0))
    t.finish()
    needs = {"quadrilateral": ("corners_mm",), "cylinder": ("line_mm", "radius_mm", "arc_deg")}[kind]
    for key in needs:
        if getattr(nominal, key) is None:
            raise t.error(key.replace("line_mm", "axis_mm"), f"missing required key (kind = {kind!r})")
    for hole in nominal.holes:
        _feature_name(t, "holes", hole, specimen)
    if nominal.levels > MAX_LEVELS:
        raise t.error("levels", f"must be <= {MAX_LEVELS} (each level doubles the spline "
                                f"elements), got {nominal.levels}")
    fine = [s * 2 ** (nominal.levels - 1) for s in nominal.spline_elements]
    if any(e % f for e, f in zip(nominal.elements, fine)):
        raise t.error("elements", f"{list(nominal.elements)} must be multiples of the finest "
                                  f"spline level's {fine} (spline_elements x 2^(levels - 1))")
    return nominal


def load_face(path: str | Path) -> Face:
    """Read a face file and the specimen file it names."""
    source = Path(path).resolve()
    top = Table(load_toml(source), "", source)
    face = Table(top.take("face", table, "a table", required=True), "[face]", source)
    name = face.take("name", string, "a string", required=True)
    specimen = load_specimen(_file(face, "specimen", source.parent))
    occluders = face.take("occluders", strings, "a list of feature names", default=())
    face.finish()
    for o in occluders:
        _feature_name(face, "occluders", o, specimen)
    nominals = tuple(_nominal(item, i, source, specimen) for i, item in enumerate(
        top.take("nominal", table_list, "[[nominal]]", required=True)))
    m = Table(top.take("method", table, "a table", default={}), "[method]", source)
    d = Method()
    method = Method(
        scales=m.take("scales", _scales, "a list of integers >= 0", default=d.scales),
        max_fixed_point=m.take("max_fixed_point", count, "an integer >= 1",
                               default=d.max_fixed_point),
        max_iter=m.take("max_iter", count, "an integer >= 1", default=d.max_iter),
        points_per_px=m.take("points_per_px", positive, "a number > 0", default=d.points_per_px),
        visibility_margin_mm=m.take("visibility_margin_mm", number, "a number (mm)",
                                    default=d.visibility_margin_mm))
    m.finish()
    if list(method.scales) != sorted(set(method.scales), reverse=True):
        raise m.error("scales", f"must decrease (coarse to fine), got {list(method.scales)}")
    a = Table(top.take("analysis", table, "a table", default={}), "[analysis]", source)
    analysis = Analysis(
        flatness_polygon_mm=a.take("flatness_polygon_mm", lambda v: array((len(v), 2))(v),
                                   "a list of [x, y] (mm)"),
        ring_feature=a.take("ring_feature", string, "a feature name"),
        ring_mm=a.take("ring_mm", pair(number), "2 numbers (mm)", default=(1.5, 6.0)),
        edge_margin_mm=a.take("edge_margin_mm", number, "a number (mm)", default=0.0))
    a.finish()
    if analysis.ring_feature is not None:
        _feature_name(a, "ring_feature", analysis.ring_feature, specimen)
    top.finish()
    return Face(source, name, specimen, occluders, nominals, method, analysis)
