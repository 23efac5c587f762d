"""Tikhonov regularization of the shape problem (Eq. 10), as a step solver of the core.

``(H + lam A) d = b - lam A q`` where ``A`` is the surface-gradient operator:
``q^T A q = int_Omega |grad_s S|^2 dX`` for the normal correction field ``S = L^T q``.

How the regularization length maps to ``lam``
---------------------------------------------
As in pyxel and in Passieux et al.'s FE-SDIC, ``lam`` is chosen so that a cosine
field of wavelength ``length_mm`` costs as much in the regularization term as in
the gray-level term:

    lam = (v^T H v) / (v^T A v),   v_I = cos(2 pi x_I . e / length_mm),

averaged over the two in-plane principal directions ``e`` of the mesh. Components of
the shape with wavelengths longer than ``length_mm`` are ruled by the images, shorter
ones by the regularization (a low-pass filter of cut-off ``length_mm``). ``lam`` is
recomputed from the current ``H`` at each call, so it follows the image scale.
"""
from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sps

from .elements import gauss_rule
from .mesh import SurfaceMesh, assemble
from .solvers import sparse_solve

logger = logging.getLogger(__name__)


def surface_gradient_operator(mesh: SurfaceMesh) -> sps.csr_matrix:
    """Assemble ``A`` with ``q^T A q = int |grad_s (L^T q)|^2 dX`` (the operator of Eq. 10).

    The surface gradient of a shape function is ``J (J^T J)^-1 dN/dxi`` with
    ``J = [dX/dxi, dX/deta]`` (3 x 2); then ``A_IJ = sum_g w_g grad_s N_I . grad_s N_J``.
    """
    element_matrices = []
    for block in mesh.blocks:
        xi, w = gauss_rule(block.family, 3)
        dN = block.family.shape_derivatives(xi)                    # (m, nn, 2)
        Xe = mesh.nodes[block.connectivity]                          # (ne, nn, 3)
        J = np.einsum("eid,mia->emda", Xe, dN)                       # (ne, m, 3, 2)
        G = np.einsum("emda,emdb->emab", J, J)                       # metric J^T J
        detG = G[..., 0, 0] * G[..., 1, 1] - G[..., 0, 1] ** 2
        Ginv = np.stack([np.stack([G[..., 1, 1], -G[..., 0, 1]], -1),
                         np.stack([-G[..., 1, 0], G[..., 0, 0]], -1)], -2) / detG[..., None, None]
        grad = np.einsum("emda,emab,mib->emid", J, Ginv, dN)         # (ne, m, nn, 3)
        dA = np.sqrt(detG) * w                                        # area weights
        element_matrices.append(np.einsum("em,emid,emjd->eij", dA, grad, grad))  # (ne, nn, nn)
    return assemble([b.connectivity for b in mesh.blocks], element_matrices, mesh.nodes.shape[0])


def tikhonov_weight(H: sps.spmatrix, A: sps.spmatrix, nodes: np.ndarray, length_mm: float) -> float:
    """``lam`` such that a cosine of wavelength ``length_mm`` costs the same in H and lam A."""
    centred = nodes - nodes.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    ratios = []
    for e in axes[:2]:
        v = np.cos(2.0 * np.pi * (centred @ e) / length_mm)
        vAv = float(v @ (A @ v))
        if vAv > 0:
            ratios.append(float(v @ (H @ v)) / vAv)
    if not ratios:
        raise ValueError(f"tikhonov length {length_mm} mm: the cosine probe has no gradient")
    return float(np.mean(ratios))


class TikhonovSolver:
    """Step solver of Eq. 10: ``(H + lam A) d = b - lam A q``.

    Parameters
    ----------
    mesh : SurfaceMesh
        The nominal FE mesh (to build ``A``).
    length_mm : float
        Regularization length (mm); see the module docstring for ``lam``.
    """

    def __init__(self, mesh: SurfaceMesh, length_mm: float):
        if not np.isfinite(length_mm) or length_mm <= 0:
            raise ValueError(f"tikhonov_length_mm must be a positive number, got {length_mm!r}")
        self.length_mm = float(length_mm)
        self.nodes = mesh.nodes
        self.A = surface_gradient_operator(mesh)
        self.last_lambda: float | None = None

    def solve(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        lam = tikhonov_weight(H, self.A, self.nodes, self.length_mm)
        self.last_lambda = lam
        return sparse_solve(H + lam * self.A, b - lam * (self.A @ q), what="H_FE + lam A")  # Eq. 10

    def __repr__(self) -> str:
        return f"TikhonovSolver(length_mm={self.length_mm})"
