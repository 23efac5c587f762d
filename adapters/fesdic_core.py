"""Glue between the geometric regularization plugin and our FE-SDIC core.

The core exposes one extension point, the linear solve of each Gauss-Newton step
(:class:`fesdic_core.solve.solvers.StepSolver`); the plugin's
:class:`georeg_plugin.levels.solver.GeometricRegularization` has exactly that ``solve``
method. This module only translates data between the two: the plugin's FE mesh of a
spline into the core's :class:`~fesdic_core.fe.mesh.SurfaceMesh`, the core's node normals
into the plugin's operators, and the measured correction ``q`` back into a spline
(Eq. 21). Neither package is changed.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Mapping

import numpy as np
import scipy.sparse as sps

from adapters.errors import LevelMeshError
from fesdic_core.fe.elements import family_from_meshio
from fesdic_core.fe.mesh import CellBlock, SurfaceMesh, node_normals
from fesdic_core.shape.gauge import rigid_normal_modes
from georeg_plugin.levels.components import component_levels
from georeg_plugin.levels.curved import is_flat
from georeg_plugin.levels.multipatch import part_component_space, part_mesh, part_space
from georeg_plugin.levels.operators import MultilevelSpace, extraction_operator, multilevel_space
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.spline.fe_mesh import check_element_degree, fe_mesh_from_spline
from georeg_plugin.spline.patch import SplinePatch
from georeg_plugin.spline.refine import refine_uniform, refine_to_elements

logger = logging.getLogger(__name__)

__all__ = ["NominalModel", "nominal_model", "part_model", "keep_elements", "georeg_solver", "displacement_space", "is_curved",
           "measured_spline", "measured_spline_std",
           "multilevel_for_mesh", "check_nested_mesh", "legacy_mesh_holds"]


@dataclasses.dataclass(frozen=True, eq=False)
class NominalModel:
    """The nominal geometry as both codes see it.

    Attributes
    ----------
    patch : the coarsest spline of the nominal geometry (the CAD model); for a part of
        several faces, its first face.
    mesh : the analysis-suitable FE mesh of the core (Eq. 17).
    uv : (n, 2) parameters of the FE nodes on ``patch`` (None for a legacy mesh); for a
        part, on the face ``node_face`` of each node.
    faces : the coarsest splines of every face of a part (:func:`part_model`), or empty
        (one patch: ``patch``).
    node_face : (n,) face of each node's ``uv`` (parts only).
    element_face : (n_elements,) face of each element (parts only; the VTU's ``face``).
    face_names : one name per face (parts only).
    """

    patch: SplinePatch
    mesh: SurfaceMesh
    uv: np.ndarray | None
    faces: tuple = ()
    node_face: np.ndarray | None = None
    element_face: np.ndarray | None = None
    face_names: tuple = ()

    @property
    def patches(self) -> tuple:
        """Every face's coarsest spline (``(patch,)`` for a one-patch model)."""
        return tuple(self.faces) if self.faces else (self.patch,)

    @property
    def is_part(self) -> bool:
        """True for a part of several faces (:func:`part_model`)."""
        return bool(self.faces)


def nominal_model(patch: SplinePatch, elements: tuple[int, int] | int, family: str = "Q9",
                  name: str = "nominal") -> NominalModel:
    """FE mesh made from ``patch`` by knot insertion and Eq. 17, as a core mesh.

    Parameters
    ----------
    patch : coarsest nominal spline.
    elements : number of FE elements per parametric direction (tuple), or an integer
        number of dyadic refinements of ``patch``.
    family : "Q9" (the paper's choice, spline degree <= 2) or "Q4" (spline degree 1 only).

    Raises
    ------
    ElementDegreeError
        If a degree of ``patch`` exceeds the element degree (Eq. 16 needs it): e.g. "Q4" with
        the usual degree-2 patches, whose finest spline level has more dofs than the Q4 mesh
        has nodes (one element per knot span) and is not reproduced between them.
    """
    check_element_degree(patch.degrees, family, f"nominal model {name!r} ({family} mesh)")
    if isinstance(elements, (int, np.integer)):
        fine, _ = refine_uniform(patch, int(elements))
    else:
        fine, _ = refine_to_elements(patch, *elements)
    fe = fe_mesh_from_spline(fine, family)
    block = CellBlock(family=family_from_meshio(fe.cell_type), connectivity=fe.connectivity)
    return NominalModel(patch=patch, mesh=SurfaceMesh(nodes=fe.nodes, blocks=(block,), name=name),
                        uv=fe.uv)


def keep_elements(model: NominalModel, keep: np.ndarray, name: str | None = None) -> NominalModel:
    """The one-patch ``model`` with only the elements ``keep`` (n_elements,) bool: a mesh of
    any outline (an L, a D, a cut-out) cut from the mesh of the patch's rectangle. The nodes
    no kept element uses are removed (renumbered in their order); the spline levels of the
    patch then have dofs outside the outline, which the solver removes
    (:mod:`georeg_plugin.levels.support`)."""
    if model.is_part or len(model.mesh.blocks) != 1:
        raise ValueError("keep_elements: a one-patch model with one element block is needed")
    block = model.mesh.blocks[0]
    keep = np.asarray(keep, dtype=bool)
    if keep.shape != (len(block.connectivity),) or not keep.any():
        raise ValueError(f"keep: ({len(block.connectivity)},) bool with at least one True "
                         f"expected, got shape {keep.shape}")
    connectivity = block.connectivity[keep]
    used = np.unique(connectivity)
    index = np.full(model.mesh.n_nodes, -1)
    index[used] = np.arange(used.size)
    mesh = SurfaceMesh(nodes=model.mesh.nodes[used],
                       blocks=(CellBlock(family=block.family, connectivity=index[connectivity]),),
                       name=name or model.mesh.name)
    return dataclasses.replace(model, mesh=mesh,
                               uv=None if model.uv is None else model.uv[used])


def part_model(faces, refinements, names=None, family: str = "Q9",
               name: str = "part", loops=None) -> NominalModel:
    """FE mesh of a part of several faces (:func:`georeg_plugin.levels.multipatch.part_mesh`):
    every face refined ``refinements`` times dyadically (one count, or one per face),
    welded along shared edges; a face
    with trimming ``loops`` (per face: outer then holes in its ``(u, v)``, or None) keeps
    the elements inside them.

    Raises :class:`~georeg_plugin.levels.multipatch.NonConformingFacesError` naming two faces whose
    shared edge's nodes do not coincide."""
    faces = tuple(faces)
    counts = np.broadcast_to(np.asarray(refinements, dtype=int), (len(faces),))
    fine = [refine_uniform(f, int(k))[0] for f, k in zip(faces, counts)]
    part = part_mesh(fine, names, family, loops=loops)
    block = CellBlock(family=family_from_meshio(part.cell_type), connectivity=part.connectivity)
    return NominalModel(patch=faces[0], mesh=SurfaceMesh(nodes=part.nodes, blocks=(block,),
                                                         name=name),
                        uv=part.uv, faces=faces, node_face=part.node_face,
                        element_face=part.element_face, face_names=part.face_names)


def elements_per_span(model: NominalModel, f: int, face: SplinePatch) -> float:
    """FE elements per coarse knot span of face ``f``: their count over the spans, or, when a
    trimmed face kept fewer (``georeg_plugin.spline.trimmed``), the spans' width over the spacing of
    the Q9 element centres (node 8, never welded: its ``uv`` is on its own face)."""
    elements = model.element_face == f
    count = np.count_nonzero(elements) / np.prod(face.n_elements)
    connectivity = model.mesh.blocks[0].connectivity[elements]
    if connectivity.shape[1] != 9:
        return count
    centres = model.uv[connectivity[:, 8]]
    ratio = 1.0
    for d, breaks in enumerate(face.breaks):
        steps = np.diff(np.unique(centres[:, d]))
        steps = steps[steps > 1e-9 * np.ptp(breaks)]
        if not steps.size:
            return count
        ratio *= np.diff(breaks).min() / steps.min()
    return max(count, round(ratio, 6))


def _check_part_levels(model: NominalModel, n_levels: int) -> None:
    """Each face's FE elements must refine its finest spline level (Eq. 16): a mesh of
    :func:`part_model` has ``4^k`` elements per coarse knot span, ``k >= n_levels - 1``."""
    for f, face in enumerate(model.faces):
        ratio = elements_per_span(model, f, face)
        if ratio < 4 ** (n_levels - 1):
            raise LevelMeshError(f"nominal model {model.mesh.name!r}: face {f} has {ratio:g} FE "
                                 f"elements per knot span, fewer than the {4 ** (n_levels - 1)} "
                                 f"the finest of {n_levels} spline levels needs (Eq. 16); use "
                                 "more elements or fewer levels")


def check_nested_mesh(model: NominalModel, finest: SplinePatch, level_name: str) -> None:
    """Raise :class:`~adapters.errors.LevelMeshError` (a ``ValueError``) if an FE element of
    ``model`` straddles a knot of ``finest``.

    Eq. 16 (the mesh reproduces the spline) needs, besides the degrees, every element of a
    mesh made from the spline to lie inside one knot span of the finest spline level: a
    spline function changes polynomial piece at a knot (it is only C^(p-1) there), which
    no single polynomial element holds. The
    element box runs from its corner 0 (the (u, v) minimum, :func:`fe_mesh_from_spline`)
    to the largest parameters of its nodes (welded seam nodes can only shrink it, never
    make a false alarm).
    """
    tol = 1e-9
    for block in model.mesh.blocks:
        uv = model.uv[block.connectivity]                       # (ne, nn, 2)
        lo, hi = uv[:, 0], uv.max(axis=1)
        for d, (breaks, name) in enumerate(zip(finest.breaks, "uv")):
            inside = (breaks[None, :] > lo[:, d, None] + tol) & (breaks[None, :] < hi[:, d, None] - tol)
            if inside.any():
                e, k = np.argwhere(inside)[0]
                raise LevelMeshError(
                    f"nominal model {model.mesh.name!r}: FE element {int(e)} spans "
                    f"{name} = [{lo[e, d]:.4g}, {hi[e, d]:.4g}] across the knot {name} = "
                    f"{breaks[k]:.4g} of {level_name}: the {block.family.name} mesh cannot "
                    "reproduce it (Eq. 16 needs the FE mesh to refine the finest spline level); "
                    "use a number of elements that is a multiple of the finest level's knot "
                    "spans, or fewer levels")


def is_curved(model: NominalModel) -> bool:
    """True if the nominal surface is not planar (control points off one plane)."""
    return not is_flat(model.patches)


def multilevel_for_mesh(model: NominalModel, n_levels: int, curved: bool | None = False
                        ) -> MultilevelSpace:
    """The operators ``C_s`` of ``n_levels`` spline levels for the core's mesh (Eq. 28).

    ``curved``: True, a shape unknown along the core's node normals on a curved face: the
    scalar spline space when it holds the rigid normal motions
    (:func:`scalar_holds_rigid_motions`: a cylinder), else the vector formulation of
    :mod:`georeg_plugin.levels.curved` (control vectors seen along the normals; both: nested levels,
    rigid normal motions in range); False (default), the scalar spline space
    ``C^T[I, J] = R_J(xi_I)`` (e.g. each component of a displacement); None: True when the
    nominal surface is not planar (:func:`is_curved`). A part of several faces always gets
    the vector formulation.
    For a mesh made from the spline (``model.uv``) the
    preconditions of Eq. 16 are checked: spline degree <= element degree, and every
    element inside one knot span of the finest level (:func:`check_nested_mesh`).
    """
    if model.is_part:          # several faces: vector, but a lone flat face or cylinder scalar
        _check_part_levels(model, n_levels)
        scalar = [face_holds_rigid_motions(face, model.uv[model.node_face == f],
                                           model.mesh.nodes[model.node_face == f])
                  for f, face in enumerate(model.faces)]
        return part_space(model.faces, n_levels, model.uv, model.node_face,
                          node_normals(model.mesh), scalar=scalar)
    if curved is None:
        curved = is_curved(model)
    family = model.mesh.blocks[0].family.name if model.uv is not None else None
    space = multilevel_space(model.patch, n_levels, model.mesh.nodes, uv=model.uv, family=family)
    if curved and not scalar_holds_rigid_motions(model, space):
        space = multilevel_space(model.patch, n_levels, model.mesh.nodes,
                                 node_normals=node_normals(model.mesh), uv=model.uv, family=family)
    if model.uv is not None:
        check_nested_mesh(model, space.patch(0), f"the finest of {n_levels} spline levels")
    return space


def component_space_for_mesh(model: NominalModel, n_levels: int) -> MultilevelSpace:
    """The scalar spline levels of one component of a field on the core's mesh (a
    displacement: ``kron(C_s, I3)`` of these): :func:`multilevel_for_mesh` with
    ``curved=False`` for one patch; for a part, every face's levels glued where faces share
    control points (:func:`~georeg_plugin.levels.multipatch.part_component_space`)."""
    if not model.is_part:
        return multilevel_for_mesh(model, n_levels, curved=False)
    _check_part_levels(model, n_levels)
    return part_component_space(model.faces, n_levels, model.uv, model.node_face)


#: FE nodes per spline dof that a legacy mesh (no node parameters) needs to hold a level: a
#: Q9 mesh has about four nodes per spline dof of the spline whose knot spans are its elements
NODES_PER_DOF = 4


def legacy_mesh_holds(n_dofs: int, n_nodes: int) -> bool:
    """True if a legacy mesh of ``n_nodes`` nodes holds a level of ``n_dofs`` spline dofs (per
    component): at most a quarter as many dofs as nodes (:data:`NODES_PER_DOF`)."""
    return n_dofs * NODES_PER_DOF <= n_nodes


def displacement_space(model: NominalModel, n_levels: int) -> MultilevelSpace:
    """The spline levels of a displacement on the core's mesh: ``kron(C_s, I3)`` of the
    scalar levels of one component (:func:`component_space_for_mesh`), in the core's
    node-major dof layout ``3 I + k`` (:func:`~georeg_plugin.levels.components.component_levels`)."""
    return component_levels(component_space_for_mesh(model, n_levels), 3)


#: the rigid normal modes must lie in the scalar space to this relative accuracy
RIGID_RTOL = 1e-8


def scalar_holds_rigid_motions(model: NominalModel, space: MultilevelSpace) -> bool:
    """True if the scalar spline space (``C^T[I, J] = R_J(xi_I)``) of a curved face holds its
    rigid normal motions ``n(xi_I) . (a + w x X_I)`` at every level (its coarsest level holds
    them: the levels are nested, Eq. 13), to :data:`RIGID_RTOL` with the surface's exact normals.

    A face whose normal components are rational functions of the NURBS's own degree does: a
    cylinder or a cone (the normal is affine in the point along each ruling; measured 1e-13).
    A doubly curved face does not (7e-4 on a paraboloid patch). Where it holds, the scalar
    space is the curved nominal's (nested, rigid-complete, one dof per control point); the
    vector formulation (:mod:`georeg_plugin.levels.curved`) has the same properties with about twice
    the dofs, whose extra directions cost accuracy: on the Stereo DIC Challenge's bars its
    cylinder-fit residual was 2.5 / 3.4 um against 1.8 / 2.7 um with the scalar space, on the
    rendered cylindrical panel 1.13 against 0.76 um (``benchmarks/bench_cad_parts.py``).
    """
    if model.uv is None:                  # no node parameters: no exact normals to check with
        return False
    return face_holds_rigid_motions(model.patch, model.uv, model.mesh.nodes,
                                    space.operators[-1])


def face_holds_rigid_motions(face: SplinePatch, uv: np.ndarray, nodes: np.ndarray,
                             C: sps.spmatrix | None = None) -> bool:
    """:func:`scalar_holds_rigid_motions` for one face: its nodes ``nodes`` at parameters
    ``uv``, ``C`` the face's coarsest scalar operator (default: ``R_J(xi_I)`` of ``face``)."""
    if len(uv) == 0:
        return False
    rigid, _ = rigid_normal_modes(np.asarray(nodes, dtype=float),
                                  np.asarray(face.normals(uv), dtype=float))
    C = (extraction_operator(face, uv) if C is None else C).toarray()   # (m, n_nodes)
    coeffs, *_ = np.linalg.lstsq(C.T, rigid, rcond=None)
    residual = np.abs(rigid - C.T @ coeffs).max() / np.abs(rigid).max()
    logger.info("curved nominal: rigid normal motions outside the scalar spline space %.2g "
                "(tolerance %.0e): the %s formulation", residual, RIGID_RTOL,
                "scalar" if residual <= RIGID_RTOL else "vector")
    return bool(residual <= RIGID_RTOL)


def georeg_solver(model: NominalModel, n_levels: int, schedule: Mapping[int, int] | None = None,
                  curved: bool | None = None) -> GeometricRegularization:
    """The plugin's solve hook for the core: level ``schedule[scale]`` at each image scale.

    By default image scale ``s`` uses spline level ``s`` (coarse images, coarse splines:
    the paper's section 3.3), clipped to the coarsest level. ``curved``: see
    :func:`multilevel_for_mesh`; by default (None) the shape's formulation follows the
    nominal (vector when it is not planar). The spline dofs that no integration point sees
    (outside a non-rectangular outline or in a cut-out of the mesh, a bar's flank beyond the
    grazing cut-off, a plate strip a feature hides) are removed from their level and keep
    their value (``hold_unseen``, :mod:`georeg_plugin.levels.support`); the solver's
    ``dropped_dofs`` says how many each level lost.
    """
    return GeometricRegularization(multilevel_for_mesh(model, n_levels, curved), schedule=schedule)


def measured_spline(solver: GeometricRegularization, q: np.ndarray, level: int = 0
                    ) -> tuple[SplinePatch, np.ndarray]:
    """The measured shape as a spline of ``level`` (Eq. 21): control points moved along
    normals (flat nominal) or by the vector formulation's control vectors (curved).

    Returns the patch and the control values (mm, each control point's displacement along
    its control normal). ``C_s^T q_s`` reproduces ``q`` at the FE nodes when ``q`` lies in
    the level's space.
    For a part of several faces the first is the tuple of every face's measured patch.
    """
    space = solver.space
    q_s = solver.control_values(q, level)
    values = space.control_point_values(q_s, level)
    faces = space.level_patches(level)
    d = np.split(space.control_vectors(q_s, level), np.cumsum([f.n_dofs for f in faces])[:-1])
    moved = tuple(dataclasses.replace(f, control_points=f.control_points + v.reshape(
        f.control_points.shape)) for f, v in zip(faces, d))
    return (moved if isinstance(space.patch(level), tuple) else moved[0]), values


def measured_spline_std(solver: GeometricRegularization, H, variance: float, level: int) -> np.ndarray:
    """Standard deviation (mm) of the measured spline's control values (Eq. 21):
    ``q_s = (C_s H C_s^T)^-1 C_s b`` has the covariance ``kappa (C_s H C_s^T)^-1`` under the
    noise model ``Cov(b) = kappa H`` of the core (before the gauge's projection of the
    rigid modes). One value per control point, as :func:`measured_spline`'s values. A dof
    that the level dropped (outside the mesh's outline, seen by no point) is not measured:
    its control value stays nominal (0) and its standard deviation here is 0."""
    space = solver.space
    inverse = solver.projected_inverse(H, level)        # zero on the dofs the level dropped
    if space.vector:                    # d_J . n_J = t_J^T q_s: variance t_J^T H_s^-1 t_J
        normals = np.vstack([p.control_normals() for p in space.level_patches(level)])
        T = space.vector[level].coefficients.reshape(len(normals), 3, -1)
        t = np.einsum("jkr,jk->jr", T, normals)
        return np.sqrt(np.clip(variance * np.einsum("jr,rs,js->j", t, inverse, t), 0.0, None))
    variance_s = variance * np.diag(inverse)
    return np.sqrt(np.clip(space.control_point_values(variance_s, level), 0.0, None))
