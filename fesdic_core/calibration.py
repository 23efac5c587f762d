"""Calibration of the extrinsic parameters at fixed shape (Eq. 6), by Gauss-Newton.

The unknowns are the 6 extrinsic parameters ``p_c = [rvec, tvec]`` of each camera (12 in
all) or, when the stereo relation ``x_cam1 = R x_cam0 + t`` is known and kept, the 6 of
camera 0 only (camera 1 follows). The residual is the same as the shape's (Eq. 3):

    dr/dp0 = grad f0^T dx0/dp0,    dr/dp1 = -grad f1^T dx1/dp1,
    M dp = -sum_g w_g G_g r_g,     M = sum_g w_g G_g G_g^T.

Some pose directions are not seen by the gray levels: sliding the specimen in its own
surface changes neither image. The driver passes them as ``frozen`` directions and the
step is taken orthogonally to them (in Jacobi-scaled parameters), so they keep their
initial value (the landmark pose) instead of drifting with noise; what is left is
solved on the eigenvectors of the scaled ``M`` above ``rcond`` times the largest.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.linalg import null_space

from .quadrature import PixelQuadrature
from .residual import GrayLevelResidual, gray_level_residual
from .rig import place_camera1, stereo_extrinsic_jacobian

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class CalibrationResult:
    cameras: tuple
    residual: GrayLevelResidual
    iterations: int
    converged: bool


def truncated_solve(M: np.ndarray, rhs: np.ndarray, rcond: float,
                    frozen: np.ndarray | None = None) -> np.ndarray:
    """Solve ``M x = rhs`` orthogonally to ``frozen`` (n, k), on eigenvalues above ``rcond``.

    Both in Jacobi-scaled variables ``y = sqrt(diag M) x``.
    """
    scale = np.sqrt(np.maximum(np.diag(M), np.finfo(float).tiny))
    Ms = M / np.outer(scale, scale)
    Z = np.eye(len(M))
    if frozen is not None and frozen.size:
        Z = null_space((frozen * scale[:, None]).T)             # complement of the gauge
    values, vectors = np.linalg.eigh(Z.T @ Ms @ Z)
    keep = values > rcond * values.max()
    y = Z @ (vectors[:, keep] @ ((vectors[:, keep].T @ (Z.T @ (rhs / scale))) / values[keep]))
    return y / scale


def _parameter_gradients(res: GrayLevelResidual, stereo_jacobian: np.ndarray | None) -> np.ndarray:
    """Rows ``G_g = dr_g/dp`` of the calibration problem, (g, 6) or (g, 12)."""
    g0, g1 = res.dr_dp[:, :6], res.dr_dp[:, 6:]       # grad f0^T dx0/dp0, -grad f1^T dx1/dp1
    if stereo_jacobian is not None:
        return g0 + g1 @ stereo_jacobian                              # camera 1 follows camera 0
    return res.dr_dp


def calibrate_extrinsics(X: np.ndarray, quad: PixelQuadrature, images: Sequence, cameras: Sequence,
                         stereo: tuple[np.ndarray, np.ndarray] | None = None,
                         normalisation: str = "element", max_iter: int = 20,
                         tol_rad: float = 1e-7, tol_mm: float = 1e-5, rcond: float = 1e-9,
                         residual_rtol: float = 1e-4,
                         frozen: np.ndarray | None = None, extra_mask=None, log=None,
                         context: dict | None = None) -> CalibrationResult:
    """Gauss-Newton on Eq. 6 at fixed surface points ``X`` (g, 3).

    Parameters
    ----------
    stereo : (R, t), optional
        Stereo relation to keep (6 unknowns); None frees both cameras (12 unknowns).
    tol_rad, tol_mm : stagnation thresholds on the rotation and translation updates.
    frozen : (6 or 12, k), optional, parameter directions not to move (the gauge).
    residual_rtol : also stop when the residual changes by less than this fraction.
    """
    cams = list(cameras)
    probe = X[np.isfinite(X).all(axis=1)][:: max(1, len(X) // 2000)]   # logs each step in px
    converged, it, previous = False, 0, np.inf
    for it in range(1, max_iter + 1):
        res = gray_level_residual(X, quad, images, cams, normalisation, "extrinsic", extra_mask)
        if abs(previous - res.std_percent) <= residual_rtol * res.std_percent:
            converged = True
            break
        previous = res.std_percent
        D = None if stereo is None else stereo_extrinsic_jacobian(cams[0], *stereo)
        G = _parameter_gradients(res, D)
        w = np.where(res.mask, quad.weight_mm2, 0.0)
        M = G.T @ (w[:, None] * G)                                   # Gauss-Newton matrix of Eq. 6
        dp = truncated_solve(M, -(G.T @ (w * res.r)), rcond, frozen)
        before = cams
        if stereo is None:
            cams = [c.with_extrinsics(c.extrinsics + dp[6 * k:6 * k + 6]) for k, c in enumerate(cams)]
        else:
            cam0 = cams[0].with_extrinsics(cams[0].extrinsics + dp)
            cams = [cam0, place_camera1(cam0, cams[1], *stereo)]
        rot = float(np.max(np.abs(dp.reshape(-1, 6)[:, :3])))
        tra = float(np.max(np.abs(dp.reshape(-1, 6)[:, 3:])))
        shift = max(float(np.max(np.linalg.norm(a.project(probe) - b.project(probe), axis=1)))
                    for a, b in zip(cams, before)) if len(probe) else 0.0
        if log is not None:
            log.add(**(context or {}), stage="calibration", iteration=it,
                    residual_percent=res.std_percent, step=max(rot, tra), shift_px=shift,
                    n_points=int(res.mask.sum()))
        logger.debug("calibration it %d: residual %.4f%%, |drot| %.2e rad, |dt| %.2e mm, "
                     "points moved %.2e px", it, res.std_percent, rot, tra, shift)
        if rot < tol_rad and tra < tol_mm:
            converged = True
            break
    res = gray_level_residual(X, quad, images, cams, normalisation, None, extra_mask)
    return CalibrationResult(cameras=tuple(cams), residual=res, iterations=it, converged=converged)
