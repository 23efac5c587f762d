"""Which visibility a run uses: the core's settings from ``[method]`` and the nominal model.

Self-occlusion (ray casting against the current surface, :mod:`fesdic_core.residual.visibility`) is
cast only where something can hide the measured surface; the faces of a CAD file that are
not measured are its extra occluders (a block's walls next to a plate).
"""
from __future__ import annotations

import numpy as np

from adapters.fesdic_core import NominalModel, is_curved
from fesdic_core.residual.visibility import VisibilitySettings

from georeg_app.config.measure import GeometryConfig, MethodConfig
from georeg_app.inputs.cad import cad_occluders

__all__ = ["visibility_settings", "scene_occluders"]


def visibility_settings(method: MethodConfig, model: NominalModel | None = None,
                        occluders: np.ndarray | None = None) -> VisibilitySettings | None:
    """The core's visibility settings of ``[method] self_occlusion, max_view_angle_deg``
    (None when both are off: every point kept).

    Self-occlusion is cast only where something can hide the surface: a part of several
    faces, a curved face, or ``occluders`` (the CAD faces that are not measured). A single
    flat face cannot hide itself, and the ray casting (about 1.4 s on the demo's mesh) is
    skipped there.
    """
    angle = None if method.max_view_angle_deg >= 90.0 else method.max_view_angle_deg
    can_hide = (model is None or model.is_part or is_curved(model) or occluders is not None)
    occlusion = method.self_occlusion and can_hide
    if not occlusion and angle is None:
        return None
    return VisibilitySettings(self_occlusion=occlusion, max_view_angle_deg=angle,
                              extra_occluders=occluders if occlusion else None)


def scene_occluders(geometry: GeometryConfig) -> np.ndarray | None:
    """Triangles (m, 3, 3) mm of what the nominal CAD holds besides the measured faces
    (``[geometry] kind = "cad"`` with ``faces``), else None."""
    if geometry.kind != "cad":
        return None
    return cad_occluders(geometry.file, geometry.faces)
