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

import difflib
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

FEATURE_KINDS = ("box", "wedge", "half_cylinder")
NOMINAL_KINDS = ("quadrilateral", "cylinder")


class ConfigError(ValueError):
    """A configuration file is unusable; the message names the file, the table and the key."""


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
class _Table:
    """Keys of one TOML table, taken with type checks; what is left over is an unknown key."""

    def __init__(self, data: Any, where: str, source: Path):
        self.where, self.source = where, source
        if not isinstance(data, dict):
            raise ConfigError(f"{source}: {where}: expected a table")
        self.data, self.known = dict(data), []

    def take(self, key: str, convert: Callable[[Any], Any], what: str, default: Any = ...) -> Any:
        self.known.append(key)
        if key not in self.data:
            if default is ...:
                raise ConfigError(f"{self.source}: {self.where} {key}: missing required key")
            return default
        value = self.data.pop(key)
        try:
            return convert(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{self.source}: {self.where} {key}: expected {what}, "
                              f"got {value!r}") from None

    def finish(self) -> None:
        for key in self.data:
            close = difflib.get_close_matches(key, self.known, n=1, cutoff=0.5)
            hint = f" (did you mean {close[0]}?)" if close else f" (known: {', '.join(self.known)})"
            raise ConfigError(f"{self.source}: {self.where} {key}: unknown key{hint}")


