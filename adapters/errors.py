"""The exception family of :mod:`adapters`.

Every exception the adapters raise on purpose derives from :class:`AdapterError` and keeps
its built-in base as well, so ``except AdapterError`` catches the family and older
``except ValueError`` code still works. Anything else escaping the adapters is a bug.
"""
from __future__ import annotations

__all__ = ["AdapterError", "LevelMeshError"]


class AdapterError(Exception):
    """Base of the exceptions raised on purpose by :mod:`adapters`."""


class LevelMeshError(AdapterError, ValueError):
    """The FE mesh of a nominal model cannot carry the spline levels asked (Eq. 16: too few
    elements per knot span, or an element across a knot); the message names the mesh, the
    face or element, and the level."""
