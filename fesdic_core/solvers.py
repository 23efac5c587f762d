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
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

logger = logging.getLogger(__name__)


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


class DirectSolver:
    """The default step solver of the core: ``d = H^-1 b`` (Eq. 8), no regularization."""

    def solve(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        return sparse_solve(H, b)

    def __repr__(self) -> str:
        return "DirectSolver()"
