"""Synthetic specimens with a known surface ``z = height(x, y)``: plates, twisted or flat.

A :class:`Specimen` is the truth that the renderer (:mod:`fesdic_core.synthetic.render`)
paints and that a measurement is compared with (:mod:`fesdic_core.synthetic.accuracy`):
its height and gradient functions, its outline (length, width, a central hole) and its
speckle size.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import numpy as np

__all__ = ["Specimen", "twisted_plate", "flat_plate", "cylindrical_panel", "HeightFunction",
           "GradientFunction", "MaterialFunction"]

HeightFunction = Callable[[np.ndarray, np.ndarray], np.ndarray]
GradientFunction = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
MaterialFunction = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _flat(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.zeros(np.broadcast(x, y).shape)


def _flat_gradient(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return _flat(x, y), _flat(x, y)


@dataclass(frozen=True)
class Specimen:
    """Speckled plate centred at the world origin, nominal plane ``z = 0``.

    x runs along ``length_mm``, y along ``width_mm``; the actual surface is
    ``z = height(x, y)``; an optional central through hole shows the background.
    ``texture`` (x, y) -> gray, if given, replaces the seeded speckle. ``material`` (x, y) ->
    bool, if given, is the plate's outline inside its ``length_mm x width_mm`` rectangle
    (True where there is material): any outline and cut-outs, beside the central hole.
    """

    length_mm: float
    width_mm: float
    hole_radius_mm: float | None = None
    height: HeightFunction = _flat
    height_gradient: GradientFunction = _flat_gradient
    speckle_mm: float = 0.3
    seed: int = 0
    texture: HeightFunction | None = field(default=None, compare=False)
    material: MaterialFunction | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        for name in ("length_mm", "width_mm", "speckle_mm"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"Specimen.{name} must be a positive number, got {value!r}")
        r = self.hole_radius_mm
        if r is not None and not (0 < r < 0.5 * min(self.length_mm, self.width_mm)):
            raise ValueError(
                f"Specimen.hole_radius_mm must lie in (0, {0.5 * min(self.length_mm, self.width_mm)}), got {r!r}"
            )
        if not (callable(self.height) and callable(self.height_gradient)):
            raise ValueError("Specimen.height and Specimen.height_gradient must be callables (x, y) -> ...")

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """True where ``(x, y)`` (mm) is material: inside the plate, outside the hole."""
        inside = (np.abs(x) <= 0.5 * self.length_mm) & (np.abs(y) <= 0.5 * self.width_mm)
        if self.hole_radius_mm is not None:
            inside &= x * x + y * y >= self.hole_radius_mm**2
        if self.material is not None:
            inside &= np.asarray(self.material(x, y), bool)
        return inside


def _twist_height(x, y, k, waviness_mm, view_length_mm, width_mm):
    z = k * x * y
    if waviness_mm:
        z = z + waviness_mm * np.cos(np.pi / view_length_mm * x) * np.cos(np.pi / width_mm * y)
    return z


def _twist_gradient(x, y, k, waviness_mm, view_length_mm, width_mm):
    dz_dx, dz_dy = k * y, k * x
    if waviness_mm:
        ax, ay = np.pi / view_length_mm, np.pi / width_mm
        cx, sx, cy, sy = np.cos(ax * x), np.sin(ax * x), np.cos(ay * y), np.sin(ay * y)
        dz_dx = dz_dx - waviness_mm * ax * sx * cy
        dz_dy = dz_dy - waviness_mm * ay * cx * sy
    return dz_dx, dz_dy


def twisted_plate(
    length_mm: float,
    width_mm: float,
    corner_mm: float = 0.5,
    hole_radius_mm: float | None = None,
    waviness_mm: float = 0.0,
    view_length_mm: float | None = None,
    speckle_mm: float = 0.3,
    seed: int = 0,
) -> Specimen:
    """Twisted plate ``z = k x y + a cos(pi x / Lv) cos(pi y / W)``.

    ``k = corner_mm / (Lv/2 * W/2)`` puts ``corner_mm`` at the corners
    ``(+-Lv/2, +-W/2)`` of the viewed central part of length ``Lv =
    view_length_mm`` (default: the whole length), where the waviness term of
    amplitude ``a = waviness_mm`` (a central bump) vanishes.
    """
    view = length_mm if view_length_mm is None else view_length_mm
    if not (0 < view <= length_mm):
        raise ValueError(f"view_length_mm must lie in (0, length_mm={length_mm}], got {view_length_mm!r}")
    params = dict(
        k=corner_mm / (0.25 * view * width_mm),
        waviness_mm=waviness_mm,
        view_length_mm=view,
        width_mm=width_mm,
    )
    return Specimen(
        length_mm=length_mm,
        width_mm=width_mm,
        hole_radius_mm=hole_radius_mm,
        height=partial(_twist_height, **params),
        height_gradient=partial(_twist_gradient, **params),
        speckle_mm=speckle_mm,
        seed=seed,
    )


def flat_plate(length_mm: float, width_mm: float, hole_radius_mm: float | None = None, **kwargs) -> Specimen:
    """Flat plate ``z = 0`` (see :class:`Specimen` for the keyword arguments)."""
    return Specimen(length_mm=length_mm, width_mm=width_mm, hole_radius_mm=hole_radius_mm, **kwargs)


def _cylinder_height(x, y, radius_mm):
    return np.sqrt(radius_mm ** 2 - x * x) - radius_mm + 0.0 * y


def _cylinder_gradient(x, y, radius_mm):
    return -x / np.sqrt(radius_mm ** 2 - x * x), 0.0 * x * y


def cylindrical_panel(length_mm: float, width_mm: float, radius_mm: float, **kwargs) -> Specimen:
    """Cylindrical panel ``z = sqrt(R^2 - x^2) - R``: its axis along y, its crown at the origin
    towards the cameras (``z <= 0`` elsewhere), ``R = radius_mm > length_mm / 2``; keyword
    arguments as :class:`Specimen` (``material`` for an outline, ``hole_radius_mm``, ...)."""
    if not radius_mm > 0.5 * length_mm:
        raise ValueError(f"cylindrical_panel: radius_mm must exceed length_mm / 2 = "
                         f"{0.5 * length_mm:g}, got {radius_mm!r}")
    return Specimen(length_mm=length_mm, width_mm=width_mm,
                    height=partial(_cylinder_height, radius_mm=float(radius_mm)),
                    height_gradient=partial(_cylinder_gradient, radius_mm=float(radius_mm)),
                    **kwargs)
