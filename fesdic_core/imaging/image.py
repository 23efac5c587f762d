"""Gray-level images ``f`` and ``g`` of Eq. 3: the image model (Gaussian prefilter + cubic
or quintic B-spline interpolant), its gradient, pyramids.

Pixel coordinates ``(x, y)`` = (column, row), pixel centres at integers, so the image
covers ``[-0.5, w - 0.5] x [-0.5, h - 0.5]``.

The image model. The pixel values are first smoothed by a sampled Gaussian of standard
deviation ``prefilter_px`` pixels (:func:`scipy.ndimage.gaussian_filter`, mode "mirror";
0 = no prefilter), then interpolated by the cubic B-spline
``f(x, y) = sum_kl c_kl b3(y - k) b3(x - l)`` through the smoothed values, with the
coefficients ``c`` computed once by :func:`scipy.ndimage.spline_filter` (mode "mirror":
the image is continued symmetrically about its first and last pixel centres, and so are
the coefficients). The prefilter lowers the sub-pixel bias of the interpolant and the
bias that the noise of the interpolated image adds (``benchmarks/bench_interpolation_bias.py``).
End to end on stereo shapes (``benchmarks/bench_image_model.py``,
docs/validation/interpolation_bias.md) it lowers the error where the sensor noise matters,
but an image-space blur is a different blur on the specimen in the two views and it mixes
the background into the texture along the specimen's edges: both grow with sigma. :data:`DEFAULT_PREFILTER_PX` is
the sigma with the lowest total error there. Both images of a pair must use the same
model (the residual compares them).

``Image.values`` stay the RAW pixel values (the noise floor of :mod:`fesdic_core.imaging.noise`
and the dynamic range are taken on them); only the interpolant (``coefficients``, what
:meth:`Image.evaluate` and :meth:`Image.evaluate_with_gradient` return) is smoothed.
:meth:`Image.with_values` builds an image of other raw values through the same model.

The gradient is the exact derivative of the spline; the value and the gradient are
evaluated together by one 4x4 tensor-product sum over the coefficients
(``b3' (t) = b2(t + 1/2) - b2(t - 1/2)``), which :func:`map_coordinates` cannot do since it
uses one spline order in both directions. That sum is the hot loop of every Gauss-Newton
iteration: it runs in the compiled kernel ``fesdic_core.imaging._bspline`` (one pass per point, the
points split over threads), or, if the package was installed without a C compiler, in the
vectorised numpy twin :func:`fesdic_core.imaging.bspline3.evaluate_numpy` (same arithmetic, about 10x slower).

``dynamic_range`` is ``max - min`` of the raw pixel values (of the data, not of the bit
depth): it is the scale of the gray-level residual reported in percent.

The interpolation order is a setting too (``order``, :data:`ORDERS`; default
:data:`DEFAULT_ORDER` = 3): ``order=5`` interpolates by the quintic B-spline
``sum_kl c_kl b5(y - k) b5(x - l)`` (coefficients by ``spline_filter(order=5)``, same
mirror boundary), whose value and gradient are one 6x6 sum, compiled in
``fesdic_core.imaging._bspline.evaluate5`` (numpy twin in :mod:`fesdic_core.imaging.bspline5`; 2-3x the cubic's time).
Its sub-pixel bias is lower (``benchmarks/bench_interpolation_bias.py``), but end to end
it changes the shape errors by a few percent at most (``bench_image_model.py --orders 3 5``,
docs/validation/interpolation_bias.md); its support is one pixel wider on each side, so
:meth:`Image.inside` keeps points 2.5 px inside the border instead of 1.5.

The multiscale images of Remark 3 (:meth:`Image.coarsen`) are 2x2 block means of the RAW
values, modelled with the same ``prefilter_px`` in coarse pixels (a coarse image is the
picture a camera of half the resolution would take, so it gets the same model; measured
in docs/validation/interpolation_bias.md); the matching camera is
:meth:`fesdic_core.cameras.camera.Camera.scaled`.
"""
from __future__ import annotations

import dataclasses
import logging
import os
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from fesdic_core.errors import FesdicCoreError
from fesdic_core.imaging import bspline3, bspline5
from fesdic_core.imaging.kernels import compiled as _bspline
from fesdic_core.parallel import for_each_block

logger = logging.getLogger(__name__)

__all__ = ["Image", "ImageError", "read_image", "pyramid", "COMPILED_KERNEL", "DEFAULT_PREFILTER_PX",
           "check_prefilter", "ORDERS", "DEFAULT_ORDER", "check_order", "COMPILED_KERNEL5"]

