"""Benchmark: the basin of convergence of the fixed point (calibration + shape, section 2.2).

For each shape amplitude (twist of the 60 x 40 mm plate at its corners) and each error of
the initial specimen pose (a rotation about the specimen centre and a translation, along
fixed generic axes), one measurement runs with the georeg solver (3 spline levels) over
image scales (3, 2, 1, 0), from the flat nominal, as ``georeg measure`` does. Reported: the
measurement's own verdict (ok, or why it failed), whether it recovered the truth (shape
RMS error below 2 % of the twist and stereo correspondence error below 0.05 px), the final
residual against the noise floor, and the time. A run that did not recover must say so
itself: "recovered NO" with verdict "ok" would be a silent failure, and is counted.

Scene: 800 x 600 px cameras (72 mm field, 25 deg stereo angle), speckle of about 4 px,
Gaussian noise of 2 gray levels; Q9 mesh made from the spline (Eq. 17).

Run: ``python benchmarks/bench_basin.py [--twists 0.5,1,2,4] [--poses 1,1 2,2 4,4 6,6]``
"""
from __future__ import annotations

import argparse
import logging
import os
import platform
import time

import numpy as np

from adapters.fesdic_core import georeg_solver, nominal_model
from fesdic_core.imaging.image import Image
from fesdic_core.shape.driver import MeasurementSettings, measure
from fesdic_core.shape.gauge import move_cameras_with_specimen
from fesdic_core.synthetic.accuracy import shape_error_to_surface, stereo_correspondence_error
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import twisted_plate
from georeg_plugin.spline.geometries import rectangle

AXIS_ROTATION = np.array([1.0, 2.0, -1.0]) / np.sqrt(6.0)     # fixed, generic directions
AXIS_TRANSLATION = np.array([0.6, -0.48, 0.64])               # unit norm


def scene(twist_mm: float, size=(800, 600)):
    cameras = demo_cameras(image_size=size, field_mm=72.0)
    specimen = twisted_plate(60.0, 40.0, corner_mm=twist_mm,
                             speckle_mm=speckle_mm_for(cameras[0], 4.0), seed=3)
    arrays = render_stereo(specimen, cameras, supersample=3, noise_std=2.0, seed=1, progress=False)
    return specimen, cameras, tuple(Image.from_array(a, source=f"cam{k}") for k, a in enumerate(arrays))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--twists", default="0.5,1,2,4", help="twist at the corners (mm), list")
    parser.add_argument("--poses", nargs="+", default=["1,1", "2,2", "4,4", "6,6"],
                        help="pose errors as degrees,mm pairs")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR, format="%(message)s")
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, python {platform.python_version()}")
    print(f"{'twist mm':>8} {'pose error':>11} {'time s':>7} {'residual %':>10} {'floor %':>8} "
          f"{'shape um':>9} {'stereo px':>9} {'recovered':>9}  verdict")
    model = nominal_model(rectangle(60.0, 40.0), 3, "Q9")
    silent = 0
    for twist in (float(v) for v in args.twists.split(",")):
        specimen, cameras, images = scene(twist)
        for pose in args.poses:
            deg, mm = (float(v) for v in pose.split(","))
            start = move_cameras_with_specimen(cameras, mm * AXIS_TRANSLATION,
                                               np.deg2rad(deg) * AXIS_ROTATION, np.zeros(3))
            t0 = time.perf_counter()
            m = measure(model.mesh, images, start, georeg_solver(model, 3),
                        MeasurementSettings(scales=(3, 2, 1, 0), calibrate=True))
            elapsed = time.perf_counter() - t0
            shape = 1e3 * float(np.sqrt(np.mean(shape_error_to_surface(m.nodes, specimen) ** 2)))
            stereo = float(np.sqrt(np.nanmean(
                stereo_correspondence_error(m.nodes, m.cameras, cameras, specimen) ** 2)))
            recovered = shape < 20.0 * twist and stereo < 0.05
            silent += int(m.ok and not recovered)
            verdict = "ok" if m.ok else f"FAILED: {m.failure[:70]}"
            print(f"{twist:8.2f} {f'{deg:g} deg/{mm:g} mm':>11} {elapsed:7.1f} "
                  f"{m.residual_percent:10.3f} {m.noise_percent:8.3f} {shape:9.1f} {stereo:9.4f} "
                  f"{'yes' if recovered else 'NO':>9}  {verdict}", flush=True)
    print(f"silent failures (verdict ok, truth not recovered): {silent}")


if __name__ == "__main__":
    main()
