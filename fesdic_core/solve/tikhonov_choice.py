"""The weight of the Tikhonov term of Eq. 10: its choice and what it costs in noise and bias.

All of it is linear algebra on the Gauss-Newton system of Eq. 8 at one state ``q``.
Under the image noise the right-hand side ``b`` of Eq. 8 has ``Cov(b) ~= kappa H``
(``kappa``: :attr:`NoiseModel.variance` of :mod:`fesdic_core.shape.uncertainty`), so the
unregularized estimate ``q_FE = q + H^-1 b`` has ``Cov(q_FE) = kappa H^-1``, and the
regularized one of Eq. 10,

    q_lam = q + (H + lam A)^-1 (b - lam A q) = (H + lam A)^-1 H q_FE,

is a linear smoother of ``q_FE`` with hat matrix ``S_lam = (H + lam A)^-1 H``.

Choice of ``lam`` (:func:`mallows_cp`)
--------------------------------------
Mallows' Cp, the unbiased estimate of the predictive risk ``E ||q_lam - q_true||_H^2``
(up to the constant ``n kappa``):

    Cp(lam) = (q_lam - q_FE)^T H (q_lam - q_FE) + 2 kappa tr((H + lam A)^-1 H).

``q_FE`` is taken on the dofs with a positive diagonal of ``H`` (the others see no
integration point; ``H`` has zero rows there and ``q_lam`` does not depend on them).
The first term is evaluated as ``d^T H d - 2 b^T d + b_P^T H_PP^-1 b_P`` with
``d = q_lam - q``; if ``H_PP`` is singular the last (constant) term is left out, which
shifts the curve but not its minimum. The trace is exact up to
:data:`DENSE_CP_MAX_DOFS` dofs (one generalized eigendecomposition of ``(H, H + lam0 A)``
serves every ``lam``); above, it is Hutchinson's estimate with
:data:`HUTCHINSON_PROBES` Rademacher probes of a fixed seed (the same probes for every
``lam``, so the curve is smooth in ``lam`` and the choice deterministic), one sparse LU
factorisation of ``H + lam A`` per ``lam``.

Noise of a step (:func:`covariance_diagonal`)
---------------------------------------------
``d = G b`` with ``G = (H + lam A)^-1``, so ``Cov(d) = kappa G H G``; the function returns
``diag(G H G)`` (without ``kappa``).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from fesdic_core.fe.mesh import SurfaceMesh, element_areas
from fesdic_core.solve.solvers import SingularSystemError

logger = logging.getLogger(__name__)

__all__ = ["DENSE_CP_MAX_DOFS", "DENSE_COVARIANCE_MAX_DOFS", "HUTCHINSON_PROBES",
           "HUTCHINSON_SEED", "COLUMN_BLOCK", "GRID_SIZE", "CpCurve", "element_size",
           "mesh_extent", "length_grid", "mallows_cp", "covariance_diagonal"]

#: up to this many dofs the trace of Cp is exact (dense generalized eigendecomposition,
#: ~0.1 s at 300 dofs, growing like n**3; Hutchinson's costs ~0.1-0.2 ms per dof)
DENSE_CP_MAX_DOFS = 300
#: up to this many dofs diag(G H G) is taken from the dense inverse (Cholesky)
DENSE_COVARIANCE_MAX_DOFS = 6000
#: Rademacher probes of Hutchinson's trace estimator, and their fixed seed
HUTCHINSON_PROBES = 16
HUTCHINSON_SEED = 20200914
#: columns of G solved at once in the sparse path of :func:`covariance_diagonal`
COLUMN_BLOCK = 256
#: lengths of the grid of the automatic choice
GRID_SIZE = 14


@dataclass(frozen=True)
class CpCurve:
    """Mallows' Cp over a grid of weights (one automatic choice).

    Attributes
    ----------
    lengths_mm, lambdas : (m,) the grid, as cosine-probe lengths and their weights
    cp : (m,) ``rss + 2 kappa dof``
    rss : (m,) ``(q_lam - q_FE)^T H (q_lam - q_FE)`` (see the module docstring)
    dof : (m,) ``tr((H + lam A)^-1 H)``, the effective number of parameters
    kappa : the noise variance used
    exact_trace : False when ``dof`` is Hutchinson's estimate
    """

    lengths_mm: np.ndarray
    lambdas: np.ndarray
    cp: np.ndarray
    rss: np.ndarray
    dof: np.ndarray
    kappa: float
    exact_trace: bool

    @property
    def best(self) -> int:
        """Index of the grid's minimum of Cp."""
        return int(np.argmin(self.cp))


