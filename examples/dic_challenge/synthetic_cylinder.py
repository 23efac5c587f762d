"""Does the method bias the radius of a bar? Synthetic images of the vertical bar, measured.

The real rig (pyvale's calibration posed by the landmarks of ``specimen.toml``) looks at a
rendered half-cylinder along the vertical bar's axis, speckle of about 7 px, noise of 1.5
gray levels (:mod:`fesdic_core.render`, ray casting onto ``z = h(x, y)``; the renderer's
Newton does not follow the step from the bar down to the plate, so the plate shows the
background: only the bar is measured).
Two true radii are rendered: the laser's 6.38 mm (axis 0.23 mm below the plate) and
6.23 mm (axis at the plate). Each pair is measured exactly like the real one
(``cylinder_v.toml``: the cylindrical nominal of radius 6.38 mm, and the flat nominal at
crest height; scales 3, 2, 1, 0; initial pose off by 0.3 mm and 0.1 degree) and the
least-squares cylinder of the measured surface is compared with the truth.

Usage: ``python examples/dic_challenge/synthetic_cylinder.py`` (about 1 minute).
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from challenge import analysis                                           # noqa: E402
from challenge.config import load_face                                   # noqa: E402
from challenge.measure import initial_cameras, load_images, measure_nominal  # noqa: E402
from fesdic_core.gauge import move_cameras_with_specimen                 # noqa: E402
from fesdic_core.image import Image                                      # noqa: E402
from fesdic_core.render import Specimen, render_stereo, speckle_mm_for   # noqa: E402

#: window of the stored images around the vertical bar, both views (x0, y0, w, h) px
WINDOW = (1330, 80, 340, 760)
AXIS_X_MM = 40.89


def bar_specimen(radius_mm: float, axis_z_mm: float, speckle_mm: float) -> Specimen:
    """A 101.6 mm plate with a half cylinder along y at ``x = AXIS_X_MM``."""
    def height(x, y):
        u = np.asarray(x, float) - AXIS_X_MM
        return np.maximum(0.0, axis_z_mm + np.sqrt(np.maximum(radius_mm ** 2 - u ** 2, 1e-6)))

    def gradient(x, y):
        u = np.asarray(x, float) - AXIS_X_MM
        on = height(x, y) > 0.0
        dz = np.where(on, -u / np.sqrt(np.maximum(radius_mm ** 2 - u ** 2, 1e-6)), 0.0)
        return dz, np.zeros_like(dz)

    return Specimen(101.6, 101.6, height=height, height_gradient=gradient,
                    speckle_mm=speckle_mm, seed=5)


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    face = load_face(HERE / "cylinder_v.toml")
    real = load_images(face.specimen, WINDOW)
    cameras = initial_cameras(face.specimen, real, WINDOW)
    speckle = speckle_mm_for(cameras[0], 7.0)
    start = move_cameras_with_specimen(cameras, np.array([0.3, -0.2, 0.1]),
                                       np.radians(0.1) * np.array([0.6, 0.8, 0.0]), np.zeros(3))
    print(f"{'true radius':>12} {'nominal':>20} {'fitted radius':>14} {'error':>9} {'fit RMS':>8}")
    for radius, axis_z in ((6.38, -0.23), (6.23, 0.0)):
        arrays = render_stereo(bar_specimen(radius, axis_z, speckle), cameras, supersample=3,
                               noise_std=1.5, seed=3, progress=False)
        images = [Image.from_array(a, f"synthetic cam{k}") for k, a in enumerate(arrays)]
        for nominal in face.nominals:
            r = measure_nominal(face, nominal, images, start)
            P = r.points_mm[r.seen]
            fit = analysis.fit_cylinder(P, [0.0, 1.0, 0.0], 6.3)
            label = f"{nominal.kind} {nominal.radius_mm or ''}".strip()
            print(f"{radius:12.3f} {label:>20} {fit.radius_mm:14.4f} "
                  f"{1e3 * (fit.radius_mm - radius):7.1f}um {1e3 * fit.rms_mm:6.2f}um")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
