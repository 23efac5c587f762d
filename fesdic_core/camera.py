"""Pinhole camera with OpenCV distortion and skew: the projection ``x = P_c(X)`` of Eq. 3.

World-to-camera transform ``x_cam = R(rvec) X + tvec`` (mm), then OpenCV's model::

    x' = x_cam / z_cam,  y' = y_cam / z_cam,  r2 = x'^2 + y'^2
    radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
    x'' = x' radial + 2 p1 x' y' + p2 (r2 + 2 x'^2)
    y'' = y' radial + p1 (r2 + 2 y'^2) + 2 p2 x' y'
    u = fx x'' + s y'' + cx,   v = fy y'' + cy          (s = K[0, 1], the skew)

Pixel centres at integer coordinates, ``(u, v)`` = (column, row). Everything is vectorised
over the points; ``cv2.Rodrigues`` gives ``R`` and its derivative with respect to ``rvec``.
The extrinsic parameters are ``p = [rvec, tvec]`` (6,), the unknowns of Eq. 6.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

logger = logging.getLogger(__name__)

__all__ = ["Camera", "rodrigues"]


def rodrigues(rvec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation matrix of ``rvec`` (3,) and its derivative ``dR[a, b]/drvec[i]`` as (3, 3, 3) [i, a, b]."""
    R, J = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    return R, J.reshape(3, 3, 3)


