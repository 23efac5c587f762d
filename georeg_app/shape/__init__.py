"""``georeg measure`` and ``georeg compare``: the methods of a run, the run and its output files."""

from georeg_app.shape.demo import DEMO, Truth, demo_specimen, demo_config
from georeg_app.shape.methods import (MethodSpec, tikhonov_spec, georeg_spec, default_specs,
                                      measure_specs)
from georeg_app.shape.outputs import (SUMMARY_FILE, CONVERGENCE_FILE, REPORT_FILE,
                                      CONVERGENCE_COLUMNS, write_json_atomic, OutputWriter,
                                      safe_stem, method_stems, summary_dict, seen_fraction,
                                      write_method_vtu, convergence_rows, write_convergence_csv,
                                      write_spline_outputs, write_all)
from georeg_app.shape.pipeline import (MethodResult, RunResult, check_sizes, check_levels,
                                       describe_mesh, input_files, run_methods)
from georeg_app.shape.visibility import visibility_settings, scene_occluders

__all__ = ["DEMO", "Truth", "demo_specimen", "demo_config", "MethodSpec", "tikhonov_spec",
           "georeg_spec", "default_specs", "measure_specs", "SUMMARY_FILE", "CONVERGENCE_FILE",
           "REPORT_FILE", "CONVERGENCE_COLUMNS", "write_json_atomic", "OutputWriter", "safe_stem",
           "method_stems", "summary_dict", "seen_fraction", "write_method_vtu", "convergence_rows",
           "write_convergence_csv", "write_spline_outputs", "write_all", "MethodResult",
           "RunResult", "check_sizes", "check_levels", "describe_mesh", "input_files", "run_methods",
           "visibility_settings", "scene_occluders"]