def element_size(mesh: SurfaceMesh) -> float:
    """Typical element size (mm): the side of a square of the median element area
    (triangles counted in pairs)."""
    sizes = [np.sqrt(areas * (2.0 if block.family.reference == "triangle" else 1.0))
             for block, areas in zip(mesh.blocks, element_areas(mesh))]
    return float(np.median(np.concatenate(sizes)))


def mesh_extent(nodes: np.ndarray) -> float:
    """Extent (mm) of the nodes along their first principal direction."""
    centred = nodes - nodes.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    return float(np.ptp(centred @ axes[0]))


def length_grid(mesh: SurfaceMesh, size: int = GRID_SIZE) -> np.ndarray:
    """Log grid of regularization lengths: 2 element sizes up to the mesh's extent."""
    extent = mesh_extent(mesh.nodes)
    shortest = min(2.0 * element_size(mesh), 0.5 * extent)
    return np.geomspace(shortest, extent, size)


def _constant_term(H: sps.csr_matrix, b: np.ndarray) -> float:
    """``b_P^T H_PP^-1 b_P`` on the dofs with a positive diagonal (0 if H_PP is singular)."""
    seen = np.flatnonzero(H.diagonal() > 0.0)
    if seen.size == 0:
        return 0.0
    try:
        with np.errstate(all="ignore"):
            x = spla.splu(sps.csc_matrix(H[seen][:, seen])).solve(b[seen])
    except RuntimeError:                                    # exactly singular
        x = np.full(seen.size, np.nan)
    if not np.all(np.isfinite(x)):
        logger.debug("Cp: H is singular on the seen dofs; the constant term is left out")
        return 0.0
    return float(b[seen] @ x)


def _cp_dense(H, b, Aq, A, lambdas):
    """Exact rss (without constant) and dof over the grid: ``V^T K0 V = I, V^T H V = diag t``."""
    lam0 = float(np.sqrt(lambdas[0] * lambdas[-1]))
    t, V = sla.eigh(H.toarray(), (H + lam0 * A).toarray())
    t = np.clip(t, 0.0, 1.0)
    a = (1.0 - t) / lam0                                    # V^T A V = diag a
    beta, alpha = V.T @ b, V.T @ Aq
    rss, dof = [], []
    for lam in lambdas:
        D = t + lam * a                                     # V^T (H + lam A) V
        y = (beta - lam * alpha) / D                        # V^-1 d, Eq. 10
        rss.append(float(t @ (y * y) - 2.0 * beta @ y))
        dof.append(float(np.sum(t / D)))
    return np.array(rss), np.array(dof)


def _cp_sparse(H, b, Aq, A, lambdas, probes, seed):
    """rss (without constant) exact, dof by Hutchinson, one sparse LU per weight."""
    Z = np.random.default_rng(seed).integers(0, 2, size=(H.shape[0], probes)) * 2.0 - 1.0
    rhs = np.asfortranarray(np.column_stack([b, np.asarray(H @ Z)]))   # one solve per weight
    rss, dof = [], []
    for lam in lambdas:
        rhs[:, 0] = b - lam * Aq                            # Eq. 10
        X = _factor(H + lam * A).solve(rhs)
        d = X[:, 0]
        rss.append(float(d @ (H @ d) - 2.0 * b @ d))
        dof.append(float(np.sum(Z * X[:, 1:])) / probes)
    return np.array(rss), np.array(dof)


def _factor(K: sps.spmatrix):
    """Sparse LU of a symmetric positive definite matrix (no pivoting needed)."""
    try:
        return spla.splu(sps.csc_matrix(K), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                         options={"SymmetricMode": True})
    except RuntimeError as error:
        raise SingularSystemError(f"H_FE + lam A is singular ({K.shape[0]} dofs): {error}"
                                  ) from None


