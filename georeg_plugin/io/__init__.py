"""Spline input/output: JSON, IGES 5.3 and CAD parts through OpenCASCADE (the optional ``cad`` extra)."""

from georeg_plugin.io.cad_kernel import (CadFace, kernel_available, read_kernel_faces,
                                         kernel_triangles, STEP_SUFFIXES, IGES_SUFFIXES)
from georeg_plugin.io.iges import IgesSurface, read_iges_surfaces, read_iges_surface_entity
from georeg_plugin.io.spline_io import (write_spline_json, read_spline_json, read_scalar_field,
                                        write_part_json, read_part_json, write_iges, read_iges)

__all__ = ["CadFace", "kernel_available", "read_kernel_faces", "kernel_triangles", "STEP_SUFFIXES",
           "IGES_SUFFIXES", "IgesSurface", "read_iges_surfaces", "read_iges_surface_entity",
           "write_spline_json", "read_spline_json", "read_scalar_field", "write_part_json",
           "read_part_json", "write_iges", "read_iges"]
