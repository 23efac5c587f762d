"""``[geometry] kind = "cad"`` with a ``pose``: the rig's triangulation places the part.

1. **Points.** SIFT stereo matches of the reference pair (:data:`MAX_FEATURES` features: a
   part's raised features need points of their own to set the pose) that agree with the
   calibrated epipolar geometry, triangulated
   (:func:`fesdic_core.cameras.triangulation.stereo_points`):
   with a rough pose, inside camera 0's silhouette of the selected faces at that pose,
   dilated by :data:`DILATE` of the image's diagonal; with ``pose = "auto"``, over the whole
   image (the part should fill most of camera 0's view; else give a rough pose).
2. **A start.** The rough pose, or (``"auto"``) the principal axes of the points matched to
   the faces' (:func:`fesdic_core.cameras.icp_start.principal_axes_starts`: each choice of signs,
   and turns about an axis when two moments nearly agree), each slid over a grid along
   the faces' plane (:func:`~fesdic_core.cameras.icp_start.best_start`), the best after a short ICP.
3. **ICP.** Point-to-plane ICP of the points onto the triangulated faces
   (:func:`georeg_app.inputs.cad.cad_triangles`,
   :func:`fesdic_core.cameras.icp.point_to_plane_icp`),
   then again on the points inside camera 0's silhouette of the faces at that pose (eroded
   by :data:`SILHOUETTE_MARGIN_PX`) only.
4. **Checks** (errors name the numbers): at least :data:`MIN_POINTS` points inside the
   silhouette, at least :data:`MIN_INLIER_SHARE` of them kept by the robust weights, and the
   fit's misfit (RMS of the kept points' residuals) against the triangulation's noise (the
   RMS of the matches' epipolar distances, px, times the depth a point moves per px along
   its epipolar line, :func:`~fesdic_core.cameras.triangulation.depth_per_px`): above
   :data:`WARN_MISFIT` times it a warning (the part departs from its CAD, or the pose is
   wrong), above :data:`MAX_MISFIT` times (and :data:`MIN_MISFIT_MM`) an error.
5. The cameras expressed in the CAD's frame; the gray-level calibration of the run refines
   their pose as it refines the landmarks' one.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import cv2
import numpy as np

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.icp import (IcpResult, TriangleSurface, point_to_plane_icp,
                                     rotation_matrix, rotation_vector)
from fesdic_core.cameras.icp_start import best_start, principal_axes_starts
from fesdic_core.cameras.triangulation import StereoPoints, depth_per_px, stereo_points
from fesdic_core.imaging.image import Image

from georeg_app.config.cad import AUTO_POSE, RoughPose
from georeg_app.config.measure import GeometryConfig
from georeg_app.errors import InputError
from georeg_app.inputs.cad import cad_face_indices, cad_triangles

logger = logging.getLogger(__name__)

__all__ = ["CadPose", "place_part", "silhouette", "in_frame", "MIN_POINTS", "MIN_INLIER_SHARE",
           "WARN_MISFIT", "MAX_MISFIT", "MIN_MISFIT_MM", "DILATE", "SILHOUETTE_MARGIN_PX",
           "DEFLECTION_MM", "MAX_FEATURES"]

MIN_POINTS = 50              # triangulated points on the part a pose needs
MIN_INLIER_SHARE = 0.5       # of them, at least this share fits the faces
WARN_MISFIT, MAX_MISFIT, MIN_MISFIT_MM = 3.0, 10.0, 0.05
DILATE = 0.05                # a rough pose's silhouette, dilated by this share of the diagonal
SILHOUETTE_MARGIN_PX = 3     # the posed silhouette, eroded by this many px
DEFLECTION_MM = 0.002        # chord deviation of the faces' triangulation (CAD kernel)
MAX_FEATURES = 20000         # SIFT features per image (the part's features need their points)
_WHERE = "[geometry] pose"


@dataclasses.dataclass(frozen=True, eq=False)
class CadPose:
    """How the part was placed.

    Attributes
    ----------
    cameras : the two cameras expressed in the CAD's frame.
    rotation, translation : (3, 3), (3,): ``X_calibration = R X_cad + t`` (the calibration's
        world frame, the cameras' as read).
    start : ``"auto"`` (principal axes) or ``"given"`` (the config's rough pose).
    points : the triangulated matches inside the posed silhouette (calibration frame).
    fit : the final ICP (points onto the faces).
    noise_mm : the triangulation's noise (see the module docstring).
    """

    cameras: tuple[Camera, Camera]
    rotation: np.ndarray
    translation: np.ndarray
    start: str
    points: StereoPoints
    fit: IcpResult
    noise_mm: float

    def pose_in_camera0(self) -> tuple[np.ndarray, np.ndarray]:
        """The part's pose in camera 0's frame as ``[geometry] pose`` takes it: the rotation
        vector (3,) deg and the translation (3,) mm of ``X_cam0 = R X_cad + t``."""
        cam0 = self.cameras[0]
        return np.degrees(rotation_vector(cam0.R)), np.asarray(cam0.tvec, dtype=float)

    def summary(self) -> dict:
        """The pose and the fit as JSON-ready numbers (for the outputs)."""
        rotation, translation = self.pose_in_camera0()
        return {"placed_by": "icp", "start": self.start,
                "pose_cam0": {"rotation_deg": rotation.tolist(),
                              "translation_mm": translation.tolist()},
                "cad_to_calibration": {"rotation_deg": np.degrees(rotation_vector(
                    self.rotation)).tolist(), "translation_mm": self.translation.tolist()},
                "points": int(self.points.n_points), "inliers": int(self.fit.inliers.sum()),
                "misfit_mm": self.fit.rms_mm, "noise_mm": self.noise_mm,
                "iterations": int(self.fit.iterations), "conditioning": self.fit.conditioning}


def in_frame(camera: Camera, rotation: np.ndarray, origin: np.ndarray) -> Camera:
    """``camera`` expressed in the frame ``X_world = rotation @ X_new + origin``."""
    R = camera.R @ rotation
    t = camera.R @ origin + camera.tvec
    return camera.with_extrinsics(np.concatenate([cv2.Rodrigues(R)[0].ravel(), t]))


def silhouette(camera: Camera, triangles: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Camera ``camera``'s pixels (h, w) bool covered by ``triangles`` (m, 3, 3) (those wholly
    in front of it)."""
    mask = np.zeros(shape, np.uint8)
    X = triangles.reshape(-1, 3)
    front = camera.in_front(X).reshape(-1, 3).all(axis=1)
    px = camera.project(X).reshape(-1, 3, 2)
    ok = front & np.all(np.isfinite(px), axis=(1, 2))
    if ok.any():
        cv2.fillPoly(mask, list(np.round(px[ok]).astype(np.int32)), 1)
    return mask > 0


def _posed(cameras: Sequence[Camera], R_icp: np.ndarray, t_icp: np.ndarray) -> tuple:
    """The cameras in the CAD's frame for the ICP motion ``X_cad = R X + t`` of the points."""
    return tuple(in_frame(c, R_icp.T, -R_icp.T @ t_icp) for c in cameras)


def _noise_mm(cameras: Sequence[Camera], points: StereoPoints) -> float:
    d = depth_per_px(cameras[0], cameras[1], points.px0, points.px1)
    return float(np.sqrt(np.mean(points.epipolar_px ** 2)) * np.median(d))


def _subset(points: StereoPoints, keep: np.ndarray) -> StereoPoints:
    return StereoPoints(points.px0[keep], points.px1[keep], points.xyz_mm[keep],
                        points.epipolar_px[keep], points.reprojection_px[keep], points.n_matches)


def _start(pose: RoughPose, cam0: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The ICP motion (points -> CAD) of a rough pose ``X_cam0 = R X_cad + t``."""
    R_p = rotation_matrix(np.radians(pose.rotation_deg))
    R_f = cam0.R.T @ R_p                                   # X_world = R_f X_cad + origin
    origin = cam0.R.T @ (np.asarray(pose.translation_mm, dtype=float) - cam0.tvec)
    return R_f.T, -R_f.T @ origin


def _check(fit: IcpResult, points: StereoPoints, noise: float) -> None:
    kept = int(fit.inliers.sum())
    if kept < MIN_INLIER_SHARE * points.n_points or kept < MIN_POINTS:
        raise InputError(f"{_WHERE}: the faces fit only {kept} of the {points.n_points} "
                         f"triangulated points on the part (at least {MIN_INLIER_SHARE:.0%} and "
                         f"{MIN_POINTS} needed): is it the part's CAD, in mm, and the rig's "
                         "calibration? (or give a rough pose, or landmarks)")
    if fit.rms_mm > max(MAX_MISFIT * noise, MIN_MISFIT_MM):
        raise InputError(f"{_WHERE}: the triangulated points lie {fit.rms_mm * 1e3:.1f} um RMS "
                         f"off the faces after ICP, {fit.rms_mm / max(noise, 1e-12):.1f} times "
                         f"the triangulation's noise ({noise * 1e3:.1f} um; at most "
                         f"{MAX_MISFIT:g} times and {MIN_MISFIT_MM * 1e3:.0f} um): the ICP "
                         "found no pose (give a rough pose, or landmarks)")
    if fit.rms_mm > WARN_MISFIT * noise:
        logger.warning("CAD pose: the points lie %.1f um RMS off the faces, %.1f times the "
                       "triangulation's noise (%.1f um): the part departs from its CAD (the "
                       "measurement corrects the nominal), or the pose is not right",
                       fit.rms_mm * 1e3, fit.rms_mm / max(noise, 1e-12), noise * 1e3)


def _too_few(points: StereoPoints, where: str) -> InputError:
    return InputError(f"{_WHERE}: too few stereo matches {where} to place the part: "
                      f"{points.n_points} triangulated of {points.n_matches} matched, at least "
                      f"{MIN_POINTS} needed (is the part in both images, textured, and the "
                      "calibration the rig's?)")


def place_part(geometry: GeometryConfig, cameras: Sequence[Camera], images: Sequence[Image]
             ) -> CadPose:
    """Place the CAD part of ``geometry`` (``kind = "cad"`` with a ``pose``) in the rig's
    frame (see the module docstring).

    Parameters
    ----------
    geometry : ``[geometry]``: the CAD file, its faces, ``pose`` ("auto" or a RoughPose).
    cameras : the calibrated pair as read (any world frame).
    images : the reference pair.

    Raises
    ------
    InputError
        Naming the numbers: too few matches, too few of them on the faces, a misfit far
        above the triangulation's noise.
    """
    triangles = cad_triangles(geometry.file, DEFLECTION_MM,
                              only=cad_face_indices(geometry.file, geometry.faces))
    surface = TriangleSurface.of(triangles)
    shape = images[0].shape
    values0, values1 = images[0].values, images[1].values
    auto = geometry.pose == AUTO_POSE
    if auto:
        points = stereo_points(cameras[0], cameras[1], values0, values1,
                               max_features=MAX_FEATURES)
        where = "in camera 0's image"
    else:
        R, t = _start(geometry.pose, cameras[0])
        rough = silhouette(_posed(cameras, R, t)[0], triangles, shape)
        size = int(np.ceil(DILATE * np.hypot(*shape)))
        mask = cv2.dilate(rough.astype(np.uint8), np.ones((2 * size + 1,) * 2, np.uint8)) > 0
        points = stereo_points(cameras[0], cameras[1], values0, values1, mask,
                               max_features=MAX_FEATURES)
        where = "near the part's silhouette at the rough pose"
    if points.n_points < MIN_POINTS:
        raise _too_few(points, where)
    if auto:
        (R, t), shares = best_start(points.xyz_mm, surface,
                                    principal_axes_starts(points.xyz_mm, surface))
        logger.info("CAD pose: %d starts from the principal axes; the best puts %.1f %% of "
                    "the points near the faces (the next %.1f %%)", len(shares),
                    100 * np.sort(shares)[-1], 100 * np.sort(shares)[-2])
    fit = point_to_plane_icp(points.xyz_mm, surface, R, t)
    cam0 = _posed(cameras, fit.rotation, fit.translation)[0]
    margin = np.ones((2 * SILHOUETTE_MARGIN_PX + 1,) * 2, np.uint8)
    inside = cv2.erode(silhouette(cam0, triangles, shape).astype(np.uint8), margin) > 0
    px = np.round(points.px0).astype(int)
    on_part = inside[np.clip(px[:, 1], 0, shape[0] - 1), np.clip(px[:, 0], 0, shape[1] - 1)]
    points = _subset(points, on_part)
    if points.n_points < MIN_POINTS:
        raise _too_few(points, "inside the part's silhouette at the ICP's pose")
    fit = point_to_plane_icp(points.xyz_mm, surface, fit.rotation, fit.translation)
    noise = _noise_mm(cameras, points)
    logger.info("CAD pose (ICP from %s): %d of %d points on the faces fit them to %.1f um RMS "
                "(triangulation noise %.1f um), %d iterations%s, conditioning %.2g",
                "the principal axes" if auto else "the rough pose", int(fit.inliers.sum()),
                points.n_points, fit.rms_mm * 1e3, noise * 1e3, fit.iterations,
                "" if fit.converged else " (not converged)", fit.conditioning)
    _check(fit, points, noise)
    posed = _posed(cameras, fit.rotation, fit.translation)
    result = CadPose(cameras=posed, rotation=fit.rotation.T,
                     translation=-fit.rotation.T @ fit.translation,
                     start="auto" if auto else "given", points=points, fit=fit, noise_mm=noise)
    rotation, translation = result.pose_in_camera0()
    logger.info("CAD pose: pose = {rotation_deg = %s, translation_mm = %s} (the part in camera "
                "0's frame)", np.round(rotation, 3).tolist(), np.round(translation, 3).tolist())
    return result
