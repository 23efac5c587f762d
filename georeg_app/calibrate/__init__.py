"""``georeg calibrate``: a stereo rig from pairs of target images.

:mod:`~georeg_app.calibrate.config` (the TOML), :mod:`~georeg_app.calibrate.run` (detect,
calibrate, compare, check), :mod:`~georeg_app.calibrate.outputs` (the files).
"""
from georeg_app.calibrate.config import CalibrateConfig, load_calibrate_config
from georeg_app.calibrate.outputs import calibration_summary, write_calibration
from georeg_app.calibrate.run import CalibrationRun, run_calibration

__all__ = ["CalibrateConfig", "load_calibrate_config", "CalibrationRun", "run_calibration",
           "calibration_summary", "write_calibration"]
