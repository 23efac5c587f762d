"""Stereo calibration from pairs of target images, the way a metrologist trusts it.

1. **Intrinsics per camera** (:func:`cv2.calibrateCameraExtended`) on every view of that
   camera where the target was found.
2. **Bad data out, said aloud.** A view whose reprojection RMS exceeds
   :data:`VIEW_REJECT_FACTOR` times the median view's (and :data:`MIN_REJECT_PX`) is left
   out; so is a point whose reprojection error exceeds :data:`POINT_REJECT_SIGMA` robust
   standard deviations. The calibration is redone until nothing more goes; every rejection
   is in :attr:`StereoCalibration.views` with its reason.
3. **The stereo relation, refined jointly** (:func:`cv2.stereoCalibrateExtended` started from
   step 1's intrinsics) on the target points both cameras saw in the same view, with the
   same rejection.
4. **Circle centres** (dot grids and circle grids with a known dot diameter): the detected
   centre of a dot is the centroid of its projected area, not the projection of its centre
   (:func:`~fesdic_core.cameras.targets.covariance.circle_centre_bias`); with the poses of
   step 3 the bias is subtracted from every detection and step 3 is redone.
5. **Its own uncertainty**: the covariance of every parameter from the Jacobian at the
   optimum (the stereo bundle of :mod:`~fesdic_core.cameras.targets.bundle` linearised), the
   epipolar distance of the target points.

Camera 0 is the world frame: ``cameras[0]`` has zero extrinsics, ``cameras[1]`` the stereo
relation ``X_1 = R X_0 + T`` (mm), the core's camera format.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.rig import CalibrationError
from fesdic_core.cameras.targets.bundle import gauge_mask, released_bundle
from fesdic_core.cameras.targets.covariance import (INTRINSIC_NAMES, circle_centre_bias,
                                                     epipolar_distances)
from fesdic_core.cameras.targets.target import Detection, Target

logger = logging.getLogger(__name__)

__all__ = ["DISTORTION_MODELS", "CalibrationModel", "ViewReport", "StereoCalibration",
           "calibrate_stereo", "VIEW_REJECT_FACTOR", "MIN_REJECT_PX", "POINT_REJECT_SIGMA",
           "MIN_VIEWS", "MIN_POINTS"]

#: the distortion coefficients estimated (the others fixed at zero); the core's camera holds
#: OpenCV's k1 k2 p1 p2 k3
DISTORTION_MODELS = {"k1": ("k1",), "k1k2": ("k1", "k2"), "k1k2k3": ("k1", "k2", "k3"),
                     "k1k2p1p2": ("k1", "k2", "p1", "p2"),
                     "k1k2p1p2k3": ("k1", "k2", "p1", "p2", "k3")}
VIEW_REJECT_FACTOR = 3.0    # a view this many times the median view's RMS is out ...
MIN_REJECT_PX = 0.1         # ... if also above this (px): sub-0.1 px views are all good
POINT_REJECT_SIGMA = 6.0    # a point this many robust std off is out
MIN_VIEWS = 3               # views a calibration needs
MIN_POINTS = 8              # points a view needs (not all on a line)


@dataclass(frozen=True)
class CalibrationModel:
    """What is estimated: ``distortion`` (a key of :data:`DISTORTION_MODELS`), whether the
    principal point and the aspect ratio ``fy / fx`` are fixed (at the image centre and 1), and
    whether the target's points are estimated too (``refine_target``: a target as printed,
    :mod:`~fesdic_core.cameras.targets.bundle`)."""

    distortion: str = "k1k2p1p2k3"
    fix_principal_point: bool = False
    fix_aspect: bool = False
    refine_target: bool = False

    def __post_init__(self) -> None:
        if self.distortion not in DISTORTION_MODELS:
            raise ValueError(f"distortion model must be one of {tuple(DISTORTION_MODELS)} (the "
                             f"core's camera holds k1 k2 p1 p2 k3), got {self.distortion!r}")

    @property
    def free(self) -> np.ndarray:
        """(9,) bool over :data:`INTRINSIC_NAMES`: what is estimated."""
        kept = set(DISTORTION_MODELS[self.distortion])
        return np.array([True, not self.fix_aspect, not self.fix_principal_point,
                         not self.fix_principal_point] + [n in kept for n in INTRINSIC_NAMES[4:]])

    @property
    def flags(self) -> int:
        kept = DISTORTION_MODELS[self.distortion]
        f = 0
        if "k2" not in kept:
            f |= cv2.CALIB_FIX_K2
        if "k3" not in kept:
            f |= cv2.CALIB_FIX_K3
        if "p1" not in kept:
            f |= cv2.CALIB_ZERO_TANGENT_DIST
        if self.fix_principal_point:
            f |= cv2.CALIB_FIX_PRINCIPAL_POINT
        if self.fix_aspect:
            f |= cv2.CALIB_FIX_ASPECT_RATIO
        return f


@dataclass(frozen=True)
class ViewReport:
    """One view (a pair of images): points found, used, and the reprojection RMS per camera
    (NaN where unused); ``status`` "used" or why the view was left out."""

    index: int
    sources: tuple[str, str]
    found: tuple[int, int]
    used: int
    rms_px: tuple[float, float]
    status: str


@dataclass(frozen=True, eq=False)
class StereoCalibration:
    """A calibrated rig and what its optimum says about it.

    Attributes
    ----------
    cameras : camera 0 at the world origin, camera 1 by the stereo relation.
    std : each parameter's standard deviation, by name ("cam0.fx", ..., "rvec", "T").
    rms_px : the stereo reprojection RMS over every used point of both cameras.
    sigma_px : the residual's std per degree of freedom (the covariance's scale).
    epipolar_px : (m, 2) every used target point's epipolar distance, both ways.
    views : one :class:`ViewReport` per pair of images.
    residuals : per used view, (points (m, 2) px of camera 0 and 1, residual vectors).
    bias_corrected : whether the circle centres' perspective bias was subtracted.
    target_deviation_mm : (N, 3) the target's points as estimated minus as drawn
        (``refine_target``), else None.
    """

    cameras: tuple[Camera, Camera]
    std: dict
    rms_px: float
    sigma_px: float
    epipolar_px: np.ndarray = field(repr=False)
    views: tuple[ViewReport, ...] = ()
    residuals: tuple = field(default=(), repr=False)
    bias_corrected: bool = False
    target_deviation_mm: np.ndarray | None = field(default=None, repr=False)

    @property
    def baseline_mm(self) -> float:
        return float(np.linalg.norm(self.cameras[1].tvec))

    @property
    def stereo_angle_deg(self) -> float:
        return float(np.degrees(np.linalg.norm(self.cameras[1].rvec)))


def _arrays(d: Detection, target: Target, ids: np.ndarray):
    where = np.searchsorted(d.ids, ids) if len(ids) else np.zeros(0, int)
    return (target.object_points()[ids].astype(np.float32).reshape(-1, 1, 3),
            d.px[where].astype(np.float32).reshape(-1, 1, 2))


def _rms(residual: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1)))) if len(residual) else np.nan


def _view_outliers(rms: np.ndarray) -> np.ndarray:
    median = float(np.median(rms))
    return rms > max(VIEW_REJECT_FACTOR * median, MIN_REJECT_PX)


def _point_outliers(residuals: Sequence[np.ndarray]) -> list[np.ndarray]:
    norms = np.concatenate([np.linalg.norm(r, axis=1) for r in residuals])
    sigma = 1.4826 * float(np.median(norms)) / np.sqrt(np.log(4.0))     # Rayleigh's median
    return [np.linalg.norm(r, axis=1) > POINT_REJECT_SIGMA * max(sigma, 1e-3) for r in residuals]


def _stereo(objects, px0, px1, K, dist, size, model: CalibrationModel):
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | model.flags
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    out = cv2.stereoCalibrateExtended(  # type: ignore[call-overload]
        objects, px0, px1, K[0].copy(), dist[0].copy(), K[1].copy(), dist[1].copy(), size, None,
        None, flags=flags, criteria=criteria)
    _, K0, d0, K1, d1, R, T, _, _, rvecs, tvecs, _ = out
    return [K0, K1], [d0.ravel()[:5], d1.ravel()[:5]], R, T.ravel(), rvecs, tvecs


def _residuals(objects, px, K, dist, rvecs, tvecs, R=None, T=None):
    res = []
    for v, X in enumerate(objects):
        rv, tv = rvecs[v], tvecs[v]
        if R is not None:
            rv, tv = cv2.composeRT(rv, tv, cv2.Rodrigues(R)[0], T.reshape(3, 1))[:2]
        proj, _ = cv2.projectPoints(X, rv, tv, K, dist)
        res.append(px[v].reshape(-1, 2) - proj.reshape(-1, 2))
    return res


def _intrinsics(detections: Sequence[Detection], target: Target, size, model: CalibrationModel,
                name: str):
    """One camera's intrinsics on its good views; (K, dist, kept views, reasons)."""
    reasons = {}
    for v, d in enumerate(detections):
        if d.n_points < MIN_POINTS:
            reasons[v] = d.note or f"{d.n_points} target points found, {MIN_POINTS} needed"
    keep = {v: detections[v].ids for v in range(len(detections)) if v not in reasons}
    K = dist = None
    for _ in range(5):
        views = sorted(keep)
        if len(views) < MIN_VIEWS:
            raise CalibrationError(f"{name}: the target was found in {len(views)} usable views, "
                                   f"at least {MIN_VIEWS} needed ({_why(reasons, detections)})")
        objects, pixels = zip(*(_arrays(detections[v], target, keep[v]) for v in views))
        K0 = np.array([[1.0, 0, 0.5 * (size[0] - 1)], [0, 1.0, 0.5 * (size[1] - 1)], [0, 0, 1]])
        K0[0, 0] = K0[1, 1] = float(max(size))
        _, K, dist, rvecs, tvecs, _, _, errors = cv2.calibrateCameraExtended(
            list(objects), list(pixels), size, K0, np.zeros(5), flags=model.flags)
        res = _residuals(objects, pixels, K, dist, rvecs, tvecs)
        bad_views = _view_outliers(np.array([_rms(r) for r in res]))
        bad_points = _point_outliers(res)
        if not bad_views.any() and not any(b.any() for b in bad_points):
            break
        for v, bad_v, bad_p, r in zip(views, bad_views, bad_points, res):
            if bad_v:
                reasons[v] = (f"{name} reprojection RMS {_rms(r):.3f} px, more than "
                              f"{VIEW_REJECT_FACTOR:g} times the median view's")
                del keep[v]
            elif bad_p.any():
                keep[v] = keep[v][~bad_p]
    return K, np.asarray(dist, float).ravel()[:5], keep, reasons


