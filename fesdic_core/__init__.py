"""fesdic_core: a finite-element stereo digital image correlation code (the "legacy" code).

The pipeline of Colantonio et al. (2020), sections 2.1-2.2, one subpackage a step:

- :mod:`fesdic_core.imaging`: the images ``f``, ``g`` of Eq. 3 (image model, pyramids, noise);
- :mod:`fesdic_core.cameras`: the projection ``P_c`` of Eq. 3, the stereo rig and calibration files;
- :mod:`fesdic_core.fe`: the surface FE mesh (Eq. 4), mesh I/O and the pixel quadrature;
- :mod:`fesdic_core.residual`: the gray-level residual (Eq. 3, Remark 2), edges, visibility;
- :mod:`fesdic_core.solve`: the linear solve of each Gauss-Newton step (the one extension
  point, :class:`~fesdic_core.solve.StepSolver`, and its optional hooks), the damped loop,
  Tikhonov (Eq. 10);
- :mod:`fesdic_core.shape`: the shape (Eqs. 7-8), calibration (Eq. 6), the gauge, the
  multiscale fixed point, the uncertainty and the verdict;
- :mod:`fesdic_core.displacement`: displacements of the measured surface over a series;
- :mod:`fesdic_core.synthetic`: a renderer with a known truth, and accuracy against it.

The names below are the ones a program needs most; every subpackage exports its own.
"""
import _georeg_moved  # noqa: F401  (the old flat import paths, kept for one release)

from fesdic_core import cameras, displacement, fe, imaging, residual, shape, solve, synthetic
from fesdic_core.cameras import (Camera, CalibrationError, read_cameras_json, read_dice,
                                 read_opencv_stereo, read_pyvale_csv, read_vic3d, write_cameras_json)
from fesdic_core.checks import MeasurementInputError
from fesdic_core.displacement import (DisplacementMeasurement, DisplacementSettings,
                                      displacement_reference, measure_displacement)
from fesdic_core.errors import FesdicCoreError
from fesdic_core.fe import MeshError, SurfaceMesh, read_mesh, write_mesh
from fesdic_core.imaging import Image, ImageError, pyramid, read_image
from fesdic_core.shape import Measurement, MeasurementSettings, ShapeDivergedError, measure
from fesdic_core.solve import (BiasStepHook, DirectSolver, FactorizeHook, SingularSystemError,
                               StartScaleHook, StepCovarianceHook, StepSolver, TikhonovSolver)

__all__ = ["cameras", "displacement", "fe", "imaging", "residual", "shape", "solve", "synthetic",
           "FesdicCoreError",
           "Camera", "CalibrationError", "read_cameras_json", "write_cameras_json",
           "read_opencv_stereo", "read_vic3d", "read_dice", "read_pyvale_csv",
           "Image", "ImageError", "read_image", "pyramid",
           "SurfaceMesh", "MeshError", "read_mesh", "write_mesh",
           "StepSolver", "StartScaleHook", "StepCovarianceHook", "BiasStepHook", "FactorizeHook",
           "DirectSolver", "TikhonovSolver", "SingularSystemError",
           "MeasurementSettings", "Measurement", "measure", "MeasurementInputError",
           "ShapeDivergedError",
           "DisplacementSettings", "DisplacementMeasurement", "displacement_reference",
           "measure_displacement"]
