"""The keys of ``[geometry] kind = "roi"``: a specimen drawn on camera 0's reference image.

::

    [geometry]
    kind = "roi"
    polygon_px = [[420, 310], [1500, 300], [1510, 900], [430, 905]]   # x = column, y = row
    exclude_px = [[[900, 500], [1000, 500], [1000, 600], [900, 600]]]  # holes (optional)
    # mask = "roi.png"            # instead of the polygons: nonzero = specimen (camera 0's size)
    surface = "plane"             # "plane" (default) | "quadric" (z = f(x, y), gently curved)
    elements = 400                # approximate number of FE elements

No landmarks are needed: the surface is triangulated by the calibrated rig
(:mod:`georeg_app.inputs.roi`).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from georeg_app.config.toml_schema import Table, existing_file, string

__all__ = ["ROI_SURFACES", "RoiConfig", "take_roi"]

ROI_SURFACES = ("plane", "quadric")


@dataclasses.dataclass(frozen=True, eq=False)
class RoiConfig:
    """The region of interest: ``polygon`` (k, 2) px and ``exclude`` (holes), or ``mask``.

    ``surface``: the fitted surface, one of :data:`ROI_SURFACES`."""

    polygon: np.ndarray | None = None
    exclude: tuple[np.ndarray, ...] = ()
    mask: Path | None = None
    surface: str = "plane"

    @classmethod
    def of(cls, geometry: Any) -> RoiConfig:
        """The ROI of a ``GeometryConfig`` (its keys ``polygon_px``, ``exclude_px``, ``mask``,
        ``surface``), as arrays."""
        polygon = geometry.polygon_px
        return cls(polygon=None if polygon is None else np.array(polygon, dtype=float),
                   exclude=tuple(np.array(p, dtype=float) for p in geometry.exclude_px or ()),
                   mask=geometry.mask, surface=geometry.surface or "plane")


def _polygon(value: Any) -> np.ndarray:
    a = np.asarray(value, dtype=float) if isinstance(value, list) else None
    if a is None or a.ndim != 2 or a.shape[1] != 2 or len(a) < 3 or not np.all(np.isfinite(a)):
        raise ValueError(value)
    if abs(_area(a)) <= 0.0:
        raise ValueError(value)
    return a


def _polygons(value: Any) -> tuple[np.ndarray, ...]:
    if not isinstance(value, list):
        raise TypeError(value)
    return tuple(_polygon(v) for v in value)


def _area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


_POLYGON = "a list of at least 3 [x, y] pixel vertices enclosing an area"


def _rows(polygon: np.ndarray) -> tuple:
    return tuple(tuple(row) for row in polygon.tolist())


def take_roi(t: Table, kind: str, base: Path) -> dict:
    """Take the ROI keys of ``[geometry]`` (before ``t.finish()``): the keyword arguments of
    ``GeometryConfig`` they give (polygons as tuples of ``(x, y)``); empty unless kind "roi".

    Raises ConfigError naming the key: a key of the ROI with another kind, neither or both
    of ``polygon_px`` and ``mask``, a polygon that is not one, an unknown ``surface``.
    """
    polygon = t.take("polygon_px", _polygon, _POLYGON)
    exclude = t.take("exclude_px", _polygons, f"a list of polygons, each {_POLYGON}")
    mask = t.take("mask", string, "an image file path (string)")
    surface = t.take("surface", string, "a string")
    given = {k: v for k, v in (("polygon_px", polygon), ("exclude_px", exclude), ("mask", mask),
                               ("surface", surface)) if v is not None}
    if kind != "roi":
        for key in given:
            raise t.error(key, f'not used with kind = "{kind}"; remove it')
        return {}
    if (polygon is None) == (mask is None):
        raise t.error(None, 'kind = "roi" needs exactly one of `polygon_px` and `mask`, got '
                            + ("both" if polygon is not None else "neither"))
    if exclude is not None and mask is not None:
        raise t.error("exclude_px", "not used with `mask` (draw the holes in the mask); remove it")
    surface = "plane" if surface is None else surface
    if surface not in ROI_SURFACES:
        raise t.error("surface", "expected one of " + ", ".join(f'"{s}"' for s in ROI_SURFACES)
                      + f', got "{surface}"')
    return {"polygon_px": None if polygon is None else _rows(polygon),
            "exclude_px": None if exclude is None else tuple(_rows(p) for p in exclude),
            "mask": existing_file(t, "mask", mask, base), "surface": surface}
