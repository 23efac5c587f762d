"""Local validity of a measured shape: the checks of :mod:`fesdic_core.residual.validity` on
the shape's residual (Eq. 3: camera 0 against camera 1) and its ``H`` (Eq. 8).

Per node ``I``, on its support at the measured surface: the residual's root mean square
against the local noise floor of the pair (each image at its projection of the points); the
texture of both images there; the node's diagonal entry of ``H`` per unit support area
against the median node's (when the measurement kept its linearised state); the distance of
the correction ``q_I`` from its neighbours' median against its standard deviation (when
estimated) plus the neighbours' spread.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import scipy.sparse as sps

from fesdic_core.fe.mesh import SurfaceMesh
from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.imaging.noise import residual_noise_floor
from fesdic_core.residual.graylevel import GrayLevelResidual
from fesdic_core.residual.validity import (NodeValidity, Support, block_conditioning,
                                           local_image, local_noise_gray, neighbour_ratio,
                                           node_neighbours, node_validity)

__all__ = ["shape_validity"]


def shape_validity(mesh: SurfaceMesh, nodes: np.ndarray, q: np.ndarray, quad: PixelQuadrature,
                   residual: GrayLevelResidual, images: Sequence, cameras: Sequence,
                   H: sps.spmatrix | None = None, q_std: np.ndarray | None = None
                   ) -> NodeValidity:
    """The local checks of every node of a shape measurement.

    Parameters
    ----------
    mesh : the nominal mesh (its connectivity)
    nodes : (n, 3) measured node positions (mm)
    q : (n,) the measured normal correction (mm)
    quad : the finest scale's quadrature; ``residual`` its residual at the measured state
    images, cameras : the two images and cameras at the finest scale
    H : (n, n) the shape's Gauss-Newton operator at that state (None: conditioning not judged)
    q_std : (n,) the standard deviation of ``q`` (None: the neighbours' spread alone)
    """
    support = Support(quad)
    X = quad.points(nodes)
    w = np.where(residual.mask, quad.weight_mm2, 0.0)
    floor = residual_noise_floor(X, residual.mask, images, cameras)
    ratio = floor.contrast[0] / floor.contrast[1] if floor.contrast[1] > 0 else 1.0
    local = [local_image(support, w, image, camera, X) for image, camera in zip(images, cameras)]
    noise = 100.0 * local_noise_gray(local[0], local[1], ratio) / float(residual.dynamic_range)
    squared = support.mean(np.nan_to_num(residual.percent) ** 2, w)
    with np.errstate(invalid="ignore", divide="ignore"):
        residual_to_noise = np.sqrt(squared) / noise
    texture = np.minimum(local[0].texture_ratio, local[1].texture_ratio)
    if H is None:
        conditioning = np.ones(len(q))
    else:
        conditioning = block_conditioning(sps.csr_matrix(H).diagonal(),
                                          support.total(quad.weight_mm2))
    std = np.zeros(len(q)) if q_std is None else np.nan_to_num(np.asarray(q_std, float))
    neighbours = node_neighbours([b.connectivity for b in mesh.blocks], mesh.n_nodes)
    return node_validity(residual_to_noise, texture, conditioning,
                         neighbour_ratio(neighbours, nodes, np.asarray(q, float), std),
                         seen=support.total(w) > 0)
