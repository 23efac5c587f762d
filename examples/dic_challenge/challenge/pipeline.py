"""Measure the four faces of the specimen and compute the comparison of issue 5.

:func:`run_challenge` measures every nominal of every face on the same images from the
same landmark pose, puts all of them in one world frame (the measured base plane at
z = 0) and :func:`compare` computes the figures of merit (:class:`Comparison`).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy.spatial import ConvexHull

from . import analysis
from .config import Face, Feature, load_face
from .geometry import feature_vertices
from .measure import (FaceResult, base_plane_frame, initial_cameras, load_images,
                      measure_nominal, moved)

logger = logging.getLogger(__name__)

FACES = ("base", "block_top", "cylinder_h", "cylinder_v")


@dataclasses.dataclass(frozen=True, eq=False)
class ChallengeRun:
    faces: dict[str, Face]
    results: dict[str, FaceResult]     # by nominal name, world frame (base plane z = 0)
    time_s: float
    scales: tuple[int, ...] | None
    crop: tuple[int, int, int, int] | None


def run_challenge(folder: str | Path, faces: Sequence[str] = FACES, *, scales=None, crop=None,
                  progress: bool = False) -> ChallengeRun:
    """Measure ``faces`` (``<folder>/<face>.toml``); ``scales`` overrides every face's.

    ``crop = (x0, y0, w, h)`` measures on a crop of the images (px of the stored pair).
    """
    folder = Path(folder)
    if "base" not in faces:
        raise ValueError(f"faces {list(faces)}: 'base' is needed (it defines the base plane)")
    t0 = time.perf_counter()
    loaded = {name: load_face(folder / f"{name}.toml") for name in faces}
    specimen = loaded["base"].specimen
    images = load_images(specimen, crop)
    cameras = initial_cameras(specimen, images, crop)
    results = {}
    for face in loaded.values():
        for nominal in face.nominals:
            logger.info("measuring %s (%s nominal) ...", nominal.name, nominal.kind)
            results[nominal.name] = measure_nominal(face, nominal, images, cameras, scales=scales,
                                                    progress=progress)
    base = results["base"]
    R, t = base_plane_frame(base.points_mm[base.seen])
    results = {k: moved(r, R, t) for k, r in results.items()}
    return ChallengeRun(loaded, results, time.perf_counter() - t0,
                        None if scales is None else tuple(scales), crop)


def footprint(feature: Feature) -> np.ndarray:
    """(m, 2) convex footprint of a feature in (x, y), counter-clockwise."""
    xy = feature_vertices(feature)[:, :2]
    return xy[ConvexHull(xy).vertices]


@dataclasses.dataclass(frozen=True, eq=False)
class CylinderReport:
    name: str
    fit: analysis.CylinderFit               # cylindrical nominal
    fit_flat: analysis.CylinderFit | None   # flat nominal
    crest_above_ring_mm: float
    axis_below_ring_mm: float
    by_arc: list                            # (half angle, radius, n)
    fixed: dict                             # radius -> CylinderFit with that radius imposed
    flat_vs_cylinder_rms_mm: float | None
    flat_vs_cylinder_mean_mm: float | None
    points: np.ndarray                      # the fitted points (cylindrical nominal)


@dataclasses.dataclass(frozen=True, eq=False)
class Comparison:
    base_plane_rms_mm: float                # README region
    base_quadric_rms_mm: float
    base_all_plane_rms_mm: float            # the whole measured plate
    base_all_quadric_rms_mm: float
    block: analysis.BlockHeight | None
    cylinders: dict[str, CylinderReport]
    residual_percent: dict[str, float]      # gray-level residual std per nominal
    masked_fraction: dict[str, float]
    n_points: dict[str, int]


REFERENCE_RADII_MM = {"laser": {"cylinder_v": 6.38, "cylinder_h": 6.62},
                      "pyvale": {"cylinder_v": 6.157, "cylinder_h": 6.178}}


def _ring(base: np.ndarray, feature: Feature, ring_mm) -> np.ndarray:
    d = analysis.distance_to_footprint(base, footprint(feature))
    return base[(d >= ring_mm[0]) & (d <= ring_mm[1])]


def compare(run: ChallengeRun) -> Comparison:
    """All figures of merit of a run (see :mod:`challenge.analysis`)."""
    res = run.results
    base_face = run.faces["base"]
    base = res["base"].points_mm[res["base"].seen]
    region = base
    if base_face.analysis.flatness_polygon_mm is not None:
        region = base[analysis.inside_polygon(base, base_face.analysis.flatness_polygon_mm)]
    block = None
    if "block_top" in res and base_face.analysis.ring_feature is not None:
        top = res["block_top"]
        block = analysis.block_height(top.points_mm[top.seen], base,
                                      base_face.specimen.feature(base_face.analysis.ring_feature),
                                      base_face.analysis.ring_mm)
    cylinders = {}
    for name in ("cylinder_h", "cylinder_v"):
        if name not in run.faces:
            continue
        face = run.faces[name]
        cyl = next(n for n in face.nominals if n.kind == "cylinder")
        flat = next((n for n in face.nominals if n.kind == "quadrilateral"), None)
        axis = np.diff(np.asarray(cyl.line_mm), axis=0)[0]
        P = res[cyl.name].points_mm[res[cyl.name].seen]
        fit = analysis.fit_cylinder(P, axis, cyl.radius_mm)
        fit_flat = rms_d = mean_d = None
        if flat is not None:
            Q = res[flat.name].points_mm[res[flat.name].seen]
            fit_flat = analysis.fit_cylinder(Q, axis, cyl.radius_mm)
            d = analysis.surface_distance(P, Q, fit.axis_direction)
            d = d[np.isfinite(d)]
            rms_d, mean_d = analysis.rms(d), float(np.mean(d))
        ring = _ring(base, face.specimen.feature(name), base_face.analysis.ring_mm)
        centre, axes = analysis.plane_frame(ring)
        up = np.cross(analysis.unit(np.cross(fit.axis_direction, [0.0, 0.0, 1.0])), fit.axis_direction)
        crest = float((fit.axis_point_mm + fit.radius_mm * up - centre) @ axes[2])
        below = float(-(fit.axis_point_mm - centre) @ axes[2])
        fixed = {f"{who} {radii[name]:g} mm": analysis.fit_cylinder(P, fit.axis_direction, radii[name],
                                                                    radius=radii[name])
                 for who, radii in REFERENCE_RADII_MM.items()}
        cylinders[name] = CylinderReport(name, fit, fit_flat, crest, below,
                                         analysis.radius_by_arc(P, fit), fixed, rms_d, mean_d, P)
    residual = {k: float(r.measurement.residual_percent) for k, r in res.items()}
    masked = {k: float(np.mean(~r.seen)) for k, r in res.items()}
    counts = {k: int(np.count_nonzero(r.seen)) for k, r in res.items()}
    return Comparison(analysis.rms(analysis.plane_residuals(region)),
                      analysis.rms(analysis.quadric_residuals(region)),
                      analysis.rms(analysis.plane_residuals(base)),
                      analysis.rms(analysis.quadric_residuals(base)),
                      block, cylinders, residual, masked, counts)
