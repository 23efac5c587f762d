"""The installed version of the ``georeg`` distribution."""
from importlib import metadata

__all__ = ["installed_version"]


def installed_version() -> str:
    """The installed version of ``georeg`` ("unknown" when it is not installed)."""
    try:
        return metadata.version("georeg")
    except metadata.PackageNotFoundError:
        return "unknown"
