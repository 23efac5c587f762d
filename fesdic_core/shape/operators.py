"""Shape measurement at fixed cameras: Eq. 7 by Gauss-Newton, Eq. 8 with Remark 1.

The unknown is the scalar correction ``q_I`` of each node along its nominal unit normal
``n_I`` (Remark 1), so the surface is ``X = sum_I L_I (X0_I + q_I n_I)``. With
``g = J0^T grad f0 - J1^T grad f1`` at each integration point (normalised gradients),

    phi_g[I] = L_I(X_g) (g_g . n_I),
    H_FE = sum_g w_g phi_g phi_g^T,    b_FE = -sum_g w_g phi_g r_g          (Eq. 8)

and each step ``d`` comes from the :class:`~fesdic_core.solve.solvers.StepSolver` hook.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sps

from fesdic_core.fe.mesh import assemble
from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.parallel import for_each_block
from fesdic_core.residual.graylevel import GrayLevelResidual, gray_level_residual
from fesdic_core.solve.gauss_newton import damped_gauss_newton, predicted_change
from fesdic_core.solve.solvers import StepSolver

logger = logging.getLogger(__name__)

__all__ = ["current_nodes", "shape_operators", "shape_pose_coupling", "GaussNewtonLog",
           "ShapeResult", "chi_square", "chi_square_change", "predicted_chi_square_change",
           "shape_gauss_newton"]

_ELEMENT_BLOCK = 1 << 15     # integration points per block of elements in the assembly


def current_nodes(nodes0: np.ndarray, normals: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Node positions of the corrected surface ``X0_I + q_I n_I`` (Remark 1)."""
    return nodes0 + q[:, None] * normals


