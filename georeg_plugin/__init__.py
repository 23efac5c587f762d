"""georeg_plugin: multilevel spline spaces of the nominal geometry and the operators ``C_s``.

The geometric regularization of Colantonio et al. (2020), section 3, knowing nothing of
any DIC code: it takes plain arrays (FE node coordinates, connectivity, node normals) and
returns sparse operators and a solve hook.

- :mod:`georeg_plugin.spline`: B-spline/NURBS patches (Eqs. 11-12), knot insertion
  (Eqs. 13-15), the paper's geometries, the FE mesh made from a spline (Eq. 17);
- :mod:`georeg_plugin.levels`: the levels and their operators ``C_s`` (Eqs. 16, 26-28),
  parts of several faces, the level choice and the solve hook (Eqs. 18-21);
- :mod:`georeg_plugin.io`: spline JSON, IGES 5.3 and CAD parts (the ``cad`` extra).
"""
import _georeg_moved  # noqa: F401  (the old flat import paths, kept for one release)

from georeg_plugin import io, levels, spline
from georeg_plugin.errors import GeoregPluginError, SplineFileError
from georeg_plugin.io import read_iges, read_spline_json, write_iges, write_spline_json
from georeg_plugin.levels import (GeometricRegularization, MultilevelSpace, SingularProjectionError,
                                  component_levels, extraction_operator, multilevel_space,
                                  node_parameters)
from georeg_plugin.spline import (SplinePatch, fe_mesh_from_spline, plate_with_hole, rectangle,
                                  refine_uniform)

__all__ = ["io", "levels", "spline", "GeoregPluginError", "SplineFileError",
           "SplinePatch", "rectangle", "plate_with_hole", "refine_uniform", "fe_mesh_from_spline",
           "MultilevelSpace", "multilevel_space", "extraction_operator", "node_parameters",
           "component_levels", "GeometricRegularization", "SingularProjectionError",
           "read_spline_json", "write_spline_json", "read_iges", "write_iges"]
