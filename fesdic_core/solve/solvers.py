"""The one extension point of the core: the linear solve of each Gauss-Newton step.

At Gauss-Newton iteration k of the shape problem (Eq. 7) the core assembles
``H_FE`` and ``b_FE`` (Eq. 8, projected on the nominal normals, Remark 1) and asks a
:class:`StepSolver` for the descent direction ``d`` such that ``q_k = q_{k-1} + d``.
The default is a plain sparse direct solve of ``H d = b``. Tikhonov regularization
(Eq. 10) is another step solver of the core (:mod:`fesdic_core.solve.tikhonov`); a plugin
supplies its own from outside, without the core knowing about it.
"""
from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING, Callable, Protocol, runtime_checkable

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sps
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import reverse_cuthill_mckee

from fesdic_core.errors import FesdicCoreError

if TYPE_CHECKING:  # typing only: the shape package imports this one
    from fesdic_core.shape.uncertainty import NoiseModel

logger = logging.getLogger(__name__)

__all__ = ["SingularSystemError", "StepSolver", "StartScaleHook", "StepCovarianceHook",
           "BiasStepHook", "FactorizeHook", "sparse_solve", "sparse_factor", "seen_dofs",
           "DirectSolver", "CachedFactorization", "inverse_diagonal", "inverse_covariance"]


class SingularSystemError(FesdicCoreError, RuntimeError):
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


# Optional hooks of a step solver. The core looks for each with ``isinstance(solver, Hook)``
# (runtime-checkable protocols: a solver implements them by having the method, without
# importing the core; the plugin's solver does so). A method that exists only through a
# ``__getattr__`` that forwards to a wrapped solver is seen on Python 3.11 but not from 3.12
# on (``isinstance`` then looks attributes up statically): a wrapper defines the hooks it
# forwards.


@runtime_checkable
class StartScaleHook(Protocol):
    """A step solver that chooses its regularization from the data of each image scale.

    The shape driver calls ``start_scale(scale, noise)`` before the shape Gauss-Newton of each
    image scale (and again in the later fixed-point iterations of the same scale), with the
    scale's noise model; the displacement driver calls it with ``noise=None`` at the start of
    each scale.

    Parameters of ``start_scale``
    -----------------------------
    scale : int
        Image scale about to be solved (0 is the finest).
    noise : :class:`fesdic_core.shape.uncertainty.NoiseModel` or None
        ``Cov(b) ~= noise.variance * H`` at the scale's first state; None when the caller
        has no noise model (the displacement).
    """

    def start_scale(self, scale: int, noise: NoiseModel | None) -> None:
        ...


@runtime_checkable
class StepCovarianceHook(Protocol):
    """A step solver that gives the covariance of its step, for the shape uncertainty
    (:func:`fesdic_core.shape.uncertainty.shape_std`, at the converged state).

    Parameters of ``step_covariance``
    ---------------------------------
    H : scipy.sparse matrix, (n, n)
        ``H_FE`` of Eq. 8 at the converged state.
    scale : int
        Image scale (the finest of the schedule).

    Returns
    -------
    diag : ndarray, (n,)
        The diagonal of ``C = G H G^T``, the covariance of the step ``d = G b`` per unit noise
        (``Cov(b) = H``).
    apply : callable
        ``V (n, k) -> C V (n, k)``.
    """

    def step_covariance(self, H: sps.spmatrix,
                        scale: int) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        ...


