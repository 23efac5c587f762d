"""How sure a measured displacement is: the image noise through the Gauss-Newton step, and
the bias indicator of its regularization (the displacement's counterpart of
:mod:`fesdic_core.shape.uncertainty`).

At the converged field ``U`` of the finest scale, ``H`` and ``b`` are those of the full
Gauss-Newton (the deformed images' derivative at ``U``; Eq. 8 with three components per
node, :mod:`fesdic_core.displacement.residual`). Noise in the images moves ``b`` by ``b_n``
and the field by ``G b_n``, ``G`` the step solver's linear map (FE: ``H^-1``; a spline level
per component: ``kron(C_s, I3)^T (kron(C_s, I3) H kron(C_s, I3)^T)^-1 kron(C_s, I3)``,
Eq. 21). With the noise model of the shape

    Cov(b) = kappa H                                                     (noise model)

the covariance of the field is ``kappa G H G^T`` and each component's standard deviation
``sqrt(kappa diag(G H G^T))`` (:class:`~fesdic_core.solve.solvers.StepCovarianceHook`).

``kappa`` is measured on the frame itself, per component ``k``: the residual that the
richest model (the FE mesh, a linearised step from ``U``) leaves, ``chi2 - b^T H^-1 b``, is
the noise's share of the cost. Draws of white noise added to the deformed images and passed
through the same image model, interpolation and per-element normalisation give the
solver's own step of the noise, ``G b_n``, and the cost the FE model leaves of each draw;
``kappa_k = sum_k (G b_n)^2 / sum_k diag(G H G^T)`` scaled by the frame's unexplained cost
over the draws'. The draws' amplitude cancels: only the correlation of the points' noise
(the interpolation's, which a coarse level's averaging feels) is taken from them, and the
degrees of freedom the fit absorbs are counted alike in both costs (without that, the
fields spread 1.22-1.31 times the std on the tests' renders). The reference images' noise
enters the residual as the deformed ones' does (the same interpolation at nearly the same
sub-pixel positions), so it is in the frame's cost and needs no draw of its own.

The bias indicator is the solver's :class:`~fesdic_core.solve.solvers.BiasStepHook`: the
change ``Delta = (G' - G) b`` of the field with the regularization one notch weaker (``G'``:
the next finer spline level, or the unregularized step at the finest; FE: none). ``Delta``
holds the noise the weaker step adds: for nested levels ``Cov(Delta) = kappa (G' H G'^T -
G H G^T)``, so ``Delta^2 - Var(Delta)`` is an unbiased estimate of the squared bias (the
solver's optional ``weaker(scale)`` gives ``G'``; None: the unregularized step). The
uncertainty of each component is ``sqrt(std^2 + max(Delta^2 - Var(Delta), 0))``: the expected
squared error, bias plus variance. Without the de-biasing the finest level's indicator
(the FE step, every FE dof's noise) covered 99.4-99.8 % of the nodes of
``benchmarks/bench_displacement_levels.py``'s cases, with it 92-97 %.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from fesdic_core.displacement.residual import (DisplacementResidual, ReferenceView, chi_square,
                                               displacement_operators, displacement_residual,
                                               displacement_rhs)
from fesdic_core.solve.solvers import (BiasStepHook, DirectSolver, StepCovarianceHook, StepSolver,
                                      seen_dofs)

logger = logging.getLogger(__name__)

__all__ = ["DisplacementUncertainty", "displacement_noise_variance", "displacement_uncertainty"]


@dataclasses.dataclass(frozen=True, eq=False)
class DisplacementUncertainty:
    """Per node and component (world frame, mm) how far the field may be off.

    std_mm : (n, 3) the noise's standard deviation, or None (a solver with no covariance)
    bias_mm : (n, 3) the bias indicator's magnitude ``|Delta|``, or None (a solver without one)
    bias_noise_mm : (n, 3) the standard deviation of ``Delta`` under the noise (zeros if the
        solver has no ``weaker``)
    variance : (3,) ``kappa`` of ``Cov(b) = kappa H`` per component, in the solver's step
    residual_ratio : the FE-unexplained residual over the draw's (the noise's amplitude
        relative to the draw's)
    """

    std_mm: np.ndarray | None
    bias_mm: np.ndarray | None
    variance: np.ndarray
    residual_ratio: float = float("nan")
    bias_noise_mm: np.ndarray | None = None

    @property
    def squared_bias_mm2(self) -> np.ndarray | None:
        """(n, 3) ``max(Delta^2 - Var(Delta), 0)``: the estimated squared bias, or None."""
        if self.bias_mm is None:
            return None
        noise = 0.0 if self.bias_noise_mm is None else self.bias_noise_mm
        return np.clip(np.square(self.bias_mm) - np.square(noise), 0.0, None)

    @property
    def uncertainty_mm(self) -> np.ndarray | None:
        """(n, 3) ``sqrt(std^2 + squared bias)`` per component (std alone without a bias
        indicator), or None."""
        if self.std_mm is None:
            return None
        bias2 = self.squared_bias_mm2
        return np.sqrt(np.square(self.std_mm) + (0.0 if bias2 is None else bias2))


#: the noise draw's standard deviation, in fractions of each image's dynamic range (it cancels
#: from ``kappa``; it only has to stay well inside the range)
DRAW_FRACTION = 0.01

#: noise draws behind ``kappa`` (each: one residual and one step)
DRAWS = 2


def displacement_noise_variance(res: DisplacementResidual, H: sps.spmatrix, b: np.ndarray,
                                U: np.ndarray, view: ReferenceView, images: Sequence,
                                normalisation: str, step, diag: np.ndarray, draws: int = DRAWS,
                                seed: int = 0) -> tuple[np.ndarray, float]:
    """``kappa`` of each component and the residual ratio (module docstring).

    Parameters
    ----------
    res : the residual at ``U`` with its derivative (``dr_du``).
    H, b : (3n, 3n), (3n,) the full Gauss-Newton's operators of ``res``.
    U : (n, 3) the converged field; ``view``, ``images``: its scale's reference and images.
    step : ``b -> G b``, the solver's step map at this state.
    diag : (3n,) ``diag(G H G^T)``.

    Returns
    -------
    kappa : (3,) per component, ``sum_k (G b_n)^2 / sum_k diag(G H G^T)`` over the draws and
        the dofs of component ``k``, scaled by the ratio: the noise's variance in the
        solver's own step (a coarse level averages many points, whose noise the
        interpolation correlates).
    ratio : the FE-unexplained residual over the draws' mean FE-unexplained cost.
    """
    seen = seen_dofs(H)
    if not seen.any():
        return np.full(3, np.nan), float("nan")
    lu = spla.splu(sps.csc_matrix(H[seen][:, seen]))
    cost = chi_square(res, view.quad)[0]
    unexplained = cost - float(b[seen] @ lu.solve(b[seen]))          # the FE model's residual
    rng = np.random.default_rng(seed)
    wG = np.where(res.mask, view.quad.weight_mm2, 0.0)[:, :, None] * res.dr_du   # w dr/du
    squares, costs = np.zeros(3), []
    for _ in range(int(draws)):
        noisy = [im.with_values(im.values + rng.normal(0.0, DRAW_FRACTION * im.dynamic_range,
                                                       im.shape)) for im in images]
        drawn = displacement_residual(U, view, noisy, normalisation, False)
        both = res.mask & drawn.mask
        simulated = dataclasses.replace(res, r=np.where(both, drawn.r - res.r, 0.0), mask=both)
        b_n = displacement_rhs(view.quad, wG, simulated.r)             # b of the draw alone
        squares += np.sum(np.square(step(b_n)).reshape(-1, 3), axis=0)
        # the draw's cost that the FE model leaves, as the frame's (RSS / (N - p), not / N)
        costs.append(chi_square(simulated, view.quad)[0] - float(b_n[seen] @ lu.solve(b_n[seen])))
    ratio = max(unexplained, 0.0) / float(np.mean(costs)) if np.mean(costs) > 0 else float("nan")
    per_unit = np.sum(np.nan_to_num(diag).reshape(-1, 3), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        kappa = squares / int(draws) / per_unit * ratio
    return kappa, ratio


def displacement_uncertainty(U: np.ndarray, view: ReferenceView, images: Sequence,
                             solver: StepSolver,
                             normalisation: str = "element") -> DisplacementUncertainty:
    """The standard deviation and bias indicator of the converged field ``U`` (n, 3).

    Parameters
    ----------
    U : (n, 3) the field at the end of the finest scale.
    view : the finest scale's :class:`ReferenceView`; ``images``: the deformed pair at it.
    solver : the step solver of the measurement (``StepCovarianceHook`` for the std,
        ``BiasStepHook`` for the bias; without them the parts are None).
    normalisation : the residual's (Remark 2).
    """
    U = np.asarray(U, float).reshape(-1, 3)
    q = U.reshape(-1)
    res = displacement_residual(U, view, images, normalisation, True)
    H, b = displacement_operators(view.quad, res)
    H = sps.csr_matrix(H)
    if not isinstance(solver, StepCovarianceHook):
        logger.info("%r gives no step covariance: no displacement uncertainty", solver)
        return DisplacementUncertainty(std_mm=None, bias_mm=None, variance=np.full(3, np.nan))
    diag, _ = solver.step_covariance(H, view.scale)
    zero = np.zeros_like(q)
    factorize = getattr(solver, "factorize", None)           # (a step map factorized once)
    step = factorize(H, view.scale) if callable(factorize) else \
        (lambda b_n, q_n: solver.solve(H, b_n, q_n, view.scale))
    kappa, ratio = displacement_noise_variance(res, H, b, U, view, images, normalisation,
                                               lambda b_n: step(b_n, zero), diag)
    std = np.sqrt(np.clip(kappa * np.nan_to_num(diag).reshape(-1, 3), 0.0, None))
    bias = bias_noise = None
    if isinstance(solver, BiasStepHook):       # the weaker step's change to the solver's own
        bias = np.abs(solver.bias_step(H, b, q, view.scale) - step(b, q)).reshape(-1, 3)
        weaker = getattr(solver, "weaker", None)
        if callable(weaker):                   # Var(Delta) = kappa (diag G'HG' - diag GHG)
            finer = weaker(view.scale)
            diag_f = (DirectSolver() if finer is None else finer).step_covariance(H, view.scale)[0]
            change = np.clip(np.nan_to_num(diag_f - diag), 0.0, None).reshape(-1, 3)
            bias_noise = np.sqrt(kappa * change)
    logger.info("displacement uncertainty: std median %.3g um, max %.3g um (kappa %s)",
                1e3 * np.median(std), 1e3 * np.max(std), np.array2string(kappa, precision=3))
    return DisplacementUncertainty(std_mm=std, bias_mm=bias, variance=kappa, residual_ratio=ratio,
                                   bias_noise_mm=bias_noise)
