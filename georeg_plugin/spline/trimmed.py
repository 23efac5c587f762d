"""Trimmed faces: the FE elements (and triangles) of a face that lie inside its trimming loops.

A CAD face is a NURBS surface cut by trimming loops drawn in its parameter space (the outer
loop and the holes; :mod:`georeg_plugin.io.cad_kernel` reads them). The face is meshed as an
untrimmed one (the Q9 mesh of its whole parameter box, Eq. 17) and the elements whose whole
parametric footprint (all their nodes) lies inside the outer loop and outside every hole are
kept; the nodes are renumbered and keep their ``(u, v)`` on the face.

The boundary of the kept mesh is therefore a staircase of element edges inside the trimming
curve: the area lost is at most the band of elements the curve crosses, of width about one
element diagonal along the curve, and shrinks with the elements (``test_trimmed`` measures
it). A thin feature narrower than an element can also be bridged (all nine nodes inside while
the element straddles a slot). The spline levels stay on the untrimmed patch: the control
points whose support lies under a hole (no FE node) carry no data and are constrained only
through their neighbours, the nested ranks of :mod:`georeg_plugin.levels.curved` drop them.

Point-in-polygon is matplotlib's ``Path.contains_points`` (vectorised).
"""
from __future__ import annotations

import logging
from typing import Sequence

import numpy as np
from matplotlib.path import Path as _Polygon

from georeg_plugin.spline.fe_mesh import SplineFEMesh
from georeg_plugin.spline.patch import SplinePatch

logger = logging.getLogger(__name__)

__all__ = ["inside_loops", "trim_mesh", "grid_triangles", "FOOTPRINT_SHRINK"]

#: element footprints are shrunk by this fraction towards their centroid before the test, so
#: that a node lying on a loop (a plate's straight edge, the box boundary) counts as inside
FOOTPRINT_SHRINK = 1e-7


def _check_loops(loops: Sequence) -> list[np.ndarray]:
    loops = [np.asarray(loop, dtype=float) for loop in loops]
    if not loops:
        raise ValueError("loops: at least the outer loop is needed")
    for k, loop in enumerate(loops):
        if loop.ndim != 2 or loop.shape[1] != 2 or len(loop) < 3 or not np.all(np.isfinite(loop)):
            raise ValueError(f"loops[{k}]: expected a finite closed polyline (k >= 3, 2), got "
                             f"shape {loop.shape}")
    return loops


def inside_loops(uv: np.ndarray, loops: Sequence) -> np.ndarray:
    """True (m,) where ``uv`` (m, 2) lies inside ``loops[0]`` and outside ``loops[1:]``."""
    loops = _check_loops(loops)
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    inside = _Polygon(loops[0]).contains_points(uv)
    for hole in loops[1:]:
        inside &= ~_Polygon(hole).contains_points(uv)
    return inside


def _footprints_inside(uv: np.ndarray, connectivity: np.ndarray, loops) -> np.ndarray:
    """Elements (ne,) whose nodes, shrunk slightly towards the element centroid, are inside."""
    points = uv[connectivity]                                     # (ne, nn, 2)
    centre = points.mean(axis=1, keepdims=True)
    shrunk = points + FOOTPRINT_SHRINK * (centre - points)
    inside = inside_loops(shrunk.reshape(-1, 2), loops).reshape(connectivity.shape)
    return np.asarray(inside.all(axis=1))                 # (numpy types all(axis) as maybe a scalar)


def trim_mesh(mesh: SplineFEMesh, loops: Sequence, where: str = "face") -> SplineFEMesh:
    """The elements of ``mesh`` (one face's untrimmed mesh) inside its trimming loops.

    Parameters
    ----------
    mesh : a face's mesh (:func:`~georeg_plugin.spline.fe_mesh.fe_mesh_from_spline`).
    loops : the outer loop (k, 2) then the holes, in the face's ``(u, v)``.
    where : names the face in the error.

    Returns
    -------
    SplineFEMesh of the kept elements, nodes renumbered (each keeps its ``uv``).

    Raises
    ------
    ValueError
        If no element lies inside the loops (the elements are too coarse).
    """
    keep = _footprints_inside(mesh.uv, mesh.connectivity, loops)
    if not keep.any():
        raise ValueError(f"{where}: none of its {mesh.n_elements} FE elements lies inside its "
                         "trimming loops; use more elements")
    connectivity = mesh.connectivity[keep]
    used, renumber = np.unique(connectivity, return_inverse=True)
    logger.debug("%s: kept %d of %d elements inside the trimming loops", where,
                 connectivity.shape[0], mesh.n_elements)
    return SplineFEMesh(nodes=mesh.nodes[used], connectivity=renumber.reshape(connectivity.shape),
                        cell_type=mesh.cell_type, uv=mesh.uv[used])


def grid_triangles(patch: SplinePatch, loops: Sequence | None = None,
                   per_span: int = 16, max_per_direction: int = 256) -> np.ndarray:
    """Triangles (m, 3, 3) mm of a parameter grid of ``patch``, inside ``loops`` if given.

    ``per_span`` cells per knot span and direction (at most ``max_per_direction``); two
    triangles per cell, ordered along ``S_u x S_v``; with ``loops``, the cells whose four
    corners are inside (a staircase, as :func:`trim_mesh`).
    """
    grids = []
    for b in patch.breaks:
        k = max(1, min(per_span, max_per_direction // (len(b) - 1)))
        t = (b[:-1, None] + np.diff(b)[:, None] * np.arange(k)[None, :] / k).ravel()
        grids.append(np.append(t, b[-1]))
    gu, gv = grids
    U, V = np.meshgrid(gu, gv, indexing="ij")
    uv = np.column_stack([U.ravel(), V.ravel()])
    x = patch.evaluate(uv)
    nv = gv.size
    a, b = np.meshgrid(np.arange(gu.size - 1), np.arange(nv - 1), indexing="ij")
    c00 = (a * nv + b).ravel()
    cells = np.column_stack([c00, c00 + nv, c00 + nv + 1, c00 + 1])    # counter-clockwise in uv
    if loops is not None:
        cells = cells[_footprints_inside(uv, cells, loops)]
    tri = np.concatenate([cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]])
    return x[tri]
