"""The multilevel spline spaces, the operators C_s (Eqs. 16, 26-28), the level choice and the solve hook (Eqs. 18-21)."""
