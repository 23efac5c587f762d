"""The surface FE mesh (Eq. 4): element families, geometry map, normals, mesh I/O and the pixel quadrature."""

from fesdic_core.fe.elements import (ElementFamily, FAMILIES, family_from_meshio, centroid,
                                     gauss_rule)
from fesdic_core.fe.mesh import (CellBlock, SurfaceMesh, MeshError, map_points, tangents,
                                 surface_jacobian, element_areas, nodal_areas, node_normals,
                                 validate_mesh, rectangle_mesh, edges, boundary_edges,
                                 boundary_nodes, assemble)
from fesdic_core.fe.mesh_io import read_mesh, write_mesh
from fesdic_core.fe.quadrature import ElementGroup, PixelQuadrature, subdivisions, pixel_quadrature

__all__ = ["ElementFamily", "FAMILIES", "family_from_meshio", "centroid", "gauss_rule", "CellBlock",
           "SurfaceMesh", "MeshError", "map_points", "tangents", "surface_jacobian",
           "element_areas", "nodal_areas", "node_normals", "validate_mesh", "rectangle_mesh",
           "edges", "boundary_edges", "boundary_nodes", "assemble", "read_mesh", "write_mesh",
           "ElementGroup", "PixelQuadrature", "subdivisions", "pixel_quadrature"]
