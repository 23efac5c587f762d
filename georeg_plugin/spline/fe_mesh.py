"""An analysis-suitable Lagrange FE mesh made from a spline patch, Eq. 17.

One element per non-empty knot span pair (the Bezier elements of the patch). The Q9
nodes are the Lagrange points of each Bezier element: its corners, edge midpoints and
centre in parameter space. The node positions are the spline evaluated there,
``x_FE = C_FE^T x_f`` (Eq. 17); for a NURBS patch this is Eq. 27's ``x_FE = x_LAG``
(the FE nodes are the rational Lagrange control points, which interpolate the surface).

The nodes shared by neighbouring elements are merged by construction: the nodes are the
points of one global parametric grid of ``(2 n_u + 1) x (2 n_v + 1)`` values (Q9) or
``(n_u + 1) x (n_v + 1)`` (Q4), numbered ``a * n_cols + b`` (``a`` along ``u``).
The local axes of every element are ``(xi, eta) = (u, v)``, so the FE normal
``x_xi x x_eta`` has the direction of the spline normal ``S_u x S_v``.

Exactness (Eq. 16: ``R^f = C_FE L``, the Lagrange elements reproduce every spline function)
needs the spline degree <= the element degree in each direction: <= 2 for Q9, <= 1 for Q4.
A higher degree is refused (:func:`check_element_degree`); such a spline can still
regularize a mesh through point inversion (``operators.node_parameters``), where the
spline is only interpolated at the nodes and Eq. 16 is not claimed.

A closed patch (``plate_with_hole``: ``u = 0`` and ``u = 1`` are the same line) gives
coincident nodes along that seam: they are welded (the node of smaller index is kept,
with its parameters), so the mesh is conforming; ``multilevel_space`` glues the
matching spline dofs of every level.
"""
from __future__ import annotations

import dataclasses
import logging

import numpy as np
from scipy.spatial import cKDTree

from georeg_plugin.errors import GeoregPluginError
from georeg_plugin.spline.patch import SplinePatch

logger = logging.getLogger(__name__)

__all__ = ["SplineFEMesh", "fe_mesh_from_spline", "check_element_degree", "ELEMENT_DEGREES",
           "ElementDegreeError"]

#: polynomial degree of the Lagrange element families a spline may be extracted to
ELEMENT_DEGREES = {"Q4": 1, "Q9": 2, "T3": 1, "T6": 2}


class ElementDegreeError(GeoregPluginError, ValueError):
    """The spline degree exceeds the element degree: Eq. 16 would not hold."""


def check_element_degree(degrees: tuple[int, int], family: str, what: str = "spline") -> None:
    """Raise :class:`ElementDegreeError` unless the spline degree <= the element degree.

    Eq. 16 (``R^f = C_FE L``: the FE mesh extracted from the spline reproduces it exactly)
    holds only if each spline function is a polynomial of the element's space on every
    element: ``max(degrees) <= ELEMENT_DEGREES[family]`` for quadrangles (tensor
    products), ``sum(degrees)`` (the total degree of ``u^p_u v^p_v``) for triangles.
    """
    if family not in ELEMENT_DEGREES:
        raise ValueError(f"family must be one of {sorted(ELEMENT_DEGREES)}, got {family!r}")
    element_degree = ELEMENT_DEGREES[family]
    spline_degrees = tuple(int(p) for p in degrees)
    triangle = family.startswith("T")
    needed = sum(spline_degrees) if triangle else max(spline_degrees)
    if needed > element_degree:
        kind = "total degree" if triangle else "degree"
        raise ElementDegreeError(
            f"{what}: degree {spline_degrees} is higher than the degree {element_degree} of {family} "
            f"elements: a {family} mesh cannot reproduce the spline (Eq. 16 needs spline "
            f"{kind} <= element degree, i.e. <= {element_degree} for {family}); use "
            f"{'Q9 elements or ' if family != 'Q9' else ''}a spline of lower degree, or a "
            "legacy mesh with point inversion (georeg_plugin.levels.operators.node_parameters), "
            "where the spline is only interpolated at the nodes")

#: family -> (meshio cell type, points per span, local (a, b) grid offsets, gmsh order)
_FAMILIES = {
    # corners counter-clockwise in (u, v), mid-edges of edges 0-1, 1-2, 2-3, 3-0, centre
    "Q9": ("quad9", 2, np.array([[0, 0], [2, 0], [2, 2], [0, 2],
                                 [1, 0], [2, 1], [1, 2], [0, 1], [1, 1]])),
    "Q4": ("quad", 1, np.array([[0, 0], [1, 0], [1, 1], [0, 1]])),
}


