"""Surface mesh input/output through meshio (.msh, .vtu, .inp, ... any format it knows).

meshio stores cells in VTK node order, which for "triangle", "triangle6", "quad" and
"quad9" is the gmsh order used by :mod:`fesdic_core.fe.elements`; the round-trip tests
check that .msh (gmsh 2.2 / 4.1), .vtu and Abaqus .inp keep it.
"""
from __future__ import annotations

import contextlib
import io
import logging
import os
import pathlib

import meshio
import numpy as np

from fesdic_core.atomic import atomic_path
from fesdic_core.fe.elements import family_from_meshio
from fesdic_core.fe.mesh import CellBlock, MeshError, SurfaceMesh

logger = logging.getLogger(__name__)

__all__ = ["read_mesh", "write_mesh"]

#: meshio cell types of dimension 0 and 1, silently ignored on reading
_IGNORED_PREFIXES = ("vertex", "line")


@contextlib.contextmanager
def _meshio_messages(path: pathlib.Path):
    """Route meshio's console messages to the log, and its sys.exit to a MeshError."""
    buffer = io.StringIO()
    try:
        with contextlib.redirect_stdout(buffer), contextlib.redirect_stderr(buffer):
            yield
    except SystemExit:      # meshio.read exits when no reader accepts the file
        lines = [line for line in buffer.getvalue().splitlines() if line.strip()]
        raise MeshError(lines[-1] if lines else f"meshio cannot read {path}") from None
    finally:
        if buffer.getvalue().strip():
            logger.debug("meshio on %s: %s", path, buffer.getvalue().strip())


def _meshio_read(path: pathlib.Path) -> meshio.Mesh:
    """meshio.read, trying gmsh first for .msh (meshio would try ANSYS first)."""
    with _meshio_messages(path):
        if path.suffix.lower() == ".msh":
            try:
                return meshio.read(path, file_format="gmsh")
            except (Exception, SystemExit):
                logger.debug("%s is not a gmsh file; letting meshio guess", path)
        return meshio.read(path)


def read_mesh(path: str | os.PathLike) -> SurfaceMesh:
    """Read a surface mesh with meshio.

    Points (n, 2) get z = 0; vertex and line cells are ignored; blocks of the same
    supported type are merged (in order of first appearance). Node coordinates are
    taken as they are (mm expected).

    Raises
    ------
    FileNotFoundError : the file does not exist.
    MeshError : (a ``ValueError``) meshio cannot read it, its points are not 2-D/3-D, it
        holds an unsupported surface or volume cell type, or no surface cell at all.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    try:
        raw = _meshio_read(path)
    except Exception as exc:   # meshio raises ReadError, KeyError, ValueError, ...
        raise MeshError(f"cannot read mesh file {path}: {exc}") from exc
    points = np.asarray(raw.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"mesh file {path}: points must be (n, 2) or (n, 3), "
                        f"got {points.shape}")
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    by_type: dict[str, list[np.ndarray]] = {}
    for cells in raw.cells:
        if cells.type.startswith(_IGNORED_PREFIXES):
            logger.debug("%s: ignoring %d %s cells", path, len(cells.data), cells.type)
            continue
        try:
            family_from_meshio(cells.type)
        except ValueError as exc:
            raise MeshError(f"mesh file {path}: {exc}") from None
        by_type.setdefault(cells.type, []).append(np.asarray(cells.data))
    if not by_type:
        raise MeshError(f"mesh file {path} holds no surface cell of a supported type "
                        f"(triangle, triangle6, quad, quad9)")
    try:                       # e.g. a cell that refers to a node the file does not have
        blocks = tuple(CellBlock(family_from_meshio(t), np.concatenate(data))
                       for t, data in by_type.items())
        mesh = SurfaceMesh(points, blocks, name=path.stem)
    except ValueError as exc:
        raise MeshError(f"mesh file {path}: {exc}") from None
    logger.info("read %s: %d nodes, %s", path, mesh.n_nodes,
                ", ".join(f"{b.n_elements} {b.family.name}" for b in blocks))
    return mesh


def _checked_data(data: dict | None, size: int, what: str) -> dict[str, np.ndarray]:
    out = {}
    for key, values in (data or {}).items():
        values = np.asarray(values)
        if values.ndim == 0 or values.shape[0] != size:
            raise ValueError(f"write_mesh: {what}[{key!r}] has shape {values.shape}, "
                             f"expected first dimension {size}")
        out[key] = values
    return out


def write_mesh(path: str | os.PathLike, mesh: SurfaceMesh, point_data: dict | None = None,
               cell_data: dict | None = None, file_format: str | None = None) -> None:
    """Write a mesh atomically with meshio (format from the extension unless given).

    Parameters
    ----------
    path : target file; its folder must exist.
    mesh : the surface mesh.
    point_data : name -> (n_nodes, ...) arrays.
    cell_data : name -> list with one (ne_b, ...) array per block (meshio layout);
        a single array is accepted for a one-block mesh.
    file_format : meshio format name, e.g. "gmsh22" for gmsh 2.2; default from the
        extension, with .msh meaning gmsh 4.1 (meshio's ambiguous default is ANSYS).

    The mesh goes to a temporary file in the same folder with the same extension, then
    ``os.replace`` moves it onto the target; on failure the temporary file is removed.
    """
    path = pathlib.Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"write_mesh: folder of {path} does not exist")
    points = _checked_data(point_data, mesh.n_nodes, "point_data")
    cells = {}
    for key, values in (cell_data or {}).items():
        if not isinstance(values, (list, tuple)):
            values = [values]
        if len(values) != len(mesh.blocks):
            raise ValueError(f"write_mesh: cell_data[{key!r}] has {len(values)} arrays for "
                             f"{len(mesh.blocks)} blocks")
        cells[key] = [_checked_data({key: v}, b.n_elements, "cell_data")[key]
                      for v, b in zip(values, mesh.blocks)]
    if file_format is None and path.suffix.lower() == ".msh":
        file_format = "gmsh"      # meshio would otherwise pick ANSYS for .msh
    if file_format is not None and file_format.startswith("gmsh"):
        for tag in ("gmsh:physical", "gmsh:geometrical"):   # element tags gmsh expects
            cells.setdefault(tag, [np.ones(b.n_elements, dtype=np.int32) for b in mesh.blocks])
    out = meshio.Mesh(mesh.nodes, [(b.family.meshio_type, b.connectivity) for b in mesh.blocks],
                      point_data=points, cell_data=cells)
    with atomic_path(path) as tmp, _meshio_messages(path):
        meshio.write(tmp, out, file_format=file_format)
    logger.info("wrote %s: %d nodes, %d elements", path, mesh.n_nodes, mesh.n_elements)
