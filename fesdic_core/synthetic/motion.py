"""Known motions of a synthetic specimen, and where a displaced surface meets the rays.

A motion maps the material points ``X`` (n, 3) of the undeformed surface to their
displacements ``u`` (n, 3) mm; the renderer paints each point's texture at ``X + u``
(:func:`intersect_displaced`), so a deformed pair has a known displacement field.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from fesdic_core.synthetic.rays import intersect_surface
from fesdic_core.synthetic.specimen import Specimen

logger = logging.getLogger(__name__)

__all__ = ["Motion", "RigidMotion", "BendingMotion", "StretchMotion", "HeightMotion",
           "intersect_displaced"]

#: a displacement of the specimen's material points: ``X`` (n, 3) on the undeformed surface
#: ``z = height(x, y)`` (mm) -> ``u`` (n, 3) mm; the point and its paint move to ``X + u``
Motion = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class RigidMotion:
    """``u(X) = R (X - centre) + centre + translation - X``; ``R`` of the rotation vector
    ``rvec`` (rad, Rodrigues)."""

    translation_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rvec: tuple[float, float, float] = (0.0, 0.0, 0.0)
    centre_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __call__(self, X: np.ndarray) -> np.ndarray:
        R = cv2.Rodrigues(np.asarray(self.rvec, float).reshape(3, 1))[0]
        c = np.asarray(self.centre_mm, float)
        Y = np.asarray(X, float) - c
        moved = Y[:, :1] * R[:, 0] + Y[:, 1:2] * R[:, 1] + Y[:, 2:] * R[:, 2]   # R Y, row-wise
        return moved - Y + np.asarray(self.translation_mm, float)


@dataclass(frozen=True)
class BendingMotion:
    """Out-of-plane bending ``u = (0, 0, deflection (2 x / span)**2)``: a parabola along x,
    zero at ``x = 0`` and ``deflection_mm`` at ``x = +-span_mm / 2``."""

    deflection_mm: float
    span_mm: float

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, float)
        u = np.zeros_like(X)
        u[:, 2] = self.deflection_mm * (2.0 * X[:, 0] / self.span_mm) ** 2
        return u


@dataclass(frozen=True)
class StretchMotion:
    """Uniform in-plane stretch along x: ``u = (strain (x - centre_x), 0, 0)`` (engineering
    strain; the Green-Lagrange strain is ``strain + strain**2 / 2``)."""

    strain: float
    centre_x_mm: float = 0.0

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, float)
        u = np.zeros_like(X)
        u[:, 0] = self.strain * (X[:, 0] - self.centre_x_mm)
        return u


@dataclass(frozen=True)
class HeightMotion:
    """Out-of-plane ``u = (0, 0, height(x, y))`` of a flat specimen's points: its paint moved
    onto the surface ``z = height(x, y)`` of another specimen (e.g. ``twisted_plate(...).height``:
    the flat plate, then the same paint twisted and wavy)."""

    height: Callable[[np.ndarray, np.ndarray], np.ndarray]

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, float)
        u = np.zeros_like(X)
        u[:, 2] = self.height(X[:, 0], X[:, 1])
        return u


def intersect_displaced(specimen: Specimen, motion: Motion, origins: np.ndarray,
                        directions: np.ndarray, tol_mm: float = 1e-10, max_iter: int = 30,
                        step_mm: float = 1e-4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Material points ``(x, y)`` whose displaced position lies on the rays, and the ray
    parameters ``lam``: ``phi(x, y) = origins + lam directions`` with
    ``phi(x, y) = X + motion(X)``, ``X = (x, y, height(x, y))``.

    Vectorised Newton on the three unknowns ``(x, y, lam)``, started from the undeformed
    surface (:func:`intersect_surface`); ``dphi/dx`` and ``dphi/dy`` by central
    differences of ``step_mm`` (they only steer Newton: the converged point satisfies the
    equation to ``tol_mm``). Rays not converged get NaN.
    """
    o = np.broadcast_to(np.asarray(origins, float), np.shape(directions))
    d = np.asarray(directions, float)

    def phi(x, y):
        X = np.column_stack([x, y, specimen.height(x, y)])
        return X + np.asarray(motion(X), float)

    lam = intersect_surface(specimen, o, d)
    x, y = o[:, 0] + lam * d[:, 0], o[:, 1] + lam * d[:, 1]
    active = np.isfinite(lam)
    for _ in range(max_iter):
        F = phi(x[active], y[active]) - o[active] - lam[active, None] * d[active]
        if not np.max(np.abs(F), initial=0.0) > tol_mm:
            break
        xa, ya = x[active], y[active]
        a = (phi(xa + step_mm, ya) - phi(xa - step_mm, ya)) / (2.0 * step_mm)      # dphi/dx
        b = (phi(xa, ya + step_mm) - phi(xa, ya - step_mm)) / (2.0 * step_mm)      # dphi/dy
        c, r = -d[active], -F                                      # [a b c] delta = r (Cramer)
        bc = np.cross(b, c)
        with np.errstate(all="ignore"):
            det = np.einsum("ij,ij->i", a, bc)
            x[active] += np.einsum("ij,ij->i", r, bc) / det
            y[active] += np.einsum("ij,ij->i", a, np.cross(r, c)) / det
            lam[active] += np.einsum("ij,ij->i", r, np.cross(a, b)) / det
        active &= np.isfinite(lam)
    F = phi(x, y) - o - lam[:, None] * d
    bad = ~(np.max(np.abs(F), axis=1) <= tol_mm)
    if np.any(bad & np.isfinite(lam)):
        logger.warning("displaced ray intersection: %d of %d rays did not converge",
                       int(np.sum(bad & np.isfinite(lam))), lam.size)
    lam[bad] = np.nan
    return x, y, lam
