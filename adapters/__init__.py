"""adapters: the glue that drops the geometric regularization into an FE-DIC code.

- :mod:`adapters.protocol`: what a host FE-DIC code gives the plugin and gets back;
- :mod:`adapters.fesdic_core`: the plugin's solve hook in this project's core;
- :mod:`adapters.level_search`: the level chosen from the data, driven through the core;
- :mod:`adapters.pyxel`: the plugin in the third-party pyxel-dic, without changing it.
"""
from adapters.errors import AdapterError, LevelMeshError
from adapters.fesdic_core import (NominalModel, displacement_space, georeg_solver, measured_spline,
                                  keep_elements, measured_spline_std, nominal_model, part_model)
from adapters.level_search import LevelSearch, measure_auto_levels
from adapters.protocol import Adapter, LevelRecord, reduced_basis
from adapters.pyxel import PyxelAdapter, correlate_multilevel

__all__ = ["AdapterError", "LevelMeshError",
           "Adapter", "LevelRecord", "reduced_basis",
           "NominalModel", "nominal_model", "part_model", "keep_elements", "georeg_solver", "displacement_space",
           "measured_spline", "measured_spline_std",
           "LevelSearch", "measure_auto_levels",
           "PyxelAdapter", "correlate_multilevel"]
