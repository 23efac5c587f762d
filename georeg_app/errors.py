"""The exception family of the ``georeg`` application, and what the command line calls a
user error.

:class:`GeoregError` is the base of the application's own exceptions; each keeps a built-in
base too (``class InputError(GeoregError, ValueError)``), so older ``except ValueError`` code
still works. :data:`USER_ERRORS` is what ``georeg`` reports as one error line (exit status 1):
the four packages' bases and ``OSError`` (a file missing, unreadable or not writable). Any
other exception reaching the command line is a bug of georeg (:mod:`georeg_app.cli`).
"""
from __future__ import annotations

from adapters.errors import AdapterError
from fesdic_core.errors import FesdicCoreError
from georeg_plugin.errors import GeoregPluginError

__all__ = ["GeoregError", "InputError", "MeasurementFailed", "USER_ERRORS"]


class GeoregError(Exception):
    """Base of the exceptions raised on purpose by :mod:`georeg_app`."""


class InputError(GeoregError, ValueError):
    """Inputs of a run that do not fit together (image sizes, levels, frames, a reference
    folder); the message names the file or value at fault."""


class MeasurementFailed(GeoregError, RuntimeError):
    """The run finished but its measurement(s) cannot be trusted (the message says why)."""


#: the exceptions ``georeg`` reports as a user error (one line, exit status 1)
USER_ERRORS: tuple[type[BaseException], ...] = (FesdicCoreError, GeoregPluginError, AdapterError,
                                                GeoregError, OSError)
