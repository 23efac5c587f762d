"""Stereo rig: the stereo transform, calibration files and an initial pose of the cameras.

Conventions: ``x_cam = R(rvec) X_world + tvec`` for each camera, and the stereo transform
``(R, t)`` maps camera-0 coordinates to camera-1 coordinates, ``x_cam1 = R x_cam0 + t``.
Keeping ``(R, t)`` fixed while camera 0 moves is how the extrinsic calibration (Eq. 6)
respects a calibrated rig; :func:`stereo_extrinsic_jacobian` is ``d p1 / d p0``.

Camera file (JSON, read by :func:`read_cameras_json`, written atomically by
:func:`write_cameras_json`)::

    {"cameras": [
        {"name": "cam0",
         "image_size_px": [w, h],
         "K": [[fx, s, cx], [0, fy, cy], [0, 0, 1]],
         "dist": [k1, k2, p1, p2, k3],
         "rvec": [r1, r2, r3],
         "tvec_mm": [t1, t2, t3]},
        {...}]}

with OpenCV's distortion model (see :mod:`fesdic_core.cameras.camera`), ``s`` the skew, pixels with
centres at integers and ``x_cam = R(rvec) X_world + tvec_mm``.

The pyvale calibration text (:func:`read_pyvale_csv`) is two columns ``name,value``:
``cam{0,1}_{fx,fy,fs,cx,cy}_px``, ``cam{0,1}_{k1,k2,p1,p2,k3}``, ``t{x,y,z}_mm`` and
``{theta,phi,psi}_deg`` with ``R = Rz(psi) Ry(phi) Rx(theta)``; it holds no pose of the
specimen, so camera 0 is put at the identity pose (world = camera-0 frame).
"""
from __future__ import annotations

import csv
import json
import logging
import os
from collections.abc import Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares

from fesdic_core.atomic import write_text_atomic
from fesdic_core.cameras.camera import Camera
from fesdic_core.errors import FesdicCoreError

logger = logging.getLogger(__name__)

__all__ = ["CalibrationError", "stereo_transform", "place_camera1", "apply_stereo",
           "stereo_extrinsic_jacobian", "read_cameras_json", "write_cameras_json",
           "read_pyvale_csv", "initial_pose", "initial_rig_pose"]


class CalibrationError(FesdicCoreError, ValueError):
    """A calibration file or value that cannot be used; the message names the file and field."""


