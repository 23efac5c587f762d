"""Local validity of a measured displacement: the checks of
:mod:`fesdic_core.residual.validity` on the displacement's residual and ``H``.

Per node ``I`` of the reference surface, on its support (the points ``L_I`` weighs):

- the residual of both cameras (:attr:`DisplacementResidual.percent`), root mean square
  over the support, against the local noise floor of each camera's pair (reference image
  at the reference points, deformed image at the displaced points), pooled over the
  cameras as the residual is;
- the texture of each image over the support (the worst camera and instant);
- the smallest eigenvalue of the node's 3 x 3 diagonal block of ``H`` per unit support area
  against the median node's;
- the distance of ``U_I`` from its neighbours' median against the noise's standard
  deviation of ``U_I``, ``sigma_r sqrt(w (B_I^-1)_kk)`` with ``B_I`` that block, ``w`` the
  support's mean point weight and ``sigma_r`` the local noise floor in units of the
  normalised residual (the node's own dofs only: the coupling with the neighbours makes the
  true deviation larger, which the neighbours' spread in the check's scale covers).
"""
from __future__ import annotations

import weakref
from typing import Sequence

import numpy as np
import scipy.sparse as sps

from fesdic_core.displacement.residual import DisplacementResidual, ReferenceView
from fesdic_core.residual.validity import (LocalImage, NodeValidity, Support, block_conditioning,
                                           local_image, local_noise_gray, neighbour_ratio,
                                           node_neighbours, node_validity)

__all__ = ["node_blocks", "residual_blocks", "hessian_blocks", "displacement_validity"]


