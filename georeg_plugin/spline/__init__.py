"""B-spline/NURBS patches (section 3.1), knot insertion (Eqs. 13-15), nominal geometries and the FE mesh made from a spline (Eq. 17)."""