def _as_array(value, shape: tuple, field: str, name: str) -> np.ndarray:
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"camera {name!r}: {field} must be numbers of shape {shape}") from exc
    if a.shape != shape:
        raise ValueError(f"camera {name!r}: {field} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"camera {name!r}: {field} has non-finite entries: {a.tolist()}")
    a.flags.writeable = False
    return a


def _points(X: np.ndarray, dim: int = 3) -> np.ndarray:
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != dim:
        raise ValueError(f"points must have shape (n, {dim}), got {X.shape}")
    return X


@dataclass(frozen=True, eq=False)
class Camera:
    """Calibrated camera.

    Attributes
    ----------
    K : (3, 3) intrinsic matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` (px)
    dist : (5,) distortion ``[k1, k2, p1, p2, k3]`` (OpenCV order)
    rvec : (3,) rotation vector (world to camera)
    tvec : (3,) translation (mm), ``x_cam = R(rvec) X + tvec``
    image_size : (w, h) image size in px
    name : label used in messages and files
    """

    K: np.ndarray
    dist: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    image_size: tuple[int, int]
    name: str = "cam"

    def __post_init__(self) -> None:
        name = str(self.name)
        K = _as_array(self.K, (3, 3), "K", name)
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise ValueError(f"camera {name!r}: K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], "
                             f"got {K.tolist()}")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"camera {name!r}: K focal lengths must be > 0, got fx={K[0, 0]}, fy={K[1, 1]}")
        try:
            size = tuple(int(v) for v in self.image_size)
            ok = len(size) == 2 and all(s == v for s, v in zip(size, self.image_size)) and min(size) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"camera {name!r}: image_size must be two positive integers (w, h), "
                             f"got {self.image_size!r}")
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", _as_array(self.dist, (5,), "dist", name))
        object.__setattr__(self, "rvec", _as_array(self.rvec, (3,), "rvec", name))
        object.__setattr__(self, "tvec", _as_array(self.tvec, (3,), "tvec", name))
        object.__setattr__(self, "image_size", size)

    # ------------------------------------------------------------------ pose
    @property
    def R(self) -> np.ndarray:
        """(3, 3) world-to-camera rotation."""
        return cv2.Rodrigues(self.rvec.reshape(3, 1))[0]

    @property
    def extrinsics(self) -> np.ndarray:
        """(6,) extrinsic parameters ``p = [rvec, tvec]``."""
        return np.concatenate([self.rvec, self.tvec])

    def with_extrinsics(self, p: np.ndarray) -> "Camera":
        """Same intrinsics, extrinsics ``p = [rvec, tvec]`` (6,)."""
        p = np.asarray(p, dtype=np.float64).ravel()
        if p.shape != (6,):
            raise ValueError(f"camera {self.name!r}: extrinsics must have 6 entries, got {p.shape}")
        return Camera(self.K, self.dist, p[:3], p[3:], self.image_size, self.name)

    @property
    def center(self) -> np.ndarray:
        """(3,) optical centre in world coordinates, ``-R^T tvec``."""
        return -self.R.T @ self.tvec

    def to_camera(self, X: np.ndarray) -> np.ndarray:
        """(n, 3) points in the camera frame, ``R X + tvec``."""
        return _points(X) @ self.R.T + self.tvec

    def depth(self, X: np.ndarray) -> np.ndarray:
        """(n,) depth ``z_cam`` of world points (mm)."""
        return self.to_camera(X)[:, 2]

    def in_front(self, X: np.ndarray) -> np.ndarray:
        """(n,) bool, points strictly in front of the camera."""
        return self.depth(X) > 0.0

    # ------------------------------------------------------------ projection
    def _distort(self, xn: np.ndarray, with_jacobian: bool):
        """Distorted pixel coordinates of normalised ``xn`` (n, 2) and d(u, v)/d(x', y') (n, 2, 2)."""
        k1, k2, p1, p2, k3 = self.dist
        x, y = xn[:, 0], xn[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        K = self.K
        uv = np.column_stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]])
        if not with_jacobian:
            return uv, None
        drad = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))     # d radial / d r2, times 2
        D = np.empty((len(x), 2, 2))
        D[:, 0, 0] = radial + drad * x * x + 2.0 * p1 * y + 6.0 * p2 * x
        D[:, 0, 1] = drad * x * y + 2.0 * p1 * x + 2.0 * p2 * y
        D[:, 1, 0] = drad * x * y + 2.0 * p1 * x + 2.0 * p2 * y
        D[:, 1, 1] = radial + drad * y * y + 6.0 * p1 * y + 2.0 * p2 * x
        fx, skew, fy = K[0, 0], K[0, 1], K[1, 1]                 # A = [[fx, s], [0, fy]]
        AD = np.empty_like(D)
        AD[:, 0, :] = fx * D[:, 0, :] + skew * D[:, 1, :]
        AD[:, 1, :] = fy * D[:, 1, :]
        return uv, AD

    def _project_camera_frame(self, Xc: np.ndarray, with_jacobian: bool):
        """Pixels of camera-frame points (n, 2) and d(u, v)/d x_cam (n, 2, 3)."""
        z = Xc[:, 2]
        xn = Xc[:, :2] / z[:, None]
        uv, D = self._distort(xn, with_jacobian)
        if not with_jacobian:
            return uv, None
        # d(x', y')/d x_cam = [[1/z, 0, -x'/z], [0, 1/z, -y'/z]], applied to D explicitly
        inv_z = (1.0 / z)[:, None]
        J = np.empty((len(z), 2, 3))
        J[:, :, 0] = D[:, :, 0] * inv_z
        J[:, :, 1] = D[:, :, 1] * inv_z
        J[:, :, 2] = -(J[:, :, 0] * xn[:, :1] + J[:, :, 1] * xn[:, 1:])
        return uv, J

    def project(self, X: np.ndarray) -> np.ndarray:
        """Project world points ``X`` (n, 3) mm to pixels (n, 2)."""
        return self._project_camera_frame(self.to_camera(X), False)[0]

    def project_jacobian(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (n, 2) and the derivative ``dx/dX`` (n, 2, 3) px/mm."""
        uv, Jc = self._project_camera_frame(self.to_camera(X), True)
        return uv, (Jc.reshape(-1, 3) @ self.R).reshape(-1, 2, 3)

    def extrinsic_jacobian(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (n, 2) and the derivative ``dx/dp`` (n, 2, 6), ``p = [rvec, tvec]``."""
        X = _points(X)
        R, dR = rodrigues(self.rvec)
        uv, Jc = self._project_camera_frame(X @ R.T + self.tvec, True)
        dXc_dr = np.einsum("iab,nb->nai", dR, X)                  # d(R X)/d rvec, (n, 3, 3)
        return uv, np.concatenate([Jc @ dXc_dr, Jc], axis=2)

    # ------------------------------------------------------------ pyramids
    def scaled(self, level: int) -> "Camera":
        """Camera of the image after ``level`` 2x2 block-mean aggregations.

        With pixel centres at integers one aggregation maps ``x -> (x - 0.5) / 2``, so after
        ``level`` of them ``x -> (x - (2^level - 1) / 2) / 2^level``; the image size is
        halved (floor) at each level.
        """
        if int(level) != level or level < 0:
            raise ValueError(f"camera {self.name!r}: level must be a non-negative integer, got {level!r}")
        level = int(level)
        if level == 0:
            return self
        f = 2.0 ** level
        S = np.array([[1.0 / f, 0.0, -(f - 1.0) / (2.0 * f)],
                      [0.0, 1.0 / f, -(f - 1.0) / (2.0 * f)],
                      [0.0, 0.0, 1.0]])
        w, h = self.image_size
        size = (w >> level, h >> level)
        if min(size) < 1:
            raise ValueError(f"camera {self.name!r}: image {self.image_size} too small for level {level}")
        return Camera(S @ self.K, self.dist, self.rvec, self.tvec, size, self.name)

    def __repr__(self) -> str:
        K = self.K
        return (f"Camera(name={self.name!r}, f=({K[0, 0]:.6g}, {K[1, 1]:.6g}), c=({K[0, 2]:.6g}, "
                f"{K[1, 2]:.6g}), skew={K[0, 1]:.3g}, rvec={self.rvec.tolist()}, "
                f"tvec={self.tvec.tolist()}, image_size={self.image_size})")
