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
from typing import Literal, overload

import cv2
import numpy as np

logger = logging.getLogger(__name__)

__all__ = ["Camera", "Linearisation", "rodrigues"]


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
    def linearise(self, X: np.ndarray) -> tuple[np.ndarray, "Linearisation"]:
        """Pixels (n, 2) of world points ``X`` (n, 3) and the projection linearised there.

        The :class:`Linearisation` gives vector-Jacobian products ``J^T g`` without forming
        ``J``: what the Gauss-Newton operators need (``J^T grad f``, Eqs. 6 and 8).
        """
        return self._project(X, True)

    @overload
    def _project(self, X: np.ndarray, linearise: Literal[True]) -> tuple[np.ndarray, Linearisation]:
        ...

    @overload
    def _project(self, X: np.ndarray, linearise: Literal[False]) -> tuple[np.ndarray, None]:
        ...

    def _project(self, X: np.ndarray, linearise: bool) -> tuple[np.ndarray, Linearisation | None]:
        X = _points(X)
        R, t = self.R, self.tvec
        inv_z = X @ R[2]                                          # camera frame, one axis a pass
        inv_z += t[2]
        np.reciprocal(inv_z, out=inv_z)
        xn = X @ R[0]
        xn += t[0]
        xn *= inv_z                                               # x' = x_cam / z_cam
        yn = X @ R[1]
        yn += t[1]
        yn *= inv_z
        k1, k2, p1, p2, k3 = self.dist
        fx, skew, cx, fy, cy = self.K[0, 0], self.K[0, 1], self.K[0, 2], self.K[1, 1], self.K[1, 2]
        uv = np.empty((len(X), 2))
        if not self.dist.any():                                   # pinhole: D = identity
            uv[:, 0] = fx * xn + skew * yn + cx
            uv[:, 1] = fy * yn + cy
            return uv, (Linearisation(self, X, R, inv_z, xn, yn, None) if linearise else None)
        xx, yy, xy = xn * xn, yn * yn, xn * yn
        r2 = xx + yy
        radial = k3 * r2                                          # 1 + k1 r2 + k2 r2^2 + k3 r2^3
        radial += k2
        radial *= r2
        radial += k1
        radial *= r2
        radial += 1.0
        xd = xn * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx)
        yd = yn * radial + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy
        uv[:, 0] = fx * xd + skew * yd + cx
        uv[:, 1] = fy * yd + cy
        if not linearise:
            return uv, None
        drad = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))     # d radial / d r2, times 2
        D = (radial + drad * xx + 2.0 * p1 * yn + 6.0 * p2 * xn,           # d(x'', y'')/d(x', y')
             drad * xy + 2.0 * p1 * xn + 2.0 * p2 * yn,                     # (symmetric)
             radial + drad * yy + 6.0 * p1 * yn + 2.0 * p2 * xn)
        return uv, Linearisation(self, X, R, inv_z, xn, yn, D)

    def project(self, X: np.ndarray) -> np.ndarray:
        """Project world points ``X`` (n, 3) mm to pixels (n, 2)."""
        return self._project(X, False)[0]

    def project_jacobian(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (n, 2) and the derivative ``dx/dX`` (n, 2, 3) px/mm."""
        uv, lin = self.linearise(X)
        return uv, lin.dense(lin.pull_point)

    def extrinsic_jacobian(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (n, 2) and the derivative ``dx/dp`` (n, 2, 6), ``p = [rvec, tvec]``."""
        uv, lin = self.linearise(X)
        return uv, lin.dense(lin.pull_extrinsic)

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


@dataclass(frozen=True, eq=False)
class Linearisation:
    """The projection ``x = P(X)`` linearised at points X, as vector-Jacobian products.

    With ``x_cam = R X + t``, ``x' = x_cam / z``, distortion ``d = D(x')`` and pixels
    ``x = A d + c`` (``A = [[fx, s], [0, fy]]``), a pixel-space row vector ``g`` (n, 2)
    (an image gradient) pulls back to the camera frame as

        c = (1/z) [b_x, b_y, -(x' b_x + y' b_y)],   b = D^T A^T g,

    then to the world point (``R^T c``) or to the extrinsics ``p = [rvec, tvec]``
    (``[(dR/drvec X)^T c, c]``). ``D`` is None for a camera without distortion.
    """

    camera: Camera
    X: np.ndarray
    R: np.ndarray
    inv_z: np.ndarray
    xn: np.ndarray
    yn: np.ndarray
    D: tuple | None

    def _camera_frame(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        K = self.camera.K
        ax = K[0, 0] * g[:, 0]                                    # A^T g
        ay = K[0, 1] * g[:, 0] + K[1, 1] * g[:, 1]
        if self.D is not None:
            d00, d01, d11 = self.D
            ax, ay = d00 * ax + d01 * ay, d01 * ax + d11 * ay     # D^T A^T g
        bx, by = ax * self.inv_z, ay * self.inv_z
        return bx, by, -(self.xn * bx + self.yn * by)

    def pull_point(self, g: np.ndarray) -> np.ndarray:
        """``(dx/dX)^T g`` (n, 3) for pixel-space vectors ``g`` (n, 2)."""
        return np.column_stack(self._camera_frame(g)) @ self.R

    def pull_extrinsic(self, g: np.ndarray) -> np.ndarray:
        """``(dx/dp)^T g`` (n, 6), ``p = [rvec, tvec]``, for pixel-space vectors ``g`` (n, 2)."""
        c = np.column_stack(self._camera_frame(g))
        _, dR = rodrigues(self.camera.rvec)                       # dR[i] = dR / drvec_i
        # c . (dR_i X) = sum_ab (c_a X_b) dR_i[a, b]; einsum, not a thin (n, 3) @ (3, 9)
        # matmul, which a multithreaded BLAS slows down many times inside the core's threads
        cX = (c[:, :, None] * self.X[:, None, :]).reshape(-1, 9)
        rot = np.einsum("nk,ik->ni", cX, dR.reshape(3, 9))
        return np.concatenate([rot, c], axis=1)

    def dense(self, pull) -> np.ndarray:
        """The Jacobian itself (n, 2, k): the pull-backs of the two pixel axes."""
        n = len(self.inv_z)
        rows = [pull(np.broadcast_to(e, (n, 2))) for e in np.eye(2)]
        return np.stack(rows, axis=1)