#: True when the fused C kernel is in use (else the numpy twin)
COMPILED_KERNEL = _bspline is not None

#: default standard deviation (px) of the Gaussian prefilter of the image model
#: (measured choice: benchmarks/bench_image_model.py, docs/validation/interpolation_bias.md)
DEFAULT_PREFILTER_PX = 0.5

#: the B-spline orders of the image model: 3 (cubic, 4x4 support) or 5 (quintic, 6x6)
ORDERS = (3, 5)
#: default interpolation order of the image model
DEFAULT_ORDER = 3
#: True when the quintic kernel is compiled (else its numpy twin)
COMPILED_KERNEL5 = bspline5.COMPILED

_BGR_TO_GRAY = np.array([0.114, 0.587, 0.299])                    # ITU-R BT.601, as cv2


class ImageError(FesdicCoreError, ValueError):
    """An image file or array that cannot be used (unreadable, non-finite, wrong shape)."""


_PARALLEL_BLOCK = 1 << 17         # points per block shared out over threads


def check_prefilter(prefilter_px: float) -> float:
    """``prefilter_px`` as a float; raises ValueError unless it is a finite number >= 0."""
    try:
        sigma = float(prefilter_px)
    except (TypeError, ValueError):
        raise ValueError(f"prefilter_px must be a number >= 0 (px), got {prefilter_px!r}") from None
    if not (np.isfinite(sigma) and sigma >= 0.0):
        raise ValueError(f"prefilter_px must be a finite number >= 0 (px), got {prefilter_px!r}")
    return sigma


def check_order(order: int) -> int:
    """``order`` as an int; raises ValueError unless it is one of :data:`ORDERS` (3 or 5)."""
    if isinstance(order, (bool, np.bool_)) or order not in ORDERS:
        raise ValueError(f"interpolation order must be one of {', '.join(map(str, ORDERS))}, got {order!r}")
    return int(order)


def _noise_gain(prefilter_px: float) -> float:
    """``sum w^2`` of the 1-D sampled Gaussian of :func:`scipy.ndimage.gaussian_filter` (1 for 0)."""
    if prefilter_px <= 0:
        return 1.0
    radius = int(4.0 * prefilter_px + 0.5)                     # scipy's default truncate = 4
    impulse = np.zeros(2 * radius + 1)
    impulse[radius] = 1.0
    weights = ndimage.gaussian_filter1d(impulse, prefilter_px, mode="constant")
    return float(np.sum(weights ** 2))


def _xy(xy: np.ndarray) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"image coordinates must have shape (n, 2), got {xy.shape}")
    return xy


