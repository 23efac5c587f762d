"""Build of the one compiled module (metadata lives in setup.cfg).

``fesdic_core.imaging._bspline`` holds the fused bicubic and biquintic B-spline interpolation of
images (value and gradient). It is optional: without a C compiler the install goes on and
``fesdic_core.imaging.image`` falls back to its numpy implementations (same results, slower).
"""
from setuptools import Extension, setup

setup(ext_modules=[Extension("fesdic_core.imaging._bspline", ["fesdic_core/imaging/_bspline.c"], optional=True)])
