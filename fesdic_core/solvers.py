"""The one extension point of the core: the linear solve of each Gauss-Newton step.

At Gauss-Newton iteration k of the shape problem (Eq. 7) the core assembles
``H_FE`` and ``b_FE`` (Eq. 8, projected on the nominal normals, Remark 1) and asks a
:class:`StepSolver` for the descent direction ``d`` such that ``q_k = q_{k-1} + d``.
The default is a plain sparse direct solve of ``H d = b``. Tikhonov regularization
(Eq. 10) is another step solver of the core (:mod:`fesdic_core.tikhonov`); a plugin
supplies its own from outside, without the core knowing about it.
"""
from __future__ import annotations

import logging
from typing import Callable, Protocol, runtime_checkable

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sps
import scipy.sparse.linalg as spla

logger = logging.getLogger(__name__)

#: up to this many dofs a step covariance is computed densely (memory ~ 8 n^2 bytes)
DENSE_LIMIT = 8000


class SingularSystemError(RuntimeError):
    """The Gauss-Newton system is singular (a node sees no integration point)."""


@runtime_checkable
class StepSolver(Protocol):
    """Solve one Gauss-Newton step of the shape problem.

    Parameters of ``solve``
    -----------------------
    H : scipy.sparse matrix, (n, n)
        ``H_FE`` of Eq. 8 in the normal-projected unknown (Remark 1), symmetric.
    b : ndarray, (n,)
        ``b_FE`` of Eq. 8.
    q : ndarray, (n,)
        Current shape correction (mm along the nominal node normals).
    scale : int
        Image scale of the current iteration (0 is the finest).

    Returns
    -------
    d : ndarray, (n,)
        The update, ``q <- q + d``.
    """

    def solve(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        ...


# Optional methods of a step solver, used when present (duck typing):
#
# start_scale(scale, noise) -> None
#     called before the shape Gauss-Newton of each image scale (again in later fixed-point
#     iterations of the same scale) with the scale's noise model
#     (:class:`fesdic_core.uncertainty.NoiseModel`: ``Cov(b) ~= noise.variance * H``), for
#     solvers that choose their regularization from the data;
# step_covariance(H, scale) -> (diag, apply)
#     the covariance of the step ``d = G b`` per unit noise: ``C = G H G^T``, as its
#     diagonal (n,) and the action ``V (n, k) -> C V``; the shape uncertainty
#     (:func:`fesdic_core.uncertainty.shape_std`);
# bias_step(H, b, q, scale) -> (n,)
#     how much the shape would move, linearised at the converged state, if the
#     regularization were one notch weaker (zeros for none): the bias indicator.


def sparse_solve(H: sps.spmatrix, b: np.ndarray, what: str = "H_FE") -> np.ndarray:
    """Sparse direct solve of ``H d = b`` with a clear error when ``H`` is singular."""
    H = sps.csc_matrix(H)
    diagonal = H.diagonal()
    empty = np.flatnonzero(diagonal <= 0.0)
    if empty.size:
        raise SingularSystemError(
            f"{what} has {empty.size} empty rows (first: dof {empty[0]}): no integration "
            "point sees these nodes; crop the mesh to the visible region or regularize")
    with np.errstate(all="ignore"):
        d = spla.spsolve(H, b)
    if not np.all(np.isfinite(d)):
        raise SingularSystemError(f"{what} is numerically singular ({H.shape[0]} dofs)")
    return np.asarray(d, dtype=float)


def seen_dofs(H: sps.spmatrix) -> np.ndarray:
    """(n,) bool: the dofs whose diagonal term of ``H`` is not zero (some point sees them)."""
    d = H.diagonal()
    return d > 1e-12 * (d.max() if d.size else 0.0)


class DirectSolver:
    """The default step solver of the core: ``d = H^-1 b`` (Eq. 8), no regularization."""

    def solve(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        return sparse_solve(H, b)

    def step_covariance(self, H: sps.spmatrix, scale: int):
        """``G H G^T = H^-1`` (:func:`inverse_covariance`)."""
        return inverse_covariance(H)

    def bias_step(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        """No regularization, no bias: zeros."""
        return np.zeros(H.shape[0])

    def __repr__(self) -> str:
        return "DirectSolver()"


def inverse_covariance(H: sps.spmatrix) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """``diag(H^-1)`` and ``V -> H^-1 V``: the step covariance of the plain FE solve (in
    units of ``kappa``), over the dofs that see a point (others: NaN, their columns 0)."""
    n = H.shape[0]
    seen = seen_dofs(H)
    diag = np.full(n, np.nan)
    if np.count_nonzero(seen) <= DENSE_LIMIT:
        factor = sla.cho_factor(H[seen][:, seen].toarray(), lower=True, check_finite=False)
        inverse = sla.cho_solve(factor, np.eye(np.count_nonzero(seen)), check_finite=False)
        diag[seen] = np.diag(inverse)

        def apply(V: np.ndarray) -> np.ndarray:
            out = np.zeros((n,) + V.shape[1:])
            out[seen] = inverse @ V[seen]
            return out
        return diag, apply
    lu = spla.splu(sps.csc_matrix(H[seen][:, seen]))
    diag[seen] = _probed_diagonal(lu.solve, int(np.count_nonzero(seen)))

    def apply_sparse(V: np.ndarray) -> np.ndarray:
        out = np.zeros((n,) + V.shape[1:])
        out[seen] = lu.solve(np.asarray(V[seen], dtype=float))
        return out
    return diag, apply_sparse


def _probed_diagonal(solve: Callable[[np.ndarray], np.ndarray], n: int, probes: int = 128,
                     seed: int = 0) -> np.ndarray:
    """Diagonal of a symmetric operator by Rademacher probing (Bekas et al. 2007)."""
    z = np.random.default_rng(seed).choice([-1.0, 1.0], size=(n, probes))
    return np.sum(z * solve(z), axis=1) / probes