@dataclass(frozen=True, eq=False)
class Image:
    """A gray-level image and its image model (Gaussian prefilter + cubic or quintic B-spline).

    Build it with :meth:`from_array` or :func:`read_image`; the constructor takes the
    coefficients as given (``prefilter_px`` then only records how they were made).

    Attributes
    ----------
    values : (h, w) float64 RAW pixel values (not prefiltered)
    coefficients : (h, w) B-spline coefficients (of ``order``) of the prefiltered values
        (mirror boundary)
    dynamic_range : ``max - min`` of ``values``
    source : file name or label, used in messages
    prefilter_px : standard deviation (px) of the Gaussian applied to ``values`` before the
        spline (0 = none)
    order : B-spline order of the interpolant, 3 (cubic) or 5 (quintic)
    """

    values: np.ndarray
    coefficients: np.ndarray
    dynamic_range: float
    source: str = "array"
    prefilter_px: float = 0.0
    order: int = DEFAULT_ORDER
    #: the coefficients padded for the kernels, raveled (set by ``__post_init__``)
    _padded: np.ndarray = dataclasses.field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for field in ("values", "coefficients"):
            a = np.asarray(getattr(self, field), dtype=np.float64)
            if a.ndim != 2 or min(a.shape) < 1:
                raise ImageError(f"image {self.source!r}: {field} must be a non-empty 2-D array, "
                                 f"got shape {a.shape}")
            if a.flags.writeable:                                  # never freeze a caller's array
                a = a.copy()
                a.flags.writeable = False
            object.__setattr__(self, field, a)
        if self.values.shape != self.coefficients.shape:
            raise ImageError(f"image {self.source!r}: coefficients shape {self.coefficients.shape} "
                             f"differs from values shape {self.values.shape}")
        try:
            object.__setattr__(self, "prefilter_px", check_prefilter(self.prefilter_px))
        except ValueError as err:
            raise ImageError(f"image {self.source!r}: {err}") from None
        try:
            object.__setattr__(self, "order", check_order(self.order))
        except ValueError as err:
            raise ImageError(f"image {self.source!r}: {err}") from None
        object.__setattr__(self, "dynamic_range", float(self.dynamic_range))
        pad = bspline5.PAD if self.order == 5 else bspline3.PAD
        padded = np.pad(self.coefficients, pad, mode="reflect")    # numpy "reflect" = scipy "mirror"
        object.__setattr__(self, "_padded", np.ascontiguousarray(padded).ravel())

    @classmethod
    def from_array(cls, a: np.ndarray, source: str = "array",
                   prefilter_px: float = DEFAULT_PREFILTER_PX, order: int = DEFAULT_ORDER) -> "Image":
        """Image of a 2-D array (h, w) of raw pixel values.

        Parameters
        ----------
        a : (h, w) pixel values (copied)
        source : file name or label, used in messages
        prefilter_px : standard deviation (px) of the Gaussian prefilter of the model
            (0 = the B-spline through the raw values)
        order : B-spline order of the interpolant, 3 (cubic) or 5 (quintic)

        Raises
        ------
        ImageError
            For NaN/inf values, a wrong shape, a negative or non-finite ``prefilter_px``, or
            an ``order`` other than 3 or 5.
        """
        values = np.array(a, dtype=np.float64)
        if values.ndim != 2 or min(values.shape) < 1:
            raise ImageError(f"image {source!r}: expected a non-empty 2-D array, got shape {values.shape}")
        bad = np.count_nonzero(~np.isfinite(values))
        if bad:
            raise ImageError(f"image {source!r}: {bad} non-finite (NaN/inf) pixel values")
        try:
            sigma = check_prefilter(prefilter_px)
            order = check_order(order)
        except ValueError as err:
            raise ImageError(f"image {source!r}: {err}") from None
        smoothed = ndimage.gaussian_filter(values, sigma, mode="mirror") if sigma > 0 else values
        coefficients = ndimage.spline_filter(smoothed, order=order, output=np.float64, mode="mirror")
        values.flags.writeable = coefficients.flags.writeable = False   # owned here: no copy
        return cls(values, coefficients, float(values.max() - values.min()), str(source), sigma, order)

    @property
    def noise_gain(self) -> float:
        """Standard deviation of the model's (prefiltered) pixel values per unit of white noise
        in the raw pixels: ``sum_n w_n^2`` for the 1-D weights ``w`` of the sampled Gaussian
        (the 2-D kernel is their outer product); 1 without prefilter (0.64 at 0.5 px, 0.31
        at 0.9 px). The noise floor of the residual (:mod:`fesdic_core.imaging.noise`) scales by it."""
        return _noise_gain(self.prefilter_px)

    def with_values(self, values: np.ndarray) -> "Image":
        """A new image of the raw pixel ``values`` (h', w') through the SAME model and source.

        E.g. to simulate noise through the image model: ``image.with_values(image.values + n)``.
        """
        return Image.from_array(values, self.source, prefilter_px=self.prefilter_px, order=self.order)

    def __repr__(self) -> str:
        h, w = self.values.shape
        return (f"Image(source={self.source!r}, {w}x{h} px, dynamic_range={self.dynamic_range:.6g}, "
                f"prefilter_px={self.prefilter_px:g}, order={self.order})")

    @property
    def shape(self) -> tuple[int, int]:
        """(h, w) in px."""
        return self.values.shape

    def evaluate(self, xy: np.ndarray) -> np.ndarray:
        """Gray levels of the model (prefiltered, interpolated) at ``xy`` (n, 2) = (x, y); returns (n,).

        The compiled kernel's value-only pass (the value of :meth:`evaluate_with_gradient`
        without its gradient), else (no compiler) scipy's :func:`map_coordinates` (the same
        interpolant).
        """
        xy = _xy(xy)
        if _bspline is None:
            return ndimage.map_coordinates(self.coefficients, [xy[:, 1], xy[:, 0]], order=self.order,
                                           mode="mirror", prefilter=False)
        xy = np.ascontiguousarray(xy)
        h, w = self.values.shape
        value = np.empty(len(xy))
        kernel, pad = (_bspline.evaluate5, bspline5.PAD) if self.order == 5 else (_bspline.evaluate, bspline3.PAD)

        def run(block: slice) -> None:
            kernel(self._padded, h, w, pad, xy[block], value[block], None)

        for_each_block(run, len(xy), _PARALLEL_BLOCK)
        return value

    def evaluate_with_gradient(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gray levels (n,) and exact spline gradient (n, 2) = [d/dx, d/dy] at ``xy`` (n, 2).

        ``f = sum_ab c[i+a, j+b] wy_a wx_b`` over the 4x4 support (6x6 for ``order`` 5),
        ``df/dx`` with ``wx'``, ``df/dy`` with ``wy'``. NaN coordinates give NaN.
        """
        xy = np.ascontiguousarray(_xy(xy))
        h, w = self.values.shape
        value = np.empty(len(xy))
        grad = np.empty((len(xy), 2))
        kernel = bspline3.evaluate_compiled if _bspline is not None else bspline3.evaluate_numpy
        if self.order == 5:
            kernel = bspline5.evaluate_compiled if bspline5.COMPILED else bspline5.evaluate_numpy

        def run(block: slice) -> None:
            kernel(self._padded, h, w, xy[block], value[block], grad[block])

        for_each_block(run, len(xy), _PARALLEL_BLOCK)
        return value, grad

    def gradient(self, xy: np.ndarray) -> np.ndarray:
        """Exact gradient (n, 2) = [d/dx, d/dy] of the interpolant at ``xy`` (n, 2)."""
        return self.evaluate_with_gradient(xy)[1]

    def inside(self, xy: np.ndarray, margin: float | None = None) -> np.ndarray:
        """(n,) bool: finite points at least ``margin`` px inside the image border.

        The border is the outer edge of the edge pixels (``-0.5`` and ``w - 0.5``). The
        default margin, ``order / 2`` (1.5 px cubic, 2.5 px quintic), keeps the points whose
        spline support reaches no coefficient beyond the first and last pixel centres.
        """
        xy = _xy(xy)
        margin = 0.5 * self.order if margin is None else margin
        h, w = self.values.shape
        lo = margin - 0.5
        with np.errstate(invalid="ignore"):
            return ((xy[:, 0] >= lo) & (xy[:, 0] <= w - 0.5 - margin)
                    & (xy[:, 1] >= lo) & (xy[:, 1] <= h - 0.5 - margin))

    def coarsen(self) -> "Image":
        """The next scale of Remark 3: 2x2 block means of the RAW values (an odd last
        row/column is dropped), with the same model (``prefilter_px`` in coarse pixels)."""
        h, w = self.values.shape
        if h < 2 or w < 2:
            raise ImageError(f"image {self.source!r}: {w}x{h} px is too small to coarsen")
        v = self.values[: h - h % 2, : w - w % 2]
        coarse = v.reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))
        return Image.from_array(coarse, f"{self.source} /2", prefilter_px=self.prefilter_px,
                                order=self.order)


def read_image(path: str | os.PathLike, prefilter_px: float = DEFAULT_PREFILTER_PX,
               order: int = DEFAULT_ORDER) -> Image:
    """Read an 8- or 16-bit (or float) TIFF/PNG as gray levels (colour is converted to gray).

    ``prefilter_px``, ``order``: the Gaussian prefilter and the B-spline order of the image
    model (see :meth:`Image.from_array`).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ImageError
        If OpenCV cannot decode it, or it holds NaN/inf values (or ``prefilter_px`` is
        negative or not finite, or ``order`` is not 3 or 5).
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"image file not found: {path}")
    a = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if a is None:
        raise ImageError(f"cannot read image file {path!r} (not an image OpenCV can decode)")
    a = a.astype(np.float64)
    if a.ndim == 3:
        if a.shape[2] == 1:
            a = a[:, :, 0]
        elif a.shape[2] in (3, 4):
            a = a[:, :, :3] @ _BGR_TO_GRAY                        # OpenCV stores BGR(A)
        else:
            raise ImageError(f"image file {path!r}: unsupported {a.shape[2]} channels")
    image = Image.from_array(a, source=path, prefilter_px=prefilter_px, order=order)
    logger.debug("read %s: %dx%d px, range %.6g", path, a.shape[1], a.shape[0], image.dynamic_range)
    return image


def pyramid(image: Image, n_scales: int) -> list[Image]:
    """Images of scales ``0 .. n_scales - 1`` (index = scale, 0 = finest), by :meth:`Image.coarsen`."""
    if int(n_scales) != n_scales or n_scales < 1:
        raise ValueError(f"n_scales must be a positive integer, got {n_scales!r}")
    levels = [image]
    for _ in range(int(n_scales) - 1):
        levels.append(levels[-1].coarsen())
    return levels
