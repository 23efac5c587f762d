"""The multilevel spline spaces, the operators C_s (Eqs. 16, 26-28), the level choice and the solve hook (Eqs. 18-21)."""

from georeg_plugin.levels.components import componentwise, component_levels
from georeg_plugin.levels.curved import (RANK_RTOL, vector_extraction, range_basis, is_flat,
                                         vector_gluing, VectorLevel, vector_level)
from georeg_plugin.levels.multipatch import (PartMesh, part_mesh, part_space, part_component_space,
                                             isolated_faces, NonConformingFacesError)
from georeg_plugin.levels.operators import (extraction_operator, node_parameters, MultilevelSpace,
                                            multilevel_space, nested_space, NodesOutsidePatchError)
from georeg_plugin.levels.selection import (LevelTrial, information_criterion, noise_gain,
                                            penalty_per_dof, predicted_fit)
from georeg_plugin.levels.solver import GeometricRegularization, SingularProjectionError
from georeg_plugin.levels.support import (LevelSupport, level_restriction, mesh_seen, dof_location,
                                          SLIVER_RATIO)

__all__ = ["componentwise", "component_levels", "RANK_RTOL", "vector_extraction", "range_basis",
           "is_flat", "vector_gluing", "VectorLevel", "vector_level", "PartMesh", "part_mesh",
           "part_space", "part_component_space", "isolated_faces", "NonConformingFacesError",
           "extraction_operator", "node_parameters", "MultilevelSpace", "multilevel_space",
           "nested_space", "NodesOutsidePatchError", "LevelTrial", "information_criterion",
           "noise_gain", "penalty_per_dof", "predicted_fit", "GeometricRegularization",
           "SingularProjectionError", "LevelSupport", "level_restriction", "mesh_seen",
           "dof_location", "SLIVER_RATIO"]
