"""Shape error against a known surface, modulo SMALL rigid motions (test helper).

The tests' gauge is a pose error of at most 2 degrees and 2 mm, tighter than the library's
default bound (:func:`fesdic_core.synthetic.accuracy.shape_error_to_surface`, 5 degrees and 5 % of
the extent): a localized feature of the truth cannot be dodged by the alignment.
"""
import numpy as np

from fesdic_core.synthetic.accuracy import shape_error_to_surface


def bounded_shape_error(points, specimen, max_angle_deg=2.0, max_shift_mm=2.0):
    """Signed distances (n,) of ``points`` to the true surface after the best rigid motion
    of at most ``max_angle_deg`` (each rotation-vector component) and ``max_shift_mm``."""
    return shape_error_to_surface(np.asarray(points, float), specimen,
                                  max_rotation_rad=np.radians(max_angle_deg),
                                  max_shift_mm=max_shift_mm)


def rms(values):
    return float(np.sqrt(np.mean(np.square(values))))
