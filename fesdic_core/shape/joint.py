"""One Gauss-Newton on the camera poses and the shape together (Eqs. 6 and 7 as one problem).

The fixed point of section 2.2 alternates the calibration (Eq. 6: the poses ``p`` at fixed
shape) and the shape (Eq. 7: ``q`` at fixed poses). Both minimise the same cost
``sum_g w_g r_g^2`` (Eq. 2); here each Gauss-Newton step moves both. Linearised at ``(q, p)``
the residual is ``r + phi . dq + G . dp`` (``phi`` of Eq. 8, ``G`` the rows of Eq. 6) and the
step solves

    [ H       H_qp ] [dq]   [ b   ]     H, b of Eq. 8;  M, b_p of Eq. 6;
    [ H_qp^T  M    ] [dp] = [ b_p ]     H_qp = sum_g w_g phi_g G_g^T.

The shape block is solved only through the :class:`~fesdic_core.solve.solvers.StepSolver` hook,
so that FE, Tikhonov and the plugin's geometric regularization work unchanged: the hook's
step is an affine map of its right-hand side, ``d = A b + a(q)`` (``A = H^-1``;
``C_s^T (C_s H C_s^T)^-1 C_s``, Eq. 21; ``(H + lam K)^-1``, Eq. 10). Eliminating ``dq`` (the
Schur complement on the few pose unknowns)::

    d0 = solve(H, b, q),     U = A H_qp Z,     V = A N,
    dq = d0 - U y - V lam,   dp = Z y,

with ``(y, lam)`` from the small system of the pose rows and the gauge (:func:`joint_step`).

The gauge (section 2.2, :mod:`fesdic_core.shape.gauge`). A rigid motion of the specimen undone
by the cameras changes neither image, so the cost is flat along it:

- the slides of the surface in itself (:func:`~fesdic_core.shape.gauge.tangential_motions`) move
  no node along its normal: the poses keep them at their start (``dp = Z y``, ``Z`` orthogonal
  to their pose directions in Jacobi-scaled parameters, as the calibration's frozen ones);
- the other rigid motions have a normal part ``N`` at the nodes that ``q`` could take: ``q`` is
  kept orthogonal to it (``N^T (q + dq) = 0``, weighted by the area each node's elements
  show the images, :func:`seen_areas`; ``lam`` its Lagrange multipliers). The poses own the rigid motion, as after the alternation's hand-over, but
  the condition holds inside the step instead of moving the state after it, which is not an
  exact symmetry on a part of several faces.

Each step is damped (Levenberg-Marquardt: ``H + mu diag H`` through the hook, ``M + mu diag
M``) and guarded: it is taken only if the cost it minimises, ``sum_g w_g r_g^2``, does not
grow (:mod:`fesdic_core.solve.damping`; the residual's ``std_percent``, which the shape and
calibration steps guard, weighs the points otherwise, and near the optimum of the part it
refused steps that lowered the cost).
The state is a minimum when the plain step predicts a fall of the cost below one unit of
chi-square (no direction left that the data can tell from noise: the Newton decrement,
:attr:`JointResult.decrement`), or when it moves no node by ``tol_mm`` and no point's image by
``tol_px``; that step is not taken.
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from typing import Callable, Sequence, cast

import numpy as np
from scipy.linalg import null_space

from fesdic_core.cameras.rig import place_camera1
from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.residual.graylevel import GrayLevelResidual, gray_level_residual
from fesdic_core.shape.calibration import pose_normal_equations, rig_motion
from fesdic_core.shape.gauge import normal_gauge, pose_directions, tangential_motions
from fesdic_core.shape.operators import (GaussNewtonLog, chi_square, current_nodes,
                                         shape_operators, shape_pose_coupling)
from fesdic_core.solve.damping import damped_step, relaxed
from fesdic_core.solve.gauss_newton import STRETCH_RATIO, damped, stretch_factor
from fesdic_core.solve.solvers import FactorizeHook, StepSolver

logger = logging.getLogger(__name__)

__all__ = ["COUPLINGS", "JointResult", "JointSystem", "seen_areas", "point_derivative",
           "joint_system", "joint_step", "joint_gauss_newton"]

#: how the poses and the shape are solved: one joint Gauss-Newton, or the fixed point of
#: section 2.2 (calibration and shape in turn)
COUPLINGS = ("joint", "alternate")


@dataclass(frozen=True)
class JointResult:
    """End of a joint Gauss-Newton.

    ``cameras``: the final cameras (those given, moved); ``residual``: at the final state,
    with ``dr_dX``; ``stop``: "step" (the plain step moves nothing), "noise no step" (the plain
    step's predicted fall is below one unit of chi-square; not taken), "noise" (the last
    accepted step changed the cost by less than that), "no descent", "residual", "no point
    seen" or "iteration limit"; ``decrement``: the plain step's predicted fall at the final
    state (chi-square units: the gradient against its noise, ``b^T H^-1 b`` over the residual
    variance per point; NaN if not computed, see ``final_decrement``).
    """

    q: np.ndarray
    cameras: tuple
    residual: GrayLevelResidual
    iterations: int
    converged: bool
    stop: str
    damping: float = 0.0
    decrement: float = float("nan")


@dataclass(frozen=True)
class JointSystem:
    """The joint Gauss-Newton system at one state: ``H`` (n, n) sparse and ``b`` (n,) of Eq. 8,
    ``M`` (k, k) and ``b_p`` (k,) of Eq. 6, ``H_qp`` (n, k), the frozen pose directions ``F``
    (k, k_t), the normal gauge ``N`` (n, k_n) and the cost ``(c, n_points)``."""

    H: object
    b: np.ndarray
    M: np.ndarray
    b_p: np.ndarray
    H_qp: np.ndarray
    F: np.ndarray
    N: np.ndarray
    cost: tuple[float, int]

    def predicted_fall(self, dq: np.ndarray, dp: np.ndarray) -> float:
        """Fall of the linearised cost ``2 (dq.b + dp.b_p) - [dq dp] K [dq dp]``, in units of
        chi-square (``c / n``), as :func:`~fesdic_core.solve.gauss_newton.predicted_change`."""
        c, n = self.cost
        quadratic = dq @ (self.H @ dq) + 2.0 * dq @ (self.H_qp @ dp) + dp @ (self.M @ dp)
        fall = 2.0 * (dq @ self.b + dp @ self.b_p) - quadratic
        return float(fall) * n / c if c > 0.0 and n else float("inf")


def point_derivative(res: GrayLevelResidual, cameras: Sequence) -> np.ndarray:
    """``dr/dX`` (g, 3) from the extrinsic derivative ``dr/dp`` (g, 12).

    ``x_cam = R X + t``: a point's move is its camera's translation turned by ``R``, so
    ``dr/dX = dr/dt0 R0 + dr/dt1 R1`` (the signs of Eq. 3 are in ``dr/dp``).
    """
    if res.dr_dp is None:
        raise ValueError("point_derivative: the residual has no dr/dp")
    return res.dr_dp[:, 3:6] @ cameras[0].R + res.dr_dp[:, 9:12] @ cameras[1].R


def _coupling(res: GrayLevelResidual, X: np.ndarray, quad: PixelQuadrature, normals: np.ndarray,
              cameras: Sequence, stereo) -> np.ndarray:
    """``H_qp`` (n, k): with camera 1 following camera 0, ``G = u T`` (the rig's motion is the
    specimen's, :func:`~fesdic_core.shape.calibration.rigid_rig_gradients`), so
    ``H_qp = (sum w phi u^T) T`` from the moments ``u = [X x dr/dX, dr/dX]``; else ``G = dr/dp``."""
    dr_dX, dr_dp = res.dr_dX, res.dr_dp
    if stereo is None:
        if dr_dp is None:
            raise ValueError("the joint system: the residual has no dr/dp")
        extrinsic: np.ndarray = dr_dp
        return shape_pose_coupling(quad, normals, res, lambda points: extrinsic[points], 12)
    if dr_dX is None:
        raise ValueError("the joint system: the residual has no dr/dX")

    def moments(points: slice) -> np.ndarray:
        return np.concatenate([np.cross(X[points], dr_dX[points]), dr_dX[points]], axis=1)
    return shape_pose_coupling(quad, normals, res, moments, 6) @ rig_motion(cameras[0])


def joint_system(res: GrayLevelResidual, X: np.ndarray, quad: PixelQuadrature,
                 nodes0: np.ndarray, normals: np.ndarray, node_weights: np.ndarray,
                 cameras: Sequence, stereo) -> JointSystem:
    """Assemble the :class:`JointSystem` at the state whose residual is ``res`` (with ``dr_dX``,
    and ``dr_dp`` when both cameras are free) at the points ``X`` (g, 3), with its gauge
    (module docstring; ``nodes0``, ``normals``, ``node_weights``: the nominal mesh's)."""
    w = np.where(res.mask, quad.weight_mm2, 0.0)
    H, b = shape_operators(quad, normals, res)                               # Eq. 8
    M, b_p = pose_normal_equations(res, X, cameras, stereo, w)               # Eq. 6
    H_qp = _coupling(res, X, quad, normals, cameras, stereo)
    keep_stereo = stereo is not None
    slides, centre = tangential_motions(nodes0, normals, node_weights)
    F = pose_directions(cameras, slides, centre, keep_stereo)
    return JointSystem(H=H, b=b, M=M, b_p=b_p, H_qp=H_qp, F=F,
                       N=normal_gauge(nodes0, normals, seen_areas(quad, res.mask, len(nodes0))),
                       cost=chi_square(res, quad))


def seen_areas(quad: PixelQuadrature, mask: np.ndarray, n_nodes: int) -> np.ndarray:
    """(n,) the area of the surface the residual sees around each node (mm^2): each element's
    seen integration weights, shared equally among its nodes. The gauge's metric.

    With nodal areas instead, a node that few points see could balance the condition
    ``N^T q = 0`` almost for free: on the demo plate, plain FE took a 61 mm step at its
    coarsest scale and diverged; on the Stereo DIC Challenge part the steps walked a valley of
    rigid pose motions balanced by 0.1-1 mm at the weakly seen nodes.
    """
    out = np.zeros(n_nodes)
    w = np.where(mask, quad.weight_mm2, 0.0)
    for group in quad.groups:
        E, (m, nn) = len(group.elements), group.N.shape
        seen = w[group.start:group.start + E * m].reshape(E, m).sum(axis=1)
        out += np.bincount(group.connectivity.ravel(), weights=np.repeat(seen / nn, nn),
                           minlength=n_nodes)
    return out


def _shape_map(solver: StepSolver, H, scale: int, q: np.ndarray
               ) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]:
    """The hook's step ``b -> solve(H, b, q)`` and its linear part ``v -> A v``, with ``H``
    factorized once when the solver can (:class:`FactorizeHook`)."""
    zero = np.zeros_like(q)
    if isinstance(solver, FactorizeHook):
        step = solver.factorize(H, scale)
        return (lambda b: step(b, q)), (lambda v: step(v, zero))
    return (lambda b: solver.solve(H, b, q, scale)), (lambda v: solver.solve(H, v, zero, scale))


def joint_step(system: JointSystem, solver: StepSolver, q: np.ndarray, scale: int,
               mu: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The (damped) Gauss-Newton step ``(dq (n,), dp (k,))`` of the joint system, the shape
    block solved through ``solver`` (module docstring).

    With ``y`` the free pose unknowns (``dp = Z y``) and ``lam`` the gauge's multipliers::

        [ Z^T (M - H_qp^T A H_qp) Z   -Z^T H_qp^T V ] [y  ]   [ Z^T (b_p - H_qp^T d0) ]
        [ -N^T U                      -N^T V        ] [lam] = [ -N^T (q + d0)         ]
    """
    s = system
    H = s.H if mu == 0.0 else damped(s.H, mu)
    M = s.M + mu * np.diag(np.diag(s.M))
    jacobi = np.sqrt(np.maximum(np.diag(s.M), np.finfo(float).tiny))       # pose scaling
    Z = np.eye(len(jacobi))
    if s.F.size:                                            # the slides: not moved (gauge)
        Z = null_space((s.F * jacobi[:, None]).T)
    Z = Z / jacobi[:, None]
    step, A = _shape_map(solver, H, scale, q)
    d0 = step(s.b)                                          # the shape step alone (hook)
    HZ = s.H_qp @ Z
    columns = [A(c) for c in HZ.T] + [A(c) for c in s.N.T]  # A H_qp Z and A N (hook)
    W = np.column_stack(columns) if columns else np.zeros((len(q), 0))
    U, V = W[:, :HZ.shape[1]], W[:, HZ.shape[1]:]
    K = np.block([[Z.T @ M @ Z - HZ.T @ U, -HZ.T @ V],
                  [-s.N.T @ U, -s.N.T @ V]])
    rhs = np.r_[Z.T @ (s.b_p - s.H_qp.T @ d0), -s.N.T @ (q + d0)]
    norms = np.linalg.norm(K, axis=0)
    norms[norms == 0.0] = 1.0
    x = np.linalg.lstsq(K / norms, rhs, rcond=1e-12)[0] / norms
    y, lam = x[:HZ.shape[1]], x[HZ.shape[1]:]
    return d0 - U @ y - V @ lam, Z @ y


def _moved(cameras: Sequence, dp: np.ndarray, stereo) -> list:
    """The cameras after the pose step ``dp``: camera 0 (camera 1 following), or both."""
    if stereo is None:
        return [c.with_extrinsics(c.extrinsics + dp[6 * k:6 * k + 6]) for k, c in enumerate(cameras)]
    cam0 = cameras[0].with_extrinsics(cameras[0].extrinsics + dp)
    return [cam0, place_camera1(cam0, cameras[1], *stereo)]


def _shift_px(a: Sequence, b: Sequence, X: np.ndarray) -> float:
    """Largest move (px) of the images of the points ``X`` (k, 3) between two camera pairs."""
    if not len(X):
        return 0.0
    return max(float(np.max(np.linalg.norm(ca.project(X) - cb.project(X), axis=1)))
               for ca, cb in zip(a, b))


def joint_gauss_newton(nodes0: np.ndarray, normals: np.ndarray, q0: np.ndarray,
                       quad: PixelQuadrature, images: Sequence, cameras: Sequence,
                       solver: StepSolver, scale: int, stereo, node_weights: np.ndarray,
                       normalisation: str = "element", max_iter: int = 20, tol_mm: float = 1e-4,
                       tol_px: float = 1e-2, max_damping: int = 3,
                       residual_rtol: float | None = None, extra_mask=None,
                       log: GaussNewtonLog | None = None, context: dict | None = None,
                       start: GrayLevelResidual | None = None,
                       final_decrement: bool = False) -> JointResult:
    """Minimise Eq. 2 over the shape ``q`` and the poses from ``(q0, cameras)`` by the joint
    Gauss-Newton of the module docstring.

    Parameters
    ----------
    nodes0, normals : (n, 3) the nominal nodes and their unit normals (Remark 1)
    q0 : (n,) the starting correction
    quad, images, cameras : the scale's quadrature, images and cameras (moved and returned)
    solver : the shape step's hook; scale : the image scale it is told
    stereo : (R, t) to keep (6 pose unknowns, camera 1 follows camera 0), or None (12)
    node_weights : (n,) >= 0, nodal areas (the metric of the slides; the rigid normal part is
        weighed by the seen area, :func:`seen_areas`)
    tol_mm, tol_px : the plain step is stagnant when it moves no node by ``tol_mm`` and no
        point's image by ``tol_px`` (or predicts a fall below one unit of chi-square)
    max_damping : at most this many tenfold increases of the Levenberg-Marquardt factor after
        a refused step (from 1e-4: up to 1e-2 with 3), then the state has stagnated. Measured
        on the Stereo DIC Challenge part: with 8, the last iteration took 8 increases, up to
        100, for a step of 5e-4 mm that lowered the cost by 0.84 units of chi-square (4 s of
        its 20 s)
    residual_rtol : a coarse scale also stops when the residual falls by less than this
        fraction in a step (Remark 3)
    start : the residual at ``(q0, cameras)``, with ``dr_dX`` (``dr_dp`` too when ``stereo`` is
        None), if the caller has it
    final_decrement : when the loop ends on an accepted step, assemble the system once more
        at the final state for :attr:`JointResult.decrement` (no image evaluation)
    """
    jacobian = "point" if stereo is not None else "extrinsic"

    def evaluate(q: np.ndarray, cams: Sequence) -> tuple[np.ndarray, GrayLevelResidual]:
        X = quad.points(current_nodes(nodes0, normals, q))
        res = gray_level_residual(X, quad, images, cams, normalisation, jacobian, extra_mask)
        return X, _with_point_derivative(res, cams, stereo)

    q, cams = np.asarray(q0, float).copy(), list(cameras)
    if start is not None and start.dr_dX is not None and (stereo is not None
                                                          or start.dr_dp is not None):
        X, res = quad.points(current_nodes(nodes0, normals, q)), \
            _with_point_derivative(start, cams, stereo)
    else:
        X, res = evaluate(q, cams)
    mu, converged, stop, it, decrement = 0.0, False, "iteration limit", 0, float("nan")
    for it in range(1, max_iter + 1):
        std = res.std_percent
        if not np.isfinite(std):
            logger.warning("joint GN scale %d: no integration point is seen", scale)
            stop = "no point seen"
            break
        probe = current_nodes(nodes0, normals, q)           # the pose step's shift, in px
        system = joint_system(res, X, quad, nodes0, normals, node_weights, cams, stereo)
        dq, dp = joint_step(system, solver, q, scale)                      # the plain step
        decrement = system.predicted_fall(dq, dp)
        shift = _shift_px(_moved(cams, dp, stereo), cams, probe)
        if (np.max(np.abs(dq), initial=0.0) < tol_mm and shift < tol_px) or abs(decrement) < 1.0:
            converged, stop, it = True, "step" if abs(decrement) >= 1.0 else "noise no step", it - 1
            logger.debug("joint GN scale %d: the next step is stagnant (max|dq| %.2e mm, poses "
                         "%.2e px, predicted chi-square fall %.3g)", scale,
                         np.max(np.abs(dq), initial=0.0), shift, decrement)
            break
        within_noise: list[float] = []

        def propose(mu: float):
            if within_noise:                      # more damping only shortens a stagnant step
                return None
            d = (dq, dp) if mu == 0.0 else joint_step(system, solver, q, scale, mu)
            if not (np.all(np.isfinite(d[0])) and np.all(np.isfinite(d[1]))):
                return None
            if mu > 0.0 and abs(system.predicted_fall(*d)) < 1.0:
                within_noise.append(mu)           # a refused step damped into the noise
                return None
            moved = _moved(cams, d[1], stereo)
            return d, moved, *evaluate(q + d[0], moved)

        # the cost that the Gauss-Newton model minimises (Eq. 2), not the residual's std
        accepted, mu = damped_step(propose, system.cost[0], mu, max_damping,
                                   lambda r: chi_square(cast(GrayLevelResidual, r), quad)[0])
        if accepted is None:
            converged, stop = True, "no descent"
            logger.debug("joint GN scale %d it %d: no damped step lowers the residual (%.4f%%)",
                         scale, it, std)
            break
        (step_q, step_p), moved, X, res = accepted
        if mu == 0.0:
            (step_q, step_p), moved, X, res = _stretched(
                system, (step_q, step_p), moved, X, res,
                lambda f: (_moved(cams, f * step_p, stereo),
                           *evaluate(q + f * step_q, _moved(cams, f * step_p, stereo))), quad)
        shift = _shift_px(moved, cams, probe)
        q, cams = q + step_q, moved
        if log is not None:
            log.add(**(context or {}), scale=scale, stage="joint", iteration=it,
                    residual_percent=res.std_percent, step=float(np.max(np.abs(step_q), initial=0)),
                    shift_px=shift, damping=mu, n_points=int(res.mask.sum()))
        fall = _fall(system.cost, chi_square(res, quad))
        logger.debug("joint GN scale %d it %d: residual %.4f%% -> %.4f%%, max|dq| %.2e mm, poses "
                     "%.2e px, mu %.1e, chi-square fall %.4g (predicted %.4g)", scale, it, std,
                     res.std_percent, np.max(np.abs(step_q), initial=0.0), shift, mu, fall,
                     system.predicted_fall(step_q, step_p))
        mu = relaxed(mu)
        if abs(fall) < 1.0:
            converged, stop = True, "noise"      # the data cannot tell the two states apart
            break
        if residual_rtol is not None and std - res.std_percent <= residual_rtol * std:
            converged, stop = True, "residual"
            break
    if final_decrement and stop not in ("step", "noise no step", "no descent", "no point seen"):
        system = joint_system(res, X, quad, nodes0, normals, node_weights, cams, stereo)
        decrement = system.predicted_fall(*joint_step(system, solver, q, scale))
    res = dataclasses.replace(res, dr_dp=None)
    return JointResult(q=q, cameras=tuple(cams), residual=res, iterations=it,
                       converged=converged, stop=stop, damping=mu, decrement=decrement)


def _stretched(system: JointSystem, step: tuple, moved: list, X: np.ndarray,
               res: GrayLevelResidual, at: Callable, quad: PixelQuadrature) -> tuple:
    """The accepted plain step, stretched along itself to the minimum of the cost's parabola
    when it fell by more than :data:`~fesdic_core.solve.gauss_newton.STRETCH_RATIO` times what the
    linearised model predicted.

    The Gauss-Newton model leaves out ``sum_g w_g r_g d^2 r_g``; where the misfit is the image
    model's (not noise), along the valley that the poses and the shape trade in, the cost falls
    past the Gauss-Newton step (measured: 2 to 2.5 times the predicted fall, step after step, on
    the Stereo DIC Challenge part and on a plate with both cameras free). Along the step ``f d``
    the cost is a parabola with the exact slope ``g = d . [b, b_p]`` and the fall measured at
    ``f = 1`` (:func:`~fesdic_core.solve.gauss_newton.stretch_factor`); its minimum is
    evaluated once and kept if the cost is lower there. ``at(f)``: the cameras, points and
    residual at ``f`` times the step.
    """
    c0, c1 = system.cost[0], chi_square(res, quad)[0]
    if not _fall(system.cost, (c1, 0)) > STRETCH_RATIO * system.predicted_fall(*step) > 0.0:
        return step, moved, X, res
    f = stretch_factor(c0, c1, float(step[0] @ system.b + step[1] @ system.b_p))
    if f <= STRETCH_RATIO:
        return step, moved, X, res
    moved_f, X_f, res_f = at(f)
    if not chi_square(res_f, quad)[0] < c1:
        return step, moved, X, res
    logger.debug("joint GN: step stretched %.3g times (residual %.4f%% -> %.4f%%)", f,
                 res.std_percent, res_f.std_percent)
    return (f * step[0], f * step[1]), moved_f, X_f, res_f


def _fall(before: tuple[float, int], after: tuple[float, int]) -> float:
    """The fall of the cost between two states, in units of chi-square (``c / n``)."""
    (c0, n), (c1, _) = before, after
    return (c0 - c1) * n / c0 if c0 > 0.0 and n else float("inf")


def _with_point_derivative(res: GrayLevelResidual, cameras: Sequence, stereo) -> GrayLevelResidual:
    """``res`` with ``dr_dX``, derived from ``dr_dp`` when both cameras are free."""
    if stereo is not None or res.dr_dX is not None:
        return res
    return dataclasses.replace(res, dr_dX=point_derivative(res, cameras))
