"""Lagrange element families T3, T6, Q4, Q9 in gmsh node numbering.

The FE approximation of the paper (Eq. 4, isoparametric: the same ``L_I`` describe the
geometry ``X(xi) = sum_I L_I(xi) X_I`` and the shape correction ``S = L^T q``) uses the
Lagrange shape functions of this module, evaluated on the reference element:

* quadrangles on ``[-1, 1]^2``: corners counter-clockwise from ``(-1, -1)``, then the
  mid-edge nodes of edges 0-1, 1-2, 2-3, 3-0, then the centre (gmsh types 3 and 10);
* triangles on the unit triangle ``(0, 0), (1, 0), (0, 1)``: corners, then the mid-edge
  nodes of edges 0-1, 1-2, 2-0 (gmsh types 2 and 9).

meshio and VTK use the same order for these four types.

The nodal basis is built from the monomial (modal) basis of the element's polynomial
space: with ``P(xi)`` the row of monomials and ``V[J, k] = p_k(xi_J)`` the Vandermonde
matrix at the nodes, ``L(xi) = P(xi) V^-1`` satisfies ``L_I(xi_J) = delta_IJ``.
"""
from __future__ import annotations

import dataclasses
import logging

import numpy as np

logger = logging.getLogger(__name__)

__all__ = [
    "ElementFamily",
    "FAMILIES",
    "family_from_meshio",
    "centroid",
    "gauss_rule",
]


def _exponents(reference: str, degree: int) -> np.ndarray:
    """Monomial exponents ``(a, b)`` of ``xi^a eta^b`` spanning the element space, (nn, 2)."""
    pairs = [(a, b) for b in range(degree + 1) for a in range(degree + 1)
             if reference == "quad" or a + b <= degree]
    return np.array(pairs, dtype=np.int64)


def _powers(t: np.ndarray, degree: int) -> np.ndarray:
    """``t**k`` for k = 0..degree, (m, degree + 1), by repeated products."""
    out = np.empty((len(t), degree + 1))
    out[:, 0] = 1.0
    for k in range(1, degree + 1):
        out[:, k] = out[:, k - 1] * t
    return out


def _monomials(xi: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """Monomials ``xi^a eta^b`` at the points, (m, nn)."""
    degree = int(exponents.max())
    px, py = _powers(xi[:, 0], degree), _powers(xi[:, 1], degree)
    return px[:, exponents[:, 0]] * py[:, exponents[:, 1]]


def _monomial_derivatives(xi: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """Derivatives d/dxi, d/deta of the monomials at the points, (m, 2, nn)."""
    degree = int(exponents.max())
    px, py = _powers(xi[:, 0], degree), _powers(xi[:, 1], degree)
    a, b = exponents[:, 0], exponents[:, 1]
    d_xi = a * px[:, np.maximum(a - 1, 0)] * py[:, b]
    d_eta = b * px[:, a] * py[:, np.maximum(b - 1, 0)]
    return np.stack([d_xi, d_eta], axis=1)


@dataclasses.dataclass(frozen=True, eq=False)
class ElementFamily:
    """A Lagrange element family on its reference element.

    Attributes
    ----------
    name : "T3", "T6", "Q4" or "Q9".
    gmsh_type : gmsh element type number.
    meshio_type : meshio cell type name.
    n_nodes : number of nodes per element, nn.
    reference : "triangle" (unit triangle) or "quad" ([-1, 1]^2).
    degree : polynomial degree (1 or 2).
    ref_nodes : (nn, 2) parametric coordinates of the nodes, gmsh order.
    edges : (n_edges, degree + 1) local node indices of each edge:
        first corner, second corner, then the mid-edge node (degree 2).
    """

    name: str
    gmsh_type: int
    meshio_type: str
    n_nodes: int
    reference: str
    degree: int
    ref_nodes: np.ndarray = dataclasses.field(repr=False)
    edges: np.ndarray = dataclasses.field(repr=False)
    _inverse_vandermonde: np.ndarray = dataclasses.field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        ref_nodes = np.array(self.ref_nodes, dtype=np.float64)
        if ref_nodes.shape != (self.n_nodes, 2):
            raise ValueError(f"ElementFamily {self.name}: ref_nodes has shape {ref_nodes.shape}, "
                             f"expected ({self.n_nodes}, 2)")
        if self.reference not in ("triangle", "quad"):
            raise ValueError(f"ElementFamily {self.name}: reference must be 'triangle' or "
                             f"'quad', got {self.reference!r}")
        exponents = _exponents(self.reference, self.degree)
        if len(exponents) != self.n_nodes:
            raise ValueError(f"ElementFamily {self.name}: {self.n_nodes} nodes do not match "
                             f"the {len(exponents)} monomials of degree {self.degree}")
        vandermonde = _monomials(ref_nodes, exponents)  # V[J, k] = p_k(xi_J)
        inverse = np.linalg.inv(vandermonde)
        ref_nodes.setflags(write=False)
        inverse.setflags(write=False)
        edges = np.array(self.edges, dtype=np.int64)
        edges.setflags(write=False)
        object.__setattr__(self, "ref_nodes", ref_nodes)
        object.__setattr__(self, "edges", edges)
        object.__setattr__(self, "_inverse_vandermonde", inverse)

    @property
    def exponents(self) -> np.ndarray:
        """Monomial exponents of the element's polynomial space, (nn, 2)."""
        return _exponents(self.reference, self.degree)

    def _points(self, xi: np.ndarray) -> np.ndarray:
        xi = np.asarray(xi, dtype=np.float64)
        if xi.ndim != 2 or xi.shape[1] != 2:
            raise ValueError(f"{self.name}: parametric points xi must have shape (m, 2), "
                             f"got {xi.shape}")
        return xi

    def shape_functions(self, xi: np.ndarray) -> np.ndarray:
        """Shape functions ``L_I(xi)`` at parametric points xi (m, 2) -> (m, nn)."""
        xi = self._points(xi)
        return _monomials(xi, self.exponents) @ self._inverse_vandermonde

    def shape_derivatives(self, xi: np.ndarray) -> np.ndarray:
        """Derivatives ``(dL_I/dxi, dL_I/deta)`` at xi (m, 2) -> (m, nn, 2)."""
        xi = self._points(xi)
        d_monomials = _monomial_derivatives(xi, self.exponents)  # (m, 2, nn)
        m, nn = len(xi), self.n_nodes
        dN = (d_monomials.reshape(2 * m, nn) @ self._inverse_vandermonde).reshape(m, 2, nn)
        return np.ascontiguousarray(dN.transpose(0, 2, 1))


_QUAD_CORNERS = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
_QUAD_MIDS = [(0.0, -1.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)]
_TRI_CORNERS = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)]
_TRI_MIDS = [(0.5, 0.0), (0.5, 0.5), (0.0, 0.5)]

