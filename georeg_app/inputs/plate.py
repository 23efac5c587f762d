"""``[geometry] kind = "rectangle"`` and ``"plate_with_hole"``: the nominal plate as one spline patch.

The rectangle is a flat B-spline patch split into near-square knot spans; the plate with a
central hole is the paper's single NURBS patch (section 4.1, Fig. 7(a)).
"""
from __future__ import annotations

from georeg_plugin.spline.geometries import plate_with_hole, rectangle
from georeg_plugin.spline.patch import SplinePatch
from georeg_plugin.spline.refine import refine_to_elements

from georeg_app.config.measure import GeometryConfig

__all__ = ["coarse_patch"]


def coarse_patch(geometry: GeometryConfig) -> SplinePatch:
    """The coarsest nominal spline (the CAD model) of ``[geometry]``."""
    if geometry.kind == "plate_with_hole":
        return plate_with_hole(geometry.length_mm, geometry.width_mm, geometry.hole_radius_mm)
    if geometry.kind == "rectangle":
        patch = rectangle(geometry.length_mm, geometry.width_mm)
        aspect = geometry.length_mm / geometry.width_mm
        n_u, n_v = (max(1, round(aspect)), 1) if aspect >= 1 else (1, max(1, round(1 / aspect)))
        return patch if (n_u, n_v) == (1, 1) else refine_to_elements(patch, n_u, n_v)[0]
    raise ValueError(f"[geometry] kind {geometry.kind!r} has no spline of its own")
