"""Shape measurement at fixed cameras: Eq. 7 by Gauss-Newton, Eq. 8 with Remark 1.

The unknown is the scalar correction ``q_I`` of each node along its nominal unit normal
``n_I`` (Remark 1), so the surface is ``X = sum_I L_I (X0_I + q_I n_I)``. With
``g = J0^T grad f0 - J1^T grad f1`` at each integration point (normalised gradients),

    phi_g[I] = L_I(X_g) (g_g . n_I),
    H_FE = sum_g w_g phi_g phi_g^T,    b_FE = -sum_g w_g phi_g r_g          (Eq. 8)

and each step ``d`` comes from the :class:`~fesdic_core.solvers.StepSolver` hook.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sps

from .mesh import assemble
from .parallel import for_each_block
from .quadrature import PixelQuadrature
from .residual import GrayLevelResidual, gray_level_residual
from .solvers import StepSolver

logger = logging.getLogger(__name__)

_ELEMENT_BLOCK = 1 << 15     # integration points per block of elements in the assembly


class DivergenceError(RuntimeError):
    """Gauss-Newton diverged; ``best`` holds the best state reached (lowest residual)."""

    def __init__(self, message: str, best=None):
        super().__init__(message)
        self.best = best


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
    w = np.where(res.mask, quad.weight_mm2, 0.0)
    n = normals.shape[0]
    element_matrices, b = [], np.zeros(n)
    for group in quad.groups:
        E, (m, nn) = len(group.elements), group.N.shape
        He, be = np.empty((E, nn, nn)), np.empty((E, nn))

        def element_block(span: slice) -> None:
            points = slice(group.start + span.start * m, group.start + span.stop * m)
            g = res.dr_dX[points].reshape(-1, m, 3)                  # dr/dX = J0^T df0 - J1^T df1
            n_e = normals[group.connectivity[span]]                    # (e, nn, 3)
            phi = (g @ n_e.transpose(0, 2, 1)) * group.N               # L_I (g . n_I), (e, m, nn)
            wphi = phi * w[points].reshape(-1, m, 1)
            He[span] = wphi.transpose(0, 2, 1) @ phi                   # Eq. 8
            be[span] = -(res.r[points].reshape(-1, 1, m) @ wphi)[:, 0]  # Eq. 8

        for_each_block(element_block, E, max(1, _ELEMENT_BLOCK // m))
        element_matrices.append(He)
        b += np.bincount(group.connectivity.ravel(), weights=be.ravel(), minlength=n)
    return assemble([g.connectivity for g in quad.groups], element_matrices, n), b


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
    q: np.ndarray
    residual: GrayLevelResidual
    iterations: int
    converged: bool
    diverged: bool


def shape_gauss_newton(nodes0: np.ndarray, normals: np.ndarray, q0: np.ndarray,
                       quad: PixelQuadrature, images: Sequence, cameras: Sequence,
                       solver: StepSolver, scale: int = 0, normalisation: str = "element",
                       max_iter: int = 20, tol_mm: float = 1e-4, divergence_window: int = 3,
                       divergence_rtol: float = 1e-3, residual_rtol: float = 1e-4,
                       log: GaussNewtonLog | None = None, extra_mask=None,
                       context: dict | None = None,
                       on_iteration: Callable[[int, float], None] | None = None) -> ShapeResult:
    """Solve Eq. 7 at fixed cameras by Gauss-Newton, each step through ``solver``.

    Stops when ``max |d| < tol_mm`` (q stagnates) or when the residual decreased by less
    than ``residual_rtol`` (relative) over the last step. If the residual grows (by more than
    ``divergence_rtol``, relative) for ``divergence_window`` consecutive iterations, stops
    and returns the best state with ``diverged=True``.
    """
    q = q0.copy()
    best_q, best_res, best_std = q.copy(), None, np.inf
    rising, converged, diverged, it = 0, False, False, 0
    previous = np.inf
    for it in range(1, max_iter + 1):
        X = quad.points(current_nodes(nodes0, normals, q))
        res = gray_level_residual(X, quad, images, cameras, normalisation, "point", extra_mask)
        std = res.std_percent
        if std < best_std:
            best_q, best_res, best_std = q.copy(), res, std
        rising = rising + 1 if std > previous * (1.0 + divergence_rtol) else 0
        if it > 1 and abs(previous - std) <= residual_rtol * std:
            converged = True                                          # the residual stagnates
            previous = std
            break
        previous = std
        if rising >= divergence_window:
            diverged = True
            logger.warning("shape Gauss-Newton diverged at scale %d (residual grew %d times); "
                           "keeping the best state (%.3f%%)", scale, rising, best_std)
            break
        H, b = shape_operators(quad, normals, res)
        d = solver.solve(H, b, q, scale)
        q = q + d
        step = float(np.max(np.abs(d))) if d.size else 0.0
        if log is not None:
            log.add(**(context or {}), scale=scale, stage="shape", iteration=it,
                    residual_percent=std, step=step, n_points=int(res.mask.sum()))
        if on_iteration is not None:
            on_iteration(it, std)
        logger.debug("shape GN scale %d it %d: residual %.4f%%, max|d| %.2e mm", scale, it, std, step)
        if step < tol_mm:
            converged = True
            break
    X = quad.points(current_nodes(nodes0, normals, q))
    res = gray_level_residual(X, quad, images, cameras, normalisation, None, extra_mask)
    if diverged or res.std_percent > best_std:
        q, res = best_q, best_res
    return ShapeResult(q=q, residual=res, iterations=it, converged=converged, diverged=diverged)
