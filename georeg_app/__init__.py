"""georeg_app: the ``georeg`` command line, its runs, outputs and reports.

- :mod:`georeg_app.config`: the TOML files of ``measure``, ``compare`` and ``track``;
- :mod:`georeg_app.inputs`: the nominal model of each geometry kind, and the cameras;
- :mod:`georeg_app.shape`: ``georeg measure`` and ``compare`` (methods, run, output files);
- :mod:`georeg_app.series`: ``georeg track`` (reference, frames, Dask, output files);
- :mod:`georeg_app.report`: figures and the HTML reports;
- :mod:`georeg_app.cli`: the command line itself.

The Python front of the whole package is :mod:`georeg` (``georeg.measure``, ``georeg.track``).
"""
import _georeg_moved  # noqa: F401  (the old flat import paths, kept for one release)

from georeg_app.errors import USER_ERRORS, GeoregError, InputError, MeasurementFailed
from georeg_app.version import installed_version

__all__ = ["installed_version", "GeoregError", "InputError", "MeasurementFailed", "USER_ERRORS"]
