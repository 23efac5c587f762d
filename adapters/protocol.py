"""What a host FE-DIC code gives the plugin, and what it gets back.

The plugin (``georeg_plugin``) knows nothing about any DIC code: it needs the FE
node coordinates (to locate each node on the nominal spline, Eq. 26 / Remark 6) and
returns the operators ``C_s`` (Eq. 28) with ``C_s^T[I, J] = R^s_J(xi_I)``. A host
code then uses them in one of two ways:

- a **solve hook**: the host calls ``solve(H, b, q, scale) -> d`` at each
  Gauss-Newton step and the plugin returns ``d = C^T (C H C^T)^-1 C b`` (Eqs. 18-21);
  this is how :mod:`adapters.fesdic_core` works;
- a **reduced basis**: the host already restricts its updates to a basis
  ``B`` (``H -> B^T H B``, ``U += B dU``); the adapter places ``C_s^T`` in the host's
  dof numbering, one block per displacement component (:func:`reduced_basis`);
  this is how :mod:`adapters.pyxel` works.

:class:`Adapter` is the structural type of a reduced-basis host
(:class:`adapters.pyxel.PyxelAdapter` satisfies it); a host with a solve hook needs
only ``solve(H, b, q, scale)``, which the plugin's ``GeometricRegularization`` has.
"""
from __future__ import annotations

import dataclasses
from typing import Mapping, Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sps

__all__ = ["Adapter", "LevelRecord", "reduced_basis"]


@dataclasses.dataclass(frozen=True, eq=False)
class LevelRecord:
    """What one level of a multilevel regularized correlation gave back.

    Attributes
    ----------
    level : int
        Spline level s, Eq. 28 numbering: 0 is the FINEST level, ``n_levels - 1`` the
        coarsest (the first run, on the coarsest images).
    image_scale : int
        Image scale of the run (images after ``image_scale`` 2x2 aggregations).
    n_basis : int
        Number of columns of the reduced basis actually used (all components).
    residual_std : float
        Standard deviation of the gray-level residual at convergence (gray levels).
    n_iterations : int
        Gauss-Newton iterations run by the host at this level.
    U : ndarray, (n_dof,)
        Displacement dof vector at the end of the level (host numbering).
    dropped : int
        Columns of the level's basis ``C_s^T`` removed because they are zero on the mesh's
        nodes or no integration point sees them (the level restricted to the outline).
    """

    level: int
    image_scale: int
    n_basis: int
    residual_std: float
    n_iterations: int
    U: np.ndarray
    dropped: int = 0


@runtime_checkable
class Adapter(Protocol):
    """A host FE-DIC code, as the plugin sees it.

    Attributes
    ----------
    nodes : ndarray, (n, dim)
        FE node coordinates in the host's mesh unit.
    connectivity : Mapping[str, ndarray]
        Element connectivity per element type (meshio type name -> (ne, nn) node
        indices into ``nodes``).
    dof_layout : ndarray of int, (n, n_components)
        ``dof_layout[I, c]`` is the host's dof index of displacement component ``c``
        at node ``I``, or -1 when node I carries no dof.
    n_dof : int
        Length of the host's dof vector.
    """

    nodes: np.ndarray
    connectivity: Mapping[str, np.ndarray]
    dof_layout: np.ndarray
    n_dof: int

    def correlate(self, basis: sps.csr_matrix | None, U0: np.ndarray | None,
                  image_scale: int) -> tuple[np.ndarray, float, int]:
        """Run the host's Gauss-Newton correlation at one image scale.

        Parameters
        ----------
        basis : csr (n_dof, k) or None
            Reduced basis ``B`` of the updates (``U += B dU``); None: plain FE-DIC.
        U0 : ndarray (n_dof,) or None
            Starting displacement (in the range of ``basis`` when one is given).
        image_scale : int
            Number of 2x2 image aggregations.

        Returns
        -------
        (U (n_dof,), residual_std, n_iterations)
        """
        ...


def reduced_basis(C: sps.spmatrix, dof_layout: np.ndarray, n_dof: int) -> sps.csr_matrix:
    """Place ``C^T`` in a host dof numbering, one block per displacement component.

    Parameters
    ----------
    C : sparse (n_spline, n_nodes)
        Extraction operator of one level (Eq. 28), ``C^T[I, J] = R_J(xi_I)``;
        its columns follow the rows of ``dof_layout``.
    dof_layout : int array (n_nodes, n_components)
        Host dof index per node and component, -1 for nodes without dofs.
    n_dof : int
        Length of the host's dof vector.

    Returns
    -------
    B : csr (n_dof, n_components * n_spline)
        ``B[dof_layout[I, c], c * n_spline + J] = C[J, I]``: component ``c`` of the
        displacement is the spline field of the block ``c`` of the reduced unknown.
    """
    layout = np.asarray(dof_layout)
    if layout.ndim != 2 or not np.issubdtype(layout.dtype, np.integer):
        raise ValueError(f"dof_layout must be an integer array (n_nodes, n_components), "
                         f"got dtype {layout.dtype} and shape {layout.shape}")
    n_spline, n_nodes = C.shape
    if layout.shape[0] != n_nodes:
        raise ValueError(f"C has {n_nodes} columns (nodes) but dof_layout has "
                         f"{layout.shape[0]} rows")
    if layout.max(initial=-1) >= n_dof:
        raise ValueError(f"dof_layout refers to dof {int(layout.max())} >= n_dof = {n_dof}")
    CT = sps.coo_matrix(C).T.tocoo()  # (n_nodes, n_spline): row I, column J
    rows, cols, vals = [], [], []
    for c in range(layout.shape[1]):  # one block per displacement component
        dof = layout[CT.row, c]
        keep = dof >= 0
        rows.append(dof[keep])
        cols.append(CT.col[keep] + c * n_spline)
        vals.append(CT.data[keep])
    return sps.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n_dof, layout.shape[1] * n_spline))
