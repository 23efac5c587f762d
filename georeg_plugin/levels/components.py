"""The levels of a vector field: one copy of a scalar space per component (``kron(C_s, I_k)``).

A displacement has ``k = 3`` unknowns per FE node, in the node-major layout ``k I + c``
(node ``I``, component ``c``). Each component is regularized by the same scalar spline
levels, so the operator of level ``s`` is ``kron(C_s, I_k)`` (Eq. 28 on each component),
and the refinement and gluing matrices go along the same way: ``kron(C_r, I_k)
kron(C_s, I_k) = kron(C_r C_s, I_k)`` keeps the levels nested (Eq. 13) exactly as the
scalar levels are.
"""
from __future__ import annotations

import scipy.sparse as sps

from georeg_plugin.levels.operators import MultilevelSpace

__all__ = ["componentwise", "component_levels"]


def componentwise(C: sps.spmatrix, n_components: int = 3) -> sps.csr_matrix:
    """``kron(C, I_k)`` (k = ``n_components``): the scalar operator ``C`` on each component,
    rows and columns in the node-major layout ``k I + c``."""
    return sps.kron(sps.csr_matrix(C), sps.identity(n_components, format="csr"), format="csr")


def component_levels(space: MultilevelSpace, n_components: int = 3) -> MultilevelSpace:
    """The space of a field of ``n_components`` per node from the scalar levels ``space``.

    Parameters
    ----------
    space : the scalar levels (``operators[s]`` of shape (n_spline_s, n_fe)).
    n_components : components per node (3 for a displacement).

    Returns
    -------
    MultilevelSpace
        ``operators[s]`` = ``kron(C_s, I_k)`` of shape (k n_spline_s, k n_fe), the
        refinement and gluing matrices likewise, the same patches.

    Raises
    ------
    ValueError
        For a space in the vector formulation (its dofs are already vectors per control
        point), or a number of components below 1.
    """
    if int(n_components) != n_components or n_components < 1:
        raise ValueError(f"n_components must be a positive integer, got {n_components!r}")
    if space.vector:
        raise ValueError("component_levels takes scalar levels; this space is in the vector "
                         "formulation (georeg_plugin.levels.curved)")
    k = int(n_components)
    return MultilevelSpace(patches=space.patches,
                           operators=tuple(componentwise(C, k) for C in space.operators),
                           refinement=tuple(componentwise(Cr, k) for Cr in space.refinement),
                           gluing=tuple(componentwise(G, k) for G in space.gluing))
