"""Nominal surfaces of the faces and the solids of the raised features (world frame, mm).

* Each face is one spline patch of the plugin: a flat :func:`~georeg_plugin.geometries.quadrilateral`
  (base plate, block top, the flat nominal of a cylinder at crest height) or an exact NURBS
  :func:`~georeg_plugin.geometries.cylinder` moved onto the bar's axis. Its analysis-suitable
  Q9 mesh comes from the refined spline (Eq. 17).
* The base plate is one flat patch with the features' footprints cut out of its FE mesh:
  a mesh that is not the spline's own (a "legacy" mesh); the operators ``C_s`` then come
  from the parameters of the remaining nodes (Remark 6), the same formula.
* Every raised feature is a convex solid (box, wedge, half cylinder) given by the
  half-spaces ``n . X + d <= 0`` of its convex hull; they hide parts of the base plate
  from a camera (see :mod:`challenge.visibility`) and give the holes of the base mesh.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from adapters.fesdic_core import NominalModel, nominal_model
from fesdic_core.mesh import CellBlock, SurfaceMesh
from georeg_plugin.geometries import cylinder, quadrilateral, transformed
from georeg_plugin.patch import SplinePatch
from georeg_plugin.refine import refine_to_elements

from .config import Feature, Nominal

logger = logging.getLogger(__name__)

ARC_STEP_DEG = 5.0          # facets of the polygonal half cylinders (inscribed: < 6 um inside)


@dataclass(frozen=True, eq=False)
class ConvexSolid:
    """A convex solid ``{X : normals @ X + offsets <= 0}`` (facets of its convex hull)."""

    name: str
    normals: np.ndarray       # (k, 3) outward unit normals
    offsets: np.ndarray       # (k,)
    bounds: np.ndarray        # (2, 3) lower and upper corners of its bounding box

    def inflated(self, margin_mm: float) -> ConvexSolid:
        """The solid grown by ``margin_mm`` along every facet normal."""
        return ConvexSolid(self.name, self.normals, self.offsets - margin_mm,
                           self.bounds + [[-margin_mm], [margin_mm]])

    def contains(self, X: np.ndarray) -> np.ndarray:
        """(n,) bool: points ``X`` (n, 3) inside or on the solid."""
        return np.all(X @ self.normals.T + self.offsets <= 0.0, axis=1)


def _frame(line: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Unit axis of a segment, the lateral unit vector in the plane z = 0, and the length."""
    axis = line[1] - line[0]
    length = float(np.linalg.norm(axis))
    axis = axis / length
    lateral = np.cross(axis, [0.0, 0.0, 1.0])                # lateral x axis = +z
    return axis, lateral / np.linalg.norm(lateral), length


def feature_vertices(f: Feature) -> np.ndarray:
    """Vertices (m, 3) whose convex hull is the feature's solid."""
    if f.kind == "box":
        foot = np.asarray(f.footprint_mm)
        return np.concatenate([np.c_[foot, np.zeros(4)], np.c_[foot, np.full(4, f.height_mm)]])
    line = np.asarray(f.line_mm)
    _, lateral, _ = _frame(line)
    if f.kind == "wedge":
        base = np.concatenate([line + f.half_width_mm * lateral, line - f.half_width_mm * lateral])
        base[:, 2] = 0.0
        return np.concatenate([line, base])
    # half cylinder: arcs at both ends, above z = 0 (the axis may lie below the base plane)
    z_axis = line[:, 2]
    top = np.arcsin(np.clip(-z_axis.max() / f.radius_mm, -1, 1))      # angle where the arc meets z = 0
    angles = np.radians(np.arange(-90.0, 90.0 + 1e-9, ARC_STEP_DEG))
    angles = np.clip(angles, -np.pi / 2 + top, np.pi / 2 - top)
    pts = []
    for end in line:
        arc = (end[None] + f.radius_mm * (np.sin(angles)[:, None] * lateral
                                          + np.cos(angles)[:, None] * [0.0, 0.0, 1.0]))
        arc[:, 2] = np.maximum(arc[:, 2], 0.0)
        pts.append(arc)
    return np.concatenate(pts)


def feature_solid(f: Feature) -> ConvexSolid:
    """The convex solid of a feature (facet normals and offsets of its hull)."""
    vertices = feature_vertices(f)
    eq = ConvexHull(vertices).equations
    return ConvexSolid(f.name, eq[:, :3].copy(), eq[:, 3].copy(),
                       np.array([vertices.min(axis=0), vertices.max(axis=0)]))


def nominal_patch(n: Nominal) -> SplinePatch:
    """The coarsest spline of a nominal surface (``spline_elements`` elements)."""
    if n.kind == "quadrilateral":
        patch = quadrilateral(n.corners_mm)
    else:
        line = np.asarray(n.line_mm)
        axis, lateral, length = _frame(line)
        patch = cylinder(n.radius_mm, length, n.arc_deg, axis="y")   # axis along y, crest +z
        # local (x = lateral, y = axis, z = up) -> world; a proper rotation
        up = np.cross(lateral, axis)
        R = np.column_stack([lateral, axis, up])
        patch = transformed(patch, R, line.mean(axis=0))
        arcs = patch.n_elements[0]
        if n.spline_elements[0] % arcs:
            raise ValueError(f"nominal {n.name!r}: spline_elements[0] = {n.spline_elements[0]} must "
                             f"be a multiple of the {arcs} rational arcs of {n.arc_deg:g} degrees")
    if tuple(n.spline_elements) != patch.n_elements:
        patch, _ = refine_to_elements(patch, *n.spline_elements)
    return patch


def face_model(n: Nominal, holes: tuple[ConvexSolid, ...] = ()) -> NominalModel:
    """Nominal spline and analysis-suitable Q9 mesh of one nominal surface.

    Elements with a node (or their centre) inside a hole solid grown by ``hole_margin_mm``
    are removed; the remaining nodes keep their spline parameters.
    """
    patch = nominal_patch(n)
    model = nominal_model(patch, tuple(n.elements), "Q9", name=n.name)
    if not holes:
        return model
    mesh = model.mesh
    conn = mesh.blocks[0].connectivity
    cut = np.zeros(len(conn), bool)
    centres = mesh.nodes[conn].mean(axis=1)
    for solid in holes:
        grown = solid.inflated(n.hole_margin_mm)
        inside = grown.contains(mesh.nodes)
        cut |= inside[conn].any(axis=1) | grown.contains(centres)
    kept = conn[~cut]
    used = np.unique(kept)
    renumber = np.full(len(mesh.nodes), -1)
    renumber[used] = np.arange(len(used))
    block = CellBlock(family=mesh.blocks[0].family, connectivity=renumber[kept])
    logger.info("nominal %s: %d of %d elements cut out by %s", n.name, cut.sum(), len(conn),
                ", ".join(s.name for s in holes))
    return NominalModel(patch=patch, mesh=SurfaceMesh(nodes=mesh.nodes[used], blocks=(block,),
                                                      name=n.name), uv=model.uv[used])