@dataclasses.dataclass(frozen=True, eq=False)
class SplineFEMesh:
    """A Lagrange FE mesh of a spline patch.

    Attributes
    ----------
    nodes : (n, 3) node coordinates, mm.
    connectivity : (ne, nn) node indices of each element, gmsh order.
    cell_type : meshio cell type, "quad9" or "quad".
    uv : (n, 2) parametric coordinates of each node on the patch.
    """

    nodes: np.ndarray
    connectivity: np.ndarray
    cell_type: str
    uv: np.ndarray

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, dtype=float)
        conn = np.asarray(self.connectivity, dtype=np.int64)
        uv = np.asarray(self.uv, dtype=float)
        if nodes.ndim != 2 or nodes.shape[1] != 3:
            raise ValueError(f"nodes must be (n, 3), got {nodes.shape}")
        if uv.shape != (nodes.shape[0], 2):
            raise ValueError(f"uv must be ({nodes.shape[0]}, 2), got {uv.shape}")
        if conn.ndim != 2 or (conn.size and (conn.min() < 0 or conn.max() >= len(nodes))):
            raise ValueError("connectivity must be (ne, nn) with indices in "
                             f"[0, {len(nodes) - 1}]")
        for name, value in (("nodes", nodes), ("connectivity", conn), ("uv", uv)):
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    @property
    def n_nodes(self) -> int:
        """Number of nodes, n."""
        return self.nodes.shape[0]

    @property
    def n_elements(self) -> int:
        """Number of elements, ne."""
        return self.connectivity.shape[0]

    def to_meshio(self):
        """The mesh as a ``meshio.Mesh`` (one cell block), with ``uv`` as point data."""
        import meshio

        return meshio.Mesh(self.nodes, [(self.cell_type, self.connectivity)],
                           point_data={"uv": self.uv})


def _parametric_grid(b: np.ndarray, per_span: int) -> np.ndarray:
    """Span ends ``b`` and ``per_span - 1`` equally spaced points inside each span."""
    t = np.arange(per_span) / per_span
    inner = (b[:-1, None] + t[None, :] * np.diff(b)[:, None]).ravel()
    return np.append(inner, b[-1])


def coincident_groups(points: np.ndarray, tol: float) -> np.ndarray:
    """Representative index (n,) of each point: the smallest index within ``tol`` of it."""
    representative = np.arange(len(points))
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    if pairs.size:
        pairs = np.sort(pairs, axis=1)
        order = np.argsort(pairs[:, 1])
        np.minimum.at(representative, pairs[order, 1], pairs[order, 0])
        representative = representative[representative]        # chains a-b-c -> a
    return representative


def fe_mesh_from_spline(patch: SplinePatch, family: str = "Q9", weld: bool = True,
                        exact: bool = True) -> SplineFEMesh:
    """FE mesh with one element per Bezier element of ``patch``, nodes on the spline.

    Parameters
    ----------
    patch : SplinePatch (usually refined by knot insertion to the FE resolution).
    family : "Q9" (nodes at the Lagrange points, Eq. 17) or "Q4" (span corners).
    exact : refuse a degree above the element degree (Eq. 16). ``False`` places the nodes on
        the surface at the same parametric positions all the same (e.g. a bicubic CAD
        face): the elements then interpolate the spline between the nodes, Eq. 16 holds
        only approximately (the operators only need ``R_J(xi_I)`` at the nodes).

    Returns
    -------
    SplineFEMesh with ``nodes = patch.evaluate(uv)`` (Eqs. 17, 27); with ``weld``,
    coincident nodes (the seam of a closed patch) are merged.

    Raises
    ------
    ElementDegreeError
        If a degree of ``patch`` exceeds the element degree (2 for Q9, 1 for Q4): the mesh
        would not reproduce the spline (Eq. 16).
    """
    if family not in _FAMILIES:
        raise ValueError(f"family must be one of {sorted(_FAMILIES)}, got {family!r}")
    if exact:
        check_element_degree(patch.degrees, family)
    cell_type, per_span, local = _FAMILIES[family]
    gu, gv = (_parametric_grid(b, per_span) for b in patch.breaks)  # non-empty spans
    n_cols = gv.size
    uu, vv = np.meshgrid(gu, gv, indexing="ij")
    uv = np.column_stack([uu.ravel(), vv.ravel()])  # node a * n_cols + b
    # element (e_u, e_v) starts at grid point (per_span e_u, per_span e_v)
    eu, ev = np.meshgrid(np.arange((gu.size - 1) // per_span) * per_span,
                         np.arange((gv.size - 1) // per_span) * per_span, indexing="ij")
    a = eu.ravel()[:, None] + local[None, :, 0]
    b = ev.ravel()[:, None] + local[None, :, 1]
    connectivity = a * n_cols + b
    nodes = patch.evaluate(uv)  # Eq. 17 / Eq. 27: x_FE = x_LAG
    if weld:
        size = float(np.ptp(nodes, axis=0).max()) or 1.0
        representative = coincident_groups(nodes, 1e-9 * size)
        kept = np.unique(representative)
        if kept.size < len(nodes):
            renumber = np.full(len(nodes), -1)
            renumber[kept] = np.arange(kept.size)
            connectivity = renumber[representative[connectivity]]
            nodes, uv = nodes[kept], uv[kept]
            logger.debug("welded %d coincident nodes", len(representative) - kept.size)
    logger.debug("%s mesh from spline: %d elements, %d nodes", family,
                 len(connectivity), len(nodes))
    return SplineFEMesh(nodes=nodes, connectivity=connectivity, cell_type=cell_type, uv=uv)
