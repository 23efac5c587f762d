"""The damped Gauss-Newton loop shared by the shape (Eq. 7) and the displacement.

Both minimise a weighted sum of squared gray-level residuals over a nodal unknown ``q``
with steps ``(H + mu diag H) d = b`` solved by a :class:`~fesdic_core.solve.solvers.StepSolver`,
under the Levenberg-Marquardt guard of :mod:`fesdic_core.solve.damping` (the residual never
grows). The problem is given as plain functions: ``evaluate(q)`` the residual (with
``std_percent``), ``operators(res)`` its ``H, b`` (Eq. 8), ``solve(H, b, q)`` the step,
``chi_square(res)`` the cost and the number of points seen.

Convergence is the stagnation of ``q`` (section 2.2): the step is below ``tol`` (largest
component), or it changes the fit by less than one unit of chi-square (the data cannot tell
``q`` from ``q + d``), or no damped step lowers the residual. The plain step is tested
before the images are evaluated at its end (its size, and the fall of chi-square the
linearised model predicts, :func:`predicted_change`): a stagnant step is not taken, and the
iteration that would only have confirmed it costs no residual evaluation. ``residual_rtol``
(a coarse scale, which only starts the next, Remark 3) also stops it when the residual
falls by less than that fraction in a step.

With ``stretch``, an accepted plain step that lowered the cost by more than
:data:`STRETCH_RATIO` times the linearised model's prediction is stretched along itself to
the minimum of the cost's parabola (:func:`stretch_factor`), evaluated once and kept if the
cost is lower there: where the Gauss-Newton model overestimates the curvature (it leaves
out the residual's second derivatives), the steps fall short along one direction, step
after step.

The Levenberg-Marquardt matrices ``H + mu diag H`` are kept per ``mu`` while ``H`` is the
same object, so that a step solver that caches its factorization on the matrix
(:class:`~fesdic_core.solve.solvers.CachedFactorization`, the displacement's modified
Gauss-Newton, whose ``H`` is constant) factorizes each once.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import scipy.sparse as sps

from fesdic_core.solve.damping import damped_step, relaxed

logger = logging.getLogger(__name__)

__all__ = ["GaussNewtonOutcome", "damped", "predicted_change", "damped_gauss_newton",
           "stretch_factor", "STRETCH_RATIO", "MAX_STRETCH"]

#: a plain step that lowered the cost by more than this many times the linearised model's
#: prediction is stretched along itself, up to :data:`MAX_STRETCH` times (:func:`stretch_factor`)
STRETCH_RATIO = 1.25
MAX_STRETCH = 8.0


@dataclass(frozen=True)
class GaussNewtonOutcome:
    """End of a damped Gauss-Newton: the unknown, its residual, the iterations taken (a
    stagnant step found before evaluating it is not counted), whether ``q`` stagnated, the
    damping in force and why it stopped ("step", "noise", "residual", "no descent",
    "no point seen", "iteration limit")."""

    q: np.ndarray
    residual: Any
    iterations: int
    converged: bool
    damping: float
    stop: str


def damped(H, mu: float):
    """Levenberg-Marquardt matrix ``H + mu diag(H)`` (Marquardt's scaling; ``mu = 0``: H)."""
    if mu == 0.0:
        return H
    return (H + mu * sps.diags(H.diagonal())).tocsr()


def predicted_change(H, b: np.ndarray, d: np.ndarray, cost: tuple[float, int]) -> float:
    """How much the step ``d`` would improve the fit by the linearised model, in units of
    chi-square, without evaluating the images there: the cost linearised at ``q`` is
    ``c - 2 d.b + d.H d`` (Eq. 8, ``b = -sum w phi r``), so the predicted fall is
    ``2 d.b - d.H d``, divided by ``c / n`` (``cost = (c, n)``)."""
    c, n = cost
    fall = 2.0 * float(d @ b) - float(d @ (H @ d))
    return fall * n / c if c > 0.0 and n else float("inf")


def stretch_factor(c0: float, c1: float, g: float) -> float:
    """The factor ``f`` of a step ``d`` at the minimum of the cost's parabola along it.

    Along ``f d`` the cost is ``c(f) = c0 - 2 f g + k f^2`` with the exact slope ``g = d . b``
    (``b = -sum w phi r``, Eq. 8) and ``k = c1 - c0 + 2 g`` from the cost ``c1`` measured at
    ``f = 1``; its minimum is ``f = g / k``, at most :data:`MAX_STRETCH` (``k <= 0``: the
    largest). A factor at most :data:`STRETCH_RATIO` means: keep the step.
    """
    k = (c1 - c0) + 2.0 * g
    return MAX_STRETCH if k <= 0.0 else min(MAX_STRETCH, g / k)


def damped_gauss_newton(q0: np.ndarray, start, evaluate: Callable, operators: Callable,
                        solve: Callable, chi_square: Callable, tol: float, max_iter: int,
                        max_damping: int, residual_rtol: float | None = None,
                        on_step: Callable | None = None, name: str = "GN",
                        stretch: bool = False) -> GaussNewtonOutcome:
    """Minimise from ``q0`` (its residual ``start``); ``on_step(it, std_before, res, step,
    mu)`` after each accepted step (logs). See the module docstring."""
    q, res = np.asarray(q0, float).copy(), start
    mu, converged, it, stop = 0.0, False, 0, "iteration limit"
    matrices: dict[float, Any] = {}
    for it in range(1, max_iter + 1):
        std = res.std_percent
        if not np.isfinite(std):                      # no point seen: nothing to measure
            logger.warning("%s: no integration point is seen", name)
            stop = "no point seen"
            break
        H, b = operators(res)
        if matrices.get(0.0) is not H:                # a new H: its damped matrices too
            matrices = {0.0: H}
        cost = chi_square(res)
        plain = solve(H, b, q)                                    # the Gauss-Newton step, Eq. 8
        if np.all(np.isfinite(plain)):
            step = float(np.max(np.abs(plain))) if plain.size else 0.0
            stagnant = ("step" if step < tol else "noise"
                        if abs(predicted_change(H, b, plain, cost)) < 1.0 else None)
            if stagnant is not None:                  # q stagnates: the step is not taken
                converged, stop, it = True, stagnant, it - 1
                logger.debug("%s: the next step (max|d| %.2e) is stagnant (%s)", name, step,
                             stagnant)
                break
        within_noise: list[float] = []

        def propose(mu: float):
            if within_noise:                          # more damping only shortens a stagnant step
                return None
            if mu == 0.0:
                d = plain
            else:
                if mu not in matrices:
                    matrices[mu] = damped(H, mu)
                d = solve(matrices[mu], b, q)
            if not np.all(np.isfinite(d)):
                return None
            if mu > 0.0 and abs(predicted_change(H, b, d, cost)) < 1.0:
                within_noise.append(mu)               # a refused step damped into the noise
                return None
            return d, evaluate(q + d)

        accepted, mu = damped_step(propose, std, mu, max_damping)
        if accepted is None:                          # no damped step lowers the residual
            converged, stop = True, "no descent"
            logger.debug("%s it %d: no damped step lowers the residual (%.4f%%); stagnant",
                         name, it, std)
            break
        d, trial = accepted
        c0, n = cost
        c1 = chi_square(trial)[0]
        if stretch and mu == 0.0 and c0 > 0.0 and n and \
                (c0 - c1) * n / c0 > STRETCH_RATIO * predicted_change(H, b, d, cost) > 0.0:
            f = stretch_factor(c0, c1, float(d @ b))
            if f > STRETCH_RATIO:
                longer = evaluate(q + f * d)
                c_f = chi_square(longer)[0]
                if c_f < c1:
                    logger.debug("%s it %d: step stretched %.3g times (residual %.4f%% -> "
                                 "%.4f%%)", name, it, f, trial.std_percent, longer.std_percent)
                    d, trial, c1 = f * d, longer, c_f
        change = (c0 - c1) * n / c0 if c0 > 0.0 and n else float("inf")
        q, res = q + d, trial
        step = float(np.max(np.abs(d))) if d.size else 0.0
        if on_step is not None:
            on_step(it, std, res, step, mu)
        mu = relaxed(mu)
        if step < tol:
            converged, stop = True, "step"
            break
        if abs(change) < 1.0:                         # the data cannot tell q from q + d
            converged, stop = True, "noise"
            break
        if residual_rtol is not None and std - res.std_percent <= residual_rtol * std:
            converged, stop = True, "residual"
            break
    return GaussNewtonOutcome(q=q, residual=res, iterations=it, converged=converged,
                              damping=mu, stop=stop)