@runtime_checkable
class BiasStepHook(Protocol):
    """A step solver that gives the bias indicator of its regularization (the shape driver
    calls it once, at the converged state of the finest scale).

    Parameters of ``bias_step``: those of :meth:`StepSolver.solve`.

    Returns
    -------
    d : ndarray, (n,)
        How much the shape would move, linearised at the converged state, if the
        regularization were one notch weaker (zeros for a solver without regularization).
    """

    def bias_step(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        ...


@runtime_checkable
class FactorizeHook(Protocol):
    """A step solver whose step for a fixed ``H`` can be factorized once.

    :class:`CachedFactorization` calls ``factorize(H, scale)`` once per ``H`` (the same object
    from one iteration to the next: the displacement's modified Gauss-Newton) and serves the
    later steps with the map it returns.

    Parameters of ``factorize``
    ---------------------------
    H : scipy.sparse matrix, (n, n)
    scale : int

    Returns
    -------
    step : callable
        ``(b (n,), q (n,)) -> d (n,)``, equal to ``solve(H, b, q, scale)``.
    """

    def factorize(self, H: sps.spmatrix,
                  scale: int) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        ...


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


def sparse_factor(H: sps.spmatrix, what: str = "H_FE") -> Callable[[np.ndarray], np.ndarray]:
    """The map ``b -> H^-1 b`` of a symmetric positive definite ``H``, factorized once
    (SuperLU with a symmetric ordering), with the errors of :func:`sparse_solve`."""
    H = sps.csc_matrix(H)
    empty = np.flatnonzero(H.diagonal() <= 0.0)
    if empty.size:
        raise SingularSystemError(
            f"{what} has {empty.size} empty rows (first: dof {empty[0]}): no integration "
            "point sees these nodes; crop the mesh to the visible region or regularize")
    try:
        lu = spla.splu(H, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    except RuntimeError as err:                                # "Factor is exactly singular"
        raise SingularSystemError(f"{what} is singular ({H.shape[0]} dofs): {err}") from None

    def solve(b: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            d = lu.solve(np.asarray(b, dtype=float))
        if not np.all(np.isfinite(d)):
            raise SingularSystemError(f"{what} is numerically singular ({H.shape[0]} dofs)")
        return d
    return solve


def seen_dofs(H: sps.spmatrix) -> np.ndarray:
    """(n,) bool: the dofs whose diagonal term of ``H`` is not zero (some point sees them)."""
    d = H.diagonal()
    return d > 1e-12 * (d.max() if d.size else 0.0)


class DirectSolver:
    """The default step solver of the core: ``d = H^-1 b`` (Eq. 8), no regularization."""

    def solve(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        return sparse_solve(H, b)

    def factorize(self, H: sps.spmatrix,
                  scale: int) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        """``(b, q) -> H^-1 b`` with ``H`` factorized once (:func:`sparse_factor`)."""
        solve = sparse_factor(H)
        return lambda b, q: solve(b)

    def step_covariance(self, H: sps.spmatrix,
                        scale: int) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        """``G H G^T = H^-1`` (:func:`inverse_covariance`)."""
        return inverse_covariance(H)

    def bias_step(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        """No regularization, no bias: zeros."""
        return np.zeros(H.shape[0])

    def __repr__(self) -> str:
        return "DirectSolver()"


class CachedFactorization:
    """A step solver for a Gauss-Newton whose ``H`` stays the same object while it does not
    change (the displacement's modified Gauss-Newton: one ``H`` per image scale, built from
    the reference). The wrapped solver's ``factorize(H, scale)`` runs once per ``(H, scale)``
    and its step serves every later call with that very ``H``; a solver without
    ``factorize`` is called as usual.

    The cache is keyed on the identity of ``H`` (a reference to it is kept, so the key cannot
    be reused by another matrix); the last ``max_entries`` are kept (the undamped ``H`` of
    each scale and a few Levenberg-Marquardt matrices). ``copy.deepcopy`` returns the same
    object (the steps are functions of ``H`` alone, shared by every frame of a series) and
    pickling drops the factors (each Dask worker factorizes once).
    """

    def __init__(self, solver: StepSolver, max_entries: int = 8):
        self.solver = solver
        self.max_entries = int(max_entries)
        self._steps: dict[tuple[int, int],
                          tuple[sps.spmatrix, Callable[[np.ndarray, np.ndarray], np.ndarray]]] = {}
        self._lock = threading.Lock()

    def solve(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        if not isinstance(self.solver, FactorizeHook):
            return self.solver.solve(H, b, q, scale)
        key = (int(scale), id(H))
        entry = self._steps.get(key)
        if entry is None or entry[0] is not H:
            entry = (H, self.solver.factorize(H, scale))
            with self._lock:
                self._steps[key] = entry
                while len(self._steps) > self.max_entries:
                    self._steps.pop(next(iter(self._steps)))
        return entry[1](b, q)

    def __deepcopy__(self, memo: dict) -> "CachedFactorization":
        return self

    def __getstate__(self) -> dict:
        return {"solver": self.solver, "max_entries": self.max_entries}

    def __setstate__(self, state: dict) -> None:
        CachedFactorization.__init__(self, state["solver"], state["max_entries"])

    def __repr__(self) -> str:
        return f"CachedFactorization({self.solver!r})"


def inverse_diagonal(H: sps.spmatrix) -> np.ndarray:
    """``diag(H^-1)`` of a sparse symmetric positive definite matrix without forming ``H^-1``.

    Reverse Cuthill-McKee ordering makes ``H`` banded (bandwidth ``w``: a few rows of nodes
    of a structured FE mesh) and ``H = U^T U`` its banded Cholesky factor. With ``U`` cut
    into blocks of ``w`` rows, ``U S = U^-T`` (``S = H^-1``) gives, from the last block
    ``K`` back to the first (Takahashi's recurrence, K. Takahashi et al. 1973, by blocks):

        S_IK = -U_II^-1 U_IK S_KK,     S_II = U_II^-1 (U_II^-T - U_IK S_IK^T),

    for the block ``I`` and the next one ``K`` (``U`` has no entry beyond ``K`` in the rows
    of ``I``): about ``5 n w^2`` flops in BLAS instead of the ``n^3 / 3`` of a dense inverse.
    """
    n = H.shape[0]
    perm = reverse_cuthill_mckee(sps.csr_matrix(H), symmetric_mode=True)
    A = sps.coo_matrix(sps.csr_matrix(H)[perm][:, perm])
    w = max(1, int(np.max(np.abs(A.row - A.col))) if A.nnz else 1)
    # SuperLU without pivoting on the banded SPD matrix: A = L U with U = D L^T, so the
    # Cholesky factor is D^-1/2 U (sparse, within the band; LAPACK's banded potrf is slower)
    lu = spla.splu(sps.csc_matrix(A), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    if np.any(lu.perm_r != np.arange(n)) or np.any(lu.U.diagonal() <= 0.0):
        raise SingularSystemError(f"H ({n} dofs) is not positive definite")
    U = sps.csr_matrix(sps.diags(1.0 / np.sqrt(lu.U.diagonal())) @ lu.U)

    def block(r0: int, r1: int, c0: int, c1: int) -> np.ndarray:      # dense U[r0:r1, c0:c1]
        return U[r0:r1, c0:c1].toarray()

    diag = np.empty(n)
    S_next = None
    for start in range(((n - 1) // w) * w, -1, -w):                # blocks of w rows, last first
        stop = min(n, start + w)
        U_inv = sla.solve_triangular(block(start, stop, start, stop), np.eye(stop - start),
                                     lower=False, check_finite=False)
        if S_next is None:
            S = U_inv @ U_inv.T
        else:
            U_ik = block(start, stop, stop, stop + len(S_next))
            S_ik = -U_inv @ (U_ik @ S_next)
            S = U_inv @ (U_inv.T - U_ik @ S_ik.T)
        S_next = 0.5 * (S + S.T)
        diag[start:stop] = np.diag(S)
    out = np.empty(n)
    out[perm] = diag
    return out


def inverse_covariance(H: sps.spmatrix) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """``diag(H^-1)`` and ``V -> H^-1 V``: the step covariance of the plain FE solve (in
    units of ``kappa``), over the dofs that see a point (others: NaN, their columns 0)."""
    n = H.shape[0]
    seen = seen_dofs(H)
    diag = np.full(n, np.nan)
    H_seen = sps.csc_matrix(H[seen][:, seen])
    diag[seen] = inverse_diagonal(H_seen)
    lu = spla.splu(H_seen)

    def apply(V: np.ndarray) -> np.ndarray:
        out = np.zeros((n,) + V.shape[1:])
        out[seen] = lu.solve(np.asarray(V[seen], dtype=float))
        return out
    return diag, apply
