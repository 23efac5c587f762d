"""Shape error against a known surface, modulo SMALL rigid motions (test helper).

``fesdic_core.accuracy.shape_error_to_surface`` aligns with an unbounded rigid motion; on a
surface with a localized feature the alignment may carry the points away from the feature
(tests/fesdic_core/test_accuracy_localized.py documents it). Here the alignment is the same
least squares on the point-to-surface distance, with the motion bounded to what a pose error
can be (default 2 degrees, 2 mm), so a localized feature cannot be dodged.
"""
import cv2
import numpy as np
from scipy.optimize import least_squares


def _normal_distance(specimen, X):
    gx, gy = specimen.height_gradient(X[:, 0], X[:, 1])
    return (X[:, 2] - specimen.height(X[:, 0], X[:, 1])) / np.sqrt(1.0 + gx ** 2 + gy ** 2)


def _moved(X, p, centre):
    R, _ = cv2.Rodrigues(p[:3].reshape(3, 1))
    return (X - centre) @ R.T + centre + p[3:]


def bounded_shape_error(points, specimen, max_angle_deg=2.0, max_shift_mm=2.0):
    """Signed distances (n,) of ``points`` to the true surface after the best rigid motion
    of at most ``max_angle_deg`` (each rotation-vector component) and ``max_shift_mm``."""
    points = np.asarray(points, float)
    centre = points.mean(axis=0)
    a, t = np.radians(max_angle_deg), float(max_shift_mm)
    bound = np.r_[np.full(3, a), np.full(3, t)]
    fit = least_squares(lambda p: _normal_distance(specimen, _moved(points, p, centre)),
                        np.zeros(6), bounds=(-bound, bound), method="trf",
                        x_scale=np.r_[np.full(3, 1e-3), np.full(3, 1e-2)])
    return _normal_distance(specimen, _moved(points, fit.x, centre))


def rms(values):
    return float(np.sqrt(np.mean(np.square(values))))