def _number(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise TypeError
    return float(v)


def _positive(v: Any) -> float:
    if _number(v) <= 0:
        raise ValueError
    return float(v)


def _count(v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise TypeError
    return v


def _scales(v: Any) -> tuple[int, ...]:
    if not isinstance(v, list) or not v or any(isinstance(x, bool) or not isinstance(x, int) or x < 0
                                               for x in v):
        raise TypeError
    return tuple(v)


def _array(shape: tuple[int, ...]) -> Callable[[Any], np.ndarray]:
    def convert(v: Any) -> np.ndarray:
        a = np.array(v, dtype=object)
        if a.shape != shape:
            raise TypeError
        out = np.vectorize(_number, otypes=[float])(a)
        out.setflags(write=False)
        return out
    return convert


def _pair(convert: Callable[[Any], Any]) -> Callable[[Any], tuple]:
    def pair(v: Any) -> tuple:
        if not isinstance(v, list) or len(v) != 2:
            raise TypeError
        return tuple(convert(x) for x in v)
    return pair


def _names(v: Any) -> tuple[str, ...]:
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise TypeError
    return tuple(v)


def _file(table: _Table, key: str, base: Path) -> Path:
    value = table.take(key, lambda v: v if isinstance(v, str) else int("x"), "a file path (string)")
    path = (base / value).resolve()
    if not path.is_file():
        raise ConfigError(f"{table.source}: {table.where} {key}: file not found: {path}")
    return path


def _load(path: Path) -> dict:
    if not path.is_file():
        raise ConfigError(f"{path}: configuration file not found")
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None


def _tables(data: Any, where: str, source: Path) -> list:
    if not isinstance(data, list):
        raise ConfigError(f"{source}: {where}: expected an array of tables ([[...]])")
    return data


def _feature(item: Any, i: int, source: Path) -> Feature:
    t = _Table(item, f"[[features]][{i}]", source)
    name = t.take("name", lambda v: v if isinstance(v, str) else int("x"), "a string")
    kind = t.take("kind", lambda v: v if v in FEATURE_KINDS else int("x"),
                  f"one of {', '.join(FEATURE_KINDS)}")
    required = {"box": ("footprint_mm", "height_mm"), "wedge": ("line_mm", "half_width_mm"),
                "half_cylinder": ("line_mm", "radius_mm")}[kind]
    values = {key: t.take(key, conv, what, None) for key, conv, what in (
        ("footprint_mm", _array((4, 2)), "4 corners [x, y] (mm)"),
        ("height_mm", _positive, "a number > 0 (mm)"),
        ("line_mm", _array((2, 3)), "2 points [x, y, z] (mm)"),
        ("half_width_mm", _positive, "a number > 0 (mm)"),
        ("radius_mm", _positive, "a number > 0 (mm)"))}
    t.finish()
    for key in required:
        if values[key] is None:
            raise ConfigError(f"{source}: [[features]][{i}] {key}: missing required key (kind = {kind!r})")
    for key, value in values.items():
        if value is not None and key not in required:
            raise ConfigError(f"{source}: [[features]][{i}] {key}: not used with kind = {kind!r}")
    return Feature(name=name, kind=kind, **values)


def load_specimen(path: str | Path) -> Specimen:
    """Read ``specimen.toml`` (images, calibration, landmarks, features)."""
    source = Path(path).resolve()
    top = _Table(_load(source), "", source)
    base = source.parent
    images = _Table(top.take("images", dict, "a table"), "[images]", source)
    cam0, cam1 = _file(images, "cam0", base), _file(images, "cam1", base)
    images.finish()
    cameras = _Table(top.take("cameras", dict, "a table"), "[cameras]", source)
    csv = _file(cameras, "pyvale_csv", base)
    cameras.finish()
    landmarks = []
    for i, item in enumerate(_tables(top.take("landmarks", list, "[[landmarks]]"), "[[landmarks]]", source)):
        t = _Table(item, f"[[landmarks]][{i}]", source)
        landmarks.append(Landmark(t.take("xyz_mm", _array((3,)), "3 numbers (mm)"),
                                  t.take("cam0_px", _array((2,)), "2 numbers (px)"),
                                  t.take("cam1_px", _array((2,)), "2 numbers (px)")))
        t.finish()
    if len(landmarks) < 4:
        raise ConfigError(f"{source}: [[landmarks]]: at least 4 are needed, got {len(landmarks)}")
    features = tuple(_feature(item, i, source) for i, item in enumerate(
        _tables(top.take("features", list, "[[features]]"), "[[features]]", source)))
    top.finish()
    return Specimen(source, cam0, cam1, csv, tuple(landmarks), features)


def _nominal(item: Any, i: int, source: Path, specimen: Specimen) -> Nominal:
    where = f"[[nominal]][{i}]"
    t = _Table(item, where, source)
    name = t.take("name", lambda v: v if isinstance(v, str) else int("x"), "a string")
    kind = t.take("kind", lambda v: v if v in NOMINAL_KINDS else int("x"),
                  f"one of {', '.join(NOMINAL_KINDS)}")
    nominal = Nominal(
        name=name, kind=kind,
        elements=t.take("elements", _pair(_count), "2 integers >= 1"),
        spline_elements=t.take("spline_elements", _pair(_count), "2 integers >= 1", (1, 1)),
        levels=t.take("levels", _count, "an integer >= 1", 3),
        corners_mm=t.take("corners_mm", _array((4, 3)), "4 corners [x, y, z] (mm)", None),
        line_mm=t.take("axis_mm", _array((2, 3)), "2 points [x, y, z] (mm)", None),
        radius_mm=t.take("radius_mm", _positive, "a number > 0 (mm)", None),
        arc_deg=t.take("arc_deg", _positive, "a number > 0 (degrees)", None),
        holes=t.take("holes", _names, "a list of feature names", ()),
        hole_margin_mm=t.take("hole_margin_mm", _number, "a number (mm)", 1.0))
    t.finish()
    needs = {"quadrilateral": ("corners_mm",), "cylinder": ("line_mm", "radius_mm", "arc_deg")}[kind]
    for key in needs:
        if getattr(nominal, key) is None:
            raise ConfigError(f"{source}: {where} {key.replace('line_mm', 'axis_mm')}: missing "
                              f"required key (kind = {kind!r})")
    for hole in nominal.holes:
        specimen.feature(hole)
    fine = [s * 2 ** (nominal.levels - 1) for s in nominal.spline_elements]
    if any(e % f for e, f in zip(nominal.elements, fine)):
        raise ConfigError(f"{source}: {where} elements: {list(nominal.elements)} must be multiples of "
                          f"the finest spline level's {fine} (spline_elements x 2^(levels - 1))")
    return nominal


def load_face(path: str | Path) -> Face:
    """Read a face file and the specimen file it names."""
    source = Path(path).resolve()
    top = _Table(_load(source), "", source)
    face = _Table(top.take("face", dict, "a table"), "[face]", source)
    name = face.take("name", lambda v: v if isinstance(v, str) else int("x"), "a string")
    specimen = load_specimen(_file(face, "specimen", source.parent))
    occluders = face.take("occluders", _names, "a list of feature names", ())
    face.finish()
    for o in occluders:
        specimen.feature(o)
    nominals = tuple(_nominal(item, i, source, specimen) for i, item in enumerate(
        _tables(top.take("nominal", list, "[[nominal]]"), "[[nominal]]", source)))
    m = _Table(top.take("method", dict, "a table", {}), "[method]", source)
    d = Method()
    method = Method(
        scales=m.take("scales", _scales, "a list of integers >= 0", d.scales),
        max_fixed_point=m.take("max_fixed_point", _count, "an integer >= 1", d.max_fixed_point),
        max_iter=m.take("max_iter", _count, "an integer >= 1", d.max_iter),
        points_per_px=m.take("points_per_px", _positive, "a number > 0", d.points_per_px),
        visibility_margin_mm=m.take("visibility_margin_mm", _number, "a number (mm)",
                                    d.visibility_margin_mm))
    m.finish()
    if list(method.scales) != sorted(set(method.scales), reverse=True):
        raise ConfigError(f"{source}: [method] scales: must decrease (coarse to fine), got "
                          f"{list(method.scales)}")
    a = _Table(top.take("analysis", dict, "a table", {}), "[analysis]", source)
    analysis = Analysis(
        flatness_polygon_mm=a.take("flatness_polygon_mm", lambda v: _array((len(v), 2))(v),
                                   "a list of [x, y] (mm)", None),
        ring_feature=a.take("ring_feature", lambda v: v if isinstance(v, str) else int("x"),
                            "a feature name", None),
        ring_mm=a.take("ring_mm", _pair(_number), "2 numbers (mm)", (1.5, 6.0)),
        edge_margin_mm=a.take("edge_margin_mm", _number, "a number (mm)", 0.0))
    a.finish()
    if analysis.ring_feature is not None:
        specimen.feature(analysis.ring_feature)
    top.finish()
    return Face(source, name, specimen, occluders, nominals, method, analysis)
