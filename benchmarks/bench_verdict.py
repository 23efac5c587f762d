"""Benchmark: the verdict of a measurement, residual against the images' noise floor.

One rendered scene (twisted 60 x 40 mm plate, 0.5 mm at the corners, 640 x 480 px, about
4 px speckle), measured by FE over scales (2, 1, 0): without and with 2 gray levels of
noise at the true cameras, and the nonsense a user can feed it, calibrating from the
given cameras: the two images swapped, camera 1 turned by 10 degrees, and images of pure
noise (refused before any computing). Prints the final residual, the noise floor
(:mod:`fesdic_core.imaging.noise`), their ratio and the verdict (a ratio above 3 fails; a
shape that leaves its bounds at a coarse scale stops the measurement there).

Run: ``python benchmarks/bench_verdict.py``
"""
from __future__ import annotations

import logging
import os
import platform

import numpy as np

from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.imaging.image import Image
from fesdic_core.shape.driver import (MeasurementInputError, MeasurementSettings, ShapeDivergedError,
                                      measure)
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import twisted_plate


def images_of(specimen, cameras, noise_std: float) -> tuple[Image, Image]:
    arrays = render_stereo(specimen, cameras, supersample=3, noise_std=noise_std, seed=1,
                           progress=False)
    return tuple(Image.from_array(a, source=f"cam{k}") for k, a in enumerate(arrays))


def main() -> None:
    logging.basicConfig(level=logging.ERROR)
    cameras = demo_cameras(image_size=(640, 480), field_mm=72.0)
    specimen = twisted_plate(60.0, 40.0, corner_mm=0.5, speckle_mm=speckle_mm_for(cameras[0], 4.0),
                             seed=3)
    mesh = rectangle_mesh(60.0, 40.0, 12, 8, family="Q4")
    clean, noisy = images_of(specimen, cameras, 0.0), images_of(specimen, cameras, 2.0)
    turned = list(cameras)
    turned[1] = turned[1].with_extrinsics(turned[1].extrinsics + np.r_[0.0, np.deg2rad(10.0), 0, 0, 0, 0])
    rng = np.random.default_rng(5)
    noise = tuple(Image.from_array(rng.uniform(0, 255, (480, 640)), source=f"noise{k}")
                  for k in range(2))
    cases = [("no noise, true cameras", clean, cameras, False),
             ("2 gray levels, true cameras", noisy, cameras, False),
             ("images swapped", noisy[::-1], cameras, True),
             ("camera 1 turned 10 deg", noisy, turned, True),
             ("pure-noise images", noise, cameras, True)]
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, python {platform.python_version()}")
    print(f"{'case':30s} {'residual %':>10s} {'floor %':>8s} {'ratio':>6s}  verdict")
    for name, images, cams, calibrate in cases:
        try:
            m = measure(mesh, images, cams, None,
                        MeasurementSettings(scales=(2, 1, 0), calibrate=calibrate))
        except MeasurementInputError as err:
            print(f"{name:30s} {'':>10s} {'':>8s} {'':>6s}  refused: {err}")
            continue
        except ShapeDivergedError as err:                 # stopped at a coarse scale
            print(f"{name:30s} {'':>10s} {'':>8s} {'':>6s}  FAILED: {str(err)[:60]}")
            continue
        verdict = "ok" if m.ok else f"FAILED: {m.failure[:60]}"
        print(f"{name:30s} {m.residual_percent:10.3f} {m.noise_percent:8.3f} "
              f"{m.residual_percent / m.noise_percent:6.2f}  {verdict}", flush=True)


if __name__ == "__main__":
    main()
