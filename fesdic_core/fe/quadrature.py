"""Pixel quadrature: about one integration point per image pixel and element.

The integrals of Eqs. 2 and 8 are Riemann sums (section 2.2): each element is split
into sub-cells of about one pixel in its parent domain (sizes projected in the larger
of the two views, times ``points_per_px``); one point sits at the centre of each
sub-cell and weighs the sub-cell's area on the nominal surface (mm^2).
"""
from __future__ import annotations

import functools
import logging
from dataclasses import dataclass
from functools import cached_property
from typing import Sequence

import numpy as np
import scipy.sparse as sps

from fesdic_core.fe.mesh import SurfaceMesh

logger = logging.getLogger(__name__)

__all__ = ["ElementGroup", "PixelQuadrature", "subdivisions", "pixel_quadrature"]

# corners of each reference shape in the gmsh numbering (first nodes)
_N_CORNERS = {"quad": 4, "triangle": 3}


@dataclass(frozen=True, eq=False)
class ElementGroup:
    """Elements of one family cut into the same sub-cell grid.

    Their points are contiguous in the quadrature, element after element: points
    ``start + e * m + k`` (``k < m``) belong to ``elements[e]`` and sit at the parent
    coordinates ``xi[k]``, where the shape functions are ``N[k]`` (the same for every
    element of the group). Operators built element by element (Eq. 8) use this layout.

    Attributes
    ----------
    start : first point of the group
    elements : (E,) global element indices
    connectivity : (E, nn) node indices of those elements
    N : (m, nn) shape functions at the sub-cell centres
    """

    start: int
    elements: np.ndarray
    connectivity: np.ndarray
    N: np.ndarray

    @property
    def points_per_element(self) -> int:
        return self.N.shape[0]

    @property
    def span(self) -> slice:
        """The group's points in the quadrature arrays."""
        return slice(self.start, self.start + len(self.elements) * self.N.shape[0])


@dataclass(frozen=True, eq=False)
class PixelQuadrature:
    """Integration points of one image scale.

    Attributes
    ----------
    element : (g,) int
        Global element index (blocks concatenated) of each point.
    xi : (g, 2) float
        Parent coordinates.
    weight_mm2 : (g,) float
        Area of the point's sub-cell on the nominal surface.
    groups : tuple of ElementGroup
        The points, element by element (see :class:`ElementGroup`).
    n_elements, n_nodes : int
        Number of elements and of nodes of the mesh.
    """

    element: np.ndarray
    xi: np.ndarray
    weight_mm2: np.ndarray
    groups: tuple
    n_elements: int
    n_nodes: int

    @property
    def n_points(self) -> int:
        return self.element.size

    def points(self, nodes: np.ndarray) -> np.ndarray:
        """Physical positions ``X_g = sum_I L_I(xi_g) X_I`` (Eq. 4) for node values (n, k)."""
        nodes = np.asarray(nodes, dtype=np.float64)
        out = np.empty((self.n_points,) + nodes.shape[1:])
        for group in self.groups:
            local = nodes[group.connectivity]                              # (E, nn[, k])
            X = group.N @ local if local.ndim == 3 else local @ group.N.T  # (E, m[, k]), Eq. 4
            out[group.span] = X.reshape((-1,) + nodes.shape[1:])
        return out

    def to_nodes(self, values: np.ndarray) -> np.ndarray:
        """``L^T v`` (n_nodes,): point values gathered to the nodes, ``sum_g L_I(xi_g) v_g``."""
        out = np.zeros(self.n_nodes)
        for group in self.groups:
            local = np.asarray(values)[group.span].reshape(len(group.elements), -1) @ group.N
            out += np.bincount(group.connectivity.ravel(), weights=local.ravel(),
                               minlength=self.n_nodes)
        return out

    def element_sum(self, values: np.ndarray) -> np.ndarray:
        """(n_elements,) sums of point values ``values`` (g,) over each element."""
        out = np.zeros(self.n_elements)
        starts, order = self.element_runs
        out[order] = np.add.reduceat(values, starts)        # each element's points are a run
        return out

    @cached_property
    def element_runs(self) -> tuple[np.ndarray, np.ndarray]:
        """First point of each element's run of points (the points of an element are
        contiguous), and the element of each run."""
        starts = [g.start + g.points_per_element * np.arange(len(g.elements)) for g in self.groups]
        return np.concatenate(starts), np.concatenate([g.elements for g in self.groups])

    @cached_property
    def _blocks(self) -> dict:
        return {}

    def element_blocks(self, size: int) -> tuple[tuple[slice, slice], ...]:
        """Blocks of about ``size`` points made of whole elements: (points, runs) slices.

        ``runs`` indexes the element runs (:attr:`element_runs`): the elements whose points
        are exactly the block's, so per-element sums can be taken block by block.
        """
        if size not in self._blocks:
            self._blocks[size] = self._cut_blocks(size)
        return self._blocks[size]

    def _cut_blocks(self, size: int) -> tuple[tuple[slice, slice], ...]:
        starts, _ = self.element_runs
        cuts = np.unique(np.searchsorted(starts, np.arange(0, self.n_points, size)))
        edges = np.append(cuts, len(starts))
        bounds = np.append(starts, self.n_points)
        return tuple((slice(int(bounds[a]), int(bounds[b])), slice(int(a), int(b)))
                     for a, b in zip(edges[:-1], edges[1:]) if b > a)

    @cached_property
    def L(self) -> sps.csr_matrix:
        """The shape functions of every point, csr (g, n_nodes) (``L^T`` of Eq. 4)."""
        rows, cols, vals = [], [], []
        for group in self.groups:
            E, (m, nn) = len(group.elements), group.N.shape
            rows.append(np.repeat(np.arange(group.start, group.start + E * m), nn))
            cols.append(np.repeat(group.connectivity, m, axis=0).ravel())
            vals.append(np.broadcast_to(group.N, (E, m, nn)).ravel())
        return sps.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                              shape=(self.n_points, self.n_nodes))


