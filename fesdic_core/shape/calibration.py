"""Calibration of the extrinsic parameters at fixed shape (Eq. 6), by Gauss-Newton.

The unknowns are the 6 extrinsic parameters ``p_c = [rvec, tvec]`` of each camera (12 in
all) or, when the stereo relation ``x_cam1 = R x_cam0 + t`` is known and kept, the 6 of
camera 0 only (camera 1 follows). The residual is the same as the shape's (Eq. 3):

    dr/dp0 = grad f0^T dx0/dp0,    dr/dp1 = -grad f1^T dx1/dp1,
    M dp = -sum_g w_g G_g r_g,     M = sum_g w_g G_g G_g^T.

When the stereo relation is kept, moving camera 0 by ``dp0`` (camera 1 following) is the
rigid motion of the specimen ``X' = R0^T (R0(p0 + dp0) X + t0(p0 + dp0) - t0)`` seen by
fixed cameras, so the rows need no extrinsic derivative of the images: with
``c = R0 dr/dX`` (the shape's derivative, Eq. 8, in camera 0's frame)

    dr/drvec_i = c . (dR0/drvec_i X),    dr/dt0 = c,

i.e. ``G = [X x dr/dX, dr/dX] T`` with a constant ``T`` (6, 6) (:func:`rig_motion`), so
``M = T^T (sum w u u^T) T`` from the moments ``u = [X x dr/dX, dr/dX]``; and the residual
the calibration ends on carries ``dr/dX`` for the shape step that follows.

Some pose directions are not seen by the gray levels: sliding the specimen in its own
surface changes neither image. The driver passes them as ``frozen`` directions and the
step is taken orthogonally to them (in Jacobi-scaled parameters), so they keep their
initial value (the landmark pose) instead of drifting with noise; what is left is
solved on the eigenvectors of the scaled ``M`` above ``rcond`` times the largest.
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.linalg import null_space

from fesdic_core.cameras.camera import rodrigues
from fesdic_core.cameras.rig import place_camera1
from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.residual.graylevel import GrayLevelResidual, gray_level_residual
from fesdic_core.shape.operators import chi_square
from fesdic_core.solve.damping import damped_step, relaxed

logger = logging.getLogger(__name__)

__all__ = ["CalibrationResult", "truncated_solve", "rig_motion", "rigid_rig_gradients",
           "pose_normal_equations", "calibrate_extrinsics"]


@dataclass(frozen=True)
class CalibrationResult:
    """End of the calibration: the cameras, the residual at them (with ``dr_dX`` when the
    stereo relation was kept, for the shape step that follows), iterations, stagnation."""

    cameras: tuple
    residual: GrayLevelResidual
    iterations: int
    converged: bool
    steps: int = 0                         # accepted steps (0: the poses did not move)


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
    """Rows ``G_g = dr_g/dp`` of the calibration problem, (g, 6) or (g, 12), from the
    extrinsic derivative ``res.dr_dp``."""
    if res.dr_dp is None:
        raise ValueError("calibration: the residual has no dr/dp (jacobian='extrinsic' needed)")
    g0, g1 = res.dr_dp[:, :6], res.dr_dp[:, 6:]       # grad f0^T dx0/dp0, -grad f1^T dx1/dp1
    if stereo_jacobian is not None:
        return g0 + g1 @ stereo_jacobian                              # camera 1 follows camera 0
    return res.dr_dp


def rig_motion(camera0) -> np.ndarray:
    """``T`` (6, 6) with ``dr/dp0 = [X x dr/dX, dr/dX] T`` (module docstring).

    Rodrigues' derivative is ``dR0/drvec_i = [v_i]_x R0``, so with ``c = R0 dr/dX``
    ``c . (dR0/drvec_i X) = v_i . (R0 X x c) = (R0^T v_i) . (X x dr/dX)``.
    """
    R0, dR = rodrigues(camera0.rvec)
    S = dR @ R0.T                                              # [v_i]_x, (3, 3, 3)
    V = np.stack([S[:, 2, 1], S[:, 0, 2], S[:, 1, 0]], axis=1)  # rows v_i
    T = np.zeros((6, 6))
    T[:3, :3] = R0.T @ V.T                                     # columns R0^T v_i
    T[3:, 3:] = R0.T                                           # c = R0 dr/dX
    return T


def _moments(dr_dX: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``u = [X x dr/dX, dr/dX]`` (g, 6): the residual's derivative along the rigid motions."""
    return np.concatenate([np.cross(X, dr_dX), dr_dX], axis=1)


