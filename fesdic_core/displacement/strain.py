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
the engineering shear).

The strain of an FE field is discontinuous between elements and least accurate at the
nodes (the derivative of the displacement at an element's corners, where a node's noise
weighs most). Nodal values are recovered (``recovery``):

- ``"patch"`` (default): the superconvergent patch recovery of Zienkiewicz and Zhu (1992):
  the strain is sampled at the Gauss points of each element (2 x 2 for quadrangles, the
  Barlow points of Q9, 4 collapsed points for triangles), and each node's value is the
  least-squares plane ``a + b x + c y`` through the samples of the elements that share the
  node (``x, y`` in the node's tangent plane), at the node. Exact for a strain field linear
  over the patch (any affine displacement, any rigid motion); for a quadratic strain ``E''``
  it errs by at most about ``E'' h^2`` (h: the patch's size);
  On white nodal noise the patch values are 1.3 (Q4, T6) to 2 (Q9) times less noisy than
  the nodal average's (T3, constant strain per element: the same inside, a little noisier
  at the boundary, where the plane extrapolates);
- ``"nodal"``: each element's strain at its nodes, averaged over the elements that share
  a node (exact for the FE field's own strain at the nodes, noisier).
"""
from __future__ import annotations

import numpy as np

from fesdic_core.fe.elements import gauss_rule
from fesdic_core.fe.mesh import SurfaceMesh

__all__ = ["tangent_frame", "surface_green_lagrange", "RECOVERIES"]

#: the recoveries of nodal strain (module docstring)
RECOVERIES = ("patch", "nodal")
_PATCH_GAUSS = 2         # Gauss points per direction of the patch recovery's samples

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


def _element_strain(dN: np.ndarray, Xe: np.ndarray, Ue: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Strain ``(E_xx, E_yy, E_xy)`` (ne, m, 3) and area element ``|X,xi x X,eta|`` (ne, m)
    at the m points whose shape derivatives are ``dN`` (m, nn, 2), in elements with nodes
    ``Xe`` and displacements ``Ue`` (ne, nn, 3)."""
    T = np.einsum("mia,eik->emka", dN, Xe)                               # (ne, m, 3, 2)
    dU = np.einsum("mia,eik->emka", dN, Ue)                              # U,xi
    normal = np.cross(T[..., 0], T[..., 1])
    area = np.linalg.norm(normal, axis=-1)
    normal /= area[..., None]
    E = tangent_frame(normal)                                            # (ne, m, 3, 2)
    metric = np.swapaxes(T, -1, -2) @ T                                  # T^T T
    G = dU @ np.linalg.solve(metric, np.swapaxes(T, -1, -2) @ E)         # (ne, m, 3, 2)
    EtG = np.swapaxes(E, -1, -2) @ G
    strain = 0.5 * (EtG + np.swapaxes(EtG, -1, -2) + np.swapaxes(G, -1, -2) @ G)
    return np.stack([strain[..., 0, 0], strain[..., 1, 1], strain[..., 0, 1]], axis=-1), area


def surface_green_lagrange(mesh: SurfaceMesh, U: np.ndarray, recovery: str = "patch"
                           ) -> np.ndarray:
    """Nodal surface Green-Lagrange strain ``(E_xx, E_yy, E_xy)`` (n, 3) of ``U`` (n, 3)
    on the reference surface ``mesh`` (local tangent frame; ``recovery`` "patch" or
    "nodal", see the module docstring)."""
    if recovery not in RECOVERIES:
        raise ValueError(f"recovery must be one of {RECOVERIES}, got {recovery!r}")
    U = np.asarray(U, float).reshape(mesh.n_nodes, 3)
    if recovery == "patch":
        return _patch_recovery(mesh, U)
    total = np.zeros((mesh.n_nodes, 3))
    count = np.zeros(mesh.n_nodes)
    for block in mesh.blocks:
        dN = block.family.shape_derivatives(block.family.ref_nodes)        # (nn, nn, 2)
        values, _ = _element_strain(dN, mesh.nodes[block.connectivity], U[block.connectivity])
        np.add.at(total, block.connectivity.ravel(), values.reshape(-1, 3))
        count += np.bincount(block.connectivity.ravel(), minlength=mesh.n_nodes)
    return total / np.maximum(count, 1)[:, None]


def _node_normals(mesh: SurfaceMesh) -> np.ndarray:
    """(n, 3) unit normals at the nodes: the sum of the elements' normals there."""
    total = np.zeros((mesh.n_nodes, 3))
    for block in mesh.blocks:
        dN = block.family.shape_derivatives(block.family.ref_nodes)
        T = np.einsum("mia,eik->emka", dN, mesh.nodes[block.connectivity])
        normal = np.cross(T[..., 0], T[..., 1])
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        for k in range(3):
            total[:, k] += np.bincount(block.connectivity.ravel(), weights=normal[..., k].ravel(),
                                       minlength=mesh.n_nodes)
    return total / np.linalg.norm(total, axis=-1, keepdims=True)


def _patch_recovery(mesh: SurfaceMesh, U: np.ndarray) -> np.ndarray:
    """The superconvergent patch recovery (module docstring): per node the normal equations
    of the plane ``a + b x + c y`` through its patch's Gauss-point strains, summed over the
    (element, node, point) incidences, then one 3 x 3 solve per node."""
    frames = tangent_frame(_node_normals(mesh))                             # (n, 3, 2)
    AtA = np.zeros((mesh.n_nodes, 3, 3))
    Atv = np.zeros((mesh.n_nodes, 3, 3))
    for block in mesh.blocks:
        family, conn = block.family, block.connectivity
        xi, _ = gauss_rule(family, _PATCH_GAUSS)
        values, _ = _element_strain(family.shape_derivatives(xi), mesh.nodes[conn], U[conn])
        points = np.einsum("mi,eik->emk", family.shape_functions(xi), mesh.nodes[conn])
        offset = points[:, None, :, :] - mesh.nodes[conn][:, :, None, :]    # (ne, nn, m, 3)
        xy = np.einsum("eimk,eika->eima", offset, frames[conn])             # tangent coords
        rows = np.concatenate([np.ones(xy.shape[:-1] + (1,)), xy], axis=-1)  # [1 x y]
        outer = np.einsum("eima,eimb->eiab", rows, rows)                     # (ne, nn, 3, 3)
        moment = np.einsum("eima,emk->eiak", rows, values)                  # (ne, nn, 3, 3)
        nodes = conn.ravel()
        for a in range(3):
            for b in range(3):
                AtA[:, a, b] += np.bincount(nodes, weights=outer[..., a, b].ravel(),
                                            minlength=mesh.n_nodes)
                Atv[:, a, b] += np.bincount(nodes, weights=moment[..., a, b].ravel(),
                                            minlength=mesh.n_nodes)
    return np.linalg.solve(AtA, Atv)[:, 0, :]                               # the plane at the node