FAMILIES: dict[str, ElementFamily] = {
    "T3": ElementFamily("T3", 2, "triangle", 3, "triangle", 1, np.array(_TRI_CORNERS),
                        np.array([[0, 1], [1, 2], [2, 0]])),
    "T6": ElementFamily("T6", 9, "triangle6", 6, "triangle", 2, np.array(_TRI_CORNERS + _TRI_MIDS),
                        np.array([[0, 1, 3], [1, 2, 4], [2, 0, 5]])),
    "Q4": ElementFamily("Q4", 3, "quad", 4, "quad", 1, np.array(_QUAD_CORNERS),
                        np.array([[0, 1], [1, 2], [2, 3], [3, 0]])),
    "Q9": ElementFamily("Q9", 10, "quad9", 9, "quad", 2,
                        np.array(_QUAD_CORNERS + _QUAD_MIDS + [(0.0, 0.0)]),
                        np.array([[0, 1, 4], [1, 2, 5], [2, 3, 6], [3, 0, 7]])),
}

_BY_MESHIO = {family.meshio_type: family for family in FAMILIES.values()}


def family_from_meshio(cell_type: str) -> ElementFamily:
    """The element family of a meshio cell type ("triangle", "triangle6", "quad", "quad9")."""
    try:
        return _BY_MESHIO[cell_type]
    except KeyError:
        raise ValueError(f"unsupported meshio cell type {cell_type!r}; supported: "
                         f"{sorted(_BY_MESHIO)}") from None


def centroid(family: ElementFamily) -> np.ndarray:
    """Parametric coordinates of the element centroid, (2,)."""
    if family.reference == "quad":
        return np.zeros(2)
    return np.full(2, 1.0 / 3.0)


def gauss_rule(family: ElementFamily, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss quadrature on the reference element.

    Quadrangles: the tensor product of ``n_points`` Gauss-Legendre points per direction
    (exact to degree 2 n_points - 1 in each variable). Triangles: the collapsed (Duffy)
    product of the same points, exact for polynomials of total degree 2 n_points - 2.

    Returns
    -------
    xi : (n_points**2, 2) parametric points.
    weights : (n_points**2,) weights; they sum to the reference area (4 or 1/2).
    """
    if n_points < 1:
        raise ValueError(f"gauss_rule: n_points must be >= 1, got {n_points}")
    t, w = np.polynomial.legendre.leggauss(n_points)
    a, b = (g.ravel() for g in np.meshgrid(t, t, indexing="ij"))
    wa, wb = np.meshgrid(w, w, indexing="ij")
    weights = (wa * wb).ravel()
    if family.reference == "quad":
        return np.column_stack([a, b]), weights
    u = 0.5 * (a + 1.0)                     # [0, 1]
    v = 0.5 * (b + 1.0)
    xi = np.column_stack([u, v * (1.0 - u)])  # Duffy collapse of the unit square
    return xi, weights * 0.25 * (1.0 - u)