def _subcell_centres(reference: str, n: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Centres and parent areas of the sub-cells of a reference element.

    Quads are split ``n[0] x n[1]`` along (xi, eta); triangles into ``n[0]**2`` equal
    sub-triangles (``n[1]`` unused).
    """
    if reference == "quad":
        c0 = -1.0 + (2.0 * np.arange(n[0]) + 1.0) / n[0]
        c1 = -1.0 + (2.0 * np.arange(n[1]) + 1.0) / n[1]
        xi = np.stack(np.meshgrid(c0, c1, indexing="ij"), -1).reshape(-1, 2)
        return xi, np.full(len(xi), 4.0 / (n[0] * n[1]))
    m = n[0]
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    up = (i + j) <= m - 1
    down = (i + j) <= m - 2
    xi = np.concatenate([np.stack([i[up] + 1 / 3, j[up] + 1 / 3], -1),
                         np.stack([i[down] + 2 / 3, j[down] + 2 / 3], -1)]) / m
    return xi, np.full(len(xi), 0.5 / m ** 2)


def subdivisions(nodes: np.ndarray, connectivity: np.ndarray, reference: str, cameras: Sequence,
                 points_per_px: float = 1.0, max_subdivision: int = 2000) -> np.ndarray:
    """Sub-cell counts (ne, 2) giving about ``points_per_px**2`` points per pixel.

    Quads: along each parent direction, the longer projected opposite edge (px), over the
    cameras. Triangles: ``n`` with ``n**2`` sub-triangles of about one pixel each,
    ``n = sqrt(projected area)``.
    """
    n_corners = _N_CORNERS[reference]
    corners = connectivity[:, :n_corners]
    size = np.zeros((len(connectivity), 2))
    for cam in cameras:
        x = cam.project(nodes[corners.ravel()]).reshape(len(corners), n_corners, 2)
        if reference == "quad":
            edge = np.linalg.norm(x - np.roll(x, -1, axis=1), axis=-1)     # edges 01, 12, 23, 30
            along = np.stack([np.maximum(edge[:, 0], edge[:, 2]), np.maximum(edge[:, 1], edge[:, 3])], -1)
        else:
            e1, e2 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
            area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
            along = np.repeat(np.sqrt(area)[:, None], 2, axis=1)
        size = np.maximum(size, along)
    return np.clip(np.ceil(size * points_per_px).astype(int), 1, max_subdivision)


@functools.lru_cache(maxsize=4096)
def _reference_rule(family, n0: int, n1: int) -> tuple:
    """Sub-cell centres, parent areas, shape functions (m, nn) and derivatives (m, nn, 2).

    The same few subdivisions recur for every scale and every run on a mesh: cached.
    """
    xi, parent_area = _subcell_centres(family.reference, (n0, n1))
    out = (xi, parent_area, family.shape_functions(xi), family.shape_derivatives(xi))
    for a in out:
        a.flags.writeable = False
    return out


def pixel_quadrature(mesh: SurfaceMesh, cameras: Sequence, points_per_px: float = 1.0,
                     nodes: np.ndarray | None = None, max_subdivision: int = 2000) -> PixelQuadrature:
    """Build the Riemann-sum quadrature of ``mesh`` for the given (scaled) cameras.

    Parameters
    ----------
    mesh : SurfaceMesh
        Nominal mesh; weights are areas on it.
    cameras : sequence of Camera
        Cameras of the current image scale (sizes are taken in their pixels).
    points_per_px : float
        Points per pixel along each direction (1 gives about one point per pixel).
    nodes : (n, 3) array, optional
        Current node positions used to size the elements (default: nominal).
    """
    nodes_now = mesh.nodes if nodes is None else nodes
    elements, xis, weights, groups = [], [], [], []
    offset, start = 0, 0
    for block in mesh.blocks:
        family, conn = block.family, block.connectivity
        n_sub = subdivisions(nodes_now, conn, family.reference, cameras, points_per_px,
                             max_subdivision)
        for n in np.unique(n_sub, axis=0):
            members = np.flatnonzero(np.all(n_sub == n, axis=1))
            xi, parent_area, N, dN = _reference_rule(family, int(n[0]), int(n[1]))
            m = len(xi)
            Xe = mesh.nodes[conn[members]]                                   # (e, nn, 3)
            J = dN.transpose(0, 2, 1).reshape(2 * m, -1) @ Xe                # (e, 2m, 3)
            a, b = J[:, 0::2], J[:, 1::2]                                    # X,xi and X,eta
            dA = np.sqrt((a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]) ** 2  # |X,xi x X,eta|
                         + (a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]) ** 2
                         + (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]) ** 2)
            elements.append(np.repeat(members + offset, m))
            xis.append(np.tile(xi, (len(members), 1)))
            weights.append((dA * parent_area).ravel())
            groups.append(ElementGroup(start=start, elements=members + offset,
                                       connectivity=conn[members], N=N))
            start += len(members) * m
        offset += len(conn)
    quad = PixelQuadrature(element=np.concatenate(elements), xi=np.concatenate(xis),
                           weight_mm2=np.concatenate(weights), groups=tuple(groups),
                           n_elements=offset, n_nodes=mesh.nodes.shape[0])
    logger.debug("pixel quadrature: %d points on %d elements in %d groups", quad.n_points, offset,
                 len(groups))
    return quad
