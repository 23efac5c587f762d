"""The verdict of a shape measurement: trusted, or why not.

A measurement is trusted only if, at the finest scale, the gray-level residual is
consistent with the images' own noise (:mod:`fesdic_core.imaging.noise`), the shape stayed
bounded and the fixed point stagnated (:func:`judge`); a shape that leaves its bounds at a
coarse scale stops the measurement there (:class:`ShapeDivergedError`).
"""
from __future__ import annotations

from typing import Protocol

import numpy as np

from fesdic_core.errors import FesdicCoreError
from fesdic_core.shape.settings import ScaleReport

__all__ = ["ShapeDivergedError", "VerdictSettings", "judge"]


class VerdictSettings(Protocol):
    """What the verdict reads of a measurement's settings: those of the shape
    (:class:`~fesdic_core.shape.settings.MeasurementSettings`) or of a displacement
    (:class:`~fesdic_core.displacement.driver.DisplacementSettings`)."""

    @property
    def consistency_factor(self) -> float:
        """The final residual may be at most this many times the noise floor."""
        ...

    @property
    def max_shape_fraction(self) -> float:
        """The correction may reach at most this fraction of the mesh's size."""
        ...


class ShapeDivergedError(FesdicCoreError, RuntimeError):
    """The shape left its bounds at a coarse scale: the next scale is not started (its pixel
    quadrature would follow a surface metres wide)."""


def _diverged(q: np.ndarray, nodes: np.ndarray, settings: VerdictSettings) -> str | None:
    """Why the correction ``q`` is unbounded (``max_shape_fraction`` of the mesh), or None."""
    size = float(np.linalg.norm(np.ptp(nodes, axis=0)))
    largest = float(np.max(np.abs(q))) if q.size else 0.0
    if not np.isfinite(largest) or largest > settings.max_shape_fraction * size:
        return (f"the shape diverged: a correction of {largest:.3g} mm, more than "
                f"{settings.max_shape_fraction:g} of the mesh size ({size:.3g} mm)")
    return None


def judge(residual_percent: float, noise_percent: float, q: np.ndarray, nodes: np.ndarray,
          finest: ScaleReport, settings: VerdictSettings) -> str | None:
    """Why a measurement cannot be trusted, or None (see the module docstring)."""
    if not np.isfinite(residual_percent):
        return "no integration point is seen by both cameras at the finest scale"
    diverged = _diverged(q, nodes, settings)
    if diverged is not None:
        return diverged
    ratio = residual_percent / noise_percent if noise_percent > 0 else np.inf
    if not ratio <= settings.consistency_factor:
        return (f"the residual {residual_percent:.3g}% is {ratio:.3g} times the {noise_percent:.3g}% "
                f"that the image noise explains (at most {settings.consistency_factor:g}): the "
                "images do not match the surface and cameras (wrong or swapped cameras, wrong "
                "poses or specimen, a wrong minimum, or a regularization too strong for the field)")
    if not finest.converged:
        what = "Gauss-Newton" if not finest.shape_converged else "fixed point"
        return (f"the {what} did not stagnate at the finest scale (scale {finest.scale}) "
                "within its iteration limit")
    return None
