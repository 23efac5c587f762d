"""Values of calibration files: numbers, distortion, rotations and image sizes, checked.

Shared by the readers of :mod:`fesdic_core.cameras.io.formats` and
:mod:`fesdic_core.cameras.io.vic3d_dice`; every problem is a :class:`~fesdic_core.cameras.rig.CalibrationError`
whose message names the file and the field.
"""
from __future__ import annotations

import os

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.rig import CalibrationError

__all__ = ["OPENCV_DISTORTION_LENGTHS", "rotation_from_angles_deg", "as_finite", "as_dist5",
           "as_rotation", "as_size", "as_sizes", "make_camera", "existing_file"]

OPENCV_DISTORTION_LENGTHS = (4, 5, 8, 12, 14)


def rotation_from_angles_deg(alpha: float, beta: float, gamma: float) -> np.ndarray:
    """``R = Rz(gamma) Ry(beta) Rx(alpha)`` (3, 3), right-handed, angles in degrees."""
    return Rotation.from_euler("xyz", [alpha, beta, gamma], degrees=True).as_matrix()


def as_finite(values, n: int | None, path: str, field: str) -> np.ndarray:
    """``values`` as finite float64 numbers (flattened), ``n`` of them unless None."""
    if isinstance(values, (str, bytes)):
        raise CalibrationError(f"{path}: {field}: expected numbers, got {values!r}")
    try:
        a = np.array(values, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise CalibrationError(f"{path}: {field}: expected numbers, got {values!r}") from None
    if n is not None and a.size != n:
        raise CalibrationError(f"{path}: {field}: expected {n} numbers, got {a.size}")
    if not np.all(np.isfinite(a)):
        raise CalibrationError(f"{path}: {field}: non-finite value in {a.tolist()}")
    return a


def as_dist5(values, path: str, field: str) -> np.ndarray:
    """OpenCV's distortion (any of its lengths) as ``[k1, k2, p1, p2, k3]``."""
    d = as_finite(values, None, path, field)
    if d.size not in OPENCV_DISTORTION_LENGTHS:
        raise CalibrationError(f"{path}: {field}: expected 4, 5, 8, 12 or 14 coefficients, "
                               f"got {d.size}")
    if np.any(d[5:] != 0):
        raise CalibrationError(f"{path}: {field}: non-zero coefficients beyond [k1 k2 p1 p2 k3] "
                               f"({d[5:].tolist()}): the rational/thin-prism/tilt model is not "
                               f"supported")
    return np.concatenate([d[:5], np.zeros(5 - min(d.size, 5))])


def as_rotation(values, path: str, field: str) -> np.ndarray:
    """A 3x3 rotation matrix or a Rodrigues vector (3,), checked, as a rotation matrix."""
    a = as_finite(values, None, path, field)
    if a.size == 3:
        return cv2.Rodrigues(a.reshape(3, 1))[0]
    if a.size != 9:
        raise CalibrationError(f"{path}: {field}: expected a 3x3 matrix or 3 numbers, got {a.size}")
    R = a.reshape(3, 3)
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) <= 0:
        raise CalibrationError(f"{path}: {field}: not a rotation matrix: {R.tolist()}")
    return R


def as_size(value, path: str, field: str) -> tuple[int, int]:
    """Image size ``(w, h)``: two positive integers."""
    a = as_finite(value, 2, path, field)
    if np.any(a != np.round(a)) or np.any(a < 1):
        raise CalibrationError(f"{path}: {field}: expected two positive integers (w, h), "
                               f"got {a.tolist()}")
    return int(a[0]), int(a[1])


def as_sizes(image_size, path: str) -> list[tuple[int, int]] | None:
    """``image_size`` (w, h) or ((w0, h0), (w1, h1)) as two sizes, or None."""
    if image_size is None:
        return None
    try:
        pair = np.asarray(image_size, dtype=object).shape == (2, 2)
        sizes = [tuple(v) for v in image_size] if pair else [tuple(image_size)] * 2
    except TypeError:
        raise CalibrationError(f"{path}: image_size: expected (w, h) or ((w0, h0), (w1, h1)), "
                               f"got {image_size!r}") from None
    return [as_size(s, path, "image_size") for s in sizes]


def make_camera(path: str, field: str, K, dist, R, t, size, name: str) -> Camera:
    """Core camera with world-to-camera rotation ``R`` (3, 3); its errors name ``path: field``."""
    try:
        rvec = cv2.Rodrigues(np.asarray(R, dtype=np.float64).reshape(3, 3))[0].ravel()
        return Camera(K, dist, rvec, t, size, name)
    except ValueError as exc:
        raise CalibrationError(f"{path}: {field}: {exc}") from exc


def existing_file(path) -> str:
    """``path`` as a string, or a CalibrationError if it is not a file."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise CalibrationError(f"{path}: calibration file not found")
    return path
