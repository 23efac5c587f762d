"""A robust smooth fit of sparse 3-D displacements on the FE mesh (the feature start's).

The field is an affine part ``B [X, 1]`` plus a nodal field ``V`` regularized by the
surface-gradient operator ``A`` of Eq. 10 (:func:`~fesdic_core.solve.tikhonov.
surface_gradient_operator`), the weight ``lam`` from a cosine of wavelength ``length_mm``
(:func:`~fesdic_core.solve.tikhonov.tikhonov_weight`)::

    min  sum_i w_i |B [X_i, 1] + L_i V - d_i|^2 + lam V^T A V,

with ``L_i`` the mesh's shape functions at point ``i``: rigid motions and homogeneous strains
are reproduced exactly, nodes without points get a smooth value, and the points farther than a
few robust deviations are trimmed (:func:`fit_field`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from fesdic_core.solve.tikhonov import tikhonov_weight

__all__ = ["FieldFit", "fit_field"]


@dataclass(frozen=True, eq=False)
class FieldFit:
    """A robust smooth fit: ``U`` (n, 3) at the nodes, ``kept`` (m,) bool the inliers,
    ``misfit_mm`` (m,) each point's distance to the fit, ``refits`` the fits made."""

    U: np.ndarray
    kept: np.ndarray
    misfit_mm: np.ndarray
    refits: int

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.misfit_mm[self.kept] ** 2))) if self.kept.any() \
            else float("nan")


def _solve_smooth(basis: sps.csr_matrix, weights: np.ndarray, rhs: np.ndarray,
                  gradient: sps.csr_matrix, nodes: np.ndarray, length_mm: float) -> np.ndarray:
    """``V`` (n, 3) minimising ``sum_i w_i |L_i V - rhs_i|^2 + lam V^T A V`` (+ a tiny ridge
    for the nodes of a part without points)."""
    LtW = basis.T.multiply(weights).tocsr()
    H = (LtW @ basis).tocsr()
    lam = tikhonov_weight(H, gradient, nodes, length_mm)
    ridge = 1e-9 * float(H.diagonal().max(initial=1.0))
    M = (H + lam * gradient + ridge * sps.identity(len(nodes))).tocsc()
    return spla.splu(M).solve(np.asarray(LtW @ rhs))


def fit_field(basis: sps.csr_matrix, X_mm: np.ndarray, d_mm: np.ndarray,
              gradient: sps.csr_matrix, nodes: np.ndarray, length_mm: float, trim: float = 3.0,
              max_refits: int = 10, floor_mm: float = 0.0) -> FieldFit:
    """Robust smooth fit of sparse displacements on the mesh (trimmed least squares).

    The field is an affine part ``B [X, 1]`` (exact for rigid motions and homogeneous
    strains) plus a nodal field ``V`` smoothed by the surface-gradient operator ``A``:
    ``min sum_i w_i |B [X_i, 1] + L_i V - d_i|^2 + lam V^T A V``, solved by alternating
    the affine part and ``V`` (a few passes per fit), ``w_i`` 1 for the kept points, 0 for
    the others. After each fit the points farther than ``trim`` robust deviations
    (1.4826 x the median misfit of the kept points, at least ``floor_mm``) are dropped; the
    fit stops when the kept set no longer changes, or when it would keep fewer than half
    the points (a field the model misses, not outliers: ``floor_mm`` sets what is no outlier).

    Parameters
    ----------
    basis : (m, n) csr, shape functions of the mesh at each point.
    X_mm : (m, 3) the points' reference positions (mm).
    d_mm : (m, 3) their displacements (mm).
    gradient : (n, n) the surface-gradient operator ``A`` of the mesh.
    nodes : (n, 3) the mesh's nodes (mm).
    length_mm : the smoothing's wavelength (mm, :func:`tikhonov_weight`).
    trim, max_refits, floor_mm : the trimming (see above).

    Returns
    -------
    FieldFit: ``U`` (n, 3) at the nodes, the inliers and misfits.
    """
    X, d = np.asarray(X_mm, float), np.asarray(d_mm, float)
    centre = X.mean(axis=0)
    P = np.column_stack([X - centre, np.ones(len(X))])                 # (m, 4)
    Pn = np.column_stack([nodes - centre, np.ones(len(nodes))])
    kept = np.ones(len(X), bool)
    U = np.zeros((len(nodes), 3))
    misfit = np.zeros(len(X))
    refits = 0
    for refits in range(1, max_refits + 1):
        w = kept.astype(float)
        V = np.zeros((len(nodes), 3))
        for _ in range(4):                              # affine part and V, alternately
            B = np.linalg.lstsq(P[kept], (d - basis @ V)[kept], rcond=1e-10)[0]
            V = _solve_smooth(basis, w, d - P @ B, gradient, nodes, length_mm)
        U = Pn @ B + V
        misfit = np.linalg.norm(P @ B + basis @ V - d, axis=1)
        scale = max(1.4826 * float(np.median(misfit[kept])), floor_mm)
        new = misfit <= trim * scale
        if np.array_equal(new, kept) or new.sum() < max(4, len(X) // 2):
            break                 # (trimming half the points: a misfit of the model, not outliers)
        kept = new
    return FieldFit(U=U, kept=kept, misfit_mm=misfit, refits=refits)
