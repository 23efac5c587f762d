"""Images of Eq. 3: the image model (prefilter + B-spline interpolant), its gradient, pyramids and the images' noise."""

from fesdic_core.imaging.image import (Image, ImageError, read_image, pyramid, COMPILED_KERNEL,
                                       DEFAULT_PREFILTER_PX, check_prefilter, ORDERS, DEFAULT_ORDER,
                                       check_order, COMPILED_KERNEL5)
from fesdic_core.imaging.noise import (CONSISTENCY_FACTOR, MIN_TEXTURE_RATIO, NoiseFloor,
                                       immerkaer_sigma, immerkaer_response, residual_noise_floor)

__all__ = ["Image", "ImageError", "read_image", "pyramid", "COMPILED_KERNEL",
           "DEFAULT_PREFILTER_PX", "check_prefilter", "ORDERS", "DEFAULT_ORDER", "check_order",
           "COMPILED_KERNEL5", "CONSISTENCY_FACTOR", "MIN_TEXTURE_RATIO", "NoiseFloor",
           "immerkaer_sigma", "immerkaer_response", "residual_noise_floor"]
