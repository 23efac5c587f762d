"""``[geometry] kind = "cad"``: the nominal part read from its CAD (IGES), face by face.

The file's untrimmed B-spline surfaces (entity 128, placed by their entities 124; see
:mod:`georeg_plugin.iges`) are the faces; ``faces`` picks some of them by index (directory
order) or name. One face: the one-patch model of the plates (curved: the scalar spline
space if it holds the rigid normal motions, a cylinder; else the vector formulation of
:mod:`georeg_plugin.curved`; see ``adapters.fesdic_core.multilevel_for_mesh``). Several: one FE mesh over all of them, welded along shared
edges, spline levels glued there (:mod:`georeg_plugin.multipatch`). STEP needs a CAD kernel
(the future optional ``cad`` extra) and is refused with that message. A face of degree
above 2 (bicubic CAD) goes through the part's mesh (nodes placed on the surface, Eq. 16
approximate), even alone.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from adapters.fesdic_core import NominalModel, nominal_model, part_model
from georeg_plugin.iges import read_iges_surfaces

logger = logging.getLogger(__name__)

__all__ = ["CAD_SUFFIXES", "STEP_SUFFIXES", "check_cad_file", "cad_faces", "cad_model",
           "cad_refinements"]

CAD_SUFFIXES = (".igs", ".iges")
STEP_SUFFIXES = (".step", ".stp")


def check_cad_file(path: Path) -> None:
    """ValueError unless ``path`` is an IGES file (by its suffix); STEP is named."""
    suffix = Path(path).suffix.lower()
    if suffix in STEP_SUFFIXES:
        raise ValueError(f"{path}: STEP files need a CAD kernel (the future optional 'cad' "
                         "extra); export the faces as IGES (.igs) meanwhile")
    if suffix not in CAD_SUFFIXES:
        raise ValueError(f"{path}: kind = \"cad\" reads IGES files ({', '.join(CAD_SUFFIXES)}), "
                         f"got suffix {suffix or '(none)'!r}")


def _describe(surfaces) -> str:
    return ", ".join(f"{k} {s.label!r} (directory entry {s.directory_entry})"
                     for k, s in enumerate(surfaces))


def cad_faces(path: Path, faces: Sequence | None = None) -> tuple[tuple, tuple]:
    """The selected faces of an IGES file: their splines (mm, placed) and names.

    ``faces``: indices (directory order, from 0) or names; None: all. Errors name the file
    and the face (and the directory entry of the file's faces).
    """
    check_cad_file(path)
    surfaces = read_iges_surfaces(path)
    if faces is None:
        chosen = list(range(len(surfaces)))
    else:
        chosen = []
        by_name = {s.label: k for k, s in enumerate(surfaces) if s.label}
        for f in faces:
            if isinstance(f, str):
                if f not in by_name:
                    raise ValueError(f"{path}: no face named {f!r}; its faces: "
                                     f"{_describe(surfaces)}")
                chosen.append(by_name[f])
            elif not 0 <= int(f) < len(surfaces):
                raise ValueError(f"{path}: face {f} is out of range (the file has "
                                 f"{len(surfaces)}: {_describe(surfaces)})")
            else:
                chosen.append(int(f))
        if len(set(chosen)) != len(chosen):
            raise ValueError(f"{path}: faces {list(faces)} name a face twice")
    names = tuple(surfaces[k].label or f"face{k}" for k in chosen)
    return tuple(surfaces[k].patch for k in chosen), names


def cad_refinements(faces: Sequence, elements: int | None, levels: int) -> int:
    """Dyadic refinements of every face: at least ``levels - 1`` (the finest spline level
    refines the FE mesh), about ``elements`` FE elements in all (default 1000)."""
    coarse = sum(int(np.prod(f.n_elements)) for f in faces)
    target = elements or 1000
    return max(levels - 1, math.ceil(math.log(max(target / coarse, 1.0), 4) - 1e-9))


def cad_model(path: Path, faces: Sequence | None, elements: int | None,
              levels: int) -> NominalModel:
    """The nominal model of ``[geometry] kind = "cad"`` (see the module docstring)."""
    patches, names = cad_faces(path, faces)
    k = cad_refinements(patches, elements, levels)
    try:
        if len(patches) == 1 and max(patches[0].degrees) <= 2:
            model = nominal_model(patches[0], k, "Q9", name=names[0])
            return dataclasses.replace(model, face_names=names, element_face=np.zeros(
                model.mesh.n_elements, dtype=int))              # the VTU's `face`, all 0
        return part_model(patches, k, names, "Q9", name=Path(path).stem)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from err