def rigid_rig_gradients(dr_dX: np.ndarray, X: np.ndarray, camera0) -> np.ndarray:
    """Rows ``G_g = dr_g/dp0`` (g, 6) of the stereo-kept calibration from ``dr/dX`` (g, 3):
    the rig's motion is the specimen's rigid motion (module docstring)."""
    return _moments(dr_dX, X) @ rig_motion(camera0)


_ROWS = 1 << 12      # points per block of the normal equations: (6, rows) @ (rows, 6) stays
                     # below the size at which OpenBLAS uses its threads (slow when loaded)


def pose_normal_equations(res: GrayLevelResidual, X: np.ndarray, cameras: Sequence,
                          stereo: tuple | None, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``M = sum_g w_g G_g G_g^T`` and ``-sum_g w_g G_g r_g`` of Eq. 6, block by block (with
    the stereo relation kept, ``G = u T`` and ``M = T^T (sum w u u^T) T``)."""
    k = 6 if stereo is not None else 12
    derivative = res.dr_dX if stereo is not None else res.dr_dp
    if derivative is None:
        raise ValueError("calibration: the residual has no "
                         + ("dr/dX" if stereo is not None else "dr/dp"))
    M, rhs = np.zeros((k, k)), np.zeros(k)
    for start in range(0, len(w), _ROWS):
        rows = slice(start, start + _ROWS)
        G = _moments(derivative[rows], X[rows]) if stereo is not None else derivative[rows]
        wG = w[rows, None] * G
        M += G.T @ wG                                           # Gauss-Newton matrix of Eq. 6
        rhs -= wG.T @ res.r[rows]
    if stereo is not None:
        T = rig_motion(cameras[0])
        M, rhs = T.T @ M @ T, T.T @ rhs
    return M, rhs


def _shift_px(cameras, before, probe: np.ndarray) -> float:
    """Largest shift (px) of the projections of ``probe`` (k, 3) between two camera sets."""
    if not len(probe):
        return 0.0
    return max(float(np.max(np.linalg.norm(a.project(probe) - b.project(probe), axis=1)))
               for a, b in zip(cameras, before))


def calibrate_extrinsics(X: np.ndarray, quad: PixelQuadrature, images: Sequence, cameras: Sequence,
                         stereo: tuple[np.ndarray, np.ndarray] | None = None,
                         normalisation: str = "element", max_iter: int = 20,
                         tol_rad: float = 1e-7, tol_mm: float = 1e-5, undamped_px: float = 0.0,
                         rcond: float = 1e-9,
                         residual_rtol: float = 1e-4, max_damping: int = 8,
                         frozen: np.ndarray | None = None, extra_mask=None, log=None,
                         context: dict | None = None,
                         start: GrayLevelResidual | None = None) -> CalibrationResult:
    """Gauss-Newton on Eq. 6 at fixed surface points ``X`` (g, 3).

    Parameters
    ----------
    stereo : (R, t), optional
        Stereo relation to keep (6 unknowns); None frees both cameras (12 unknowns).
    tol_rad, tol_mm : stagnation thresholds on the rotation and translation updates.
    undamped_px : a Gauss-Newton step that would move no point of ``X`` by more than this
        many pixels (``cameras``' own) in either camera is not damped: if it does not lower
        the residual, p has stagnated (the linearised model's predicted fall is then below
        what the images resolve). 0: every step that raises the residual is damped. A caller
        that iterates the calibration inside a loop with a tolerance in pixels passes that
        tolerance: a smaller step cannot change the loop's verdict.
    frozen : (6 or 12, k), optional, parameter directions not to move (the gauge).
    residual_rtol : also stop when the residual changes by less than this fraction.
    max_damping : a step that raises the residual is retried with the Levenberg-Marquardt
        factor ``mu`` (``M + mu diag M``) ten times larger, at most this many times; the
        residual never grows (the divergence guard).
    start : the residual at ``cameras`` when the caller has it (same points, images, mask
        and normalisation, with ``dr_dX`` when the stereo relation is kept, else ``dr_dp``).

    Notes
    -----
    A Gauss-Newton step below the stagnation thresholds, or whose predicted fall of the cost
    is below one unit of chi-square (the data cannot tell p from p + dp, as for the shape,
    :func:`fesdic_core.shape.operators.predicted_chi_square_change`), is not taken (nor its residual
    evaluated): p has stagnated.
    """
    jacobian = "extrinsic" if stereo is None else "point"       # see the module docstring

    def evaluate(cameras_now) -> GrayLevelResidual:
        return gray_level_residual(X, quad, images, cameras_now, normalisation, jacobian,
                                   extra_mask)

    def moved(dp: np.ndarray) -> list:
        if stereo is None:
            return [c.with_extrinsics(c.extrinsics + dp[6 * k:6 * k + 6]) for k, c in enumerate(cams)]
        cam0 = cams[0].with_extrinsics(cams[0].extrinsics + dp)
        return [cam0, place_camera1(cam0, cams[1], *stereo)]

    cams = list(cameras)
    probe = X[np.isfinite(X).all(axis=1)][:: max(1, len(X) // 2000)]   # logs each step in px
    if start is not None and (start.dr_dX if stereo is not None else start.dr_dp) is not None:
        res = start                                       # the caller's, with the derivative
    else:
        res = evaluate(cams)
    converged, it, mu, steps = False, 0, 0.0, 0
    for it in range(1, max_iter + 1):
        std = res.std_percent
        if not np.isfinite(std):
            logger.warning("calibration: no integration point is seen by both cameras")
            break
        M, rhs = pose_normal_equations(res, X, cams, stereo, np.where(res.mask, quad.weight_mm2, 0.0))
        plain = truncated_solve(M, rhs, rcond, frozen)                # the undamped step
        c, n = chi_square(res, quad)
        per_unit = n / c if c > 0.0 else np.inf              # chi-square units per unit of cost

        def fall(dp: np.ndarray) -> float:                   # predicted, as for the shape
            return abs(2.0 * dp @ rhs - dp @ M @ dp) * per_unit
        rows = plain.reshape(-1, 6)
        if (np.max(np.abs(rows[:, :3])) < tol_rad and np.max(np.abs(rows[:, 3:])) < tol_mm
                or fall(plain) < 1.0):
            converged = True                   # p stagnates: the step is not taken
            logger.debug("calibration it %d: the step is stagnant (predicted chi-square fall "
                         "%.3g)", it, fall(plain))
            break

        within_noise: list[float] = []
        small = _shift_px(moved(plain), cams, probe) < undamped_px
        tried: list[float] = []

        def propose(mu: float):                            # Levenberg-Marquardt guard
            if within_noise or (small and tried):  # a small step that failed: stagnant
                return None
            tried.append(mu)
            dp = truncated_solve(M + mu * np.diag(np.diag(M)), rhs, rcond, frozen)
            if mu > 0.0 and fall(dp) < 1.0:
                within_noise.append(mu)      # a refused step damped into the noise: stagnant
                return None
            trial_cams = moved(dp)
            return dp, trial_cams, evaluate(trial_cams)

        accepted, mu = damped_step(propose, std, mu, max_damping)
        if accepted is None:                   # no damped step lowers the residual: p stagnant
            converged = True
            logger.debug("calibration it %d: no damped step lowers the residual (%.4f%%)", it, std)
            break
        dp, trial_cams, trial = accepted
        before, cams, res = cams, trial_cams, trial
        mu, steps = relaxed(mu), steps + 1
        rot = float(np.max(np.abs(dp.reshape(-1, 6)[:, :3])))
        tra = float(np.max(np.abs(dp.reshape(-1, 6)[:, 3:])))
        shift = _shift_px(cams, before, probe)
        if log is not None:
            log.add(**(context or {}), stage="calibration", iteration=it,
                    residual_percent=res.std_percent, step=max(rot, tra), shift_px=shift,
                    damping=mu, n_points=int(res.mask.sum()))
        logger.debug("calibration it %d: residual %.4f%% -> %.4f%%, |drot| %.2e rad, |dt| %.2e mm, "
                     "points moved %.2e px", it, std, res.std_percent, rot, tra, shift)
        if (rot < tol_rad and tra < tol_mm) or std - res.std_percent <= residual_rtol * std:
            converged = True                   # p stagnates (or, secondary, the residual does)
            break
    return CalibrationResult(cameras=tuple(cams), residual=dataclasses.replace(res, dr_dp=None),
                             iterations=it, converged=converged, steps=steps)
