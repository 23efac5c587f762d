"""Surface Green-Lagrange strain of a measured displacement, in the local tangent frame.

On the reference surface ``X(xi)`` (tangents ``T = [X,xi  X,eta]``, 3 x 2) with the FE
displacement ``U(xi) = sum_I L_I(xi) U_I``, a material line element of the tangent plane
``dX = E a`` (``E = [e1 e2]`` an orthonormal tangent frame, ``a`` its local coordinates)
becomes ``dx = dX + dU = (E + G) a`` with the surface displacement gradient

    G = U,xi (T^T T)^-1 T^T E        (3 x 2),

so the surface Green-Lagrange strain in the frame ``(e1, e2)`` is

    E_GL = 1/2 ((E + G)^T (E + G) - I) = 1/2 (E^T G + G^T E + G^T G)      (2 x 2).

The frame: ``e1`` is the world x axis projected on the tangent plane (the world y axis
where x is nearly normal to the surface), ``e2 = n x e1`` with the unit normal
``n = X,xi x X,eta / |...|``. ``strain_xy`` is the tensor component ``E_GL[0, 1]`` (half
the engineering shear). Values are computed in every element at its nodes and averaged
over the elements that share a node.
"""
from __future__ import annotations

import numpy as np

from .mesh import SurfaceMesh

__all__ = ["tangent_frame", "surface_green_lagrange"]

_NEARLY_NORMAL = 0.9     # |x . n| above which e1 follows the world y axis instead of x


def tangent_frame(normals: np.ndarray) -> np.ndarray:
    """Orthonormal tangent frames (..., 3, 2) ``[e1 e2]`` for unit normals (..., 3)."""
    n = np.asarray(normals, float)
    axis = np.zeros_like(n)
    use_y = np.abs(n[..., 0]) > _NEARLY_NORMAL
    axis[..., 0] = ~use_y
    axis[..., 1] = use_y
    e1 = axis - np.sum(axis * n, axis=-1, keepdims=True) * n
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(n, e1)
    return np.stack([e1, e2], axis=-1)


def surface_green_lagrange(mesh: SurfaceMesh, U: np.ndarray) -> np.ndarray:
    """Nodal surface Green-Lagrange strain ``(E_xx, E_yy, E_xy)`` (n, 3) of ``U`` (n, 3)
    on the reference surface ``mesh`` (local tangent frame, see the module docstring)."""
    U = np.asarray(U, float).reshape(mesh.n_nodes, 3)
    total = np.zeros((mesh.n_nodes, 3))
    count = np.zeros(mesh.n_nodes)
    for block in mesh.blocks:
        dN = block.family.shape_derivatives(block.family.ref_nodes)        # (nn, nn, 2)
        Xe, Ue = mesh.nodes[block.connectivity], U[block.connectivity]      # (ne, nn, 3)
        T = np.einsum("mia,eik->emka", dN, Xe)                               # (ne, nn, 3, 2)
        dU = np.einsum("mia,eik->emka", dN, Ue)                              # U,xi
        normal = np.cross(T[..., 0], T[..., 1])
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        E = tangent_frame(normal)                                            # (ne, nn, 3, 2)
        metric = np.swapaxes(T, -1, -2) @ T                                  # T^T T
        G = dU @ np.linalg.solve(metric, np.swapaxes(T, -1, -2) @ E)         # (ne, nn, 3, 2)
        EtG = np.swapaxes(E, -1, -2) @ G
        strain = 0.5 * (EtG + np.swapaxes(EtG, -1, -2) + np.swapaxes(G, -1, -2) @ G)
        values = np.stack([strain[..., 0, 0], strain[..., 1, 1], strain[..., 0, 1]], axis=-1)
        np.add.at(total, block.connectivity.ravel(), values.reshape(-1, 3))
        count += np.bincount(block.connectivity.ravel(), minlength=mesh.n_nodes)
    return total / np.maximum(count, 1)[:, None]
