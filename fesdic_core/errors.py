"""The exception family of :mod:`fesdic_core`.

Every exception the core raises on purpose derives from :class:`FesdicCoreError` and keeps
its built-in base as well (``class MeshError(FesdicCoreError, ValueError)``), so a caller may
catch the whole family with ``except FesdicCoreError`` and older ``except ValueError`` code
still works. Anything else escaping the core (a ``TypeError``, a ``KeyError``) is a bug.
"""
from __future__ import annotations

__all__ = ["FesdicCoreError"]


class FesdicCoreError(Exception):
    """Base of the exceptions raised on purpose by :mod:`fesdic_core` (bad input, a
    measurement that cannot go on); the message names the file, value or step at fault."""
