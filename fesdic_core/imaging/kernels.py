"""The B-spline kernels of the image model: the compiled module, and its numpy twin.

``compiled`` is the C module ``fesdic_core.imaging._bspline`` (fused value and gradient of
the cubic, ``evaluate``, and of the quintic, ``evaluate5``), built at install by setup.py, or
None without a C compiler. Its numpy twin :func:`tensor_sum_numpy` is shared by the cubic (:mod:`fesdic_core.imaging.bspline3`) and the quintic
(:mod:`fesdic_core.imaging.bspline5`) image models: coordinates folded into ``[0, n - 1]``
by the spline's mirror symmetry, then the ``size`` x ``size`` sum of the coefficients with
the 1-D weights and their derivatives, in blocks of points to bound memory.
"""
from __future__ import annotations

import numpy as np

try:
    from fesdic_core.imaging import _bspline as compiled  # compiled at install (setup.py), optional
except ImportError:                              # pragma: no cover - no C compiler at install
    compiled = None  # type: ignore[assignment]  # the module or None: callers test for None

__all__ = ["compiled", "fold", "tensor_sum_numpy"]

_BLOCK = 1 << 14                  # points per block of the numpy twin (bounds memory)


def fold(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Fold coordinates into ``[0, n - 1]`` by the spline's mirror symmetry; returns (x, d x_fold/d x)."""
    if n == 1:
        return np.zeros_like(x), np.zeros_like(x)
    period = 2.0 * (n - 1)
    xm = np.mod(x, period)
    back = xm > n - 1
    return np.where(back, period - xm, xm), np.where(back, -1.0, 1.0)


def tensor_sum_numpy(padded: np.ndarray, h: int, w: int, pad: int, xy: np.ndarray,
                     value: np.ndarray, grad: np.ndarray, weights, size: int) -> None:
    """Value and gradient of a B-spline of ``size`` x ``size`` support (4: cubic, 6: quintic)
    at ``xy``: the numpy twin of the compiled kernels (blocks of points to bound memory).

    ``padded``: the (h, w) coefficients padded by ``pad`` and raveled; ``weights(t)`` the
    1-D weights of the nodes ``i - size/2 + 1 .. i + size/2`` and their derivatives.
    """
    stencil = (np.arange(size)[:, None] * (w + 2 * pad) + np.arange(size)).ravel()
    first = pad - size // 2 + 1                   # offset of the support's first node
    for start in range(0, len(xy), _BLOCK):
        block = slice(start, start + _BLOCK)
        finite = np.isfinite(xy[block]).all(axis=1)
        pts = np.where(finite[:, None], xy[block], 0.0)            # NaN in, NaN out
        x, sx = fold(pts[:, 0], w)
        y, sy = fold(pts[:, 1], h)
        i, j = np.floor(y), np.floor(x)
        wy, dwy = weights(y - i)
        wx, dwx = weights(x - j)
        corner = (i.astype(np.int64) + first) * (w + 2 * pad) + j.astype(np.int64) + first
        c = padded.take(corner[:, None] + stencil).reshape(-1, size, size)
        cx = np.einsum("nab,nb->na", c, wx)
        cdx = np.einsum("nab,nb->na", c, dwx)
        value[block] = np.einsum("na,na->n", wy, cx)
        grad[block, 0] = sx * np.einsum("na,na->n", wy, cdx)
        grad[block, 1] = sy * np.einsum("na,na->n", dwy, cx)
        if not finite.all():
            value[block][~finite] = np.nan
            grad[block][~finite] = np.nan
