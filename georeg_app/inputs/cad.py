"""``[geometry] kind = "cad"``: the nominal part read from its CAD (IGES or STEP), face by face.

Two readers, chosen by the file:

- an IGES file whose faces are all untrimmed B-spline surfaces (entity 128, placed by their
  entities 124; see :mod:`georeg_plugin.io.iges`) is read without extra dependency, always by
  that reader (same results with or without the ``cad`` extra);
- a STEP file (``.step``, ``.stp``), or an IGES file with trimmed (144/142) or analytic
  surfaces, is read through OpenCASCADE (:mod:`georeg_plugin.io.cad_kernel`, the optional ``cad``
  extra, ``cadquery-ocp``): every face as NURBS with its trimming loops. Without the extra
  the error names it.

``faces`` picks some faces by index (file order) or name. One untrimmed face: the one-patch
model of the plates (curved: the scalar spline space if it holds the rigid normal motions, a
cylinder; else the vector formulation of :mod:`georeg_plugin.levels.curved`; see
``adapters.fesdic_core.multilevel_for_mesh``). Several faces, or a trimmed one: one FE mesh
over all of them, welded along shared edges, spline levels glued there
(:mod:`georeg_plugin.levels.multipatch`); a trimmed face keeps the elements inside its loops
(:mod:`georeg_plugin.spline.trimmed`: a staircase boundary; its spline levels stay on the untrimmed
surface). A face of degree above 2 (bicubic CAD) goes through the part's mesh (nodes placed on
the surface, Eq. 16 approximate), even alone.

:func:`cad_triangles` triangulates every face of the file (trimmed faces inside their loops),
for ray casting against the part.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from adapters.fesdic_core import NominalModel, nominal_model, part_model
from georeg_plugin.io.iges import read_iges_surfaces
from georeg_plugin.levels.multipatch import NonConformingFacesError
from georeg_plugin.spline.conforming import conforming_faces
from georeg_plugin.spline.trimmed import grid_triangles

from georeg_plugin.io.cad_kernel import IGES_SUFFIXES, STEP_SUFFIXES, CadFace, kernel_available

from georeg_app.errors import InputError

logger = logging.getLogger(__name__)

__all__ = ["CAD_SUFFIXES", "STEP_SUFFIXES", "check_cad_file", "cad_faces", "cad_part",
           "cad_model", "cad_refinements", "face_refinements", "cad_face_indices", "cad_occluders", "cad_triangles",
           "read_cad_faces"]

CAD_SUFFIXES = IGES_SUFFIXES + STEP_SUFFIXES
#: what a user installs for STEP and trimmed IGES
CAD_EXTRA = ("the optional 'cad' extra (OpenCASCADE: python -m pip install -e \".[cad]\", "
             "i.e. cadquery-ocp)")
_NEEDS_KERNEL = "needs a CAD kernel"


def check_cad_file(path: Path) -> None:
    """ValueError unless ``path`` is an IGES or STEP file (by its suffix); STEP without the
    ``cad`` extra is refused naming it."""
    suffix = Path(path).suffix.lower()
    if suffix in STEP_SUFFIXES and not kernel_available():
        raise InputError(f"{path}: STEP files need a CAD kernel: install {CAD_EXTRA}, or "
                         "export the faces as untrimmed B-spline surfaces in IGES (.igs)")
    if suffix not in CAD_SUFFIXES:
        raise InputError(f"{path}: kind = \"cad\" reads IGES ({', '.join(IGES_SUFFIXES)}) or "
                         f"STEP ({', '.join(STEP_SUFFIXES)}) files, got suffix "
                         f"{suffix or '(none)'!r}")


def _needs_kernel(path: Path) -> bool:
    """True for a STEP file or an IGES file the base reader refuses as needing a kernel."""
    if Path(path).suffix.lower() in STEP_SUFFIXES:
        return True
    try:
        read_iges_surfaces(path)
    except ValueError as err:
        return _NEEDS_KERNEL in str(err)
    return False


def read_cad_faces(path: Path) -> list[CadFace]:
    """Every face of a CAD file (see the module docstring for the reader used).

    Raises
    ------
    FileNotFoundError, ValueError
        Naming the file and the face (or IGES directory entry) at fault; a file that needs
        the ``cad`` extra when it is not installed.
    """
    path = Path(path)
    check_cad_file(path)
    if path.suffix.lower() in IGES_SUFFIXES:
        try:
            surfaces = read_iges_surfaces(path)
        except ValueError as err:
            if _NEEDS_KERNEL not in str(err):
                raise
            if not kernel_available():
                raise InputError(f"{err}; install {CAD_EXTRA}") from None
        else:
            return [CadFace(s.label or f"face{k}", s.patch, (), False)
                    for k, s in enumerate(surfaces)]
    from georeg_plugin.io.cad_kernel import read_kernel_faces
    return read_kernel_faces(path)


def _describe(faces: Sequence[CadFace]) -> str:
    return ", ".join(f"{k} {f.name!r}" for k, f in enumerate(faces))


def cad_face_indices(path: Path, faces: Sequence | None, every: Sequence[CadFace] | None = None
                     ) -> list[int]:
    """The file-order indices of the faces ``faces`` picks (indices or names; None: all).
    Errors name the file and the face (and the file's faces)."""
    every = read_cad_faces(path) if every is None else every
    if faces is None:
        return list(range(len(every)))
    chosen = []
    by_name = {f.name: k for k, f in enumerate(every)}
    for f in faces:
        if isinstance(f, str):
            if f not in by_name:
                raise InputError(f"{path}: no face named {f!r}; its faces: {_describe(every)}")
            chosen.append(by_name[f])
        elif not 0 <= int(f) < len(every):
            raise InputError(f"{path}: face {f} is out of range (the file has "
                             f"{len(every)}: {_describe(every)})")
        else:
            chosen.append(int(f))
    if len(set(chosen)) != len(chosen):
        raise InputError(f"{path}: faces {list(faces)} name a face twice")
    return chosen


def cad_part(path: Path, faces: Sequence | None = None) -> tuple[CadFace, ...]:
    """The selected faces of a CAD file, with their trimming loops (``faces``: see
    :func:`cad_face_indices`), the faces that meet along an edge given the same knots there
    (:func:`~georeg_plugin.spline.conforming.conforming_faces`: the same surfaces, the loops stay
    valid).

    A run asks for its part several times (the configuration's check, the sizes, the model):
    the result is kept for the file as it is (its path, size and modification time) and the
    same ``faces`` (the faces are frozen), so the common refinement, most of a short run's
    time on a part of several faces, is computed once."""
    path = Path(path)
    check_cad_file(path)
    stat = path.stat()
    return _cad_part(str(path.resolve()), stat.st_mtime_ns, stat.st_size,
                     None if faces is None else tuple(faces))


@functools.lru_cache(maxsize=8)
def _cad_part(path: str, mtime_ns: int, size: int, faces: tuple | None) -> tuple[CadFace, ...]:
    every = read_cad_faces(Path(path))
    chosen = [every[k] for k in cad_face_indices(Path(path), faces, every)]
    if len(chosen) > 1:
        patches = conforming_faces([f.patch for f in chosen], [f.name for f in chosen])
        chosen = [dataclasses.replace(f, patch=g) for f, g in zip(chosen, patches)]
    return tuple(chosen)


def cad_occluders(path: Path, faces: Sequence | None) -> np.ndarray | None:
    """The triangles of the faces of the file that are NOT measured (``faces`` picks the
    measured ones), (m, 3, 3) mm: they hide parts of the measured faces from a camera
    (a block's walls next to a plate); None when every face is measured."""
    every = read_cad_faces(path)
    others = sorted(set(range(len(every))) - set(cad_face_indices(path, faces, every)))
    if not others:
        return None
    return cad_triangles(path, only=others)


def cad_faces(path: Path, faces: Sequence | None = None) -> tuple[tuple, tuple]:
    """The selected faces of a CAD file: their untrimmed splines (mm, placed) and names."""
    part = cad_part(path, faces)
    return tuple(f.patch for f in part), tuple(f.name for f in part)


def cad_triangles(path: Path, deflection_mm: float = 0.01,
                  only: Sequence[int] | None = None) -> np.ndarray:
    """A triangulation of the faces of a CAD file (all, or the file-order indices ``only``),
    (m, 3, 3) mm, for ray casting.

    Trimmed faces are respected. Through the kernel (STEP, trimmed IGES): OpenCASCADE's
    ``BRepMesh_IncrementalMesh`` (chord deviation ``deflection_mm``); untrimmed IGES: a
    parameter grid of each face (16 cells per knot span and direction). Triangles are
    ordered along each face's normal ``S_u x S_v``.
    """
    path = Path(path)
    check_cad_file(path)
    if _needs_kernel(path):
        if not kernel_available():
            raise InputError(f"{path}: needs a CAD kernel: install {CAD_EXTRA}")
        from georeg_plugin.io.cad_kernel import kernel_triangles
        return kernel_triangles(path, deflection_mm, only=only)
    every = read_cad_faces(path)
    return np.concatenate([grid_triangles(every[k].patch, every[k].loops or None)
                           for k in (range(len(every)) if only is None else only)])


def cad_refinements(faces: Sequence, elements: int | None, levels: int) -> int:
    """Dyadic refinements of every face: at least ``levels - 1`` (the finest spline level
    refines the FE mesh), about ``elements`` FE elements in all (default 1000)."""
    coarse = sum(int(np.prod(f.n_elements)) for f in faces)
    target = elements or 1000
    return max(levels - 1, math.ceil(math.log(max(target / coarse, 1.0), 4) - 1e-9))


def face_refinements(part: Sequence[CadFace], elements: int | None, levels: int
                     ) -> tuple[int, ...]:
    """Dyadic refinements of each face so that the elements are of about one size over the
    part: face ``f`` gets about ``elements * area_f / area`` of them (its area inside its
    trimming loops), at least ``levels - 1`` refinements (the finest spline level refines
    its FE mesh, Eq. 16)."""
    def area(f: CadFace) -> float:
        t = grid_triangles(f.patch, f.loops or None)
        return 0.5 * float(np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]),
                                          axis=1).sum())
    areas = np.array([area(f) for f in part])
    share = (elements or 1000) * areas / areas.sum()
    return tuple(max(levels - 1, math.ceil(math.log(max(n / np.prod(f.patch.n_elements), 1.0), 4)
                                           - 1e-9)) for n, f in zip(share, part))


def cad_model(path: Path, faces: Sequence | None, elements: int | None,
              levels: int) -> NominalModel:
    """The nominal model of ``[geometry] kind = "cad"`` (see the module docstring)."""
    part = cad_part(path, faces)
    patches, names = tuple(f.patch for f in part), tuple(f.name for f in part)
    trimmed = any(f.trimmed for f in part)
    k = cad_refinements(patches, elements, levels)
    try:
        if len(patches) == 1 and max(patches[0].degrees) <= 2 and not trimmed:
            model = nominal_model(patches[0], k, "Q9", name=names[0])
            return dataclasses.replace(model, face_names=names, element_face=np.zeros(
                model.mesh.n_elements, dtype=int))              # the VTU's `face`, all 0
        loops = [f.loops if f.trimmed else None for f in part] if trimmed else None
        try:                                 # elements of about one size over the part
            return part_model(patches, face_refinements(part, elements, levels), names, "Q9",
                              name=Path(path).stem, loops=loops)
        except NonConformingFacesError as err:           # faces that meet need one count
            logger.info("%s: %s; every face refined %d times", path, err, k)
            return part_model(patches, k, names, "Q9", name=Path(path).stem, loops=loops)
    except ValueError as err:
        raise InputError(f"{path}: {err}") from err
