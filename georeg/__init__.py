"""georeg: FE stereo-DIC shape measurement with multilevel geometric (spline) regularization,
from Python.

The library's front: ``measure``, ``compare`` and ``track`` (as the ``georeg`` commands) on
Python values or a TOML file, and ``demo`` (the demo's rendered inputs). They build the very
objects the command line builds (:mod:`georeg_app`) and return results that save themselves::

    import georeg
    images, cameras, nominal, truth = georeg.demo()
    run = georeg.measure(images, cameras, nominal, method="georeg", levels=3)
    run.save("quickstart_out")

Nothing of the other packages imports this one.
"""
from georeg_app.config.measure import Config, GeometryConfig
from georeg_app.config.toml_schema import ConfigError, ConfigFileNotFoundError
from georeg_app.config.track import TrackConfig
from georeg_app.results import MeasurementFailed, SeriesRun, ShapeRun
from georeg_app.shape.demo import Truth
from georeg_app.version import installed_version

from georeg.api import (DemoInputs, Progress, compare, demo, load_config, load_track_config,
                        measure, track)

__version__ = installed_version()

__all__ = ["measure", "compare", "track", "demo", "load_config", "load_track_config",
           "ShapeRun", "SeriesRun", "DemoInputs", "Truth", "Progress", "MeasurementFailed",
           "Config", "TrackConfig", "GeometryConfig", "ConfigError", "ConfigFileNotFoundError",
           "__version__"]
