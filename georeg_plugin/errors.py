"""The exception family of :mod:`georeg_plugin`.

Every exception the plugin raises on purpose derives from :class:`GeoregPluginError` and
keeps its built-in base as well (``class NodesOutsidePatchError(GeoregPluginError,
ValueError)``), so ``except GeoregPluginError`` catches the family and older
``except ValueError`` code still works. Anything else escaping the plugin is a bug.
"""
from __future__ import annotations

__all__ = ["GeoregPluginError", "SplineFileError"]


class GeoregPluginError(Exception):
    """Base of the exceptions raised on purpose by :mod:`georeg_plugin` (a spline or CAD file
    that cannot be used, nodes off the patch, a singular projection)."""


class SplineFileError(GeoregPluginError, ValueError):
    """A spline file (JSON, IGES) that cannot be read; the message names the file."""
