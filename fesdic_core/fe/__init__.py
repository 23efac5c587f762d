"""The surface FE mesh (Eq. 4): element families, geometry map, normals, mesh I/O and the pixel quadrature."""
