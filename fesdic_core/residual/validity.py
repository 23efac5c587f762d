"""Local validity of a measured field: which nodes the images actually determine.

The verdict of a measurement (:func:`fesdic_core.shape.verdict.judge`) is global: the
residual over every point against the noise floor over every point. A field can pass it
with a few nodes far off (a local divergence of plain FE on a fine mesh: the global
residual barely moves when a few elements do not match). Each node ``I`` is judged here on
its *support*, the integration points its shape function ``L_I`` weighs (:class:`Support`:
weights ``w_g L_I(xi_g)**2``, those of the node's own block of ``H``, positive for every
element family, where the residual map at the nodes weighs by ``L_I``):

- ``residual_to_noise``: the root mean square of the residual over the support against
  the noise floor of :func:`~fesdic_core.imaging.noise.residual_noise_floor` taken on the
  same support (Immerkaer's estimate averaged over the pixels the support projects to,
  :func:`~fesdic_core.imaging.noise.immerkaer_response`, with each image model's gain); it
  passes up to :func:`residual_limit` (twice the median node's, within [0.5, 3]);
- ``texture_ratio``: the contrast of the gray levels over the support against that local
  noise (the global texture check of :data:`~fesdic_core.imaging.noise.MIN_TEXTURE_RATIO`,
  on the support), the worst image;
- ``conditioning``: the smallest eigenvalue of the node's diagonal block of ``H`` per unit
  of support area, against the median node's (a node that no camera sees, or sees on a
  uniform patch or along an edge only, has a small one);
- ``neighbour_ratio``: how far the node's value lies from the median of its neighbours'
  (the nodes sharing an element with it), against what the noise predicts (its standard
  deviation) plus the spread of the neighbours' values (what a smooth field's gradient
  puts between a node and its neighbours, at a boundary or a corner where they all lie on
  one side); the worst component.

A node is ``valid`` when the four pass (:func:`node_validity`); the thresholds below are
the one place where they are set. A measurement fails when the share of invalid nodes
among those the images see exceeds its ``max_invalid_share`` (:meth:`NodeValidity.failure`,
naming the worst node); a node no point sees is invalid, not counted in that share.

The thresholds were chosen on renders with known truth (``benchmarks/bench_validity.py``:
a flat plate whose paint is then twisted by 1 mm and made wavy, plain FE on a fine mesh
which diverges locally, plain FE on a coarse mesh and the spline levels, which do not;
rigid, stretch and bending pairs of the displacement tests), each value between what the
good nodes reach and what the nodes more than 10 times the median error off show.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sps

from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.imaging.noise import immerkaer_response

__all__ = ["MAX_RESIDUAL_TO_NOISE", "MIN_NODE_TEXTURE_RATIO", "MIN_NODE_CONDITIONING",
           "MAX_NEIGHBOUR_RATIO", "DEFAULT_MAX_INVALID_SHARE", "RESIDUAL_FACTOR",
           "EXPLAINED_RESIDUAL_TO_NOISE", "residual_limit", "NodeValidity", "Support",
           "LocalImage", "local_image", "local_noise_gray", "block_conditioning", "node_neighbours",
           "neighbour_ratio", "node_validity"]

# The thresholds, measured with ``benchmarks/bench_validity.py`` (see the module docstring):
# "good" nodes are those less than 3 times the median error off, "bad" those more than 10
# times and more than 20 um off (and the nodes over the background, beyond the plate).

#: a node whose residual over its support is more than this many times the local noise
#: floor is never explained by the images
MAX_RESIDUAL_TO_NOISE = 3.0
#: ... nor one whose ratio exceeds this many times the median node's (:func:`residual_limit`).
#: A converged node's ratio is about half the floor (the median node's: 0.44-0.50; the
#: global residual is 0.48-0.63 times the global floor, :mod:`fesdic_core.imaging.noise`), and
#: uniform over a uniformly speckled surface: the good nodes reach 1.1-1.6 times the median
#: with plain FE, 1.9-2.5 with the spline levels (0.2-0.4 % of their nodes, flagged); the bad
#: nodes 1.4-80, most above 2
RESIDUAL_FACTOR = 2.0
#: a residual below this share of the local noise floor is always explained (identical
#: images give 0: the median rule alone would then flag round-off)
EXPLAINED_RESIDUAL_TO_NOISE = 0.5
#: a support whose contrast is below this many times the local noise shows no texture
#: (white noise: 1). Measured: good nodes 2.8-15 (a few pixels of speckle under a fine
#: mesh's node), nodes over the uniform background 0.8-1.5: the global
#: :data:`~fesdic_core.imaging.noise.MIN_TEXTURE_RATIO`
MIN_NODE_TEXTURE_RATIO = 2.0
#: a node whose smallest eigenvalue of its block of H (per unit support area) is below this
#: fraction of the median node's is not determined by the images (a camera sees none of its
#: support: 0). Measured: good nodes down to 0.03 (Q9 nodes whose support holds a few pixels
#: of speckle; they are held by their neighbours), 0.05 on a fine Q4 mesh
MIN_NODE_CONDITIONING = 0.02
#: a node further than this from the median of its neighbours, in units of (noise standard
#: deviation + reach x spread of the neighbours, :func:`neighbour_ratio`), is inconsistent
#: with them. Measured: good nodes up to 1.7 on coarse meshes, 2.3 on the 1 mm mesh, 0.3 with
#: the spline levels; bad nodes 0.2-15 (a cluster of diverged nodes holds each other: the
#: residual check finds those)
MAX_NEIGHBOUR_RATIO = 3.0
#: the share of invalid nodes above which a measurement fails. Measured: the converged fields
#: (coarse FE, the spline levels) have 0-0.4 % invalid nodes; plain FE diverging locally
#: 2.2 % (a 2 mm mesh, 5 nodes 10 mm off, all flagged), 4.4 % and 12 % (1 mm Q4 and 2 mm Q9
#: meshes, 1.5 % and 4 % of their nodes bad); a mesh over the background 27 % (measured before
#: the displacement's prefilter of 1 px and its coarse scales' pixel count: the 1 mm mesh then
#: has 3.2 % and fails on its stagnation, the 2 mm meshes no longer diverge)
DEFAULT_MAX_INVALID_SHARE = 0.03


@dataclass(frozen=True)
class NodeValidity:
    """The local checks of every node (see the module docstring), all (n,).

    ``valid``: bool, every check passed (a node no point sees is invalid); ``seen``: bool,
    some point of the node's support entered the residual; ``residual_limit``: the largest
    ``residual_to_noise`` of a valid node in this field (:func:`residual_limit`).
    """

    residual_to_noise: np.ndarray
    texture_ratio: np.ndarray
    conditioning: np.ndarray
    neighbour_ratio: np.ndarray
    valid: np.ndarray
    seen: np.ndarray
    residual_limit: float = MAX_RESIDUAL_TO_NOISE

    def point_data(self) -> dict:
        """The VTU point data of the checks: ``valid`` (n,) uint8 0/1, ``residual_to_noise``."""
        return {"valid": self.valid.astype(np.uint8),
                "residual_to_noise": np.asarray(self.residual_to_noise, float)}

    def counts(self) -> dict:
        """``{"n_valid", "valid_share"}`` of a summary (the share of all nodes)."""
        n = int(np.count_nonzero(self.valid))
        return {"n_valid": n, "valid_share": n / self.valid.size if self.valid.size else None}

    @property
    def invalid_share(self) -> float:
        """Share of the nodes the images see that are not valid (0 if none is seen). A node
        that no point sees (hidden, masked, outside the images) is invalid but not counted
        here: its value is not measured, only held by its neighbours or a regularization
        (the measurement's coverage says where, and plain FE cannot solve for it)."""
        n = int(np.count_nonzero(self.seen))
        return float(np.count_nonzero(~self.valid & self.seen)) / n if n else 0.0

    def failure(self, nodes: np.ndarray, max_invalid_share: float) -> str | None:
        """One line naming the invalid nodes when their share exceeds ``max_invalid_share``
        (how many, the worst node by residual over noise: its index, position and ratio),
        else None. ``nodes``: (n, 3) mm."""
        share = self.invalid_share
        if not share > max_invalid_share:
            return None
        bad = np.flatnonzero(~self.valid & self.seen)
        ratio = np.where(np.isfinite(self.residual_to_noise), self.residual_to_noise, np.inf)
        worst = int(bad[np.argmax(ratio[bad])])
        x = ", ".join(f"{v:.4g}" for v in np.asarray(nodes, float)[worst])
        return (f"{bad.size} of {np.count_nonzero(self.seen)} nodes ({100 * share:.1f} %, at most "
                f"{100 * max_invalid_share:g} %) are not valid locally: the worst, node {worst} "
                f"at ({x}) mm, has a residual {self.residual_to_noise[worst]:.3g} times its local "
                f"noise (at most {self.residual_limit:.3g}), texture ratio "
                f"{self.texture_ratio[worst]:.3g}, conditioning {self.conditioning[worst]:.3g}, "
                f"{self.neighbour_ratio[worst]:.3g} from its neighbours: a local divergence or "
                "an unseen region (a coarser mesh, a regularization or a start closer to the "
                "motion)")


class Support:
    """Each node's support in a quadrature: its points, weighed by ``L_I(xi_g)**2`` (positive
    for every family: a Q9 or T6 corner's ``L_I`` turns negative inside its elements), the
    weight of a point in the node's own block of ``H``. Sums are taken element group by
    element group (:class:`~fesdic_core.fe.quadrature.ElementGroup`), as
    :meth:`~fesdic_core.fe.quadrature.PixelQuadrature.to_nodes` does with ``L_I``.
    """

    def __init__(self, quad: PixelQuadrature):
        self.quad = quad

    def total(self, values: np.ndarray) -> np.ndarray:
        """``sum_g L_I**2 v_g`` of point values (g,) -> (n,), or (g, k) -> (n, k)."""
        values = np.asarray(values, float)
        k = values.shape[1:]
        flat = values.reshape(len(values), -1)
        out = np.zeros((self.quad.n_nodes, flat.shape[1]))
        for group in self.quad.groups:
            E, (m, nn) = len(group.elements), group.N.shape
            local = flat[group.span].reshape(E, m, -1).transpose(0, 2, 1)       # (E, k, m)
            gathered = (local @ group.N ** 2).transpose(0, 2, 1)               # (E, nn, k)
            for c in range(flat.shape[1]):
                out[:, c] += np.bincount(group.connectivity.ravel(),
                                         weights=gathered[..., c].ravel(),
                                         minlength=self.quad.n_nodes)
        return out.reshape((self.quad.n_nodes,) + k)

    def mean(self, values: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """``sum_g L_I**2 w_g v_g / sum_g L_I**2 w_g`` for point values (g,) or (g, k) and
        weights (g,) -> (n,) or (n, k) (NaN for a node of zero weight; the values must be
        finite where the weight is not zero)."""
        values = np.asarray(values, float)
        weighted = (weights * values.T).T
        totals = self.total(np.column_stack([weights, weighted.reshape(len(values), -1)]))
        weight, total = totals[:, 0], totals[:, 1:].reshape((-1,) + values.shape[1:])
        safe = np.where(weight > 0, weight, 1.0).reshape((-1,) + (1,) * (values.ndim - 1))
        inside = (weight > 0).reshape(safe.shape)
        return np.where(inside, total / safe, np.nan)


@dataclass(frozen=True)
class LocalImage:
    """One image over each node's support (all (n,); NaN for a node none of whose points
    are seen): ``sigma`` Immerkaer's noise (raw gray levels) and ``contrast`` the standard
    deviation of the raw gray levels, both weighed as :class:`Support`; ``gain`` the image
    model's white-noise gain (:attr:`~fesdic_core.imaging.image.Image.noise_gain`)."""

    sigma: np.ndarray
    contrast: np.ndarray
    gain: float

    @property
    def texture_ratio(self) -> np.ndarray:
        """(n,) contrast over noise (0 where unseen or uniform, inf where noise-free)."""
        sigma, contrast = self.sigma, self.contrast
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(sigma > 0, contrast / np.where(sigma > 0, sigma, 1.0),
                             np.where(contrast > 0, np.inf, 0.0))
        return np.nan_to_num(ratio, nan=0.0, posinf=np.inf)


def local_image(support: Support, weights: np.ndarray, image, camera, X: np.ndarray
                ) -> LocalImage:
    """``image`` (an :class:`~fesdic_core.imaging.image.Image`) seen by ``camera`` at the
    points ``X`` (g, 3), over each node's support; ``weights`` (g,): ``w_g`` at the points
    the residual sees, 0 elsewhere (one projection and one pass of Immerkaer's operator)."""
    seen = weights > 0
    with np.errstate(invalid="ignore"):
        xy = np.nan_to_num(camera.project(X))          # (the unseen points weigh nothing)
    h, w = image.shape
    col = np.clip(np.rint(xy[:, 0]), 0, w - 1).astype(np.int64)
    row = np.clip(np.rint(xy[:, 1]), 0, h - 1).astype(np.int64)
    gray = np.asarray(image.values, float)[row, col]
    stats = np.column_stack([gray, gray * gray, immerkaer_response(image.values, xy)])
    mean, second, sigma = support.mean(np.where(seen[:, None], stats, 0.0), weights).T
    return LocalImage(sigma=sigma, contrast=np.sqrt(np.maximum(second - mean ** 2, 0.0)),
                      gain=float(getattr(image, "noise_gain", 1.0)))


def local_noise_gray(first: LocalImage, second: LocalImage, contrast_ratio: float) -> np.ndarray:
    """(n,) the noise floor of a residual between two images on each node's support, in gray
    levels of the first: ``sqrt((k_0 sigma_0)**2 + (s_0/s_1)**2 (k_1 sigma_1)**2)`` with the
    images' local noise ``sigma_c`` and gains ``k_c`` (:func:`local_image`) and
    ``contrast_ratio`` ``s_0/s_1``, as :func:`~fesdic_core.imaging.noise.residual_noise_floor`
    does over the whole region."""
    return np.hypot(first.gain * first.sigma, contrast_ratio * second.gain * second.sigma)


def block_conditioning(blocks: np.ndarray, area: np.ndarray) -> np.ndarray:
    """(n,) the smallest eigenvalue of each node's diagonal block of ``H`` (n, k, k) per unit
    of its support area ``area`` (n,) (``sum_g w_g L_I**2`` over every point of the support,
    seen or not), over the median node's; 0 for a node of no area."""
    blocks = np.asarray(blocks, float)
    if blocks.ndim == 1:
        blocks = blocks[:, None, None]
    low = np.linalg.eigvalsh(0.5 * (blocks + np.swapaxes(blocks, 1, 2)))[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        density = np.where(area > 0, low / np.where(area > 0, area, 1.0), 0.0)
    typical = np.median(density[area > 0]) if np.any(area > 0) else 0.0
    return density / typical if typical > 0 else np.zeros_like(density)


def node_neighbours(connectivities: Sequence[np.ndarray], n_nodes: int) -> sps.csr_matrix:
    """(n, n) bool csr: ``[I, J]`` True when nodes I != J share an element (blocks (E, nn))."""
    rows, cols = [], []
    for conn in connectivities:
        conn = np.asarray(conn)
        nn = conn.shape[1]
        rows.append(np.repeat(conn, nn, axis=1).ravel())
        cols.append(np.tile(conn, (1, nn)).ravel())
    r, c = np.concatenate(rows), np.concatenate(cols)
    keep = r != c
    A = sps.csr_matrix((np.ones(keep.sum(), bool), (r[keep], c[keep])), shape=(n_nodes, n_nodes))
    A.sum_duplicates()
    return A


def neighbour_ratio(neighbours: sps.csr_matrix, positions: np.ndarray, values: np.ndarray,
                    std: np.ndarray) -> np.ndarray:
    """(n,) the worst component of ``|v_I - median_J v_J| / (std_I + reach_I spread_I)`` over
    the neighbours J of each node (:func:`node_neighbours`).

    ``spread_I``: the range (max - min) of the neighbours' values: a smooth field puts a node
    inside its neighbours' range where they surround it. ``reach_I = 1 + |X_I - mean_J X_J| /
    mean_J |X_J - mean_J X_J|`` (1 for a node amid its neighbours, about 1.7 on a boundary and
    2.5 at a corner of a structured mesh): where the neighbours lie to one side, the node
    extrapolates them and a curved smooth field puts it beyond their range.
    ``positions``: (n, 3) mm; ``values``, ``std``: (n, k) or (n,) (the noise's standard
    deviation of each value). A node of fewer than 3 neighbours (a T3 mesh's corner) is not
    judged (0): two neighbours cannot tell a smooth field's gradient across them.
    """
    v = np.asarray(values, float).reshape(len(values), -1)
    s = np.broadcast_to(np.asarray(std, float).reshape(len(values), -1), v.shape)
    X = np.asarray(positions, float)
    indptr, indices = neighbours.indptr, neighbours.indices
    counts = np.diff(indptr)
    out = np.zeros(len(v))
    for size in np.unique(counts[counts >= 3]):          # nodes of the same neighbour count
        rows = np.flatnonzero(counts == size)
        nb = indices[indptr[rows][:, None] + np.arange(size)]            # (r, size)
        centre = X[nb].mean(axis=1)
        extent = np.linalg.norm(X[nb] - centre[:, None], axis=2).mean(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            reach = 1.0 + np.linalg.norm(X[rows] - centre, axis=1) / extent
        vals = v[nb]                                                     # (r, size, k)
        median = np.median(vals, axis=1)
        spread = np.ptp(vals, axis=1) * np.nan_to_num(reach, nan=1.0)[:, None]
        deviation = np.abs(v[rows] - median)
        with np.errstate(invalid="ignore", divide="ignore"):      # (0 / 0: no deviation)
            ratio = np.where(deviation > 0, deviation / (s[rows] + spread), 0.0)
        out[rows] = np.max(np.where(np.isnan(ratio), np.inf, ratio), axis=1)
    return out


def residual_limit(residual_to_noise: np.ndarray) -> float:
    """The largest ``residual_to_noise`` of a valid node in this field:
    :data:`RESIDUAL_FACTOR` times the median node's, within
    [:data:`EXPLAINED_RESIDUAL_TO_NOISE`, :data:`MAX_RESIDUAL_TO_NOISE`]."""
    finite = residual_to_noise[np.isfinite(residual_to_noise)]
    typical = float(np.median(finite)) if finite.size else 0.0
    return float(np.clip(RESIDUAL_FACTOR * typical, EXPLAINED_RESIDUAL_TO_NOISE,
                         MAX_RESIDUAL_TO_NOISE))


def node_validity(residual_to_noise: np.ndarray, texture_ratio: np.ndarray,
                  conditioning: np.ndarray, neighbour: np.ndarray,
                  seen: np.ndarray | None = None) -> NodeValidity:
    """The checks of every node (all (n,)) against the thresholds of this module: the
    residual within :func:`residual_limit`, the texture, the conditioning and the neighbours'
    consistency above or below their constants. ``seen``: bool (n,), some point of the
    node's support entered the residual (default: where ``residual_to_noise`` is finite)."""
    limit = residual_limit(residual_to_noise)
    with np.errstate(invalid="ignore"):
        valid = ((residual_to_noise <= limit)
                 & (texture_ratio >= MIN_NODE_TEXTURE_RATIO)
                 & (conditioning >= MIN_NODE_CONDITIONING) & (neighbour <= MAX_NEIGHBOUR_RATIO))
    return NodeValidity(residual_to_noise=np.asarray(residual_to_noise, float),
                        texture_ratio=np.asarray(texture_ratio, float),
                        conditioning=np.asarray(conditioning, float),
                        neighbour_ratio=np.asarray(neighbour, float), valid=np.asarray(valid, bool),
                        seen=np.asarray(np.isfinite(residual_to_noise) if seen is None else seen,
                                        bool), residual_limit=limit)
