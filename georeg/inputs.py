"""Python values to the command line's configuration objects, checked by its readers.

Each argument of :func:`georeg.measure` becomes the TOML table it stands for and goes
through the very reader of that table (:mod:`georeg_app.config.measure`), so a value is
checked once, by one implementation, and an error names the argument and the key::

    ConfigError: nominal: [geometry] kind: expected one of "rectangle", ..., got "disc"
    ConfigFileNotFoundError: images: [images] cam0: file not found: /data/left.tif
"""
from __future__ import annotations

import dataclasses
import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from fesdic_core.cameras.camera import Camera
from fesdic_core.imaging.image import Image

from georeg_app.config.measure import (CamerasConfig, GeometryConfig, ImagesConfig,
                                       MethodConfig, cameras_table, geometry_table, images_table, method_table)
from georeg_app.config.toml_schema import ConfigError
from georeg_app.inputs.cad import CAD_SUFFIXES
from georeg_app.inputs.cameras import temporary_cameras

__all__ = ["PathLike", "plain", "camera_source", "images_config", "cameras_config",
           "geometry_config", "method_config"]

PathLike = str | os.PathLike


def plain(value: Any) -> Any:
    """A Python value as TOML would give it: paths as strings, tuples and arrays as lists,
    numpy scalars as Python numbers, tables recursively."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value


def _is_path(value: Any) -> bool:
    return isinstance(value, (str, os.PathLike))


def _pair(value: Any, name: str, what: str) -> tuple:
    if _is_path(value) or isinstance(value, (np.ndarray, Image, Camera)) \
            or not isinstance(value, Sequence) or len(value) != 2:
        n = 1 if not isinstance(value, Sequence) or _is_path(value) else len(value)
        raise ValueError(f"{name}: a stereo pair needs 2 {what}, got {n}"
                         + ("" if n != 1 else f" ({_short(value)})"))
    return tuple(value)


def _short(value: Any) -> str:
    text = repr(value) if not isinstance(value, np.ndarray) else f"an array of shape {value.shape}"
    return text if len(text) < 80 else text[:77] + "..."


def images_config(images: Any, method: MethodConfig, base: Path
                  ) -> tuple[ImagesConfig, tuple[Image, Image] | None]:
    """``images``, two paths or two 2-D arrays or two core ``Image`` objects, as the run's
    ``[images]`` and, for arrays and Images, the loaded pair (else None: read by the run)."""
    pair = _pair(images, "images", "images")
    if all(_is_path(p) for p in pair):
        return images_table({"cam0": plain(pair[0]), "cam1": plain(pair[1])}, Path("images"), base), None
    loaded = []
    for k, item in enumerate(pair):
        if isinstance(item, Image):
            loaded.append(item)
            continue
        if _is_path(item):
            raise ValueError(f"images: cam{k} is a path but cam{1 - k} is not; give two paths "
                             "or two arrays (or Images)")
        a = np.asarray(item)
        if a.ndim != 2 or a.size == 0 or not np.issubdtype(a.dtype, np.number):
            raise ValueError(f"images: cam{k}: expected a 2-D array of gray levels, got "
                             f"{_short(item)}" + (f" (shape {a.shape})" if a.ndim != 2 else ""))
        loaded.append(Image.from_array(a.astype(float), source=f"cam{k} (array)",
                                       prefilter_px=method.prefilter_px,
                                       order=method.interpolation_order))
    names = ImagesConfig(cam0=Path(loaded[0].source or "cam0 (in memory)"),
                         cam1=Path(loaded[1].source or "cam1 (in memory)"))
    return names, (loaded[0], loaded[1])


def camera_source(path: Path) -> str:
    """The ``[cameras]`` key of a calibration file, from its suffix and, for JSON and XML,
    its content: the project's JSON (``file``: ``{"cameras": [...]}``), ``opencv``
    (FileStorage .yml/.yaml, .xml ``<opencv_storage>``, or another JSON), ``dice`` (an XML
    ``<ParameterList>``), ``vic3d`` (.z3d, or another XML) or ``pyvale_csv`` (.csv)."""
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return "pyvale_csv"
    if suffix == ".z3d":
        return "vic3d"
    if suffix in (".yml", ".yaml"):
        return "opencv"
    if suffix == ".json":
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return "file"                      # its reader names what is wrong
        return "file" if isinstance(data, dict) and "cameras" in data else "opencv"
    if suffix == ".xml":
        try:
            root = next(ET.iterparse(path, events=("start",)))[1].tag
        except (OSError, ET.ParseError, StopIteration):
            return "vic3d"
        return {"ParameterList": "dice", "opencv_storage": "opencv"}.get(root, "vic3d")
    raise ValueError(f"cameras: {path}: unknown calibration file (expected .json, .yml, .yaml, "
                     ".xml, .z3d or .csv; or say which with source=)")


def cameras_config(cameras: Any, base: Path, source: str | None = None,
                   landmarks: Sequence[dict] | None = None,
                   geometry: GeometryConfig | None = None) -> CamerasConfig:
    """``cameras``, a calibration file or a pair of core ``Camera``s, as ``[cameras]``.

    ``source``: the ``[cameras]`` key (``file``, ``pyvale_csv``, ``opencv``, ``vic3d``,
    ``dice``) when the file's kind is not to be guessed (:func:`camera_source`);
    ``landmarks``: the ``[[landmarks]]`` tables (``xyz_mm``, ``cam0_px``, ``cam1_px``) that
    pose another tool's calibration; ``geometry``: the run's ``[geometry]``, which may place
    the specimen itself (``kind = "roi"``, or ``"cad"`` with a ``pose``: no landmarks needed).
    """
    if isinstance(cameras, CamerasConfig):
        return cameras
    raw = None if landmarks is None else plain(list(landmarks))
    if _is_path(cameras):
        path = Path(cameras)
        if source is None:
            resolved = path if path.is_absolute() else base / path
            source = camera_source(resolved) if resolved.is_file() else "file"
        placed_by = {} if geometry is None else {
            "roi": geometry.kind == "roi",
            "pose": geometry.kind == "cad" and getattr(geometry, "pose", None) is not None}
        return cameras_table({source: os.fspath(path)}, raw, Path("cameras"), base, **placed_by)
    pair = _pair(cameras, "cameras", "cameras")
    for k, cam in enumerate(pair):
        if not isinstance(cam, Camera):
            raise ValueError(f"cameras: cam{k}: expected a core Camera "
                             f"(fesdic_core.cameras.camera.Camera), got {_short(cam)}")
    if landmarks is not None or source is not None:
        raise ValueError("cameras: landmarks= and source= are for a calibration file; Camera "
                         "objects are used as they are")
    return temporary_cameras(pair)


def geometry_config(nominal: Any, base: Path) -> GeometryConfig:
    """``nominal``, a ``[geometry]``-like dict, a ``GeometryConfig``, or a mesh or CAD file
    (CAD by its suffix: IGES or STEP), as ``[geometry]``."""
    if isinstance(nominal, GeometryConfig):
        nominal = {f.name: getattr(nominal, f.name) for f in dataclasses.fields(nominal)
                   if getattr(nominal, f.name) is not None}
    elif _is_path(nominal):
        kind = "cad" if Path(nominal).suffix.lower() in CAD_SUFFIXES else "mesh"
        nominal = {"kind": kind, "file": nominal}
    elif not isinstance(nominal, dict):
        raise ConfigError(f"nominal: expected a [geometry]-like dict (kind = ...), a "
                          f"GeometryConfig or a mesh or CAD file, got {_short(nominal)}")
    return geometry_table(plain(nominal), Path("nominal"), base)


def method_config(options: dict, where: str = "method options") -> MethodConfig:
    """The ``[method]`` table of keyword options (None values left to their defaults)."""
    return method_table(plain({k: v for k, v in options.items() if v is not None}), Path(where))