# ------------------------------------------------------------------ stereo transform
def stereo_transform(cam0: Camera, cam1: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Stereo transform ``(R (3, 3), t (3,))`` with ``x_cam1 = R x_cam0 + t``."""
    R = cam1.R @ cam0.R.T
    return R, cam1.tvec - R @ cam0.tvec


def _compose(cam0: Camera, R: np.ndarray, t: np.ndarray):
    rvec_s = cv2.Rodrigues(np.asarray(R, dtype=np.float64).reshape(3, 3))[0]
    return cv2.composeRT(cam0.rvec.reshape(3, 1), cam0.tvec.reshape(3, 1), rvec_s,
                         np.asarray(t, dtype=np.float64).reshape(3, 1))


def place_camera1(cam0: Camera, cam1: Camera, R: np.ndarray, t: np.ndarray) -> Camera:
    """Camera 1 (its intrinsics, name and size) placed by the stereo transform from camera 0.

    ``R1 = R R0`` and ``t1 = R t0 + t`` (``cv2.composeRT``).
    """
    out = _compose(cam0, R, t)
    return cam1.with_extrinsics(np.concatenate([out[0].ravel(), out[1].ravel()]))


apply_stereo = place_camera1          # the name of release 0.1, kept for one release


def stereo_extrinsic_jacobian(cam0: Camera, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``d p1 / d p0`` (6, 6) for ``p = [rvec, tvec]`` at fixed stereo transform ``(R, t)``."""
    _, _, dr3dr1, dr3dt1, _, _, dt3dr1, dt3dt1, _, _ = _compose(cam0, R, t)
    return np.block([[dr3dr1, dr3dt1], [dt3dr1, dt3dt1]])


# ------------------------------------------------------------------ JSON camera files
def _numbers(value, shape: tuple, where: str, path: str) -> np.ndarray:
    text = "x".join(str(s) for s in shape)
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != shape or isinstance(value, (str, bytes)):
        raise CalibrationError(f"{path}: {where}: expected {text} numbers, got {value!r}")
    if not np.all(np.isfinite(a)):
        raise CalibrationError(f"{path}: {where}: non-finite value in {value!r}")
    return a


def _camera_from_dict(d, i: int, path: str) -> Camera:
    where = f"cameras[{i}]"
    if not isinstance(d, dict):
        raise CalibrationError(f"{path}: {where}: expected an object, got {type(d).__name__}")
    for key in ("image_size_px", "K", "dist", "rvec", "tvec_mm"):
        if key not in d:
            raise CalibrationError(f"{path}: {where}.{key}: missing")
    size = _numbers(d["image_size_px"], (2,), f"{where}.image_size_px", path)
    if np.any(size != np.round(size)) or np.any(size < 1):
        raise CalibrationError(f"{path}: {where}.image_size_px: expected two positive integers, "
                               f"got {d['image_size_px']!r}")
    name = d.get("name", f"cam{i}")
    try:
        return Camera(_numbers(d["K"], (3, 3), f"{where}.K", path),
                      _numbers(d["dist"], (5,), f"{where}.dist", path),
                      _numbers(d["rvec"], (3,), f"{where}.rvec", path),
                      _numbers(d["tvec_mm"], (3,), f"{where}.tvec_mm", path),
                      (int(size[0]), int(size[1])), str(name))
    except CalibrationError:
        raise
    except ValueError as exc:
        raise CalibrationError(f"{path}: {where}: {exc}") from exc


def read_cameras_json(path: str | os.PathLike) -> list[Camera]:
    """Cameras of a JSON camera file (format in the module docstring).

    Raises ``FileNotFoundError`` or :class:`CalibrationError` naming the file and field.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"camera file not found: {path}")
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: not valid JSON: {exc}") from exc
    if not isinstance(data, dict) or "cameras" not in data:
        raise CalibrationError(f"{path}: cameras: missing (expected {{\"cameras\": [...]}})")
    if not isinstance(data["cameras"], list) or not data["cameras"]:
        raise CalibrationError(f"{path}: cameras: expected a non-empty list")
    return [_camera_from_dict(d, i, path) for i, d in enumerate(data["cameras"])]


def write_cameras_json(path: str | os.PathLike, cameras: Sequence[Camera]) -> None:
    """Write ``cameras`` to a JSON camera file (atomically; full float precision)."""
    entries = [{"name": c.name, "image_size_px": list(c.image_size), "K": c.K.tolist(),
                "dist": c.dist.tolist(), "rvec": c.rvec.tolist(), "tvec_mm": c.tvec.tolist()}
               for c in cameras]
    write_text_atomic(path, json.dumps({"cameras": entries}, indent=2) + "\n")


# ------------------------------------------------------------------ pyvale calibration text
def _elementary(axis: int, angle_deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]                      # right-handed rotation about axis
    M = np.eye(3)
    M[i, i], M[i, j], M[j, i], M[j, j] = c, -s, s, c
    return M


def read_pyvale_csv(path: str | os.PathLike, image_size) -> tuple[Camera, Camera]:
    """Stereo rig of a pyvale ``name,value`` calibration text.

    Parameters
    ----------
    path : calibration file
    image_size : (w, h) of both cameras, or ((w0, h0), (w1, h1))

    Returns
    -------
    (cam0, cam1) : cam0 at the identity pose, cam1 placed by the stereo transform
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"calibration file not found: {path}")
    values: dict[str, float] = {}
    with open(path, newline="", encoding="utf-8") as fh:
        for line, row in enumerate(csv.reader(fh), start=1):
            if not row or not row[0].strip() or row[0].lstrip().startswith("#"):
                continue
            if len(row) < 2:
                raise CalibrationError(f"{path}: line {line}: expected 'name,value', got {row!r}")
            try:
                values[row[0].strip()] = float(row[1])
            except ValueError:
                if line > 1:                                    # the first line may be a header
                    raise CalibrationError(f"{path}: line {line}: {row[0].strip()}: "
                                           f"not a number: {row[1]!r}") from None

    def get(key: str) -> float:
        if key not in values:
            raise CalibrationError(f"{path}: missing key {key!r}")
        if not np.isfinite(values[key]):
            raise CalibrationError(f"{path}: {key}: non-finite value {values[key]}")
        return values[key]

    one_size = np.asarray(image_size).ndim == 1
    sizes = [tuple(image_size)] * 2 if one_size else [tuple(s) for s in image_size]
    cams = []
    for c in (0, 1):
        p = f"cam{c}_"
        K = np.array([[get(p + "fx_px"), get(p + "fs_px"), get(p + "cx_px")],
                      [0.0, get(p + "fy_px"), get(p + "cy_px")], [0.0, 0.0, 1.0]])
        dist = np.array([get(p + k) for k in ("k1", "k2", "p1", "p2", "k3")])
        try:
            cams.append(Camera(K, dist, np.zeros(3), np.zeros(3), sizes[c], f"cam{c}"))
        except ValueError as exc:
            raise CalibrationError(f"{path}: cam{c}: {exc}") from exc
    R = (_elementary(2, get("psi_deg")) @ _elementary(1, get("phi_deg"))
         @ _elementary(0, get("theta_deg")))
    t = np.array([get("tx_mm"), get("ty_mm"), get("tz_mm")])
    return cams[0], place_camera1(cams[0], cams[1], R, t)


