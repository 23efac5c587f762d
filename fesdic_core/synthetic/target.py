"""Calibration targets with a known truth: their paint, and a rig posed in front of them.

:func:`target_specimen` paints a :class:`~fesdic_core.cameras.targets.target.Target` (dots with
ring markers, or a checkerboard) on a flat plate that the renderer
(:func:`fesdic_core.synthetic.render.render_stereo`) images; :func:`posed_rig` places the rig
for one view (the target moved by a rigid pose in the rig's frame). The target's frame (its
:meth:`~fesdic_core.cameras.targets.target.Target.object_points`: x along its rows, y down its
columns, z into the print) is the plate's frame turned by 180 degrees about x, as a print
seen from its front by cameras on the plate's +z side; :func:`plate_points` maps it.
"""
from __future__ import annotations

from functools import partial
from typing import Sequence

import cv2
import numpy as np

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.targets.target import Target
from fesdic_core.synthetic.specimen import Specimen

__all__ = ["INK", "PAPER", "RING_INNER_FRACTION", "target_origin", "plate_points",
           "target_specimen", "posed_rig"]

INK, PAPER = 30.0, 220.0
RING_INNER_FRACTION = 0.5     # a ring marker's light centre, as a fraction of its diameter


def target_origin(target: Target) -> np.ndarray:
    """(3,) the centre of the target's grid in its own frame: the plate's origin."""
    points = target.object_points()
    return 0.5 * (points.min(axis=0) + points.max(axis=0))


def plate_points(target: Target, points: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) the plate coordinates of target points (default: all of them): the grid centred
    on the plate, turned by 180 degrees about x (``y, z -> -y, -z``)."""
    p = target.object_points() if points is None else np.asarray(points, float)
    p = p - target_origin(target)
    return np.column_stack([p[:, 0], -p[:, 1], -p[:, 2]])


def _grid_uv(x, y, target: Target, origin: np.ndarray):
    """Grid coordinates (column, row) of plate points."""
    return (x + origin[0]) / target.pitch_mm, (origin[1] - y) / target.pitch_mm


def _dots(x, y, target: Target, origin: np.ndarray, diameter: float, rings: frozenset):
    u, v = _grid_uv(x, y, target, origin)
    col, row = np.rint(u), np.rint(v)
    inside = (col >= 0) & (col < target.columns) & (row >= 0) & (row < target.rows)
    r = np.hypot(u - col, v - row) * target.pitch_mm
    ink = inside & (r <= 0.5 * diameter)
    if rings:
        key = row * target.columns + col
        ring = np.isin(key, [rw * target.columns + c for c, rw in rings])
        ink &= ~(ring & (r < 0.5 * RING_INNER_FRACTION * diameter))
    return np.where(ink, INK, PAPER)


def _checker(x, y, target: Target, origin: np.ndarray):
    u, v = _grid_uv(x, y, target, origin)
    inside = (u > -1) & (u < target.columns) & (v > -1) & (v < target.rows)
    dark = (np.floor(u) + np.floor(v)) % 2 == 0
    return np.where(inside & dark, INK, PAPER)


def target_specimen(target: Target, margin_mm: float | None = None) -> Specimen:
    """A flat plate painted with ``target`` ("dots" with its ring markers, or "checkerboard";
    the dots' diameter ``dot_diameter_mm``, default 0.4 pitch), ``margin_mm`` of paper
    around the grid (default two pitches)."""
    if target.kind not in ("dots", "checkerboard"):
        raise ValueError(f"target_specimen paints dots and checkerboards, not {target.kind!r}")
    margin = 2.0 * target.pitch_mm if margin_mm is None else float(margin_mm)
    points = target.object_points()
    length, width = (np.ptp(points[:, k]) + 2.0 * margin for k in (0, 1))
    origin = target_origin(target)
    if target.kind == "dots":
        diameter = target.dot_diameter_mm or 0.4 * target.pitch_mm
        texture = partial(_dots, target=target, origin=origin, diameter=diameter,
                          rings=frozenset(tuple(m) for m in target.markers))
    else:
        texture = partial(_checker, target=target, origin=origin)
    return Specimen(length_mm=float(length), width_mm=float(width), texture=texture,
                    speckle_mm=target.pitch_mm)


def posed_rig(cameras: Sequence[Camera], rvec: np.ndarray, tvec: np.ndarray) -> list[Camera]:
    """The rig seeing the plate moved by the pose ``(rvec, tvec)``: a plate point ``X`` sits
    at ``R(rvec) X + tvec`` in the rig's frame; returns the cameras in the plate's frame."""
    out = []
    for cam in cameras:
        r, t = cv2.composeRT(np.asarray(rvec, float).reshape(3, 1), np.asarray(tvec, float).reshape(3, 1),
                             cam.rvec.reshape(3, 1), cam.tvec.reshape(3, 1))[:2]
        out.append(cam.with_extrinsics(np.concatenate([r.ravel(), t.ravel()])))
    return out
