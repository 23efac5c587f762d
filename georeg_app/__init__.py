"""The ``georeg`` application: command line, pipeline, outputs and report."""
from importlib import metadata

import _georeg_moved  # noqa: F401  (old import paths, kept for one release)


def installed_version() -> str:
    """The installed version of ``georeg`` ("unknown" when it is not installed)."""
    try:
        return metadata.version("georeg")
    except metadata.PackageNotFoundError:
        return "unknown"