# ------------------------------------------------------------------ initial pose
def _landmarks(xyz, px, name: str, allow_missing: bool = False) -> tuple[np.ndarray, np.ndarray]:
    xyz = np.asarray(xyz, dtype=np.float64)
    px = np.asarray(px, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or px.shape != (len(xyz), 2):
        raise CalibrationError(f"{name}: expected xyz_mm (n, 3) and px (n, 2), got {xyz.shape} "
                               f"and {px.shape}")
    if not np.all(np.isfinite(xyz)):
        raise CalibrationError(f"{name}: xyz_mm has {np.count_nonzero(~np.isfinite(xyz))} non-finite values")
    seen = np.all(np.isfinite(px), axis=1)
    if not allow_missing and not seen.all():
        raise CalibrationError(f"{name}: px has {np.count_nonzero(~np.isfinite(px))} non-finite values")
    return xyz, px


def _without_skew(camera: Camera, px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels and K of the skew-free equivalent camera (cv2's PnP ignores ``K[0, 1]``)."""
    K = camera.K
    yd = (px[:, 1] - K[1, 2]) / K[1, 1]
    K0 = K.copy()
    K0[0, 1] = 0.0
    return np.column_stack([px[:, 0] - K[0, 1] * yd, px[:, 1]]), K0


def initial_pose(camera: Camera, xyz_mm: np.ndarray, px: np.ndarray) -> Camera:
    """Pose of ``camera`` from ``n >= 4`` landmarks ``xyz_mm`` (n, 3) seen at ``px`` (n, 2).

    ``cv2.solvePnP`` (SQPnP) then Levenberg-Marquardt refinement, on the skew-free
    equivalent pixels so that the skew is honoured.
    """
    xyz, px = _landmarks(xyz_mm, px, f"initial_pose({camera.name})")
    if len(xyz) < 4:
        raise CalibrationError(f"initial_pose({camera.name}): need at least 4 landmarks, got {len(xyz)}")
    uv, K0 = _without_skew(camera, px)
    obj, img = xyz.reshape(-1, 1, 3), uv.reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K0, camera.dist, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        raise CalibrationError(f"initial_pose({camera.name}): cv2.solvePnP found no pose")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K0, camera.dist, rvec, tvec)
    posed = camera.with_extrinsics(np.concatenate([rvec.ravel(), tvec.ravel()]))
    rms = float(np.sqrt(np.mean(np.sum((posed.project(xyz) - px) ** 2, axis=1))))
    logger.info("initial pose of %s from %d landmarks: rms reprojection %.3g px", camera.name, len(xyz), rms)
    return posed


def initial_rig_pose(cam0: Camera, cam1: Camera, xyz_mm: np.ndarray, px0: np.ndarray,
                     px1: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[Camera, Camera]:
    """Pose of the rig from landmarks seen by both cameras, keeping ``x_cam1 = R x_cam0 + t``.

    Rows of ``px0``/``px1`` that are NaN mark landmarks not seen in that view. Starts from
    :func:`initial_pose` on the view with more landmarks (>= 4), then minimises both views'
    reprojection errors over camera 0's 6 extrinsics (``scipy.optimize.least_squares``,
    analytic Jacobian ``[dx0/dp0; dx1/dp1 dp1/dp0]``).

    Returns
    -------
    (cam0, cam1) : posed cameras
    """
    xyz, px0 = _landmarks(xyz_mm, px0, "initial_rig_pose: view 0", allow_missing=True)
    _, px1 = _landmarks(xyz_mm, px1, "initial_rig_pose: view 1", allow_missing=True)
    seen0, seen1 = np.all(np.isfinite(px0), axis=1), np.all(np.isfinite(px1), axis=1)
    if max(seen0.sum(), seen1.sum()) < 4:
        raise CalibrationError(f"initial_rig_pose: need at least 4 landmarks in one view, got "
                               f"{seen0.sum()} and {seen1.sum()}")
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64).ravel()
    if seen0.sum() >= seen1.sum():
        start = initial_pose(cam0, xyz[seen0], px0[seen0]).extrinsics
    else:                                                      # R0 = R^T R1, t0 = R^T (t1 - t)
        posed1 = initial_pose(cam1, xyz[seen1], px1[seen1])
        R0 = R.T @ posed1.R
        start = np.concatenate([cv2.Rodrigues(R0)[0].ravel(), R.T @ (posed1.tvec - t)])

    def cameras(p):
        c0 = cam0.with_extrinsics(p)
        return c0, place_camera1(c0, cam1, R, t)

    def residuals(p):
        c0, c1 = cameras(p)
        return np.concatenate([(c0.project(xyz[seen0]) - px0[seen0]).ravel(),
                               (c1.project(xyz[seen1]) - px1[seen1]).ravel()])

    def jacobian(p):
        c0, c1 = cameras(p)
        J0 = c0.extrinsic_jacobian(xyz[seen0])[1].reshape(-1, 6)
        J1 = c1.extrinsic_jacobian(xyz[seen1])[1].reshape(-1, 6)
        return np.vstack([J0, J1 @ stereo_extrinsic_jacobian(c0, R, t)])

    fit = least_squares(residuals, start, jac=jacobian, method="lm", x_scale="jac",
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    rms = float(np.sqrt(np.mean(fit.fun ** 2) * 2))
    logger.info("initial rig pose from %d + %d observations: rms reprojection %.3g px",
                seen0.sum(), seen1.sum(), rms)
    return cameras(fit.x)
