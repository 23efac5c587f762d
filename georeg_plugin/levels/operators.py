"""The operators ``C_s`` from the FE nodal space to the spline levels, Eqs. 16, 26-28.

Node evaluation (Remark 6). Row ``I`` of ``C^T`` is the level's (rational) spline basis
evaluated at the parametric coordinates ``xi_I`` of FE node ``I``:

    C^T[I, J] = R_J(xi_I)                                   (Eq. 26 / 27, Remark 6)

* B-spline patch, FE mesh made from the spline (``fe_mesh_from_spline``): the Lagrange
  interpolant of ``R_J`` at the Q9 nodes is ``R_J`` itself (the spline space is contained
  in the C0 Q9 space), so ``R^f = C_FE L`` holds exactly (Eq. 16), ``C_FE = D_LAG``.
  The coarser levels: ``R^c = C_r R^f`` (Eq. 13) at the nodes gives
  ``C_{s+1}^T = C_s^T C_r^T``, i.e. node evaluation equals the product form of Eq. 28
  to round-off.
* NURBS patch: ``C^T[I, J] = w_J N_J(xi_I) / W(xi_I)`` is ``D^W_LAG`` of Eq. 26 read at
  the nodes, and ``R^f ~ D^W_LAG L`` is Eq. 27's approximation (exact at the nodes,
  converging with refinement of the last level).  ``C_r`` of NURBS knot insertion
  also satisfies ``R^c = C_r R^f`` exactly, so Eq. 28 still equals node evaluation.
* Both need the spline degree <= the element degree (Q9: 2, Q4: 1; ``multilevel_space``
  checks it when told the ``family`` of a mesh made from the spline).
* Legacy mesh (not made from the spline): the ``xi_I`` come from point inversion of
  the nodes on the nominal surface (``node_parameters``); the same formula applies, but
  Eq. 16 is not claimed: ``C^T q_s`` is the spline field at the nodes only, and the FE
  field interpolates it between them (any element family, any spline degree).
* Curved surface: the FE unknown of node ``I`` is a displacement along its normal
  ``n_I`` (Remark 1). ``multilevel_space`` / ``nested_space`` given the node normals use
  the vector formulation of :mod:`georeg_plugin.levels.curved` (control VECTORS seen along
  ``n_I``: nested levels, rigid motions in range). ``extraction_operator`` with normals
  still gives the first formula tried, ``C^T[I, J] = R_J(xi_I) (n_I . n_J)`` (a dof
  moving its control point along its own normal ``n_J``), kept for comparison only:
  it breaks the nesting (Eq. 13) on a cylinder.
"""
from __future__ import annotations

import dataclasses
import logging

from typing import Sequence

import numpy as np
import scipy.sparse as sps

from georeg_plugin.errors import GeoregPluginError
from georeg_plugin.levels.curved import vector_level
from georeg_plugin.spline.fe_mesh import check_element_degree, coincident_groups
from georeg_plugin.spline.patch import SplinePatch, invert_points
from georeg_plugin.spline.refine import refine_uniform

logger = logging.getLogger(__name__)

__all__ = ["extraction_operator", "node_parameters", "MultilevelSpace",
           "multilevel_space", "nested_space", "NodesOutsidePatchError"]


class NodesOutsidePatchError(GeoregPluginError, ValueError):
    """FE nodes lie outside the spline patch (beyond the tolerance)."""


def extraction_operator(patch: SplinePatch, uv: np.ndarray,
                        node_normals: np.ndarray | None = None) -> sps.csr_matrix:
    """``C`` (n_spline, n_fe) with ``C^T[I, J] = R_J(xi_I) [n_I . n_J]`` (Eqs. 26-27).

    Parameters
    ----------
    patch : the spline level (dof ``J = i * nv + j``).
    uv : (n_fe, 2) parametric coordinates of the FE nodes.
    node_normals : (n_fe, 3) unit normals of the FE nodes, optional; with them each
        entry is multiplied by ``n_I . n_J``, ``n_J = patch.control_normals()``.

    Returns
    -------
    C : csr (n_spline, n_fe), explicit zeros dropped.
    """
    uv = np.asarray(uv, dtype=float)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must be (n_fe, 2), got {uv.shape}")
    Ct = sps.coo_matrix(patch.basis(uv))  # Remark 6: R_J(xi_I), (n_fe, n_spline)
    data = Ct.data
    if node_normals is not None:
        n_fe = np.asarray(node_normals, dtype=float)
        if n_fe.shape != (uv.shape[0], 3):
            raise ValueError(f"node_normals must be ({uv.shape[0]}, 3), got {n_fe.shape}")
        n_spline = np.asarray(patch.control_normals(), dtype=float).reshape(-1, 3)
        data = data * np.einsum("kd,kd->k", n_fe[Ct.row], n_spline[Ct.col])  # n_I . n_J
    C = sps.csr_matrix((data, (Ct.col, Ct.row)), shape=(Ct.shape[1], Ct.shape[0]))
    C.eliminate_zeros()
    return C


