"""Geometric regularization: multilevel spline spaces of the nominal geometry and the operators C_s."""
import _georeg_moved  # noqa: F401  (old import paths, kept for one release)