def mallows_cp(H: sps.spmatrix, b: np.ndarray, q: np.ndarray, A: sps.spmatrix,
               lambdas: np.ndarray, kappa: float, lengths_mm: np.ndarray | None = None, *,
               dense_max_dofs: int | None = None, probes: int | None = None,
               seed: int = HUTCHINSON_SEED) -> CpCurve:
    """Mallows' Cp of the Eq. 10 step at the state ``q`` over a grid of weights.

    Parameters
    ----------
    H, b : the Gauss-Newton system of Eq. 8 at ``q`` (``H`` symmetric, ``n x n``)
    q : (n,) the current state
    A : the regularization operator of Eq. 10
    lambdas : (m,) increasing positive weights
    kappa : noise variance, ``Cov(b) = kappa H``
    lengths_mm : (m,) optional lengths the weights stand for (reported only)
    dense_max_dofs : exact trace up to this many dofs (default :data:`DENSE_CP_MAX_DOFS`)
    probes, seed : Hutchinson's estimator above it (default :data:`HUTCHINSON_PROBES`)

    Returns
    -------
    CpCurve
    """
    if not (np.isfinite(kappa) and kappa > 0):
        raise ValueError(f"Mallows' Cp needs a positive noise variance kappa, got {kappa!r}")
    lambdas = np.asarray(lambdas, dtype=float)
    H = sps.csr_matrix(H)
    A = sps.csr_matrix(A)
    b = np.asarray(b, dtype=float)
    Aq = A @ np.asarray(q, dtype=float)
    limit = DENSE_CP_MAX_DOFS if dense_max_dofs is None else dense_max_dofs
    exact = H.shape[0] <= limit
    if exact:
        rss, dof = _cp_dense(H, b, Aq, A, lambdas)
    else:
        rss, dof = _cp_sparse(H, b, Aq, A, lambdas, probes or HUTCHINSON_PROBES, seed)
    rss = rss + _constant_term(H, b)
    lengths = (np.full(lambdas.shape, np.nan) if lengths_mm is None
               else np.asarray(lengths_mm, dtype=float))
    return CpCurve(lengths_mm=lengths, lambdas=lambdas, cp=rss + 2.0 * kappa * dof, rss=rss,
                   dof=dof, kappa=float(kappa), exact_trace=exact)


def covariance_diagonal(H: sps.spmatrix, A: sps.spmatrix, lam: float, *,
                        dense_max_dofs: int | None = None) -> np.ndarray:
    """``diag(G H G)`` with ``G = (H + lam A)^-1``: the step's variance per dof over ``kappa``.

    Exact in both paths. Up to ``dense_max_dofs`` (default
    :data:`DENSE_COVARIANCE_MAX_DOFS`): the dense inverse ``M = G`` by Cholesky (LAPACK
    potrf/potri), then ``diag(M H M)_i = sum_j M_ji (H M)_ji``. Above: one sparse LU of
    ``H + lam A`` and the columns of ``G`` solved :data:`COLUMN_BLOCK` at a time,
    ``diag_j = g_j^T H g_j`` (``n`` solves: exact, linear in memory, slower).
    """
    H = sps.csr_matrix(H)
    K = (H + lam * sps.csr_matrix(A)).tocsr()
    n = K.shape[0]
    limit = DENSE_COVARIANCE_MAX_DOFS if dense_max_dofs is None else dense_max_dofs
    if n <= limit:
        c, info = sla.lapack.dpotrf(K.toarray(), lower=False, clean=True)
        if info == 0:
            M, info = sla.lapack.dpotri(c, lower=False)
        if info != 0:
            raise SingularSystemError(f"H_FE + lam A is not positive definite ({n} dofs)")
        M = np.triu(M) + np.triu(M, 1).T
        return np.einsum("ji,ji->i", M, np.asarray(H @ M))
    logger.debug("covariance diagonal: %d dofs, %d sparse solves", n, n)
    lu = _factor(K)
    out = np.empty(n)
    for start in range(0, n, COLUMN_BLOCK):
        stop = min(n, start + COLUMN_BLOCK)
        E = np.zeros((n, stop - start))
        E[np.arange(start, stop), np.arange(stop - start)] = 1.0
        Y = lu.solve(E)                                     # columns of G
        out[start:stop] = np.einsum("ij,ij->j", Y, np.asarray(H @ Y))
    return out