def _anchors(target: Target, common: dict) -> list[int]:
    """Three points for the target's gauge, seen in every used view: a dot grid's ring
    markers, else the three most seen of the grid's corners."""
    grid = target.grid
    if target.kind == "dots":
        return [int(np.argmin(np.linalg.norm(grid - m, axis=1))) for m in target.markers[:3]]
    seen = np.zeros(len(grid), int)
    for ids in common.values():
        seen[ids] += 1
    lo, hi = grid.min(axis=0), grid.max(axis=0)
    corners = [int(np.argmin(np.linalg.norm(grid - c, axis=1))) for c in
               (lo, (hi[0], lo[1]), (lo[0], hi[1]), hi)]
    corners.sort(key=lambda i: -seen[i])
    return corners[:3]


def _why(reasons: dict, detections) -> str:
    return "; ".join(f"{detections[v].source or f'view {v}'}: {r}" for v, r in
                     sorted(reasons.items())[:4]) or "no view"


def calibrate_stereo(detections0: Sequence[Detection], detections1: Sequence[Detection],
                     target: Target, model: CalibrationModel = CalibrationModel()
                     ) -> StereoCalibration:
    """Calibrate the rig from the target's detections in each pair of images.

    Parameters
    ----------
    detections0, detections1 : per view, camera 0's and camera 1's :class:`Detection`.
    target : the target the detections refer to.
    model : what is estimated.

    Raises
    ------
    CalibrationError
        Too few usable views, naming why views were left out.
    """
    if len(detections0) != len(detections1):
        raise CalibrationError(f"{len(detections0)} views of camera 0 but {len(detections1)} of "
                               "camera 1: the views come in pairs")
    sizes = [{d.image_size for d in ds} for ds in (detections0, detections1)]
    for c, s in enumerate(sizes):
        if len(s) != 1:
            raise CalibrationError(f"camera {c}: views of different sizes {sorted(s)}")
    size0, size1 = (next(iter(s)) for s in sizes)
    K, dist, keep, reasons = [], [], [], []
    for c, (ds, size) in enumerate(((detections0, size0), (detections1, size1))):
        k, d, kept, why = _intrinsics(ds, target, size, model, f"camera {c}")
        K.append(k)
        dist.append(d)
        keep.append(kept)
        reasons.append(why)
    common = {}
    for v in range(len(detections0)):
        if v in keep[0] and v in keep[1]:
            ids = np.intersect1d(keep[0][v], keep[1][v])
            if len(ids) >= MIN_POINTS:
                common[v] = ids
    px_shift: dict = {}
    bias_corrected = False
    R = T = rvecs = tvecs = None
    stereo_reasons: dict = {}
    for _ in range(8):
        views = sorted(common)
        if len(views) < MIN_VIEWS:
            raise CalibrationError(
                f"the target was found in both cameras in {len(views)} views, at least "
                f"{MIN_VIEWS} needed (camera 0: {_why(reasons[0], detections0)}; camera 1: "
                f"{_why(reasons[1], detections1)})")
        objects, px0, px1 = [], [], []
        for v in views:
            o, p0 = _arrays(detections0[v], target, common[v])
            _, p1 = _arrays(detections1[v], target, common[v])
            if v in px_shift:
                p0 = p0 - px_shift[v][0].reshape(-1, 1, 2).astype(np.float32)
                p1 = p1 - px_shift[v][1].reshape(-1, 1, 2).astype(np.float32)
            objects.append(o)
            px0.append(p0)
            px1.append(p1)
        K, dist, R, T, rvecs, tvecs = _stereo(objects, px0, px1, K, dist, size0, model)
        res0 = _residuals(objects, px0, K[0], dist[0], rvecs, tvecs)
        res1 = _residuals(objects, px1, K[1], dist[1], rvecs, tvecs, R, T)
        rms = np.array([_rms(np.vstack([a, b])) for a, b in zip(res0, res1)])
        bad_views = _view_outliers(rms)
        bad_points = [a | b for a, b in zip(_point_outliers(res0), _point_outliers(res1))]
        changed = False
        for v, bad_v, bad_p, r in zip(views, bad_views, bad_points, rms):
            if bad_v:
                stereo_reasons[v] = (f"stereo reprojection RMS {r:.3f} px, more than "
                                     f"{VIEW_REJECT_FACTOR:g} times the median view's")
                del common[v]
                changed = True
            elif bad_p.any():
                common[v] = common[v][~bad_p]
                if v in px_shift:
                    px_shift[v] = tuple(s[~bad_p] for s in px_shift[v])
                changed = True
        if changed:
            continue
        if target.circular and target.dot_diameter_mm and not bias_corrected:
            radius = 0.5 * target.dot_diameter_mm
            for i, v in enumerate(views):
                X = objects[i].reshape(-1, 3).astype(float)
                r1, t1 = cv2.composeRT(rvecs[i], tvecs[i], cv2.Rodrigues(R)[0], T.reshape(3, 1))[:2]
                px_shift[v] = (circle_centre_bias(X, radius, rvecs[i], tvecs[i], K[0], dist[0]),
                               circle_centre_bias(X, radius, r1, t1, K[1], dist[1]))
            bias_corrected = True
            continue
        break
    if R is None or T is None or rvecs is None or tvecs is None:   # (the loop ran)
        raise CalibrationError("stereo calibration: no stereo solution")
    free = model.free
    target_deviation = None
    grid_points = target.object_points()
    # the stereo bundle at its optimum gives the covariance; refine_target also releases
    # the target's points and moves the optimum
    free_points = (gauge_mask(len(grid_points), _anchors(target, common)) if model.refine_target
                   else np.zeros((len(grid_points), 3), bool))
    bundle = released_bundle(grid_points, [common[v] for v in views],
                             [p.reshape(-1, 2) for p in px0], [p.reshape(-1, 2) for p in px1],
                             K, dist, R, T, rvecs, tvecs, free, free_points,
                             tie_aspect=model.fix_aspect, refine=model.refine_target)
    cov, sigma = bundle.cov, bundle.sigma_px
    if model.refine_target:
        K, dist, R, T = bundle.K, bundle.dist, bundle.R, bundle.T
        res0 = [r[0] for r in bundle.residuals]
        res1 = [r[1] for r in bundle.residuals]
        target_deviation = bundle.points - grid_points
    std_all = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    names = [n for n, f in zip(INTRINSIC_NAMES, free) if f]
    n = len(names)
    std = {f"cam{c}.{name}": float(std_all[c * n + i]) for c in range(2) for i, name in enumerate(names)}
    std["rvec"] = std_all[2 * n:2 * n + 3].tolist()
    std["T"] = std_all[2 * n + 3:2 * n + 6].tolist()
    t_hat = T / np.linalg.norm(T)
    rvec = cv2.Rodrigues(R)[0].ravel()
    r_hat = rvec / max(float(np.linalg.norm(rvec)), 1e-300)
    std["baseline_mm"] = float(np.sqrt(t_hat @ cov[2 * n + 3:2 * n + 6, 2 * n + 3:2 * n + 6] @ t_hat))
    std["stereo_angle_deg"] = float(np.degrees(np.sqrt(r_hat @ cov[2 * n:2 * n + 3, 2 * n:2 * n + 3] @ r_hat)))
    epi = np.vstack([epipolar_distances(a.reshape(-1, 2), b.reshape(-1, 2), K, dist, R, T)
                     for a, b in zip(px0, px1)])
    cam0 = Camera(K[0], dist[0], np.zeros(3), np.zeros(3), size0, "cam0")
    cam1 = Camera(K[1], dist[1], rvec, T, size1, "cam1")
    rows, residuals = [], []
    used = {v: i for i, v in enumerate(views)}
    for v in range(len(detections0)):
        found = (detections0[v].n_points, detections1[v].n_points)
        sources = (detections0[v].source, detections1[v].source)
        if v in used:
            i = used[v]
            rows.append(ViewReport(v, sources, found, len(common[v]),
                                   (_rms(res0[i]), _rms(res1[i])), "used"))
            residuals.append((px0[i].reshape(-1, 2), res0[i], px1[i].reshape(-1, 2), res1[i]))
        else:
            why = (reasons[0].get(v) or reasons[1].get(v) or stereo_reasons.get(v)
                   or f"fewer than {MIN_POINTS} target points seen by both cameras")
            rows.append(ViewReport(v, sources, found, 0, (np.nan, np.nan), why))
    all_res = np.vstack([np.vstack([a, b]) for a, b in zip(res0, res1)])
    result = StereoCalibration(cameras=(cam0, cam1), std=std, rms_px=_rms(all_res),
                               sigma_px=sigma, epipolar_px=epi, views=tuple(rows),
                               residuals=tuple(residuals), bias_corrected=bias_corrected,
                               target_deviation_mm=target_deviation)
    logger.info("stereo calibration: %d of %d views, RMS %.4f px, baseline %.3f mm, stereo angle "
                "%.3f deg, median epipolar distance %.4f px", len(views), len(detections0),
                result.rms_px, result.baseline_mm, result.stereo_angle_deg, float(np.median(epi)))
    return result
