"""The cubic B-spline of the image model (``order=3`` in :mod:`fesdic_core.imaging.image`).

``f(x, y) = sum_kl c_kl b3(y - k) b3(x - l)`` with the coefficients of
``scipy.ndimage.spline_filter(order=3, mode="mirror")``, evaluated with its exact gradient by
one 4x4 tensor-product sum over the coefficients (nodes ``i-1 .. i+2`` in each direction) read
from a copy padded by :data:`PAD` = 2 on each side: in the compiled kernel
``fesdic_core.imaging._bspline.evaluate`` or, without a C compiler at install, in the numpy
twin :func:`evaluate_numpy` (same arithmetic, about 10x slower).
"""
from __future__ import annotations

import numpy as np

from fesdic_core.imaging.kernels import compiled, tensor_sum_numpy

__all__ = ["COMPILED", "PAD", "weights", "evaluate_compiled", "evaluate_numpy"]

#: True when the compiled 4x4 kernel is in use (else the numpy twin)
COMPILED = compiled is not None
#: coefficient padding: covers the 4x4 support of x in [0, n - 1]
PAD = 2


def weights(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic B-spline weights (m, 4) of the nodes ``i-1 .. i+2`` at ``i + t``, and their derivatives."""
    t = t[:, None]
    s = 1.0 - t
    t2 = t * t
    w = np.hstack([s * s * s, 3.0 * t2 * t - 6.0 * t2 + 4.0, -3.0 * t2 * t + 3.0 * t2 + 3.0 * t + 1.0,
                   t2 * t]) * (1.0 / 6.0)
    dw = np.hstack([-s * s, 3.0 * t2 - 4.0 * t, -3.0 * t2 + 2.0 * t + 1.0, t2]) * 0.5
    return w, dw


def evaluate_compiled(padded: np.ndarray, h: int, w: int, xy: np.ndarray, value: np.ndarray,
                      grad: np.ndarray) -> None:
    """Fill ``value`` (n,) and ``grad`` (n, 2) at ``xy`` (n, 2) with the compiled kernel."""
    compiled.evaluate(padded, h, w, PAD, xy, value, grad)


def evaluate_numpy(padded: np.ndarray, h: int, w: int, xy: np.ndarray, value: np.ndarray,
                   grad: np.ndarray) -> None:
    """The numpy twin of the compiled cubic kernel."""
    tensor_sum_numpy(padded, h, w, PAD, xy, value, grad, weights, 4)
