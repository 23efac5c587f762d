"""Surface finite-element mesh in 3D: geometry map, area element, nodal normals.

Geometry and shape correction share the Lagrange shape functions ``L_I`` (isoparametric
elements, Eq. 4): a point of the surface is ``X(xi) = sum_I L_I(xi) X_I``. The scalar
shape unknown ``q[I]`` moves node I along its unit nominal normal ``n_I`` (Remark 1,
the columns of the operator Z: ``X_I = X0_I + q[I] n_I``), computed by :func:`node_normals`.

Blocks group the elements of one family; every function is vectorised over the
elements of a block (the only Python loops run over the handful of blocks).
"""
from __future__ import annotations

import dataclasses
import logging

import numpy as np
import scipy.sparse as sps

from fesdic_core.errors import FesdicCoreError
from fesdic_core.fe.elements import FAMILIES, ElementFamily, centroid, gauss_rule

logger = logging.getLogger(__name__)

__all__ = [
    "CellBlock",
    "SurfaceMesh",
    "MeshError",
    "map_points",
    "tangents",
    "surface_jacobian",
    "element_areas",
    "nodal_areas",
    "node_normals",
    "validate_mesh",
    "rectangle_mesh",
    "edges",
    "boundary_edges",
    "boundary_nodes",
    "assemble",
]

#: relative area element below which an element is called degenerate
DEGENERATE_TOL = 1e-6


class MeshError(FesdicCoreError, ValueError):
    """A mesh or mesh file is unusable (unreadable, unsupported cells, degenerate, folded or
    inverted element)."""


@dataclasses.dataclass(frozen=True, eq=False)
class CellBlock:
    """Elements of one family.

    Attributes
    ----------
    family : the element family.
    connectivity : (ne, nn) int64 node indices, gmsh order.
    """

    family: ElementFamily
    connectivity: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.family, ElementFamily):
            raise ValueError(f"CellBlock.family must be an ElementFamily, got {self.family!r}")
        conn = np.asarray(self.connectivity)
        if conn.ndim != 2 or conn.shape[1] != self.family.n_nodes:
            raise ValueError(f"CellBlock.connectivity must have shape (ne, "
                             f"{self.family.n_nodes}) for {self.family.name}, got {conn.shape}")
        if conn.size and not np.issubdtype(conn.dtype, np.integer):
            raise ValueError(f"CellBlock.connectivity must hold integers, got {conn.dtype}")
        if conn.size and conn.min() < 0:
            raise ValueError(f"CellBlock.connectivity holds a negative node index {conn.min()}")
        conn = np.array(conn, dtype=np.int64)
        conn.setflags(write=False)
        object.__setattr__(self, "connectivity", conn)

    @property
    def n_elements(self) -> int:
        return self.connectivity.shape[0]


@dataclasses.dataclass(frozen=True, eq=False)
class SurfaceMesh:
    """Surface mesh in 3D (mm).

    Attributes
    ----------
    nodes : (n, 3) float64 node coordinates.
    blocks : tuple of CellBlock.
    name : label used in messages and output files.
    """

    nodes: np.ndarray
    blocks: tuple[CellBlock, ...]
    name: str = "mesh"

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes)
        if nodes.ndim != 2 or nodes.shape[1] != 3:
            raise ValueError(f"SurfaceMesh '{self.name}': nodes must have shape (n, 3), "
                             f"got {nodes.shape}")
        if not (np.issubdtype(nodes.dtype, np.floating) or np.issubdtype(nodes.dtype, np.integer)):
            raise ValueError(f"SurfaceMesh '{self.name}': nodes must be real numbers, "
                             f"got {nodes.dtype}")
        nodes = np.array(nodes, dtype=np.float64)
        if not np.all(np.isfinite(nodes)):
            raise ValueError(f"SurfaceMesh '{self.name}': nodes hold non-finite coordinates")
        nodes.setflags(write=False)
        blocks = tuple(self.blocks)
        if not blocks:
            raise ValueError(f"SurfaceMesh '{self.name}': blocks is empty")
        for b, block in enumerate(blocks):
            if not isinstance(block, CellBlock):
                raise ValueError(f"SurfaceMesh '{self.name}': blocks[{b}] is not a CellBlock")
            if block.connectivity.size and block.connectivity.max() >= len(nodes):
                raise ValueError(f"SurfaceMesh '{self.name}': blocks[{b}].connectivity refers "
                                 f"to node {block.connectivity.max()} but there are "
                                 f"{len(nodes)} nodes")
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "blocks", blocks)

    @property
    def n_nodes(self) -> int:
        return self.nodes.shape[0]

    @property
    def n_elements(self) -> int:
        return sum(block.n_elements for block in self.blocks)

    def with_nodes(self, nodes: np.ndarray) -> SurfaceMesh:
        """The same topology on new node coordinates (n, 3)."""
        return dataclasses.replace(self, nodes=nodes)