def node_parameters(patch: SplinePatch, nodes: np.ndarray, warn_mm: float = 1e-3,
                    outside_mm: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Parametric coordinates of the nodes of a legacy mesh by point inversion.

    Parameters
    ----------
    patch : the nominal surface.
    nodes : (n, 3) node coordinates, mm.
    warn_mm : distance to the surface above which a warning is logged.
    outside_mm : tangential distance beyond the patch boundary above which
        ``NodesOutsidePatchError`` is raised.

    Returns
    -------
    uv : (n, 2) parameters of the closest surface points.
    distance : (n,) distances node - surface, mm.
    """
    nodes = np.asarray(nodes, dtype=float)
    if nodes.ndim != 2 or nodes.shape[1] != 3:
        raise ValueError(f"nodes must be (n, 3), got {nodes.shape}")
    uv, distance = invert_points(patch, nodes)
    uv, distance = np.asarray(uv, dtype=float), np.asarray(distance, dtype=float)
    # residual = normal part (off the surface) + tangential part (off the patch domain)
    residual = nodes - patch.evaluate(uv)
    normal = np.asarray(patch.normals(uv), dtype=float)
    tangential = np.linalg.norm(
        residual - np.einsum("kd,kd->k", residual, normal)[:, None] * normal, axis=1)
    outside = np.flatnonzero(tangential > outside_mm)
    if outside.size:
        worst = int(outside[np.argmax(tangential[outside])])
        raise NodesOutsidePatchError(
            f"{outside.size} of {len(nodes)} FE nodes lie outside the spline patch by "
            f"more than {outside_mm} mm; worst: node {worst} at {nodes[worst].tolist()}, "
            f"{tangential[worst]:.3g} mm beyond the boundary")
    far = np.flatnonzero(distance > warn_mm)
    if far.size:
        worst = int(far[np.argmax(distance[far])])
        logger.warning("%d of %d FE nodes are more than %g mm from the spline surface "
                       "(worst: node %d, %.3g mm)", far.size, len(nodes), warn_mm, worst,
                       distance[worst])
    return uv, distance


@dataclasses.dataclass(frozen=True, eq=False)
class MultilevelSpace:
    """The spline levels of the regularization and their operators (Eq. 28).

    Attributes
    ----------
    patches : tuple of SplinePatch, coarse -> fine (``patches[-1]`` is level 0).
    operators : tuple of csr ``C_s`` (n_spline_s, n_fe), ``s = 0`` the FINEST level
        (Eq. 28 numbering): ``operators[s]`` belongs to ``patches[-1 - s]``.
    refinement : tuple of csr ``C_r`` with ``refinement[s]`` (n_spline_{s+1},
        n_spline_s) mapping level ``s`` to the coarser level ``s + 1``:
        ``R^{s+1} = refinement[s] R^s`` (Eq. 13), ``C_{s+1} = refinement[s] C_s``
        (empty when dofs are glued).
    gluing : tuple of csr ``G_s`` (n_dofs_s, n_control_points_s), one per level (same
        numbering as ``operators``), or empty: the dofs of a closed patch glue its
        coincident control points (``C_s = G_s C_s^patch``); the values of the control
        points of level ``s`` are ``G_s^T q_s``.
    vector : tuple of :class:`~georeg_plugin.levels.curved.VectorLevel`, one per level (same
        numbering as ``operators``), or empty: a curved part's levels move their control
        points by vectors (``operators[s]`` is then a basis of the range, :func:`~georeg_plugin.levels.curved.range_basis`).
    """

    patches: tuple
    operators: tuple
    refinement: tuple = ()
    gluing: tuple = ()
    vector: tuple = ()

    def __post_init__(self) -> None:
        ops = tuple(sps.csr_matrix(C) for C in self.operators)
        if not ops:
            raise ValueError("operators: at least one level is needed")
        n_fe = {C.shape[1] for C in ops}
        if len(n_fe) != 1:
            raise ValueError(f"operators: all C_s must have the same number of FE "
                             f"nodes (columns), got {sorted(n_fe)}")
        if len(self.patches) != len(ops):
            raise ValueError(f"patches: {len(self.patches)} patches for {len(ops)} "
                             "operators")
        refinement = tuple(sps.csr_matrix(Cr) for Cr in self.refinement)
        if refinement:
            if len(refinement) != len(ops) - 1:
                raise ValueError(f"refinement: {len(ops) - 1} matrices C_r expected, "
                                 f"got {len(refinement)}")
            for s, Cr in enumerate(refinement):
                if Cr.shape != (ops[s + 1].shape[0], ops[s].shape[0]):
                    raise ValueError(f"refinement[{s}] has shape {Cr.shape}, expected "
                                     f"{(ops[s + 1].shape[0], ops[s].shape[0])}")
        object.__setattr__(self, "patches", tuple(self.patches))
        object.__setattr__(self, "operators", ops)
        object.__setattr__(self, "refinement", refinement)

    @property
    def n_levels(self) -> int:
        """Number of spline levels."""
        return len(self.operators)

    @property
    def n_fe(self) -> int:
        """Number of FE nodal unknowns (columns of every ``C_s``)."""
        return self.operators[0].shape[1]

    def patch(self, level: int) -> SplinePatch:
        """The spline patch of a level (``0`` = finest)."""
        return self.patches[-1 - level]

    def control_point_values(self, q_s: np.ndarray, level: int) -> np.ndarray:
        """Values (n_control_points,) of the level's control points from its dofs ``q_s``:
        the scalar dofs, or in the vector formulation the control vector along the
        control normal ``d_J . n_J``."""
        if self.vector:
            d = self.control_vectors(q_s, level)
            normals = np.vstack([p.control_normals() for p in self.level_patches(level)])
            return np.einsum("kd,kd->k", d, normals)
        return q_s if not self.gluing else self.gluing[level].T @ q_s

    def control_vectors(self, q_s: np.ndarray, level: int) -> np.ndarray:
        """Control point displacements (n_control_points, 3) of the level's dofs ``q_s``:
        the vector formulation's ``d``, else the scalar values along the control normals."""
        if self.vector:
            return self.vector[level].control_vectors(q_s)
        normals = self.patch(level).control_normals()
        return self.control_point_values(q_s, level)[:, None] * normals

    def level_patches(self, level: int) -> tuple:
        """The patches (faces) of a level (``0`` = finest): one unless the part has faces."""
        p = self.patch(level)
        return tuple(p) if isinstance(p, (tuple, list)) else (p,)


def gluing_matrix(patch: SplinePatch, tol: float = 1e-9) -> sps.csr_matrix:
    """``G`` (n_dofs, n_control_points) summing coincident control points into one dof.

    Coincident control points (same position and weight) are those of the seam of a closed
    patch; a dof moving them together keeps the surface continuous across the seam.
    """
    cp = patch.control_points.reshape(-1, 3)
    w = patch.weights.reshape(-1, 1) if patch.weights is not None else np.ones((len(cp), 1))
    size = float(np.ptp(cp, axis=0).max()) or 1.0
    representative = coincident_groups(np.hstack([cp, w * size]), tol * size)
    kept, dof = np.unique(representative, return_inverse=True)
    return sps.csr_matrix((np.ones(len(cp)), (dof, np.arange(len(cp)))), shape=(kept.size, len(cp)))


def multilevel_space(coarse_patch: SplinePatch, n_levels: int, nodes: np.ndarray,
                     node_normals: np.ndarray | None = None,
                     uv: np.ndarray | None = None, glue: bool = True,
                     family: str | None = None) -> MultilevelSpace:
    """Levels by dyadic refinement of ``coarse_patch``, operators by node evaluation.

    Parameters
    ----------
    coarse_patch : the coarsest spline (level ``n_levels - 1``).
    n_levels : number of levels; each finer one halves every knot span.
    nodes : (n_fe, 3) FE node coordinates, mm (used for point inversion if ``uv`` is None).
    node_normals : (n_fe, 3), optional: curved surfaces, the vector formulation of
        :mod:`georeg_plugin.levels.curved` (control vectors seen along the node normals).
    uv : (n_fe, 2) parameters of the nodes if known (mesh made from the spline).
    family : element family ("Q9", "Q4", ...) of a mesh made from the spline; the exact
        extraction (Eq. 16) it stands for needs every degree of ``coarse_patch`` <= the
        element degree, else :class:`~georeg_plugin.spline.fe_mesh.ElementDegreeError`. None: not
        checked (legacy mesh: the spline is only interpolated at the nodes).

    Returns
    -------
    MultilevelSpace. Without normals, ``C_s`` equals the product form of Eq. 28
    (``C_{s+1} = C_r C_s``) to round-off, for B-splines and NURBS alike; with normals
    the ranges of the ``C_s^T`` are nested (``C_s`` is then dense). With ``glue``,
    coincident control points (the seam of a closed patch) share one dof per level; the
    glued levels stay nested (boundary dofs refine one to one).
    """
    if int(n_levels) < 1:
        raise ValueError(f"n_levels must be >= 1, got {n_levels}")
    if family is not None:
        check_element_degree(coarse_patch.degrees, family, "multilevel_space: coarse_patch")
    patches, refinements = [coarse_patch], []
    for _ in range(int(n_levels) - 1):
        fine, C_r = refine_uniform(patches[-1], 1)  # Eq. 13: R_c = C_r R_f
        patches.append(fine)
        refinements.append(C_r)
    return nested_space(patches, refinements, nodes, node_normals, uv, glue, family)


def nested_space(patches: Sequence[SplinePatch], refinements: Sequence, nodes: np.ndarray,
                 node_normals: np.ndarray | None = None, uv: np.ndarray | None = None,
                 glue: bool = True, family: str | None = None) -> MultilevelSpace:
    """The operators ``C_s`` of any nested sequence of levels (Eqs. 13, 28).

    ``patches`` coarse to fine, each made from the previous by knot insertion with the
    matrix ``refinements[k]`` (``R_k = C_r R_{k+1}``, Eq. 13; e.g. :func:`refine_uniform`
    or :func:`~georeg_plugin.spline.refine.insert_knots`, which need not halve the spans: the
    last level may be the spline of an FE mesh of any number of elements). Other
    parameters as :func:`multilevel_space`.
    """
    patches = list(patches)
    if len(refinements) != len(patches) - 1:
        raise ValueError(f"refinements: {len(patches) - 1} matrices expected for {len(patches)} "
                         f"levels, got {len(refinements)}")
    if family is not None:
        check_element_degree(patches[0].degrees, family, "nested_space: coarsest patch")
    refinements = [sps.csr_matrix(C_r) for C_r in refinements]
    if uv is None:
        uv, _ = node_parameters(patches[-1], nodes)
    if node_normals is not None:                                  # curved: vector formulation
        n_fe = np.asarray(uv).shape[0]
        every = [np.arange(n_fe)]
        levels = [vector_level([p], every, [uv], node_normals, n_fe, glue)
                  for p in reversed(patches)]
        logger.info("multilevel space (vector): %d levels, ranks %s of %s, %d FE nodes",
                    len(patches), [lv.operator.shape[0] for lv in levels],
                    [3 * p.n_dofs for p in reversed(patches)], n_fe)
        return MultilevelSpace(patches=tuple(patches),
                               operators=tuple(lv.operator for lv in levels), vector=tuple(levels))
    operators = [extraction_operator(p, uv, node_normals) for p in reversed(patches)]
    gluing = [gluing_matrix(p) for p in reversed(patches)] if glue else []
    if gluing and all(G.shape[0] == G.shape[1] for G in gluing):
        gluing = []                                              # nothing to glue
    if gluing:
        operators = [(G @ C).tocsr() for G, C in zip(gluing, operators)]
        refinements = []
    logger.info("multilevel space: %d levels, spline dofs %s, %d FE nodes", len(patches),
                [C.shape[0] for C in operators], np.asarray(uv).shape[0])
    return MultilevelSpace(patches=tuple(patches), operators=tuple(operators),
                           refinement=tuple(reversed(refinements)), gluing=tuple(gluing))
