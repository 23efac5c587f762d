"""The gray-level residual of Eq. 3 and where it holds: edges and visibility of the integration points."""
