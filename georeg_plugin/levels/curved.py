"""Curved nominal surfaces: a vector spline correction seen along the FE node normals.

On a curved (or folded, multi-face) nominal surface the FE unknown of node ``I`` is a
displacement ``q_I`` along its nominal normal ``n_I`` (Eq. 8, Remark 1). The spline level
moves its control points by VECTORS ``d_J`` (3 components each, the rational basis
``R_J`` of the NURBS, Eq. 12):

    u(xi) = sum_J R_J(xi) d_J,         q_I = n_I . u(xi_I)
    A[I, 3 J + k] = R_J(xi_I) n_I[k]                       (Remark 6, read along n_I)

Why vectors (and not ``R_J(xi_I) (n_I . n_J)``, a scalar dof along a control normal):

* nesting (Eq. 13): knot insertion maps the vector spline space of a coarse level into
  the fine one (``R^c = C_r R^f`` per component), so ``range(A_c) ⊂ range(A_f)`` exactly;
  the product with ``n_I . n_J`` breaks it (measured 0.4-1.6 % on a cylinder);
* rigid motions: ``a + w x X(xi) = sum_J R_J(xi) (a + w x P_J)`` (partition of unity and
  ``X = sum_J R_J P_J``) is in the vector spline space, so its normal part
  ``n_I . (a + w x X_I)`` is in the range for ANY node normals ``n_I``;
* the measured shape is a NURBS of the level (``P_J + d_J``, Eq. 21), what a CAD tool reads;
* on a flat plate (``n_I = n``) the range is that of the scalar operator ``R_J(xi_I)``.

The tangential part of ``u`` is (up to the curvature terms) invisible: ``A`` has a null
space (2/3 of its columns on a flat plate). The operator handed to the solver is a basis
of ``range(A)`` (:func:`range_basis`): the columns themselves where they are independent (a
flat face once its tangential columns, zero, are left out: sparse, no SVD), else
``C_s = U_r^T`` from the SVD ``A = U S V^T`` of the faces that share rows, keeping the
singular values ``S_k > RANK_RTOL * S_0``. The gap is wide: on a 30 degree cylinder
panel (R 100 mm) the smallest kept value is 2e-7 S_0 at the 4th level and the largest
dropped 4e-16 S_0. The control vectors of a level's values ``q_s`` are then
``d = V_r S_r^-1 q_s`` (minimum norm: least tangential sliding).

What it costs: on a curved part the range is larger than the scalar spline space (a
tangential control motion changes the shape by a curvature term): about 1.6-1.9 times the
number of control points on the cylinder panel above, the extra directions weak in ``A``
(they are the sagitta of tangential motions). ``C_s`` is dense ``(r, n_fe)``: this module
is for parts of up to a few thousand FE nodes and a few hundred control points per level.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import numpy as np
import scipy.sparse as sps
from scipy.sparse.csgraph import connected_components

from georeg_plugin.spline.fe_mesh import coincident_groups
from georeg_plugin.spline.patch import SplinePatch

logger = logging.getLogger(__name__)

__all__ = ["RANK_RTOL", "vector_extraction", "range_basis", "is_flat", "vector_gluing",
           "VectorLevel", "vector_level"]

#: singular values of ``A`` below ``RANK_RTOL * S_0`` count as the tangential null space
RANK_RTOL = 1e-10


def is_flat(patches: Sequence[SplinePatch], rtol: float = 1e-9) -> bool:
    """True if every control point of ``patches`` lies in one plane (within ``rtol`` times
    the size of the part): the NURBS surfaces are then planar (convex combinations)."""
    cp = np.vstack([p.control_points.reshape(-1, 3) for p in patches])
    centred = cp - cp.mean(axis=0)
    size = float(np.ptp(cp, axis=0).max()) or 1.0
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]   # least-spread direction
    return bool(np.abs(centred @ normal).max() <= rtol * size)


def vector_extraction(patch: SplinePatch, uv: np.ndarray, node_normals: np.ndarray
                      ) -> sps.csr_matrix:
    """``A`` (n_fe, 3 n_control_points): ``A[I, 3 J + k] = R_J(xi_I) n_I[k]``.

    ``A @ d.ravel()`` is the normal part ``n_I . u(xi_I)`` of the vector correction whose
    control vectors are ``d`` (n_control_points, 3).
    """
    uv = np.asarray(uv, dtype=float)
    n = np.asarray(node_normals, dtype=float)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must be (n_fe, 2), got {uv.shape}")
    if n.shape != (uv.shape[0], 3):
        raise ValueError(f"node_normals must be ({uv.shape[0]}, 3), got {n.shape}")
    R = sps.coo_matrix(patch.basis(uv))                         # R_J(xi_I), (n_fe, n_cp)
    rows = np.repeat(R.row, 3)
    cols = (3 * R.col[:, None] + np.arange(3)).ravel()
    data = (R.data[:, None] * n[R.row]).ravel()
    A = sps.csr_matrix((data, (rows, cols)), shape=(uv.shape[0], 3 * patch.n_dofs))
    A.eliminate_zeros()
    return A


#: a block of columns whose Gram matrix has all eigenvalues above this fraction of the
#: largest is independent, and its columns serve as the basis as they are (sparse); below it
#: the block goes through the SVD (the smallest kept singular values measured here are
#: 2e-5 of the largest on a 100 mm cylinder panel, i.e. 4e-10 in the Gram)
INDEPENDENT_RTOL = 1e-8


def range_basis(A, rtol: float = RANK_RTOL) -> tuple[sps.csr_matrix, np.ndarray]:
    """A basis of ``range(A)`` and the map from its coordinates to ``A``'s columns.

    Columns of norm below ``rtol`` of the largest (the tangential components of a flat
    face's control vectors, the axial ones on a cylinder) are left out; the others split
    into blocks that share no row (faces not glued together: the connected components of
    ``A^T A``). A block whose Gram matrix is well conditioned (:data:`INDEPENDENT_RTOL`)
    keeps its columns as basis vectors (sparse: a flat face costs no SVD); any other block
    gets the orthonormal basis of its SVD (``U_r^T``), singular values above ``rtol`` of
    ``A``'s largest column norm kept (the gap to the null directions is 10 orders wide on the
    measured shapes). ``C H C^T`` and every step of Eqs. 18-21 depend on the range only.

    Returns
    -------
    C : csr (r, n_rows), ``range(C^T) = range(A)``.
    T : (n_cols, r), ``A @ T = C^T``.
    """
    A = sps.csc_matrix(A, dtype=float)
    norms = np.sqrt(np.asarray(A.multiply(A).sum(axis=0)).ravel())
    if norms.size == 0 or norms.max() == 0:
        raise ValueError("range_basis: the matrix is zero (no FE node sees the spline)")
    cols = np.flatnonzero(norms > rtol * norms.max())
    gram = (A[:, cols].T @ A[:, cols]).tocsr()
    n_blocks, label = connected_components(gram, directed=False)
    biggest = float(norms.max()) ** 2
    C, T = [], []                                # per block: (r_b, n_rows), (n_cols, r_b)
    for b in range(n_blocks):
        idx = cols[label == b]
        block = A[:, idx]
        lam = np.linalg.eigvalsh(gram[label == b][:, label == b].toarray())
        Tb = np.zeros((A.shape[1], idx.size))
        if lam[0] > INDEPENDENT_RTOL * lam[-1]:              # independent: the columns
            Tb[idx, np.arange(idx.size)] = 1.0
            C.append(sps.csr_matrix(block.T))
        else:                                                # the block's SVD on its rows
            rows = np.unique(block.indices)
            U, s, Vt = np.linalg.svd(block[rows].toarray(), full_matrices=False)
            r = int(np.count_nonzero(s > rtol * np.sqrt(biggest)))
            Tb = Tb[:, :r]
            Tb[idx] = Vt[:r].T / s[:r]
            Ub = np.zeros((r, A.shape[0]))
            Ub[:, rows] = U[:, :r].T                         # orthonormal rows
            C.append(sps.csr_matrix(Ub))
        T.append(Tb)
    C = sps.vstack(C).tocsr()
    logger.debug("range basis: rank %d of %d columns, %d blocks", C.shape[0], A.shape[1], n_blocks)
    return C, np.hstack(T)


def vector_gluing(patches: Sequence[SplinePatch], tol: float = 1e-9) -> sps.csr_matrix:
    """``G`` (n_points, n_control_points of all patches): one point where control points of
    the patches (or of the seam of a closed patch) coincide in position and weight."""
    cp = np.vstack([p.control_points.reshape(-1, 3) for p in patches])
    w = np.concatenate([p.homogeneous_weights for p in patches])[:, None]
    size = float(np.ptp(cp, axis=0).max()) or 1.0
    representative = coincident_groups(np.hstack([cp, w * size]), tol * size)
    kept, point = np.unique(representative, return_inverse=True)
    return sps.csr_matrix((np.ones(len(cp)), (point, np.arange(len(cp)))),
                          shape=(kept.size, len(cp)))


@dataclasses.dataclass(frozen=True, eq=False)
class VectorLevel:
    """One spline level of a curved part in the vector formulation.

    Attributes
    ----------
    operator : csr (r, n_fe) ``C_s``, rows spanning ``range(A)`` (:func:`range_basis`).
    coefficients : (3 n_control_points, r): the control vectors (flattened, patch after
        patch, ``3 J + k``) of the level values ``q_s`` are ``coefficients @ q_s``.
    """

    operator: sps.csr_matrix
    coefficients: np.ndarray

    def control_vectors(self, q_s: np.ndarray) -> np.ndarray:
        """Control vectors ``d`` (n_control_points, 3) of the level values ``q_s``."""
        return (self.coefficients @ np.asarray(q_s, dtype=float)).reshape(-1, 3)


def vector_level(patches: Sequence[SplinePatch], rows: Sequence[np.ndarray],
                 uvs: Sequence[np.ndarray], node_normals: np.ndarray, n_fe: int,
                 glue: bool = True, rtol: float = RANK_RTOL) -> VectorLevel:
    """The level's operator for one or several patches (faces) of a part.

    Parameters
    ----------
    patches : the level's patches (one per face).
    rows : per patch, the FE node indices (k,) it evaluates (each node in one patch only).
    uvs : per patch, (k, 2) parameters of those nodes on the patch.
    node_normals : (n_fe, 3) unit normals of the FE unknowns.
    n_fe : number of FE nodes.
    glue : coincident control points (shared edges, seams) move together.
    """
    blocks = []
    for patch, idx, uv in zip(patches, rows, uvs):
        idx = np.asarray(idx, dtype=int)
        local = vector_extraction(patch, uv, np.asarray(node_normals)[idx]).tocoo()
        blocks.append(sps.csr_matrix((local.data, (idx[local.row], local.col)),
                                     shape=(n_fe, local.shape[1])))
    A = sps.hstack(blocks).tocsr()
    G3 = None
    if glue:
        G = vector_gluing(patches)
        if G.shape[0] < G.shape[1]:
            G3 = sps.kron(G, sps.identity(3)).tocsr()           # (3 points, 3 cp)
            A = (A @ G3.T).tocsr()
    C, T = range_basis(A, rtol)
    if G3 is not None:
        T = np.asarray(G3.T @ T)                                 # back to every control point
    return VectorLevel(operator=C, coefficients=T)
