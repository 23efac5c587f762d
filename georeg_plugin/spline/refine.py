"""Knot insertion on patches and the refinement operator C_r (Eqs. 13-15).

For B-splines, inserting knots in u and v gives univariate matrices ``C_u``, ``C_v``
with ``N_c = C_u N_f`` per direction, hence ``C = kron(C_u, C_v)`` for the bivariate
basis (dof ``i * nv + j``): ``N_c = C N_f`` (Eq. 13) and ``x_f = C^T x_c`` (Eq. 15).

For NURBS the insertion acts on the homogeneous control points ``(w x, w)``:
``w_f = C^T w_c`` and ``w_f x_f = C^T (w_c x_c)``. The weight function is unchanged,
``W_c = w_c^T N_c = w_c^T C N_f = w_f^T N_f = W_f``, so with ``R = diag(w) N / W``
(Eq. 12)

    R_c = diag(w_c) C N_f / W = diag(w_c) C diag(w_f)^-1 R_f = C_r R_f,
    C_r = diag(w_c) C diag(w_f)^-1,

and ``x_f = diag(w_f)^-1 C^T diag(w_c) x_c = C_r^T x_c``: Eqs. 13 and 15 hold with the
same ``C_r`` for the rational bases. The columns of ``C_r`` sum to one (both bases
are partitions of unity), so each fine control point is an affine combination of
coarse ones.
"""
from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp

from georeg_plugin.spline.bspline import insertion_matrix, span_breaks
from georeg_plugin.spline.patch import SplinePatch

logger = logging.getLogger(__name__)

__all__ = ["insert_knots", "refine_uniform", "refine_to_elements", "midpoints", "linear_patch"]


def insert_knots(patch: SplinePatch, new_u=(), new_v=()) -> tuple[SplinePatch, sp.csr_matrix]:
    """Insert knots without changing the geometry.

    Parameters
    ----------
    patch : SplinePatch (coarse)
    new_u, new_v : knots to insert in u and v (strictly inside the parameter range)

    Returns
    -------
    patch_f : SplinePatch, the same surface on the refined knot vectors
    C_r : csr_matrix (n_coarse, n_fine) with ``R_c = C_r R_f`` (Eq. 13) and
        ``x_f = C_r^T x_c`` (Eq. 15)
    """
    (pu, pv), (tu, tv) = patch.degrees, patch.knots
    try:
        Cu, tu_f = insertion_matrix(tu, pu, new_u)
    except ValueError as exc:
        raise ValueError(f"new_u: {exc}") from exc
    try:
        Cv, tv_f = insertion_matrix(tv, pv, new_v)
    except ValueError as exc:
        raise ValueError(f"new_v: {exc}") from exc
    C = sp.kron(Cu, Cv, format="csr")                       # N_c = C N_f (Eq. 13)
    shape_f = (Cu.shape[1], Cv.shape[1])
    xc = patch.control_points.reshape(-1, 3)
    if patch.weights is None:                                # a B-spline
        xf = C.T @ xc                                        # Eq. 15
        fine = SplinePatch(patch.degrees, (tu_f, tv_f), xf.reshape(shape_f + (3,)))
        return fine, C
    wc = patch.weights.ravel()
    wf = C.T @ wc                                            # homogeneous weights
    C_r = (sp.diags(wc) @ C @ sp.diags(1.0 / wf)).tocsr()    # R_c = C_r R_f (Eq. 13)
    xf = C_r.T @ xc                                          # x_f = C_r^T x_c (Eq. 15)
    fine = SplinePatch(patch.degrees, (tu_f, tv_f), xf.reshape(shape_f + (3,)),
                       wf.reshape(shape_f))
    return fine, C_r


def midpoints(knots: np.ndarray) -> np.ndarray:
    """Midpoints of the non-empty knot spans, (n_elements,)."""
    b = span_breaks(knots)
    return 0.5 * (b[:-1] + b[1:])