def map_points(nodes: np.ndarray, block: CellBlock, xi: np.ndarray) -> np.ndarray:
    """Isoparametric map ``X(xi) = sum_I L_I(xi) X_I`` (the interpolation of Eq. 4).

    nodes (n, 3), xi (m, 2) -> (ne, m, 3).
    """
    N = block.family.shape_functions(xi)                       # (m, nn)
    return np.einsum("mi,eik->emk", N, np.asarray(nodes)[block.connectivity])   # Eq. 4


def tangents(nodes: np.ndarray, block: CellBlock, xi: np.ndarray) -> np.ndarray:
    """Tangent vectors ``(dX/dxi, dX/deta)``; nodes (n, 3), xi (m, 2) -> (ne, m, 3, 2)."""
    dN = block.family.shape_derivatives(xi)                    # (m, nn, 2)
    return np.einsum("mia,eik->emka", dN, np.asarray(nodes)[block.connectivity])


def surface_jacobian(nodes: np.ndarray, block: CellBlock,
                     xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Area element and unit normal at parametric points.

    Returns
    -------
    area_element : (ne, m) ``|X_xi x X_eta|`` (mm^2 per unit reference area).
    normal : (ne, m, 3) unit normal ``X_xi x X_eta / |X_xi x X_eta|`` (zero where the
        area element vanishes).
    """
    t = tangents(nodes, block, xi)
    cross = np.cross(t[..., 0], t[..., 1])                     # (ne, m, 3)
    area_element = np.linalg.norm(cross, axis=-1)
    safe = np.where(area_element > 0.0, area_element, 1.0)
    normal = np.where(area_element[..., None] > 0.0, cross / safe[..., None], 0.0)
    return area_element, normal


def _block_areas(nodes: np.ndarray, block: CellBlock) -> np.ndarray:
    # degree + 2 points per direction: exact for flat degree-2 geometry, and the error
    # on curved elements is far below the discretisation error of the geometry itself
    xi, w = gauss_rule(block.family, block.family.degree + 2)
    area_element, _ = surface_jacobian(nodes, block, xi)
    return area_element @ w


def element_areas(mesh: SurfaceMesh) -> list[np.ndarray]:
    """Element areas (mm^2) by Gauss quadrature, one (ne,) array per block."""
    return [_block_areas(mesh.nodes, block) for block in mesh.blocks]


#: Share of its element's area that each node receives in :func:`nodal_areas`, gmsh order:
#: the element is cut into its linear sub-elements (a quadratic element into 4 T3 / Q4 of
#: equal parent area, through its mid-edge and centre nodes) and each sub-element shares its
#: area equally among its corners. T6: corners 1/12, mid-edges 3 x 1/12 = 1/4; Q9: corners
#: 1/16, mid-edges 2/16, centre 4/16. All shares are positive and sum to 1.
LINEAR_SUBELEMENT_SHARES = {
    "T3": np.full(3, 1.0 / 3.0),
    "Q4": np.full(4, 1.0 / 4.0),
    "T6": np.r_[np.full(3, 1.0 / 12.0), np.full(3, 1.0 / 4.0)],
    "Q9": np.r_[np.full(4, 1.0 / 16.0), np.full(4, 2.0 / 16.0), 4.0 / 16.0],
}


def nodal_areas(mesh: SurfaceMesh) -> np.ndarray:
    """Positive lumped nodal areas (n,) mm^2: element areas shared by linear sub-elements.

    The consistent lumping ``sum_e int L_I dA`` is not positive for every family: a T6
    corner shape function integrates to 0 over its triangle (its pixel Riemann sum is
    slightly negative), so nodal weights that must be positive (the gauge's weighted least
    squares) use this rule instead: element ``e`` gives node I the share
    :data:`LINEAR_SUBELEMENT_SHARES` of its area (Gauss-integrated). The shares sum to the
    element area, so the nodal areas sum to the mesh area; nodes of no element get 0.
    """
    total = np.zeros(mesh.n_nodes)
    for block, areas in zip(mesh.blocks, element_areas(mesh)):
        shares = LINEAR_SUBELEMENT_SHARES[block.family.name]
        total += np.bincount(block.connectivity.ravel(),
                             weights=(areas[:, None] * shares[None, :]).ravel(),
                             minlength=mesh.n_nodes)
    return total


def _nodal_contributions(mesh: SurfaceMesh) -> list[np.ndarray]:
    """Per block, area-weighted element normals at the element's own nodes, (ne, nn, 3)."""
    out = []
    for block in mesh.blocks:
        _, normal = surface_jacobian(mesh.nodes, block, block.family.ref_nodes)
        out.append(normal * _block_areas(mesh.nodes, block)[:, None, None])
    return out


def _accumulate(mesh: SurfaceMesh, contributions: list[np.ndarray]) -> np.ndarray:
    total = np.zeros((mesh.n_nodes, 3))
    for block, c in zip(mesh.blocks, contributions):
        for k in range(3):
            total[:, k] += np.bincount(block.connectivity.ravel(), weights=c[..., k].ravel(),
                                       minlength=mesh.n_nodes)
    return total


def _normalise(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, norm, out=np.zeros_like(v), where=norm > 0.0)


def node_normals(mesh: SurfaceMesh) -> np.ndarray:
    """Unit nominal normals ``n_I`` at the nodes (Remark 1: the operator Z), (n, 3).

    The area-weighted mean, over the elements sharing node I, of the element normal
    evaluated at node I's own parametric position. Nodes used by no element get zero.
    """
    return _normalise(_accumulate(mesh, _nodal_contributions(mesh)))


def _element_size(nodes: np.ndarray, block: CellBlock) -> np.ndarray:
    """Diagonal of each element's bounding box (mm), (ne,)."""
    x = nodes[block.connectivity]
    return np.linalg.norm(x.max(axis=1) - x.min(axis=1), axis=-1)


def _error(name: str, b: int, block: CellBlock, bad: np.ndarray,
           what: tuple[str, str]) -> MeshError:
    """what: (singular, plural) predicate."""
    shown = ", ".join(str(e) for e in bad[:10]) + (", ..." if len(bad) > 10 else "")
    plural = len(bad) > 1
    return MeshError(f"mesh '{name}': block {b} ({block.family.name}) element"
                     f"{'s' if plural else ''} {shown} {what[plural]}")


def validate_mesh(mesh: SurfaceMesh, name: str | None = None) -> None:
    """Raise MeshError naming the block and element index of the first bad elements.

    Checks, per element: repeated node index; area element ~0 (relative to the squared
    element size) at a node or at the centroid; folded element (normal at a node against
    the normal at the centroid); inverted element (normal at the centroid against the mean
    node normal of its nodes computed from the *other* elements only).
    """
    name = mesh.name if name is None else name
    contributions = _nodal_contributions(mesh)
    total = _accumulate(mesh, contributions)
    for b, block in enumerate(mesh.blocks):
        family, conn = block.family, block.connectivity
        ordered = np.sort(conn, axis=1)
        repeated = np.flatnonzero(np.any(ordered[:, 1:] == ordered[:, :-1], axis=1))
        if len(repeated):
            raise _error(name, b, block, repeated, ("repeats a node index", "repeat a node index"))
        points = np.vstack([family.ref_nodes, centroid(family)[None]])
        area_element, normal = surface_jacobian(mesh.nodes, block, points)
        size = _element_size(mesh.nodes, block)
        degenerate = np.flatnonzero(
            np.any(area_element <= DEGENERATE_TOL * size[:, None] ** 2, axis=1))
        if len(degenerate):
            raise _error(name, b, block, degenerate,
                         ("is degenerate (zero area element)",
                          "are degenerate (zero area element)"))
        centre_normal = normal[:, -1]                                    # (ne, 3)
        folded = np.flatnonzero(
            np.any(np.einsum("emk,ek->em", normal[:, :-1], centre_normal) <= 0.0, axis=1))
        if len(folded):
            raise _error(name, b, block, folded,
                         ("is folded (normal flips inside it)",
                          "are folded (normal flips inside them)"))
        others = _normalise(total[conn] - contributions[b])              # (ne, nn, 3)
        neighbour_normal = others.sum(axis=1)
        has_neighbours = np.linalg.norm(neighbour_normal, axis=-1) > 1e-12
        score = np.einsum("ek,ek->e", centre_normal, neighbour_normal)
        inverted = np.flatnonzero(has_neighbours & (score < 0.0))
        if len(inverted):
            inverted = inverted[np.argsort(score[inverted])]            # worst first
            raise _error(name, b, block, inverted,
                         ("is inverted (normal against those of its neighbours)",
                          "are inverted (normal against those of their neighbours)"))
    logger.debug("mesh '%s' valid: %d nodes, %d elements", name, mesh.n_nodes, mesh.n_elements)


def rectangle_mesh(length_mm: float, width_mm: float, nx: int, ny: int, family: str = "Q4",
                   center: tuple[float, float] = (0.0, 0.0)) -> SurfaceMesh:
    """Structured mesh of a rectangle in the z = 0 plane, normals +z, x along the length.

    ``nx * ny`` quadrangles (Q4, Q9), or twice as many triangles (T3, T6: each quadrangle
    cut along its diagonal from corner 1 to corner 3).
    """
    if family not in FAMILIES:
        raise ValueError(f"rectangle_mesh: unknown family {family!r}; choose from "
                         f"{sorted(FAMILIES)}")
    if nx < 1 or ny < 1:
        raise ValueError(f"rectangle_mesh: nx and ny must be >= 1, got nx={nx}, ny={ny}")
    if not (length_mm > 0 and width_mm > 0):
        raise ValueError(f"rectangle_mesh: length_mm and width_mm must be > 0, got "
                         f"{length_mm}, {width_mm}")
    fam = FAMILIES[family]
    p = fam.degree
    npx, npy = p * nx + 1, p * ny + 1
    x = center[0] + np.linspace(-0.5 * length_mm, 0.5 * length_mm, npx)
    y = center[1] + np.linspace(-0.5 * width_mm, 0.5 * width_mm, npy)
    X, Y = np.meshgrid(x, y, indexing="xy")                 # node (i, j) -> j * npx + i
    nodes = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    i0, j0 = (g.ravel() for g in np.meshgrid(p * np.arange(nx), p * np.arange(ny), indexing="xy"))

    def node(di, dj):
        return (j0 + dj) * npx + (i0 + di)

    # local quadrangle nodes at integer offsets (ref_nodes + 1) * p / 2, gmsh order
    quad = FAMILIES["Q9" if p == 2 else "Q4"]
    offsets = np.rint((quad.ref_nodes + 1.0) * p / 2).astype(int)
    q = np.column_stack([node(di, dj) for di, dj in offsets])
    if fam.reference == "quad":
        conn = q
    elif p == 1:
        conn = np.vstack([q[:, [0, 1, 3]], q[:, [2, 3, 1]]])
    else:   # corners, then mid-edges 0-1, 1-2, 2-0; the Q9 centre is mid-diagonal
        conn = np.vstack([q[:, [0, 1, 3, 4, 8, 7]], q[:, [2, 3, 1, 6, 8, 5]]])
    return SurfaceMesh(nodes, (CellBlock(fam, conn),), name=f"rectangle_{family}")


def _edge_keys(mesh: SurfaceMesh) -> np.ndarray:
    """Sorted corner nodes of every element edge, block after block, (sum ne * n_edges, 2)."""
    return np.vstack([np.sort(block.connectivity[:, block.family.edges[:, :2]].reshape(-1, 2),
                              axis=1) for block in mesh.blocks])


def edges(mesh: SurfaceMesh) -> tuple[np.ndarray, np.ndarray]:
    """Unique element edges by their corner nodes.

    Returns
    -------
    corners : (n_edges, 2) sorted corner node indices of each edge.
    count : (n_edges,) number of elements sharing the edge (1 on the boundary).
    """
    corners, count = np.unique(_edge_keys(mesh), axis=0, return_counts=True)
    return corners, count


def boundary_edges(mesh: SurfaceMesh) -> list[np.ndarray]:
    """The edges of one element only, per block that has some: (k, degree + 1) node indices
    of each, first corner, second corner, then the mid-edge node (degree 2)."""
    _, inverse, count = np.unique(_edge_keys(mesh), axis=0, return_inverse=True,
                                  return_counts=True)
    on_boundary = count[inverse.ravel()] == 1
    edge_nodes = [block.connectivity[:, block.family.edges].reshape(-1, block.family.degree + 1)
                  for block in mesh.blocks]
    sizes = np.cumsum([len(e) for e in edge_nodes])[:-1]
    found = [e[flags] for e, flags in zip(edge_nodes, np.split(on_boundary, sizes))]
    return [e for e in found if e.size]


def boundary_nodes(mesh: SurfaceMesh) -> np.ndarray:
    """Sorted indices of the nodes on boundary edges (corners and mid-edge nodes)."""
    found = boundary_edges(mesh)
    return np.unique(np.concatenate([e.ravel() for e in found])) if found else \
        np.empty(0, dtype=int)


def assemble(connectivities, element_matrices, n_nodes: int) -> sps.csr_matrix:
    """Global sparse matrix (n, n) from element matrices: the finite-element scatter-add.

    ``connectivities`` and ``element_matrices`` are matching lists of (ne, nn) node indices
    and (ne, nn, nn) matrices (one pair per block or group); duplicates are summed.
    """
    rows, cols, values = [], [], []
    for conn, Ke in zip(connectivities, element_matrices):
        nn = conn.shape[1]
        rows.append(np.repeat(conn, nn, axis=1).ravel())
        cols.append(np.tile(conn, (1, nn)).ravel())
        values.append(np.asarray(Ke).ravel())
    return sps.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n_nodes, n_nodes))
