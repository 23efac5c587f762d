"""Build of the compiled kernels (metadata lives in setup.cfg).

``fesdic_core._bspline`` and ``fesdic_core._bspline5`` are the fused bicubic and biquintic
B-spline interpolation of images (value and gradient). They are optional: without a C
compiler the install goes on and ``fesdic_core.image`` falls back to its numpy
implementations (same results, slower).
"""
from setuptools import Extension, setup

setup(ext_modules=[Extension("fesdic_core._bspline", ["fesdic_core/_bspline.c"], optional=True),
                   Extension("fesdic_core._bspline5", ["fesdic_core/_bspline5.c"], optional=True)])