def refine_uniform(patch: SplinePatch, times: int = 1) -> tuple[SplinePatch, sp.csr_matrix]:
    """Halve every non-empty knot span in u and v, ``times`` times.

    Returns
    -------
    patch_f : SplinePatch with ``2**times`` times more elements per direction
    C_r : csr_matrix (n_coarse, n_fine), the composed operator
        ``C_r = C_r^(1) C_r^(2) ...`` (Eq. 13: ``R_c = C_r R_f``)
    """
    if isinstance(times, bool) or not isinstance(times, (int, np.integer)) or times < 0:
        raise ValueError(f"times: expected an int >= 0, got {times!r}")
    C_r = sp.identity(patch.n_dofs, format="csr")
    for _ in range(times):  # a loop over levels
        patch, C = insert_knots(patch, midpoints(patch.knots[0]), midpoints(patch.knots[1]))
        C_r = (C_r @ C).tocsr()
    return patch, C_r


def _split_counts(lengths: np.ndarray, n: int, name: str) -> np.ndarray:
    """Elements per existing span, proportional to its length (largest remainders)."""
    k = len(lengths)
    if n < k:
        raise ValueError(f"{name}: {n} elements requested, the patch already has {k}")
    share = n * lengths / lengths.sum()
    counts = np.maximum(np.floor(share).astype(int), 1)
    while counts.sum() < n:  # a handful of iterations (at most k)
        counts[np.argmax(share - counts)] += 1
    while counts.sum() > n:
        over = np.where(counts > 1, counts - share, -np.inf)
        counts[np.argmax(over)] -= 1
    return counts


def refine_to_elements(patch: SplinePatch, n_u: int,
                       n_v: int) -> tuple[SplinePatch, sp.csr_matrix]:
    """Insert single knots so that the patch has ``n_u x n_v`` elements.

    Each existing span is split uniformly into a number of elements proportional to
    its parameter length.

    Returns
    -------
    patch_f, C_r as in :func:`insert_knots`.
    """
    new = []
    for d, (n, name) in enumerate([(n_u, "n_u"), (n_v, "n_v")]):
        b = span_breaks(patch.knots[d])
        counts = _split_counts(np.diff(b), int(n), name)
        knots = [b[s] + (b[s + 1] - b[s]) * np.arange(1, c) / c
                 for s, c in enumerate(counts)]
        new.append(np.concatenate(knots) if knots else np.empty(0))
    return insert_knots(patch, new[0], new[1])


def linear_patch(patch: SplinePatch) -> tuple[SplinePatch, sp.csr_matrix]:
    """The bilinear patch on the parameter domain of a B-spline ``patch``, and its ``C_r``.

    A bilinear polynomial in ``(u, v)`` lies in every B-spline space of degree >= 1 on the
    same domain, so the bilinear patch is a level nested in ``patch`` (degree elevation
    and knot insertion together, Eq. 13): ``R_lin = C_r R`` holds exactly. Its 4 control
    points are the corners of ``patch``. A NURBS patch has no such level (``u v W`` is not
    in its rational space) and raises ValueError.

    Returns
    -------
    linear : SplinePatch, degrees (1, 1), one element, 2 x 2 control points.
    C_r : csr_matrix (4, n_dofs of ``patch``) with ``R_lin = C_r R`` (Eq. 13).
    """
    if patch.weights is not None:
        raise ValueError("linear_patch: a NURBS patch has no bilinear level nested in it")
    (tu, tv) = patch.knots
    ends = [np.array([t[0], t[0], t[-1], t[-1]], dtype=float) for t in (tu, tv)]
    corners = patch.evaluate(np.array([[u, v] for u in ends[0][1:3] for v in ends[1][1:3]]))
    linear = SplinePatch((1, 1), (ends[0], ends[1]), corners.reshape(2, 2, 3))
    uv = np.stack(np.meshgrid(np.linspace(tu[0], tu[-1], 2 * patch.shape[0] + 3),
                              np.linspace(tv[0], tv[-1], 2 * patch.shape[1] + 3),
                              indexing="ij"), axis=-1).reshape(-1, 2)
    B, B_lin = patch.basis(uv).toarray(), linear.basis(uv).toarray()
    C_t, *_ = np.linalg.lstsq(B, B_lin, rcond=None)            # B C_r^T = B_lin
    misfit = float(np.abs(B @ C_t - B_lin).max())
    if misfit > 1e-9:                                          # cannot happen for a B-spline
        raise ValueError(f"linear_patch: the bilinear basis is not in the patch's space "
                         f"(misfit {misfit:.3g})")
    C_t[np.abs(C_t) < 1e-12] = 0.0
    return linear, sp.csr_matrix(C_t.T)
