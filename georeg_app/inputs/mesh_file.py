"""``[geometry] kind = "mesh"``: a legacy FE mesh read from a file (any format meshio reads).

The nominal spline is then the flat rectangle that bounds the mesh, and the mesh nodes'
parameters come from point inversion on it (Remark 6).
"""
from __future__ import annotations

import os

import numpy as np

from adapters.fesdic_core import NominalModel
from fesdic_core.fe.mesh import validate_mesh
from fesdic_core.fe.mesh_io import read_mesh
from georeg_plugin.spline.geometries import rectangle

from georeg_app.errors import InputError

__all__ = ["mesh_model"]


def mesh_model(path: str | os.PathLike) -> NominalModel:
    """The nominal model of a flat legacy mesh in ``z = 0`` read from ``path``.

    Raises ValueError naming the file when the mesh is not flat (or is degenerate).
    """
    mesh = read_mesh(path)
    validate_mesh(mesh, str(path))                   # errors name the file
    lo, hi = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
    if hi[2] - lo[2] > 1e-6 * np.ptp(mesh.nodes[:, :2]):
        raise InputError(f"{path}: kind = 'mesh' takes a flat mesh in z = 0 "
                         f"(z spans {lo[2]:g}..{hi[2]:g} mm)")
    size = hi - lo
    patch = rectangle(size[0], size[1], center=tuple((lo + hi)[:2] / 2))
    return NominalModel(patch=patch, mesh=mesh, uv=None)       # point inversion (Remark 6)
