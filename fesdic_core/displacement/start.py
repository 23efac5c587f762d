"""A start for large motions: feature matches triangulated, fitted on the reference mesh.

The displacement's Gauss-Newton (:mod:`fesdic_core.displacement.driver`) is local: from zero
it converges only if the motion is within a few pixels of the coarsest image scale. For a
larger motion the start comes from features (as VIC-3D's and DICe's seeds do):

1. once per series (:func:`feature_reference`), SIFT features of each reference image
   inside the surface's pixels, spread over tiles of the image
   (:func:`~fesdic_core.cameras.triangulation.detect_features`), matched between the cameras,
   checked against the calibrated epipolar geometry and triangulated (as
   :func:`~fesdic_core.cameras.triangulation.stereo_points` does); each point kept is tied to
   the integration point of the reference surface nearest in camera 0 (its element and parent
   coordinates: a row of the quadrature's shape functions ``L``) and must lie on the surface;
2. per deformed pair (:func:`feature_start`), each camera's reference features matched in
   its deformed image (:func:`~fesdic_core.cameras.triangulation.match_descriptors`, then
   RANSAC on a homography per camera to drop gross outliers), a stereo point followed
   ref-cam0 -> def-cam0 and ref-cam1 -> def-cam1 (its two features), checked against the
   epipolar geometry of the deformed pair and triangulated: sparse 3-D displacements
   ``d_i = Y_i - X_i``;
3. a robust smooth fit of those on the mesh
   (:func:`~fesdic_core.displacement.smooth_fit.fit_field`): an affine field plus a
   nodal field ``V`` regularized by the surface-gradient operator ``A`` of Eq. 10::

       min  sum_i w_i |B [X_i, 1] + L_i V - d_i|^2 + lam V^T A V,

   (``lam`` from a cosine of wavelength ``length_mm``,
   :func:`~fesdic_core.solve.tikhonov.tikhonov_weight`), so that rigid motions and
   homogeneous strains are reproduced exactly, nodes without features get a smooth value, and
   points farther than ``trim`` robust deviations from the fit are dropped, refit until the
   kept set stops changing (a trimmed least squares).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np
import scipy.sparse as sps
from scipy.spatial import cKDTree

from fesdic_core.cameras.triangulation import (DEFAULT_MAX_EPIPOLAR_PX, Features,
                                               detect_features, epipolar_distance_px,
                                               match_descriptors, triangulate)
from fesdic_core.displacement.driver import DisplacementReference
from fesdic_core.displacement.residual import displacement_residual
from fesdic_core.fe.mesh import element_areas
from fesdic_core.imaging.image import Image, pyramid
from fesdic_core.imaging.noise import residual_noise_floor
from fesdic_core.displacement.smooth_fit import fit_field
from fesdic_core.solve.tikhonov import surface_gradient_operator

logger = logging.getLogger(__name__)

__all__ = ["StartSettings", "FeatureReference", "StartReport", "FeatureStart",
           "feature_reference", "feature_start", "start_residual_percent",
           "coarse_noise_percent", "image_shift_px"]


@dataclass(frozen=True)
class StartSettings:
    """How the feature start is made.

    max_features, spread_cells : SIFT features per image, the strongest of each of
        ``spread_cells x spread_cells`` tiles (:func:`~fesdic_core.cameras.triangulation.
        detect_features`: a specimen lit unevenly still gets features everywhere).
    ransac_px : RANSAC threshold (px) of the homography of each camera (reference to
        deformed); a deforming specimen is not a homography, so this is generous: it drops
        gross mismatches only, the robust fit the rest.
    max_epipolar_px : the deformed pair's matches farther from their epipolar line are dropped
        (the reference pair's: :data:`~fesdic_core.cameras.triangulation.DEFAULT_MAX_EPIPOLAR_PX`).
    surface_px : a reference stereo point farther than this (in camera 0's pixels at the
        specimen) from the reference surface is dropped.
    length_mm : wavelength (mm) ruled equally by the points and the smoothing (None: twice
        the median element size).
    trim : points farther from the fit than this many robust deviations are outliers.
    floor_px : the robust deviation is at least this (px at the specimen): a start needs to be
        right within a pixel or so, and a smooth fit of a strained field misses some points
        by a fraction of a pixel that is no outlier.
    max_refits : at most this many fits of the trimmed least squares.
    min_points : fewer tracked points than this give no start.
    """

    max_features: int = 8000
    spread_cells: int = 8
    ransac_px: float = 80.0
    max_epipolar_px: float = 2.0
    surface_px: float = 4.0
    length_mm: float | None = None
    trim: float = 3.0
    floor_px: float = 0.5
    max_refits: int = 10
    min_points: int = 12

    def __post_init__(self):
        for name in ("ransac_px", "max_epipolar_px", "surface_px", "trim",
                     "floor_px"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"StartSettings.{name} must be a positive number, got {value!r}")
        if self.length_mm is not None and not (np.isfinite(self.length_mm) and self.length_mm > 0):
            raise ValueError(f"StartSettings.length_mm must be positive or None, got "
                             f"{self.length_mm!r}")
        if (self.min_points < 4 or self.max_refits < 1 or self.max_features < 10
                or self.spread_cells < 0):
            raise ValueError("StartSettings: min_points >= 4, max_refits >= 1, "
                             "max_features >= 10 and spread_cells >= 0 are needed")


@dataclass(frozen=True, eq=False)
class FeatureReference:
    """The reference pair's features on the surface: built once per series.

    Attributes
    ----------
    features : the SIFT features of each reference image inside the specimen's pixels.
    index0, index1 : (m,) the stereo points' features in each camera (indices of
        ``features``): camera 0's ``index0[i]`` matches camera 1's ``index1[i]``.
    X_mm : (m, 3) the stereo points' triangulated positions (world frame).
    basis : (m, n) csr, the shape functions of the mesh at each point's place on the surface.
    mm_per_px : size of a pixel at the specimen (mm, camera 0).
    gradient : (n, n) csr, the surface-gradient operator ``A`` of the mesh (Eq. 10).
    nodes : (n, 3) the reference surface's nodes (mm).
    length_mm : the smoothing's wavelength (mm).
    n_stereo : stereo points of the reference pair before the surface check.
    """

    features: tuple[Features, Features] = field(repr=False)
    index0: np.ndarray
    index1: np.ndarray
    X_mm: np.ndarray
    basis: sps.csr_matrix = field(repr=False)
    mm_per_px: float
    gradient: sps.csr_matrix = field(repr=False)
    nodes: np.ndarray = field(repr=False)
    length_mm: float
    n_stereo: int

    @property
    def n_points(self) -> int:
        return len(self.X_mm)


@dataclass(frozen=True)
class StartReport:
    """What the feature start of one deformed pair gave.

    matches : (cam0, cam1) matches of the reference features in the deformed image.
    inliers : (cam0, cam1) of those, the RANSAC inliers.
    points : tracked in both cameras and consistent with the deformed pair's epipolar line.
    kept : points the robust fit kept.
    rms_mm : RMS misfit (mm) of the kept points to the fitted field.
    median_mm : median displacement magnitude (mm) of the kept points.
    failure : why there is no start (None: a start).
    """

    matches: tuple[int, int] = (0, 0)
    inliers: tuple[int, int] = (0, 0)
    points: int = 0
    kept: int = 0
    rms_mm: float = float("nan")
    median_mm: float = float("nan")
    failure: str | None = None

    def describe(self) -> str:
        """One line for the log."""
        head = (f"matches {self.matches[0]} / {self.matches[1]} (RANSAC inliers "
                f"{self.inliers[0]} / {self.inliers[1]}), {self.points} points in both cameras")
        if self.failure is not None:
            return f"{head}: no start ({self.failure})"
        return (f"{head}, {self.kept} kept, RMS misfit {self.rms_mm * 1e3:.1f} um, median "
                f"displacement {self.median_mm:.3g} mm")


@dataclass(frozen=True, eq=False)
class FeatureStart:
    """A starting field ``U`` (n, 3) mm (None if the start failed) and its report."""

    U: np.ndarray | None
    report: StartReport


def _pixel_mask(px: np.ndarray, shape: tuple[int, int], dilate_px: int = 2) -> np.ndarray:
    """(h, w) bool: the pixels ``px`` (k, 2) fall in, dilated by ``dilate_px``."""
    mask = np.zeros(shape, np.uint8)
    ij = np.round(px).astype(np.intp)
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < shape[1]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[0])
    mask[ij[ok, 1], ij[ok, 0]] = 1
    size = 2 * dilate_px + 1
    return cv2.dilate(mask, np.ones((size, size), np.uint8)).astype(bool)


def _element_size_mm(reference: DisplacementReference) -> float:
    return float(np.sqrt(np.median(np.concatenate(element_areas(reference.mesh)))))


def feature_reference(reference: DisplacementReference,
                      settings: StartSettings = StartSettings()) -> FeatureReference:
    """The reference pair's features on the reference surface (once per series).

    SIFT features of each reference image inside the surface's pixels, matched between the
    cameras, the matches within :data:`DEFAULT_MAX_EPIPOLAR_PX` of their epipolar line
    triangulated, and those within ``settings.surface_px`` of the surface kept.

    Parameters
    ----------
    reference : the displacement reference (surface, cameras, reference pair; the
        quadrature of its finest scale places the features on the surface).
    settings : :class:`StartSettings`.

    Returns
    -------
    FeatureReference (possibly with no point: :func:`feature_start` then reports why).
    """
    view = reference.view(reference.settings.scales[-1])
    cam0, cam1 = reference.cameras
    features, projections = [], []
    for c, (cam, im) in enumerate(zip(reference.cameras, reference.images)):
        px = cam.project(view.X[view.seen[c]])
        projections.append(px)
        features.append(detect_features(im.values, _pixel_mask(px, im.shape),
                                        settings.max_features, settings.spread_cells))
    mm_per_px = float(np.median(cam0.depth(view.X)) / cam0.K[0, 0])
    i0, i1 = match_descriptors(features[0], features[1])
    px0, px1 = features[0].px[i0], features[1].px[i1]
    epipolar = epipolar_distance_px(cam0, cam1, px0, px1) <= DEFAULT_MAX_EPIPOLAR_PX
    X, _ = triangulate(cam0, cam1, px0[epipolar], px1[epipolar])
    i0, i1, px0 = i0[epipolar], i1[epipolar], px0[epipolar]
    seen0 = np.flatnonzero(view.seen[0])
    dist, nearest = cKDTree(projections[0]).query(
        px0, distance_upper_bound=1.5 * 2.0 ** reference.settings.scales[-1])
    on_mesh = np.isfinite(dist)
    g = seen0[np.where(on_mesh, nearest, 0)]
    keep = on_mesh & (np.linalg.norm(X - view.X[g], axis=1) <= settings.surface_px * mm_per_px)
    length = settings.length_mm if settings.length_mm is not None \
        else 2.0 * _element_size_mm(reference)
    logger.info("feature start: %d / %d features in the reference images, %d stereo matches, "
                "%d on their epipolar line, %d on the surface (within %.2g mm; pixel %.3g mm, "
                "smoothing length %.3g mm)", len(features[0]), len(features[1]),
                int(epipolar.size), int(epipolar.sum()), int(keep.sum()),
                settings.surface_px * mm_per_px, mm_per_px, length)
    return FeatureReference(features=(features[0], features[1]), index0=i0[keep],
                            index1=i1[keep], X_mm=X[keep],
                            basis=sps.csr_matrix(view.quad.L[g[keep]]), mm_per_px=mm_per_px,
                            gradient=surface_gradient_operator(reference.mesh),
                            nodes=np.asarray(reference.mesh.nodes, float), length_mm=float(length),
                            n_stereo=int(epipolar.sum()))


def _tracked(reference: Features, values: np.ndarray, settings: StartSettings
             ) -> tuple[np.ndarray, int, int]:
    """One camera's reference features in its deformed image: (k, 2) the deformed pixel of
    each reference feature (NaN: not matched, or not a RANSAC inlier of a homography), the
    matches and the inliers."""
    deformed = detect_features(values, None, settings.max_features, settings.spread_cells)
    i, j = match_descriptors(reference, deformed)
    where = np.full((len(reference), 2), np.nan)
    if len(i) < 4:
        return where, len(i), 0
    _, inlier = cv2.findHomography(reference.px[i], deformed.px[j], cv2.RANSAC,
                                   settings.ransac_px, maxIters=5000, confidence=0.999)
    keep = np.zeros(len(i), bool) if inlier is None else inlier.ravel().astype(bool)
    where[i[keep]] = deformed.px[j[keep]]
    return where, len(i), int(keep.sum())


def feature_start(features: FeatureReference, images: Sequence[Image], cameras: Sequence,
                  settings: StartSettings = StartSettings()) -> FeatureStart:
    """The starting field of a deformed pair from the reference features.

    Each reference stereo point is followed into each camera's deformed image (its feature's
    match there, a RANSAC inlier), the pair checked against the epipolar line (at most
    ``settings.max_epipolar_px``), triangulated: ``d = Y - X``; then :func:`~fesdic_core.displacement.smooth_fit.fit_field`.

    Parameters
    ----------
    features : :func:`feature_reference` of the series.
    images : the two deformed full-resolution images (cam0, cam1).
    cameras : the two calibrated cameras (full resolution).
    settings : :class:`StartSettings` (as for :func:`feature_reference`).

    Returns
    -------
    FeatureStart: ``U`` (n, 3) mm on the reference nodes, or None with the report's failure.
    """
    cam0, cam1 = cameras
    where0, m0, n0 = _tracked(features.features[0], images[0].values, settings)
    where1, m1, n1 = _tracked(features.features[1], images[1].values, settings)
    q0, q1 = where0[features.index0], where1[features.index1]
    both = np.flatnonzero(np.isfinite(q0[:, 0]) & np.isfinite(q1[:, 0]))
    if both.size:
        both = both[epipolar_distance_px(cam0, cam1, q0[both], q1[both])
                    <= settings.max_epipolar_px]
    Y, _ = triangulate(cam0, cam1, q0[both], q1[both])
    matches, inliers, points = (m0, m1), (n0, n1), int(both.size)
    if both.size < settings.min_points:
        report = StartReport(matches, inliers, points,
                             failure=f"{both.size} points tracked in both cameras, "
                                     f"at least {settings.min_points} needed")
        return FeatureStart(None, report)
    d = Y - features.X_mm[both]
    length = features.length_mm if settings.length_mm is None else settings.length_mm
    fit = fit_field(features.basis[both], features.X_mm[both], d, features.gradient,
                    features.nodes, length, settings.trim, settings.max_refits,
                    floor_mm=settings.floor_px * features.mm_per_px)
    median = float(np.median(np.linalg.norm(d[fit.kept], axis=1)))
    report = StartReport(matches, inliers, points, kept=int(fit.kept.sum()), rms_mm=fit.rms_mm,
                         median_mm=median)
    return FeatureStart(fit.U, report)


def _coarsest(reference: DisplacementReference, images: Sequence[Image]):
    scale = reference.settings.scales[0]
    return reference.view(scale), [pyramid(im, scale + 1)[scale] for im in images]


def start_residual_percent(reference: DisplacementReference, images: Sequence[Image],
                           candidates: Sequence[np.ndarray]) -> list[float]:
    """The residual (percent) of each candidate start ``U`` (n, 3) at the coarsest scale of
    ``reference`` for the deformed full-resolution ``images`` (the better start is lower)."""
    view, scaled = _coarsest(reference, images)
    return [float(displacement_residual(U, view, scaled, reference.settings.normalisation,
                                        jacobian=False).std_percent) for U in candidates]


def coarse_noise_percent(reference: DisplacementReference, images: Sequence[Image]) -> float:
    """The residual (percent) that the images' noise explains at the coarsest scale
    (:func:`~fesdic_core.imaging.noise.residual_noise_floor` of each camera's reference and
    deformed images at the reference points it sees, pooled over the cameras): a start whose
    residual is below it already matches the images at that scale."""
    view, scaled = _coarsest(reference, images)
    counts = view.seen.sum(axis=1)
    floors = [residual_noise_floor(view.X, view.seen[c], [view.images[c], scaled[c]],
                                   [view.cameras[c], view.cameras[c]]).percent for c in range(2)]
    total = int(counts.sum())
    return float(np.sqrt(np.dot(counts, np.square(floors)) / total)) if total else float("nan")


def image_shift_px(reference: DisplacementReference, U: np.ndarray, V: np.ndarray,
                   percentile: float = 90.0) -> float:
    """How far apart two fields (n, 3) put the surface in camera 0's full-resolution image:
    the ``percentile`` of the nodes' pixel distances between ``X + U`` and ``X + V``."""
    X, cam0 = reference.mesh.nodes, reference.cameras[0]
    d = np.linalg.norm(cam0.project(X + U) - cam0.project(X + V), axis=1)
    return float(np.percentile(d, percentile)) if d.size else 0.0