def shape_operators(quad: PixelQuadrature, normals: np.ndarray, res: GrayLevelResidual
                    ) -> tuple[sps.csr_matrix, np.ndarray]:
    """Assemble ``H_FE`` and ``b_FE`` of Eq. 8 in the normal-projected unknown (Remark 1).

    Element by element (the points of an element are contiguous, :class:`ElementGroup`):
    ``Phi_e[g, i] = L_i(xi_g) (dr/dX_g . n_i)`` (m, nn), ``H_e = Phi_e^T W Phi_e`` and
    ``b_e = -Phi_e^T W r``, then the usual finite-element scatter into the global system.
    """
    if res.dr_dX is None:
        raise ValueError("shape_operators: the residual has no dr/dX (computed without its "
                         "derivative)")
    dr_dX = res.dr_dX
    w = np.where(res.mask, quad.weight_mm2, 0.0)
    n = normals.shape[0]
    element_matrices, b = [], np.zeros(n)
    for group in quad.groups:
        E, (m, nn) = len(group.elements), group.N.shape
        He, be = np.empty((E, nn, nn)), np.empty((E, nn))

        def element_block(span: slice) -> None:
            points = slice(group.start + span.start * m, group.start + span.stop * m)
            g = dr_dX[points].reshape(-1, m, 3)                  # dr/dX = J0^T df0 - J1^T df1
            n_e = normals[group.connectivity[span]]                    # (e, nn, 3)
            phi = (g @ n_e.transpose(0, 2, 1)) * group.N               # L_I (g . n_I), (e, m, nn)
            wphi = phi * w[points].reshape(-1, m, 1)
            He[span] = wphi.transpose(0, 2, 1) @ phi                   # Eq. 8
            be[span] = -(res.r[points].reshape(-1, 1, m) @ wphi)[:, 0]  # Eq. 8

        for_each_block(element_block, E, max(1, _ELEMENT_BLOCK // m))
        element_matrices.append(He)
        b += np.bincount(group.connectivity.ravel(), weights=be.ravel(), minlength=n)
    return assemble([g.connectivity for g in quad.groups], element_matrices, n), b


def shape_pose_coupling(quad: PixelQuadrature, normals: np.ndarray, res: GrayLevelResidual,
                        rows: Callable[[slice], np.ndarray], k: int) -> np.ndarray:
    """The off-diagonal block ``H_qp = sum_g w_g phi_g G_g^T`` (n, k) of the joint Gauss-Newton
    system on the shape and the poses (:mod:`fesdic_core.shape.joint`).

    ``phi_g`` as in :func:`shape_operators` (Eq. 8); ``rows(points)`` the rows ``G_g`` (m, k)
    of the pose problem (Eq. 6) at a slice of points, computed block by block (no (g, k)
    array for the whole quadrature).
    """
    if res.dr_dX is None:
        raise ValueError("shape_pose_coupling: the residual has no dr/dX")
    w = np.where(res.mask, quad.weight_mm2, 0.0)
    dr_dX = res.dr_dX
    n = normals.shape[0]
    out = np.zeros((n, k))
    for group in quad.groups:
        E, (m, nn) = len(group.elements), group.N.shape
        block = np.empty((E, nn, k))

        def element_block(span: slice) -> None:
            points = slice(group.start + span.start * m, group.start + span.stop * m)
            g = dr_dX[points].reshape(-1, m, 3)
            phi = (g @ normals[group.connectivity[span]].transpose(0, 2, 1)) * group.N
            wG = (w[points, None] * rows(points)).reshape(-1, m, k)
            block[span] = phi.transpose(0, 2, 1) @ wG                        # (e, nn, k)

        for_each_block(element_block, E, max(1, _ELEMENT_BLOCK // m))
        nodes = group.connectivity.ravel()
        for j in range(k):
            out[:, j] += np.bincount(nodes, weights=block[..., j].ravel(), minlength=n)
    return out


@dataclass
class GaussNewtonLog:
    """Iteration records shared by the drivers (plain dicts, for CSV and figures)."""

    records: list = field(default_factory=list)
    t0: float = field(default_factory=time.perf_counter)

    def add(self, **record) -> None:
        record["time_s"] = time.perf_counter() - self.t0
        self.records.append(record)


@dataclass(frozen=True)
class ShapeResult:
    """End of a shape Gauss-Newton.

    ``converged``: q stagnated (the last accepted step below the tolerance, or no damped
    step lowers the residual any more) or, when asked (a coarse scale), the residual
    stagnated; False when the iteration limit stopped it. ``stop`` says which:
    "step", "noise" (the step within q's own noise), "no descent", "residual" or
    "iteration limit".
    ``damping``: the Levenberg-Marquardt factor in force at the end (0: plain Gauss-Newton).
    """

    q: np.ndarray
    residual: GrayLevelResidual
    iterations: int
    converged: bool
    damping: float = 0.0
    stop: str = ""


def chi_square(res: GrayLevelResidual, quad: PixelQuadrature) -> tuple[float, int]:
    """The cost ``c = sum_g w_g r_g**2`` of Eq. 7 and the number of points seen."""
    w = np.where(res.mask, quad.weight_mm2, 0.0)
    # einsum, not np.dot: a BLAS dot of a million points runs on BLAS threads (slower when
    # the machine is loaded)
    return float(np.einsum("i,i,i->", w, res.r, res.r)), int(np.count_nonzero(res.mask))


def chi_square_change(before: GrayLevelResidual, after: GrayLevelResidual,
                      quad: PixelQuadrature) -> float:
    """How much a step improved the fit, in units of chi-square.

    The fall of the cost divided by the residual variance per point, ``c / n``: below 1
    the data cannot tell the two states apart (q moved within its own 1-sigma confidence
    region). The variance includes the model error and the pixels are correlated, so the
    figure errs towards going on.
    """
    c0, n = chi_square(before, quad)
    c1, _ = chi_square(after, quad)
    return (c0 - c1) * n / c0 if c0 > 0.0 and n else float("inf")


def predicted_chi_square_change(H, b: np.ndarray, d: np.ndarray, res: GrayLevelResidual,
                                quad: PixelQuadrature) -> float:
    """How much the step ``d`` would improve the fit by the linearised model, in units of
    chi-square (as :func:`chi_square_change`), without evaluating the images there.

    The cost linearised at ``q`` is ``c - 2 d.b + d.H d`` (Eq. 8, ``b = -sum w phi r``), so
    the predicted fall is ``2 d.b - d.H d`` (``d.b`` for the Gauss-Newton step of any
    Galerkin projection, e.g. a spline level); divided by ``c / n``.
    """
    return predicted_change(H, b, d, chi_square(res, quad))


def shape_gauss_newton(nodes0: np.ndarray, normals: np.ndarray, q0: np.ndarray,
                       quad: PixelQuadrature, images: Sequence, cameras: Sequence,
                       solver: StepSolver, scale: int = 0, normalisation: str = "element",
                       max_iter: int = 20, tol_mm: float = 1e-4, max_damping: int = 8,
                       residual_rtol: float | None = None,
                       log: GaussNewtonLog | None = None, extra_mask=None,
                       context: dict | None = None,
                       on_iteration: Callable[[int, float], None] | None = None,
                       start: GrayLevelResidual | None = None,
                       keep_derivative: bool = False) -> ShapeResult:
    """Solve Eq. 7 at fixed cameras by Gauss-Newton, each step through ``solver``.

    Each step solves ``(H + mu diag H) d = b`` through the hook (Levenberg-Marquardt;
    ``mu = 0``, the plain Gauss-Newton step of Eq. 8, whenever that lowers the residual;
    at most ``max_damping`` increases of ``mu``, :mod:`fesdic_core.solve.damping`): the residual
    never grows. Convergence is the stagnation of q (section 2.2): the step is below
    ``tol_mm`` (mm, largest node), or it changes the fit by less than one unit of chi-square
    (the data cannot tell q from q + d), or no damped step lowers the residual any more
    (:mod:`fesdic_core.solve.damping`). The plain Gauss-Newton step is first tested before the
    images are evaluated at its end (its size, and the fall of chi-square the linearised
    model predicts, :func:`predicted_chi_square_change`): a stagnant step is not taken, and
    the iteration that would only have confirmed it costs no residual evaluation; an
    accepted step is tested again with its actual change (:func:`chi_square_change`). The
    loop is :func:`fesdic_core.solve.gauss_newton.damped_gauss_newton`, shared with the
    displacement.
    ``residual_rtol`` (for the coarse scales of a multiscale run, which only start the next
    scale, Remark 3) also stops it when the residual falls by less than that fraction in a
    step. ``max_iter`` reached first leaves ``converged=False``. ``start``: the residual at
    ``q0`` with ``dr_dX`` when the caller has it (same points, images, cameras and
    normalisation; e.g. the calibration's last one), not evaluated again.
    ``keep_derivative``: the result's residual keeps its ``dr_dX`` (else dropped).
    """
    def evaluate(q: np.ndarray) -> GrayLevelResidual:
        X = quad.points(current_nodes(nodes0, normals, q))
        return gray_level_residual(X, quad, images, cameras, normalisation, "point", extra_mask)

    def on_step(it: int, std: float, res: GrayLevelResidual, step: float, mu: float) -> None:
        if log is not None:
            log.add(**(context or {}), scale=scale, stage="shape", iteration=it,
                    residual_percent=res.std_percent, step=step, damping=mu,
                    n_points=int(res.mask.sum()))
        if on_iteration is not None:
            on_iteration(it, res.std_percent)
        logger.debug("shape GN scale %d it %d: residual %.4f%% -> %.4f%%, max|d| %.2e mm, mu %.1e",
                     scale, it, std, res.std_percent, step, mu)

    out = damped_gauss_newton(
        q0, evaluate(np.asarray(q0, float)) if start is None or start.dr_dX is None else start,
        evaluate, lambda res: shape_operators(quad, normals, res),
        lambda H, b, q: solver.solve(H, b, q, scale), lambda res: chi_square(res, quad),
        tol_mm, max_iter, max_damping, residual_rtol, on_step, f"shape GN scale {scale}")
    res = out.residual if keep_derivative else dataclasses.replace(out.residual, dr_dX=None)
    return ShapeResult(q=out.q, residual=res, iterations=out.iterations,
                       converged=out.converged, damping=out.damping, stop=out.stop)
