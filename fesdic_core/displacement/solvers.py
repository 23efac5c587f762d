"""Step solvers for the displacement's node-major dofs (``3 I + k``).

A scalar nodal operator ``C`` (n_a, n) acts on each displacement component through
``kron(C, I_3)`` (:func:`componentwise`): the spline operators ``C_s`` of the plugin
(one spline per component, as the 2-D pyxel adapter does) and the Tikhonov operator ``A``
of Eq. 10 (:class:`ComponentTikhonovSolver`). The Gauss-Newton of
:mod:`fesdic_core.displacement.driver` calls ``solve(H, b, U, scale)`` exactly as the shape's.
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Callable

import numpy as np
import scipy.sparse as sps

from fesdic_core.fe.mesh import SurfaceMesh
from fesdic_core.solve.solvers import sparse_factor, sparse_solve
from fesdic_core.solve.tikhonov import (surface_gradient_integral, surface_gradient_operator,
                                       tikhonov_weight)

if TYPE_CHECKING:  # typing only
    from fesdic_core.shape.uncertainty import NoiseModel

logger = logging.getLogger(__name__)

__all__ = ["componentwise", "ComponentTikhonovSolver"]


def componentwise(C: sps.spmatrix) -> sps.csr_matrix:
    """``kron(C, I_3)``: a scalar nodal operator on each of the three components
    (rows and columns in the node-major layout ``3 I + k``)."""
    return sps.kron(sps.csr_matrix(C), sps.identity(3, format="csr"), format="csr")


class ComponentTikhonovSolver:
    """Tikhonov regularization (Eq. 10) of each displacement component at one length, on the
    departure of its gradient from its mean: ``(H + A3) d = b - A3 U`` with
    ``A3 = kron(A - G^T G / |Omega|, diag(lam_x, lam_y, lam_z))``.

    ``A`` is the surface-gradient operator (``u^T A u = int |grad_s u|^2``) and ``G u`` the
    integral of the gradient (:func:`~fesdic_core.solve.tikhonov.surface_gradient_integral`),
    so ``u^T A3 u`` penalises ``int |grad_s u - <grad_s u>|^2``: a homogeneous deformation (a
    uniform strain, a small rotation) costs nothing. With ``A`` alone it did: at 10 mm a 3 %
    stretch was read 9.5 % low (``benchmarks/bench_subpixel.py``). ``A3`` is sparse minus
    rank 9 (``kron(A, Lam) - W W^T``, ``W = kron(G^T, Lam^1/2) / |Omega|^1/2``); the step is solved by the Woodbury identity
    on the factorized sparse part.

    Each component gets its own weight ``lam_k`` from its own block of ``H`` (dofs
    ``k::3``) by the cosine probe of :func:`~fesdic_core.solve.tikhonov.tikhonov_weight`: the
    images see the out-of-plane component of a stereo rig several times less than the
    in-plane ones, so one weight for all three would regularize it at a much longer
    effective length. One weight per component and image scale, chosen at the scale's
    first step, the length ``length_mm * 2**s`` at scale ``s`` (as
    :class:`~fesdic_core.solve.tikhonov.TikhonovSolver`).

    Attributes
    ----------
    A3_unit : ``kron(A, I_3)``
    component_lambdas : dict scale -> (3,) weights
    """

    def __init__(self, mesh: SurfaceMesh, length_mm: float):
        if isinstance(length_mm, str) or not (np.isfinite(length_mm) and length_mm > 0):
            raise ValueError(f"tikhonov_length_mm of a displacement must be a positive number "
                             f"(mm), got {length_mm!r}")
        self.length_mm = float(length_mm)
        self.nodes = np.asarray(mesh.nodes, float)
        self.A = surface_gradient_operator(mesh)
        self.A3_unit = componentwise(self.A)
        G, area = surface_gradient_integral(mesh)
        self._G3 = componentwise(G).toarray() / np.sqrt(area)      # (9, 3n): kron(G, I3)
        self.component_lambdas: dict[int, np.ndarray] = {}
        self._scale: int | None = None

    def start_scale(self, scale: int, noise: NoiseModel | None = None) -> None:
        """Mark the start of a scale; a coarser one than the current starts a new pass."""
        scale = int(scale)
        if self._scale is not None and scale > self._scale:
            self.component_lambdas.clear()
        self._scale = scale

    def operator(self, scale: int) -> sps.csr_matrix:
        """The sparse part ``kron(A, Lam)`` of ``A3`` at ``scale`` (its weights must have
        been chosen); ``A3 = operator - W W^T`` with ``W = low_rank(scale)``."""
        return sps.kron(self.A, sps.diags(self.component_lambdas[int(scale)]), format="csr")

    def low_rank(self, scale: int) -> np.ndarray:
        """``W`` (3n, 9) of ``A3 = operator(scale) - W W^T`` (the gradient's mean)."""
        lam = np.tile(self.component_lambdas[int(scale)], 3)      # rows 3 d + k: lam_k
        return self._G3.T * np.sqrt(lam)

    def solve(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        return self.factorize(H, scale)(b, q)                                  # Eq. 10

    def factorize(self, H: sps.spmatrix,
                  scale: int) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        """``(b, q) -> (H + A3)^-1 (b - A3 q)`` with ``H + kron(A, Lam)`` factorized once and
        the rank-9 correction by the Woodbury identity (the weights of the scale chosen from
        ``H`` if not yet)."""
        scale = int(scale)
        self.start_scale(scale)
        A3 = self._choose(H, scale)
        W = self.low_rank(scale)
        solve = sparse_factor(H + A3, what="H + A3")
        Z = np.column_stack([solve(w) for w in W.T])                  # (H + A)^-1 W
        S = np.eye(W.shape[1]) - W.T @ Z                              # I - W^T (H + A)^-1 W

        def step(b: np.ndarray, q: np.ndarray) -> np.ndarray:
            rhs = b - (A3 @ q - W @ (W.T @ q))                        # b - A3 q (Eq. 10)
            y = solve(rhs)
            return y + Z @ np.linalg.solve(S, W.T @ y)                # Woodbury
        return step

    def _choose(self, H: sps.spmatrix, scale: int) -> sps.csr_matrix:
        """``A3`` of ``scale``, its weights chosen from ``H`` at the scale's first step."""
        if scale not in self.component_lambdas:
            length = self.length_mm * 2.0 ** scale                       # Remark 3
            H = sps.csr_matrix(H)
            self.component_lambdas[scale] = np.array(
                [tikhonov_weight(H[k::3, k::3], self.A, self.nodes, length) for k in range(3)])
            logger.info("tikhonov (per component) scale %d: length %.4g mm, lambda %s", scale,
                        length, np.array2string(self.component_lambdas[scale], precision=4))
        return self.operator(scale)

    def __repr__(self) -> str:
        return f"ComponentTikhonovSolver(length_mm={self.length_mm!r})"
