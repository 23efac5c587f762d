"""Step solvers for the displacement's node-major dofs (``3 I + k``).

A scalar nodal operator ``C`` (n_a, n) acts on each displacement component through
``kron(C, I_3)`` (:func:`componentwise`): the spline operators ``C_s`` of the plugin
(one spline per component, as the 2-D pyxel adapter does) and the Tikhonov operator ``A``
of Eq. 10 (:class:`ComponentTikhonovSolver`). The Gauss-Newton of
:mod:`fesdic_core.displacement` calls ``solve(H, b, U, scale)`` exactly as the shape's.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from .mesh import SurfaceMesh
from .tikhonov import TikhonovSolver

__all__ = ["componentwise", "ComponentTikhonovSolver"]


def componentwise(C: sps.spmatrix) -> sps.csr_matrix:
    """``kron(C, I_3)``: a scalar nodal operator on each of the three components
    (rows and columns in the node-major layout ``3 I + k``)."""
    return sps.kron(sps.csr_matrix(C), sps.identity(3, format="csr"), format="csr")


class ComponentTikhonovSolver(TikhonovSolver):
    """Tikhonov regularization (Eq. 10) of each displacement component:
    ``(H + lam A3) d = b - lam A3 U`` with ``A3 = kron(A, I_3)``.

    The weight ``lam`` is chosen as for the shape (:func:`fesdic_core.tikhonov.tikhonov_weight`)
    with the cosine probe on all three components of every node (the nodes repeated three
    times); ``length_mm`` as :class:`~fesdic_core.tikhonov.TikhonovSolver` (a fixed length;
    ``"auto"`` needs a noise model from ``start_scale``, which the displacement driver does
    not estimate: it then raises ValueError at the first step).
    """

    def __init__(self, mesh: SurfaceMesh, length_mm: float | str):
        super().__init__(mesh, length_mm)
        self.A = componentwise(self.A)
        self.nodes = np.repeat(np.asarray(mesh.nodes, float), 3, axis=0)

    def __repr__(self) -> str:
        return f"ComponentTikhonovSolver(length_mm={self.length_mm!r})"
