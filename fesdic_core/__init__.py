"""The FE stereo-DIC core (the "legacy" code): images, cameras, FE mesh, residual, solve, shape, displacement."""
import _georeg_moved  # noqa: F401  (old import paths, kept for one release)
