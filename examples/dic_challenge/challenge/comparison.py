"""The comparison of issue 5 on the specimen measured as one part.

:class:`MeasuredPart` holds the points sampled on each measured face, restricted to the
regions of ``analysis.toml`` (:func:`face_region`) and put in the world frame of the
measured base plane (z = 0, :func:`base_plane_frame`); :func:`compare` computes the figures
of merit (:class:`Comparison`): base-plate flatness, block height above the plate ring,
cylinder fits of the bars (radius, crest above the ring, the references' radii imposed), the
prisms' faces.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import ConvexHull

from . import analysis
from .config import Analysis, Feature

#: the half cylinders' arcs as facets of ARC_STEP_DEG (inscribed: < 6 um inside)
ARC_STEP_DEG = 5.0
#: the band of a prism's faces that the figures use, as fractions of the nominal ridge height
#: (off the ridge and the foot, where a nominal of the wrong slope folds the measured face)
PRISM_BAND = (0.2, 0.8)
REFERENCE_RADII_MM = {"laser": {"cylinder_v": 6.38, "cylinder_h": 6.62},
                      "pyvale": {"cylinder_v": 6.157, "cylinder_h": 6.178}}


@dataclasses.dataclass(frozen=True, eq=False)
class MeasuredPart:
    """The measured faces' points by face name (world frame, mm, base plane z = 0).

    ``time_s``: the measurement's wall time; ``scales``: its image scales; ``full_resolution``:
    whether it measured the specimen's own images (not a downsampled copy);
    ``residual_percent``: its gray-level residual std (% of the dynamic range);
    ``masked_fraction``: by face, the share of its elements left out as not seen enough.
    """

    analysis: Analysis
    points: dict[str, np.ndarray]
    time_s: float
    scales: tuple[int, ...] | None = None
    full_resolution: bool = False
    residual_percent: float = float("nan")
    masked_fraction: dict[str, float] = dataclasses.field(default_factory=dict)


def _frame(line: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Unit axis of a segment, the lateral unit vector in the plane z = 0, and the length."""
    axis = line[1] - line[0]
    length = float(np.linalg.norm(axis))
    axis = axis / length
    lateral = np.cross(axis, [0.0, 0.0, 1.0])                # lateral x axis = +z
    return axis, lateral / np.linalg.norm(lateral), length


def feature_vertices(f: Feature) -> np.ndarray:
    """Vertices (m, 3) whose convex hull is the feature's solid."""
    if f.kind == "box":
        foot = np.asarray(f.footprint_mm)
        return np.concatenate([np.c_[foot, np.zeros(4)], np.c_[foot, np.full(4, f.height_mm)]])
    line = np.asarray(f.line_mm)
    _, lateral, _ = _frame(line)
    if f.kind == "wedge":
        base = np.concatenate([line + f.half_width_mm * lateral, line - f.half_width_mm * lateral])
        base[:, 2] = 0.0
        return np.concatenate([line, base])
    # half cylinder: arcs at both ends, above z = 0 (the axis may lie below the base plane)
    top = np.arcsin(np.clip(-line[:, 2].max() / f.radius_mm, -1, 1))   # where the arc meets z = 0
    angles = np.radians(np.arange(-90.0, 90.0 + 1e-9, ARC_STEP_DEG))
    angles = np.clip(angles, -np.pi / 2 + top, np.pi / 2 - top)
    arcs = [end[None] + f.radius_mm * (np.sin(angles)[:, None] * lateral
                                       + np.cos(angles)[:, None] * [0.0, 0.0, 1.0]) for end in line]
    pts = np.concatenate(arcs)
    pts[:, 2] = np.maximum(pts[:, 2], 0.0)
    return pts


def footprint(feature: Feature) -> np.ndarray:
    """(m, 2) convex footprint of a feature in (x, y), counter-clockwise."""
    xy = feature_vertices(feature)[:, :2]
    return xy[ConvexHull(xy).vertices]


