"""How sure a measured shape is: the image noise carried through the Gauss-Newton step.

At convergence the shape ``q`` satisfies the normal equations of Eq. 8 through the step
solver. Noise ``n_c`` in image ``c`` moves the (linearised) residual by ``r_n``, the
right-hand side by ``b_n = -Phi^T W r_n`` and the shape by ``d = G b_n``, where ``G`` is
the step's linear map (FE: ``H^-1``; Tikhonov, Eq. 10: ``(H + lam A)^-1``; geometric
regularization, Eq. 21: ``C_s^T (C_s H C_s^T)^-1 C_s``). With the noise model

    Cov(b_n) = kappa H                                                     (noise model)

the covariance of the shape is ``kappa G H G^T`` (FE: ``kappa H^-1``).

``kappa`` is estimated from the images themselves by a parametric bootstrap: white noise
of each image's own (Immerkaer) standard deviation (:mod:`fesdic_core.imaging.noise`) is added
to the pixels, passed through the same image model, interpolation and per-element
normalisation (Remark 2) at the same integration points, and ``kappa = b_n^T H^-1 b_n / n``
(its expectation under the model). The interpolation's smoothing of the noise (it lowers
the variance between pixel centres) and the correlation of neighbouring points are thus
in ``kappa``, not assumed away; the model keeps only their average effect.

With calibration, the rigid normal motions of ``q`` are handed to the camera poses (the
gauge, :mod:`fesdic_core.shape.gauge`): the reported covariance is that of the shape modulo
these modes, ``P kappa G H G^T P^T`` with ``P`` the weighted projection out of them. It
is what a comparison "modulo rigid-body motion" sees. Without calibration the cameras
are exact and the rigid part is measured, so ``P = I``.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.residual.graylevel import GrayLevelResidual, gray_level_residual
from fesdic_core.shape.operators import chi_square, current_nodes, shape_operators
from fesdic_core.solve.solvers import StepCovarianceHook, seen_dofs

logger = logging.getLogger(__name__)

__all__ = ["NoiseModel", "LinearisedState", "linearised_state", "noise_model", "shape_std"]


@dataclasses.dataclass(frozen=True)
class NoiseModel:
    """``Cov(b) ~= variance * H`` at one image scale (see the module docstring).

    variance : ``kappa`` scaled to the residual that the richest model (the FE mesh, a
        linearised step from the state) leaves: the classic ``sigma^2 = RSS / n`` of least
        squares with the RSS of the full model (as in Mallows' Cp), through the image model.
        It holds the noise and the interpolation's misfit of the finest texture, which
        also varies from pixel to pixel, but not a shape the regularization misses.
    variance_images : ``kappa`` of white noise of the images' own Immerkaer sigma
        (:mod:`fesdic_core.imaging.noise`); on a fine speckle that sigma also counts texture, so this
        is an upper bound of the noise (about 3 times the variance of 2 gray levels of noise
        on a 4 px speckle).
    sigma_gray : the standard deviation drawn in each image (gray levels), Immerkaer's.
    residual_ratio : the residual's mean square over that of the simulated noise.
    draws : bootstrap draws behind the figures.
    """

    scale: int
    variance: float
    variance_images: float = float("nan")
    sigma_gray: tuple[float, ...] = (float("nan"), float("nan"))
    residual_ratio: float = float("nan")
    draws: int = 1


@dataclasses.dataclass(frozen=True, eq=False)
class LinearisedState:
    """The Gauss-Newton system at a state: ``H``, ``b`` (Eq. 8), the residual and its cost."""

    H: sps.csr_matrix
    b: np.ndarray
    residual: GrayLevelResidual = dataclasses.field(repr=False)
    chi_square: float
    n_points: int


def linearised_state(nodes0: np.ndarray, normals: np.ndarray, q: np.ndarray, quad: PixelQuadrature,
                     images: Sequence, cameras: Sequence, normalisation: str = "element",
                     mask: np.ndarray | None = None,
                     residual: GrayLevelResidual | None = None) -> LinearisedState:
    """Assemble ``H`` and ``b`` (Eq. 8) and the cost (Eq. 7) at the shape ``q``.

    ``residual``: the residual at that state with ``dr_dX``, when the caller has it (not
    evaluated again).
    """
    if residual is None or residual.dr_dX is None:
        X = quad.points(current_nodes(nodes0, normals, q))
        residual = gray_level_residual(X, quad, images, cameras, normalisation, "point", mask)
    res = residual
    H, b = shape_operators(quad, normals, res)
    c, n = chi_square(res, quad)
    return LinearisedState(H=H, b=b, residual=res, chi_square=c, n_points=n)


def noise_model(state: LinearisedState, X: np.ndarray, quad: PixelQuadrature, images: Sequence,
                cameras: Sequence, normals: np.ndarray, sigma_gray: Sequence[float], scale: int = 0,
                normalisation: str = "element", mask: np.ndarray | None = None, draws: int = 1,
                seed: int = 0) -> NoiseModel:
    """Estimate ``kappa`` of ``Cov(b) = kappa H`` by a parametric bootstrap of the image noise.

    Each draw adds white noise of ``sigma_gray[c]`` to image ``c`` (through
    :meth:`Image.with_values`, the same image model), takes the change of the residual
    at the same points ``X``, its right-hand side ``b_n`` (Eq. 8), and
    ``b_n^T H^-1 b_n / n`` over the ``n`` dofs that see a point. One draw is precise to
    about ``sqrt(2 / n)`` (2 % for 4000 nodes).
    """
    seen = seen_dofs(state.H)
    sigma_gray = tuple(float(s) for s in sigma_gray)
    if not seen.any():
        return NoiseModel(scale, float("nan"), float("nan"), sigma_gray, float("nan"), 0)
    lu = spla.splu(sps.csc_matrix(state.H[seen][:, seen]))
    rng = np.random.default_rng(seed)
    values, squares = [], []
    for _ in range(draws):
        noisy = [im.with_values(im.values + rng.normal(0.0, s, im.shape))
                 for im, s in zip(images, sigma_gray)]
        res = gray_level_residual(X, quad, noisy, cameras, normalisation, None, mask)
        both = state.residual.mask & res.mask
        r_n = np.where(both, res.r - state.residual.r, 0.0)
        simulated = dataclasses.replace(state.residual, r=r_n, mask=both)
        _, b_n = shape_operators(quad, normals, simulated)
        values.append(float(b_n[seen] @ lu.solve(b_n[seen])) / np.count_nonzero(seen))
        squares.append(chi_square(simulated, quad)[0])
    images_variance = float(np.mean(values))
    # the residual that the richest model (the FE mesh itself) would leave, linearised: a
    # regularization that misses part of the shape must not pass its misfit off as noise
    unexplained = state.chi_square - float(state.b[seen] @ lu.solve(state.b[seen]))
    ratio = unexplained / float(np.mean(squares)) if np.mean(squares) > 0 else float("nan")
    logger.debug("scale %d: noise model kappa %.4g (images' sigma %.3g, %.3g gray levels: %.4g; "
                 "residual / simulated noise %.3g)", scale, images_variance * ratio, *sigma_gray,
                 images_variance, ratio)
    return NoiseModel(scale, images_variance * ratio, images_variance, sigma_gray, ratio, draws)


def _projection_out_of(modes: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``P = I - U V^T`` removing the weighted least-squares part along ``modes`` (n, k)."""
    sw = np.sqrt(weights)
    Q, sv, _ = np.linalg.svd(modes * sw[:, None], full_matrices=False)   # rank-revealing
    Q = Q[:, sv > 1e-10 * sv.max()]
    return Q / sw[:, None], Q * sw[:, None]          # U, V: P = I - U V^T (U V^T q is the fit)


def shape_std(H: sps.spmatrix, variance: float, solver, scale: int = 0,
              modes: np.ndarray | None = None, weights: np.ndarray | None = None) -> np.ndarray | None:
    """Standard deviation of the shape at each node (mm), or None if the solver gives no
    covariance.

    Parameters
    ----------
    H : the Gauss-Newton matrix at the converged state (Eq. 8).
    variance : ``kappa`` of :func:`noise_model`.
    solver : the step solver; its optional ``step_covariance(H, scale)`` returns
        ``(diag(C), V -> C V)`` with ``C = G H G^T``
        (:class:`~fesdic_core.solve.solvers.StepCovarianceHook`).
    modes, weights : rigid normal modes (n, k) and nodal weights to project out (the
        gauge of a calibrated measurement), or None.
    """
    if modes is not None and weights is None:
        raise ValueError("shape_std: the rigid normal modes to project out need the nodal weights")
    if not isinstance(solver, StepCovarianceHook):
        logger.info("%r gives no step covariance: no shape uncertainty", solver)
        return None
    diag, apply = solver.step_covariance(H, scale)
    if modes is not None and weights is not None:
        U, V = _projection_out_of(modes, weights)
        CV = apply(V)                                             # C V (n, k)
        # diag(P C P^T) = diag(C) - 2 rowsum(U * C V) + rowsum(U * (U (V^T C V)))
        diag = diag - 2.0 * np.sum(U * CV, axis=1) + np.sum(U * (U @ (V.T @ CV)), axis=1)
    return np.sqrt(np.clip(variance * diag, 0.0, None))
