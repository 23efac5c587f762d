"""Spline input/output: JSON, IGES 5.3 and CAD parts through OpenCASCADE (the optional ``cad`` extra)."""