def face_region(name: str, points: np.ndarray, config: Analysis) -> np.ndarray:
    """(n,) bool: the points of face ``name`` inside its region of ``analysis.toml`` (all the
    points of a face it does not name)."""
    if name == "base":
        plate = config.plate
        keep = analysis.inside_polygon(points, np.asarray(plate.corners_mm)[:, :2])
        for hole in plate.holes:
            feature = config.specimen.feature(hole)
            keep &= analysis.distance_to_footprint(points, footprint(feature)) > plate.hole_margin_mm
        return keep
    if name == "block_top":
        return analysis.inside_polygon(points, np.asarray(config.block_top_mm)[:, :2])
    bar = next((b for b in config.bars if b.name == name), None)
    if bar is None:
        return np.ones(len(points), bool)
    line = np.asarray(bar.axis_mm, float)
    axis = analysis.unit(line[1] - line[0])
    lateral = analysis.unit(np.cross(axis, [0.0, 0.0, 1.0]))
    arm = points - line[0]
    along = arm @ axis
    angle = np.degrees(np.arctan2(arm @ lateral, arm @ np.cross(lateral, axis)))
    return (along >= 0) & (along <= np.linalg.norm(line[1] - line[0])) & (np.abs(angle) <= bar.arc_deg / 2)


def base_plane_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid motion ``(R, t)``, ``X -> R X + t``, putting the best-fit plane of ``points`` at
    z = 0 with the least rotation (x keeps its direction in the plane)."""
    centre = points.mean(axis=0)
    n = np.linalg.svd(points - centre, full_matrices=False)[2][2]
    n = n if n[2] > 0 else -n
    ex = np.array([1.0, 0.0, 0.0]) - n[0] * n
    ex /= np.linalg.norm(ex)
    R = np.array([ex, np.cross(n, ex), n])
    t = -R @ centre
    t[:2] += centre[:2]                  # keep the in-plane position of the centre
    return R, t


def measured_part(config: Analysis, points: dict, time_s: float, **kwargs) -> MeasuredPart:
    """The faces' ``points`` (the measurement's frame) restricted to their regions
    (:func:`face_region`) and moved so that the plate's best-fit plane is z = 0."""
    kept = {name: P[face_region(name, P, config)] for name, P in points.items()}
    if "base" not in kept or not len(kept["base"]):
        raise ValueError("no base plate among the measured faces (it defines the base plane)")
    R, t = base_plane_frame(kept["base"])
    return MeasuredPart(config, {name: P @ R.T + t for name, P in kept.items()}, time_s, **kwargs)


@dataclasses.dataclass(frozen=True, eq=False)
class CylinderReport:
    name: str
    fit: analysis.CylinderFit
    crest_above_ring_mm: float
    axis_below_ring_mm: float
    by_arc: list                            # (half angle, radius, n)
    fixed: dict                             # label -> CylinderFit with that radius imposed
    points: np.ndarray                      # the fitted points


@dataclasses.dataclass(frozen=True, eq=False)
class Comparison:
    base_plane_rms_mm: float                # README region
    base_quadric_rms_mm: float
    base_all_plane_rms_mm: float            # the whole measured plate
    base_all_quadric_rms_mm: float
    block: analysis.BlockHeight | None
    cylinders: dict[str, CylinderReport]
    prisms: dict[str, dict]
    n_points: dict[str, int]


def _ring(base: np.ndarray, feature: Feature, ring_mm) -> np.ndarray:
    d = analysis.distance_to_footprint(base, footprint(feature))
    return base[(d >= ring_mm[0]) & (d <= ring_mm[1])]


