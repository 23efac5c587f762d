"""The import paths of the flat layout of release 0.1, kept for one release.

Release 0.2 put the modules of ``fesdic_core``, ``georeg_plugin`` and ``georeg_app`` into
subpackages named after the paper's pipeline (``fesdic_core.driver`` is now
``fesdic_core.shape.driver``). An old path still imports, with a :class:`DeprecationWarning`,
and gives the very module at its new path (``sys.modules`` holds one object under both
names, so a monkeypatch through either is seen by both). The three old modules whose names
are now packages (``fesdic_core.residual``, ``fesdic_core.shape``,
``fesdic_core.displacement``, ``georeg_app.config``, ``georeg_app.report``) keep their public
names through the packages' exports.
Each package's ``__init__`` imports this module, which installs the finder once.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import types
import warnings

#: old dotted path -> new dotted path
MOVED: dict[str, str] = {
    "fesdic_core.image": "fesdic_core.imaging.image",
    "fesdic_core.bspline5": "fesdic_core.imaging.bspline5",
    "fesdic_core.noise": "fesdic_core.imaging.noise",
    "fesdic_core.camera": "fesdic_core.cameras.camera",
    "fesdic_core.rig": "fesdic_core.cameras.rig",
    "fesdic_core.calibration_formats": "fesdic_core.cameras.io.formats",
    "fesdic_core.calibration_xml": "fesdic_core.cameras.io.vic3d_dice",
    "fesdic_core.calibration_values": "fesdic_core.cameras.io.values",
    "fesdic_core.elements": "fesdic_core.fe.elements",
    "fesdic_core.mesh": "fesdic_core.fe.mesh",
    "fesdic_core.mesh_io": "fesdic_core.fe.mesh_io",
    "fesdic_core.quadrature": "fesdic_core.fe.quadrature",
    "fesdic_core.edges": "fesdic_core.residual.edges",
    "fesdic_core.visibility": "fesdic_core.residual.visibility",
    "fesdic_core.solvers": "fesdic_core.solve.solvers",
    "fesdic_core.gauss_newton": "fesdic_core.solve.gauss_newton",
    "fesdic_core.damping": "fesdic_core.solve.damping",
    "fesdic_core.tikhonov": "fesdic_core.solve.tikhonov",
    "fesdic_core.tikhonov_choice": "fesdic_core.solve.tikhonov_choice",
    "fesdic_core.calibration": "fesdic_core.shape.calibration",
    "fesdic_core.gauge": "fesdic_core.shape.gauge",
    "fesdic_core.driver": "fesdic_core.shape.driver",
    "fesdic_core.uncertainty": "fesdic_core.shape.uncertainty",
    "fesdic_core.displacement_residual": "fesdic_core.displacement.residual",
    "fesdic_core.displacement_solvers": "fesdic_core.displacement.solvers",
    "fesdic_core.displacement_strain": "fesdic_core.displacement.strain",
    "fesdic_core.render": "fesdic_core.synthetic.render",
    "fesdic_core.accuracy": "fesdic_core.synthetic.accuracy",
    "georeg_plugin.bspline": "georeg_plugin.spline.bspline",
    "georeg_plugin.patch": "georeg_plugin.spline.patch",
    "georeg_plugin.refine": "georeg_plugin.spline.refine",
    "georeg_plugin.geometries": "georeg_plugin.spline.geometries",
    "georeg_plugin.fe_mesh": "georeg_plugin.spline.fe_mesh",
    "georeg_plugin.trimmed": "georeg_plugin.spline.trimmed",
    "georeg_plugin.conforming": "georeg_plugin.spline.conforming",
    "georeg_plugin.operators": "georeg_plugin.levels.operators",
    "georeg_plugin.curved": "georeg_plugin.levels.curved",
    "georeg_plugin.multipatch": "georeg_plugin.levels.multipatch",
    "georeg_plugin.selection": "georeg_plugin.levels.selection",
    "georeg_plugin.solver": "georeg_plugin.levels.solver",
    "georeg_plugin.spline_io": "georeg_plugin.io.spline_io",
    "georeg_plugin.iges": "georeg_plugin.io.iges",
    "georeg_app.toml_schema": "georeg_app.config.toml_schema",
    "georeg_app.track_config": "georeg_app.config.track",
    "georeg_app.cad": "georeg_app.inputs.cad",
    "georeg_app.cad_kernel": "georeg_plugin.io.cad_kernel",
    "georeg_app.pipeline": "georeg_app.shape.pipeline",
    "georeg_app.methods": "georeg_app.shape.methods",
    "georeg_app.run_visibility": "georeg_app.shape.visibility",
    "georeg_app.outputs": "georeg_app.shape.outputs",
    "georeg_app.track": "georeg_app.series.track",
    "georeg_app.track_dask": "georeg_app.series.dask",
    "georeg_app.track_outputs": "georeg_app.series.outputs",
    "georeg_app.track_report": "georeg_app.report.track",
    "georeg_app.figures": "georeg_app.report.figures",
    "georeg_app.maps": "georeg_app.report.maps",
    "georeg_app.provenance": "georeg_app.report.provenance",
    "georeg_app.run_view": "georeg_app.report.run_view",
}


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old path of :data:`MOVED` and loads it as the module at its new path."""

    def find_spec(self, fullname: str, path=None, target=None) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        new = MOVED[spec.name]
        warnings.warn(f"{spec.name} has moved to {new}; the old path goes in the next release",
                      DeprecationWarning, stacklevel=2)
        return importlib.import_module(new)

    def exec_module(self, module: types.ModuleType) -> None:
        """Nothing to run: the module at the new path is already imported."""


if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
    sys.meta_path.append(_MovedModuleFinder())