def node_blocks(support: Support, weighted_dr_du: np.ndarray, weights: np.ndarray
                ) -> np.ndarray:
    """(n, 3, 3) the diagonal blocks ``sum_c sum_g w_g L_I**2 G_cg G_cg^T`` of ``H`` (Eq. 8)
    from ``w_g G_cg`` (2, g, 3) and the weights ``w`` (2, g) (0 where a camera does not see
    the point); ``support``: the quadrature's :class:`~fesdic_core.residual.validity.Support`."""
    wG = np.asarray(weighted_dr_du, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv_w = np.where(weights > 0, 1.0 / np.where(weights > 0, weights, 1.0), 0.0)
    P = np.einsum("cgk,cgl,cg->gkl", wG, wG, inv_w).reshape(-1, 9)
    return support.total(P).reshape(-1, 3, 3)


def residual_blocks(quad, residual: DisplacementResidual) -> np.ndarray | None:
    """(n, 3, 3) the nodes' diagonal blocks of ``H`` from a residual's own derivative
    (:func:`node_blocks`; None for a residual without it)."""
    if residual.dr_du is None:
        return None
    w = np.where(residual.mask, quad.weight_mm2, 0.0)
    return node_blocks(Support(quad), residual.dr_du * w[:, :, None], w)


def hessian_blocks(H: sps.spmatrix) -> np.ndarray:
    """(n, 3, 3) the diagonal blocks ``H[3 I + k, 3 I + l]`` of a symmetric (3n, 3n) ``H`` in
    the node-major layout (from its three upper diagonals)."""
    H = sps.csr_matrix(H)
    n = H.shape[0] // 3
    blocks = np.empty((n, 3, 3))
    for d in range(3):
        diagonal = H.diagonal(d)
        for k in range(3 - d):
            blocks[:, k, k + d] = blocks[:, k + d, k] = diagonal[k::3][:n]
    return blocks


def displacement_validity(view: ReferenceView, res: DisplacementResidual, U: np.ndarray,
                          nodes: np.ndarray, images: Sequence, contrast_ratios: Sequence[float],
                          blocks: np.ndarray | None = None) -> NodeValidity:
    """The local checks of every node of a displacement ``U`` (n, 3) of the reference nodes
    ``nodes`` (n, 3) mm, measured at the scale of ``view`` from the deformed ``images`` (that
    scale), ``res`` its residual there.

    ``contrast_ratios``: per camera, the reference image's contrast over the deformed one's
    over the region (:class:`~fesdic_core.imaging.noise.NoiseFloor`); ``blocks``: the nodes'
    diagonal blocks of ``H`` (default: those of the view's reference ``H``; without it, from
    the residual's own derivative).
    """
    quad = view.quad
    support = Support(quad)
    U = np.asarray(U, float).reshape(-1, 3)
    w = np.where(res.mask, quad.weight_mm2, 0.0)                      # (2, g)
    X1 = view.X + quad.points(U)
    seen_weight = np.array([support.total(w[c]) for c in range(2)])  # (2, n)
    percent = np.nan_to_num(res.percent)
    squared = sum(support.total(w[c] * percent[c] ** 2) for c in range(2))
    noise2, sigma_r2 = np.zeros(quad.n_nodes), np.zeros(quad.n_nodes)
    texture = np.full(quad.n_nodes, np.inf)
    reference = _reference_images(view, support)
    for c in range(2):
        camera = view.cameras[c]
        before = reference[c]
        after = local_image(support, w[c], images[c], camera, X1)
        gray = local_noise_gray(before, after, contrast_ratios[c])
        floor = np.nan_to_num(100.0 * gray / res.dynamic_range[c])
        noise2 += seen_weight[c] * floor ** 2
        scale = support.mean(res.sigma_ref[c], w[c])
        with np.errstate(invalid="ignore", divide="ignore"):
            sigma_r2 += seen_weight[c] * np.nan_to_num(gray / scale) ** 2
        seen = seen_weight[c] > 0
        for local in (before, after):
            texture = np.where(seen, np.minimum(texture, local.texture_ratio), texture)
    total = seen_weight.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        residual_to_noise = np.where(total > 0, np.sqrt(squared / noise2), np.nan)
        sigma_r = np.sqrt(sigma_r2 / total)
        mean_weight = sum(support.total(w[c] * w[c]) for c in range(2)) / total
    texture = np.where(np.isfinite(texture), texture, 0.0)
    if blocks is None:
        if view.hessian is not None:
            blocks = hessian_blocks(view.hessian)
        else:
            blocks = residual_blocks(quad, res)
    if blocks is None:
        raise ValueError("displacement_validity: no diagonal blocks of H (a residual without "
                         "its derivative and a view without H)")
    conditioning = block_conditioning(blocks, support.total(quad.weight_mm2))
    std = _predicted_std(blocks, sigma_r, mean_weight)
    neighbours = node_neighbours([g.connectivity for g in quad.groups], quad.n_nodes)
    return node_validity(residual_to_noise, texture, conditioning,
                         neighbour_ratio(neighbours, nodes, U, std), seen=total > 0)


#: each reference view's local images (the same for every frame of a series), per process
_REFERENCE_IMAGES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _reference_images(view: ReferenceView, support: Support) -> tuple[LocalImage, LocalImage]:
    """The reference images over the nodes' supports (the points each camera sees in its
    reference image), computed once per view."""
    if view not in _REFERENCE_IMAGES:
        w = np.where(view.seen, view.quad.weight_mm2, 0.0)
        _REFERENCE_IMAGES[view] = tuple(local_image(support, w[c], view.images[c],
                                                     view.cameras[c], view.X) for c in range(2))
    return _REFERENCE_IMAGES[view]


def _predicted_std(blocks: np.ndarray, sigma_r: np.ndarray, mean_weight: np.ndarray
                   ) -> np.ndarray:
    """(n, 3) ``sigma_r sqrt(w (B_I^-1)_kk)``: the noise's standard deviation of ``U_I`` with
    the node's own block only (inf where the block is singular)."""
    out = np.full((len(blocks), 3), np.inf)
    det = np.linalg.det(blocks)
    scale = np.max(np.abs(blocks).reshape(len(blocks), -1), axis=1)
    good = np.isfinite(det) & (np.abs(det) > 1e-12 * scale ** 3) & np.isfinite(sigma_r)
    if good.any():
        inv = np.linalg.inv(blocks[good])
        diag = np.clip(np.diagonal(inv, axis1=1, axis2=2), 0.0, None)
        out[good] = sigma_r[good, None] * np.sqrt(mean_weight[good, None] * diag)
    return out
