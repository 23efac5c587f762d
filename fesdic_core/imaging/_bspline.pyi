"""Types of the compiled module ``fesdic_core.imaging._bspline`` (source: ``_bspline.c``)."""
import numpy as np

def evaluate(padded: np.ndarray, h: int, w: int, pad: int, xy: np.ndarray, value: np.ndarray,
             grad: np.ndarray | None) -> None:
    """Bicubic B-spline value (and gradient unless ``grad`` is None) at ``xy`` (n, 2), written
    into ``value`` (n,) and ``grad`` (n, 2); C-contiguous float64 buffers."""

def evaluate5(padded: np.ndarray, h: int, w: int, pad: int, xy: np.ndarray, value: np.ndarray,
              grad: np.ndarray | None) -> None:
    """The same for the biquintic B-spline."""
