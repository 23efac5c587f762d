"""The quintic B-spline of the image model (``order=5`` in :mod:`fesdic_core.imaging.image`).

``f(x, y) = sum_kl c_kl b5(y - k) b5(x - l)`` with the coefficients ``c`` of
``scipy.ndimage.spline_filter(order=5, mode="mirror")`` (computed by the image), evaluated
with its exact gradient by one 6x6 tensor-product sum over the coefficients (nodes
``i-2 .. i+3`` in each direction) read from a copy padded by :data:`PAD` = 3 on each side.
The sum runs in the compiled kernel ``fesdic_core.imaging._bspline.evaluate5`` (beside the cubic
``evaluate``, sharing its fold and its checks) or, without a C compiler at install, in the numpy twin
:func:`evaluate_numpy` (same arithmetic, about 20x slower). Coordinates are folded into
``[0, n - 1]`` by the mirror symmetry, as for the cubic (:func:`fesdic_core.imaging.kernels.fold`).
"""
from __future__ import annotations

import numpy as np

from fesdic_core.imaging.kernels import compiled, tensor_sum_numpy

__all__ = ["COMPILED", "PAD", "weights", "evaluate_compiled", "evaluate_numpy"]

#: True when the compiled 6x6 kernel is in use (else the numpy twin)
COMPILED = compiled is not None
#: coefficient padding: covers the 6x6 support of x in [0, n - 1]
PAD = 3

#: 120 w_a(t) = sum_p _POLY[a, p] t^p: b5 at the distances t+2, t+1, t, 1-t, 2-t, 3-t
_POLY = np.array([[1, -5, 10, -10, 5, -1],
                  [26, -50, 20, 20, -20, 5],
                  [66, 0, -60, 0, 30, -10],
                  [26, 50, 20, -20, -20, 10],
                  [1, 5, 10, 10, 5, -5],
                  [0, 0, 0, 0, 0, 1]], dtype=np.float64)


def weights(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quintic B-spline weights (m, 6) of the nodes ``i-2 .. i+3`` at ``i + t``, and their derivatives."""
    powers = np.asarray(t, dtype=np.float64)[:, None] ** np.arange(6)          # (m, 6): 1, t .. t^5
    return (powers @ (_POLY.T / 120.0),
            powers[:, :5] @ ((_POLY[:, 1:] * np.arange(1, 6)).T / 120.0))


def evaluate_compiled(padded: np.ndarray, h: int, w: int, xy: np.ndarray, value: np.ndarray,
                      grad: np.ndarray) -> None:
    """Fill ``value`` (n,) and ``grad`` (n, 2) at ``xy`` (n, 2) with the compiled kernel.

    ``padded``: the (h, w) coefficients padded by :data:`PAD` (numpy "reflect"), raveled.
    """
    compiled.evaluate5(padded, h, w, PAD, xy, value, grad)


def evaluate_numpy(padded: np.ndarray, h: int, w: int, xy: np.ndarray, value: np.ndarray,
                   grad: np.ndarray) -> None:
    """The numpy twin of the compiled kernel (the image model's tensor sum with these weights)."""
    tensor_sum_numpy(padded, h, w, PAD, xy, value, grad, weights, 6)
