"""A part of several faces (untrimmed spline patches): one FE mesh, glued spline levels.

A real part is several patches assembled like finite elements (ARCHITECTURE, "A part, not
a patch"):

* one Q9 mesh per face (Eq. 17 when the face's degrees are <= 2; a higher degree, e.g. a
  bicubic CAD face, gets its nodes on the surface at the same parametric Q9 positions and
  Eq. 16 then holds only approximately: the operators only need ``R_J(xi_I)`` at the nodes);
* the meshes are welded where faces share an edge: conforming when the edge nodes of both
  faces coincide (faces that split the edge differently are first given the same knots
  there, :func:`~georeg_plugin.spline.conforming.conforming_faces`), else
  :class:`NonConformingFacesError` names the two faces; a trimmed face
  (:mod:`georeg_plugin.spline.trimmed`) keeps its elements inside its loops, a staircase: the faces
  meeting it along its trimming curve are not welded there (a gap of up to one element);
* each level moves the control points of every face by vectors (:mod:`georeg_plugin.levels.curved`),
  one vector where control points of several faces coincide (a shared edge): the correction
  ``u`` is continuous across the edge;
* a node on a sharp edge (crease) is ONE FE node: its unknown is a displacement along the
  core's node normal, the area-weighted mean of both faces' normals (not the normal of
  either face); it reads ``n_I . u(xi_I)`` with ``u`` taken on the face of lower index,
  which is the same vector on both faces when the edge's control points are glued. No
  face normal is shared across the crease: each face's shape is its own NURBS.

``PartMesh.uv`` holds, for each node, its parameters on the face ``node_face`` (the face of
lower index for a node of an edge); ``element_face`` is each element's face (cell data).
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import numpy as np
import scipy.sparse as sps

from georeg_plugin.errors import GeoregPluginError
from georeg_plugin.levels.curved import RANK_RTOL, VectorLevel, vector_gluing, vector_level
from georeg_plugin.levels.operators import MultilevelSpace, extraction_operator
from georeg_plugin.spline.fe_mesh import ELEMENT_DEGREES, coincident_groups, fe_mesh_from_spline
from georeg_plugin.spline.patch import SplinePatch, invert_points
from georeg_plugin.spline.refine import refine_uniform
from georeg_plugin.spline.trimmed import trim_mesh

logger = logging.getLogger(__name__)

__all__ = ["PartMesh", "part_mesh", "part_space", "part_component_space", "isolated_faces",
           "NonConformingFacesError"]


class NonConformingFacesError(GeoregPluginError, ValueError):
    """Two faces meet along an edge whose FE nodes do not coincide."""


@dataclasses.dataclass(frozen=True, eq=False)
class PartMesh:
    """The FE mesh of a part of several faces.

    Attributes
    ----------
    nodes : (n, 3) mm; connectivity : (ne, 9) gmsh quad9 order (or (ne, 4) quad);
    cell_type : meshio cell type; uv : (n, 2) parameters of each node on its face;
    node_face : (n,) face of each node's ``uv``; element_face : (ne,) face of each element;
    face_names : one name per face; exact : Eq. 16 holds (every face's degree <= the
    element degree).
    """

    nodes: np.ndarray
    connectivity: np.ndarray
    cell_type: str
    uv: np.ndarray
    node_face: np.ndarray
    element_face: np.ndarray
    face_names: tuple
    exact: bool

    @property
    def n_faces(self) -> int:
        return len(self.face_names)


def _face_label(names: Sequence[str], k: int) -> str:
    return f"face {k} ({names[k]!r})" if names[k] else f"face {k}"


def _on_boundary(patch: SplinePatch, uv: np.ndarray) -> np.ndarray:
    lo, hi = patch.bounds
    tol = 1e-12 * (hi - lo)
    return np.any((uv <= lo + tol) | (uv >= hi - tol), axis=1)


def part_mesh(faces: Sequence[SplinePatch], names: Sequence[str] | None = None,
              family: str = "Q9", weld_rtol: float = 1e-7,
              loops: Sequence | None = None) -> PartMesh:
    """One FE mesh over the faces (each already refined to the FE resolution).

    Parameters
    ----------
    faces : the faces' splines, one element per knot span (Eq. 17).
    names : one name per face (errors name them), optional.
    family : "Q9" or "Q4".
    weld_rtol : nodes closer than ``weld_rtol`` times the part's size are one node.
    loops : per face, its trimming loops in ``(u, v)`` (outer, then holes) or None
        (untrimmed); a trimmed face keeps the elements inside its loops
        (:func:`~georeg_plugin.spline.trimmed.trim_mesh`, a staircase boundary).

    Raises
    ------
    NonConformingFacesError
        A boundary node of one face lies on another face without being one of its nodes.
    """
    faces = list(faces)
    if not faces:
        raise ValueError("part_mesh: at least one face is needed")
    names = tuple(names) if names is not None else tuple("" for _ in faces)
    if len(names) != len(faces):
        raise ValueError(f"part_mesh: {len(faces)} faces, {len(names)} names")
    degree = ELEMENT_DEGREES[family]
    exact = all(max(f.degrees) <= degree for f in faces)
    meshes = [fe_mesh_from_spline(f, family, exact=max(f.degrees) <= degree) for f in faces]
    if loops is not None:
        if len(loops) != len(faces):
            raise ValueError(f"part_mesh: {len(faces)} faces, {len(loops)} sets of loops")
        meshes = [m if lp is None else trim_mesh(m, lp, _face_label(names, k))
                  for k, (m, lp) in enumerate(zip(meshes, loops))]
    for k, f in enumerate(faces):
        if max(f.degrees) > degree:
            logger.warning("%s has degrees %s > %d: its %s nodes are placed on the surface, "
                           "Eq. 16 holds only approximately", _face_label(names, k), f.degrees,
                           degree, family)
    offsets = np.cumsum([0] + [m.n_nodes for m in meshes])
    nodes = np.vstack([m.nodes for m in meshes])
    uv = np.vstack([m.uv for m in meshes])
    node_face = np.repeat(np.arange(len(faces)), [m.n_nodes for m in meshes])
    conn = np.vstack([m.connectivity + o for m, o in zip(meshes, offsets)])
    element_face = np.repeat(np.arange(len(faces)), [m.n_elements for m in meshes])
    size = float(np.ptp(nodes, axis=0).max()) or 1.0
    representative = coincident_groups(nodes, weld_rtol * size)   # lowest index: lowest face
    trimmed = [False] * len(faces) if loops is None else [lp is not None for lp in loops]
    _check_conforming(faces, meshes, offsets, representative, names, weld_rtol * size, trimmed)
    kept, renumber = np.unique(representative, return_inverse=True)
    logger.info("part mesh: %d faces, %d elements, %d nodes (%d welded)", len(faces), len(conn),
                kept.size, len(nodes) - kept.size)
    return PartMesh(nodes=nodes[kept], connectivity=renumber[conn], cell_type=meshes[0].cell_type,
                    uv=uv[kept], node_face=node_face[kept], element_face=element_face,
                    face_names=names, exact=exact)


def _check_conforming(faces, meshes, offsets, representative, names, tol, trimmed) -> None:
    """Every boundary node of a face lying on another, untrimmed, face must be one of its
    nodes (a trimmed face's mesh ends in a staircase inside its trimming curve: the faces
    meeting it along that curve are not welded there)."""
    for a, (fa, ma) in enumerate(zip(faces, meshes)):
        edge = np.flatnonzero(_on_boundary(fa, ma.uv))
        if not edge.size:                                   # trimmed all round
            continue
        for b, fb in enumerate(faces):
            if a == b or trimmed[b]:
                continue
            lo, hi = ma.nodes[edge].min(0) - tol, ma.nodes[edge].max(0) + tol
            box = fb.control_points.reshape(-1, 3)          # convex hull: a quick rejection
            if np.any(box.max(0) < lo) or np.any(box.min(0) > hi):
                continue
            _, distance = invert_points(fb, ma.nodes[edge])
            touching = edge[distance <= tol]
            if not touching.size:
                continue
            own = set(representative[offsets[b]:offsets[b + 1]].tolist())
            alone = [i for i in touching if representative[offsets[a] + i] not in own]
            if alone:
                i = alone[0]
                raise NonConformingFacesError(
                    f"{_face_label(names, a)} and {_face_label(names, b)} meet along an edge "
                    f"whose FE nodes do not coincide ({len(alone)} nodes of "
                    f"{_face_label(names, a)} lie on {_face_label(names, b)} between its nodes, "
                    f"first at {np.round(ma.nodes[i], 6).tolist()} mm): give both faces the "
                    "same knot spans along their shared edge")


def dyadic_levels(coarse_faces: Sequence[SplinePatch], n_levels: int) -> list[list[SplinePatch]]:
    """The faces of every level, coarse to fine: each level halves every knot span of the
    previous one (Eq. 28)."""
    levels = [list(coarse_faces)]
    for _ in range(int(n_levels) - 1):
        levels.append([refine_uniform(f, 1)[0] for f in levels[-1]])
    return levels


def isolated_faces(faces: Sequence[SplinePatch]) -> np.ndarray:
    """bool (n_faces,): the faces that share no control point with another face."""
    G = vector_gluing(faces).tocsc()                              # (points, control points)
    shared = np.asarray(G.sum(axis=1)).ravel() > 1                # points of several cps
    owner = np.repeat(np.arange(len(faces)), [f.n_dofs for f in faces])
    point = G.indices                                             # cp -> its point (csc)
    # a point of several control points of ONE face (a closed face's seam) is no contact
    touched = np.zeros(len(faces), dtype=bool)
    for pt in np.flatnonzero(shared):
        members = np.unique(owner[point == pt])
        if members.size > 1:
            touched[members] = True
    return ~touched


def _scalar_face_level(face: SplinePatch, rows: np.ndarray, uv: np.ndarray, n_fe: int
                       ) -> tuple[sps.csr_matrix, np.ndarray]:
    """A face's scalar operator ``C^T[I, J] = R_J(xi_I)`` on its nodes (control points that no
    node sees left out) and its control vectors per dof, ``d_J = c_J n_J`` (the control
    normal at the Greville point; as the one-patch output of a curved face)."""
    local = extraction_operator(face, uv).tocoo()                 # (n_cp, k)
    C = sps.csr_matrix((local.data, (local.row, rows[local.col])), shape=(local.shape[0], n_fe))
    seen = np.flatnonzero(np.asarray(abs(C).sum(axis=1)).ravel() > 0)
    normals = face.control_normals()[seen]                        # (r, 3)
    T = np.zeros((3 * face.n_dofs, seen.size))
    for k in range(3):
        T[3 * seen + k, np.arange(seen.size)] = normals[:, k]
    return C[seen], T


def part_space(coarse_faces: Sequence[SplinePatch], n_levels: int, uv: np.ndarray,
               node_face: np.ndarray, node_normals: np.ndarray, glue: bool = True,
               rtol: float = RANK_RTOL, scalar: Sequence[bool] | None = None) -> MultilevelSpace:
    """The spline levels of a part: every face refined dyadically, vector control points
    glued where faces share them (:func:`~georeg_plugin.levels.curved.vector_level`).

    ``uv``, ``node_face``: a :class:`PartMesh`'s; ``node_normals`` (n, 3): the FE unknowns'.
    ``scalar``: per face, True to give it the scalar space ``R_J(xi_I)`` of a one-patch
    model (the caller checks that this space holds the face's rigid normal motions: a flat
    face or a cylinder) instead of the vector formulation, whose extra weak directions cost
    accuracy; honoured only for a face that shares no control point with another face
    (:func:`isolated_faces`: continuity across a shared edge needs the vector one).

    ``MultilevelSpace.patches[k]`` is then the tuple of the faces of level ``k`` (coarse to
    fine); ``space.vector`` holds the control vectors of each level.
    """
    if int(n_levels) < 1:
        raise ValueError(f"n_levels must be >= 1, got {n_levels}")
    levels = dyadic_levels(coarse_faces, n_levels)
    node_face = np.asarray(node_face)
    n_faces = len(levels[0])
    rows = [np.flatnonzero(node_face == k) for k in range(n_faces)]
    uvs = [np.asarray(uv)[r] for r in rows]
    n_fe = len(node_face)
    alone = np.zeros(n_faces, dtype=bool) if scalar is None else \
        np.asarray(scalar, dtype=bool) & isolated_faces(levels[0])
    vec = np.flatnonzero(~alone)
    vector = []
    for faces in reversed(levels):
        offsets = 3 * np.cumsum([0] + [f.n_dofs for f in faces])
        operators, coefficients = [], []
        if vec.size:
            lv = vector_level([faces[k] for k in vec], [rows[k] for k in vec],
                              [uvs[k] for k in vec], node_normals, n_fe, glue, rtol)
            T = np.zeros((offsets[-1], lv.operator.shape[0]))
            T[np.concatenate([np.arange(offsets[k], offsets[k + 1]) for k in vec])] = \
                lv.coefficients
            operators.append(lv.operator)
            coefficients.append(T)
        for k in np.flatnonzero(alone):
            C, Tk = _scalar_face_level(faces[k], rows[k], uvs[k], n_fe)
            T = np.zeros((offsets[-1], C.shape[0]))
            T[offsets[k]:offsets[k + 1]] = Tk
            operators.append(C)
            coefficients.append(T)
        vector.append(VectorLevel(operator=sps.vstack(operators).tocsr(),
                                  coefficients=np.hstack(coefficients)))
    logger.info("part space: %d faces (%d in the scalar space), %d levels, ranks %s",
                n_faces, int(alone.sum()), len(levels), [v.operator.shape[0] for v in vector])
    return MultilevelSpace(patches=tuple(tuple(f) for f in levels),
                           operators=tuple(v.operator for v in vector), vector=tuple(vector))


def part_component_space(coarse_faces: Sequence[SplinePatch], n_levels: int, uv: np.ndarray,
                         node_face: np.ndarray) -> MultilevelSpace:
    """The scalar spline levels of a part, for one component of a field (a displacement).

    Level ``s``: ``C_s^T[I, J] = R_J(xi_I)`` on the face of node ``I`` (Eq. 28, no normal:
    each component of ``u`` is a spline of its own), every face refined dyadically, control
    points shared by faces glued into one dof (``C_s = G_s C_s^faces``, so the field is
    continuous across a shared edge). Control points that no node sees (under a hole cut out
    of a face's mesh) are left out.
    """
    if int(n_levels) < 1:
        raise ValueError(f"n_levels must be >= 1, got {n_levels}")
    levels = dyadic_levels(coarse_faces, n_levels)
    node_face, uv = np.asarray(node_face), np.asarray(uv)
    n_fe = len(node_face)
    operators = []
    for faces in reversed(levels):                                 # s = 0: the finest
        blocks = []
        for k, face in enumerate(faces):
            rows = np.flatnonzero(node_face == k)
            local = extraction_operator(face, uv[rows]).tocoo()  # (n_cp, k)
            blocks.append(sps.csr_matrix((local.data, (local.row, rows[local.col])),
                                         shape=(local.shape[0], n_fe)))
        C = (vector_gluing(faces) @ sps.vstack(blocks)).tocsr()  # glued dofs
        seen = np.asarray(abs(C).sum(axis=1)).ravel() > 0
        operators.append(C[seen])
    return MultilevelSpace(patches=tuple(tuple(f) for f in levels), operators=tuple(operators))
