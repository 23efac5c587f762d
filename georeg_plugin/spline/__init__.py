"""B-spline/NURBS patches (section 3.1), knot insertion (Eqs. 13-15), nominal geometries and the FE mesh made from a spline (Eq. 17)."""

from georeg_plugin.spline.bspline import (validate_knots, n_functions, basis_matrix, compact_basis,
                                          greville, insertion_matrix, span_breaks)
from georeg_plugin.spline.conforming import conforming_faces
from georeg_plugin.spline.fe_mesh import (SplineFEMesh, fe_mesh_from_spline, check_element_degree,
                                          ELEMENT_DEGREES, ElementDegreeError)
from georeg_plugin.spline.geometries import (rectangle, plate_with_hole, cylinder,
                                             arc_control_points, quadrilateral, transformed)
from georeg_plugin.spline.patch import SplinePatch, invert_points
from georeg_plugin.spline.refine import insert_knots, refine_uniform, refine_to_elements, midpoints, linear_patch
from georeg_plugin.spline.trimmed import inside_loops, trim_mesh, grid_triangles, FOOTPRINT_SHRINK

__all__ = ["validate_knots", "n_functions", "basis_matrix", "compact_basis", "greville",
           "insertion_matrix", "span_breaks", "conforming_faces", "SplineFEMesh",
           "fe_mesh_from_spline", "check_element_degree", "ELEMENT_DEGREES", "ElementDegreeError",
           "rectangle", "plate_with_hole", "cylinder", "arc_control_points", "quadrilateral",
           "transformed", "SplinePatch", "invert_points", "insert_knots", "refine_uniform",
           "refine_to_elements", "midpoints", "linear_patch", "inside_loops", "trim_mesh", "grid_triangles",
           "FOOTPRINT_SHRINK"]