def ridge_height(frames, near: np.ndarray) -> float:
    """Height (z, mm) of the line where two planes ``(centre, axes)`` meet, at its point
    nearest ``near``: ``x = near + a n1 + b n2`` on both planes."""
    (c1, a1), (c2, a2) = frames
    n1, n2 = a1[2], a2[2]
    G = np.array([[n1 @ n1, n1 @ n2], [n2 @ n1, n2 @ n2]])
    a, b = np.linalg.solve(G, [n1 @ (c1 - near), n2 @ (c2 - near)])
    return float((near + a * n1 + b * n2)[2])


def prism_figures(part: MeasuredPart) -> dict:
    """Per prism measured on both slanted faces, in the band ``PRISM_BAND`` of heights: each
    face's RMS to its best-fit plane (um), the included angle between the two planes, their
    slopes (deg) and the height of the ridge where the two planes meet (mm, base plane
    z = 0), beside the nominal angle."""
    out = {}
    for f in (f for f in part.analysis.specimen.features if f.kind == "wedge"):
        sides = sorted(k for k in part.points if k.startswith(f.name + "_"))
        if len(sides) != 2:
            continue
        lo, hi = np.array(PRISM_BAND) * f.line_mm[0][2]
        P = [p[(p[:, 2] >= lo) & (p[:, 2] <= hi)] for p in (part.points[k] for k in sides)]
        frames = [analysis.plane_frame(p) for p in P]
        n = [axes[2] for _, axes in frames]
        out[f.name] = {"rms_plane_um": {k: 1e3 * analysis.rms(analysis.plane_residuals(p)) for k, p in zip(sides, P)},
                       "ridge_height_mm": ridge_height(frames, np.concatenate(P).mean(axis=0)),
                       "included_angle_deg": 180.0 - float(np.degrees(np.arccos(np.clip(n[0] @ n[1], -1, 1)))),
                       "slope_deg": {k: float(np.degrees(np.arccos(v[2]))) for k, v in zip(sides, n)},
                       "nominal_angle_deg": float(2 * np.degrees(np.arctan2(f.half_width_mm, f.line_mm[0][2])))}
    return out


def compare(part: MeasuredPart) -> Comparison:
    """All figures of merit of a measured part (see :mod:`challenge.analysis`)."""
    config, res = part.analysis, part.points
    base = res["base"]
    region = base
    if config.plate.flatness_polygon_mm is not None:
        region = base[analysis.inside_polygon(base, config.plate.flatness_polygon_mm)]
    block = None
    if "block_top" in res and config.plate.ring_feature is not None:
        block = analysis.block_height(res["block_top"], base, config.specimen.feature(config.plate.ring_feature),
                                      config.plate.ring_mm)
    cylinders = {}
    for bar in (b for b in config.bars if b.name in res):
        axis = np.diff(np.asarray(bar.axis_mm), axis=0)[0]
        P = res[bar.name]
        fit = analysis.fit_cylinder(P, axis, bar.radius_mm)
        ring = _ring(base, config.specimen.feature(bar.name), config.plate.ring_mm)
        centre, axes = analysis.plane_frame(ring)
        up = np.cross(analysis.unit(np.cross(fit.axis_direction, [0.0, 0.0, 1.0])), fit.axis_direction)
        crest = float((fit.axis_point_mm + fit.radius_mm * up - centre) @ axes[2])
        below = float(-(fit.axis_point_mm - centre) @ axes[2])
        fixed = {f"{who} {radii[bar.name]:g} mm": analysis.fit_cylinder(P, fit.axis_direction, radii[bar.name],
                                                                        radius=radii[bar.name])
                 for who, radii in REFERENCE_RADII_MM.items() if bar.name in radii}
        cylinders[bar.name] = CylinderReport(bar.name, fit, crest, below, analysis.radius_by_arc(P, fit),
                                             fixed, P)
    return Comparison(analysis.rms(analysis.plane_residuals(region)),
                      analysis.rms(analysis.quadric_residuals(region)),
                      analysis.rms(analysis.plane_residuals(base)),
                      analysis.rms(analysis.quadric_residuals(base)),
                      block, cylinders, prism_figures(part), {k: len(P) for k, P in res.items()})
