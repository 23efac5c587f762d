"""Benchmark: the joint Gauss-Newton on poses and shape against the paper's fixed point.

Issue 25, items 1-2. The same measurement with ``coupling = "joint"`` (one Gauss-Newton on
the poses and the shape, :mod:`fesdic_core.shape.joint`) and ``coupling = "alternate"`` (the
fixed point of section 2.2), side by side in one run:

- ``plate6``, ``plate12``: the twisted 60 x 40 mm plate of the tests (640 x 480 px, no
  noise), the poses started 1 degree and 1 mm off; 6 pose unknowns (stereo kept), or 12
  (camera 1 further 0.1 degree off);
- ``part`` (``--part``): the Stereo DIC Challenge part from its STEP file
  (``examples/dic_challenge/specimen_part.toml``, needs the ``cad`` extra and the data).

Printed per case and coupling: median in-process time of ``--repeat`` runs, final residual,
iterations, the verdict, the finest scale's stop and the joint run's decrement (the plain
step's predicted fall at the final state, in chi-square units: the gradient against its
noise), then (``--trace``) the residual and step of every iteration at the finest scale.
Errors against the truth for the plates (RMS distance to the true surface, stereo
correspondence in px).

    PYTHONPATH=. python benchmarks/bench_coupling.py [--part] [--repeat 3] [--trace]
"""
from __future__ import annotations

import argparse
import logging
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fesdic_core.fe.mesh import rectangle_mesh                                 # noqa: E402
from fesdic_core.imaging.image import Image                                    # noqa: E402
from fesdic_core.shape.driver import MeasurementSettings, measure              # noqa: E402
from fesdic_core.shape.gauge import move_cameras_with_specimen                 # noqa: E402
from fesdic_core.solve.solvers import DirectSolver                             # noqa: E402
from fesdic_core.synthetic.accuracy import (shape_error_to_surface,            # noqa: E402
                                            stereo_correspondence_error)
from fesdic_core.synthetic.render import demo_cameras, render_stereo           # noqa: E402
from fesdic_core.synthetic.specimen import twisted_plate                       # noqa: E402

COUPLINGS = ("joint", "alternate")


def _plate(twelve: bool):
    specimen = twisted_plate(60.0, 40.0, corner_mm=0.5, speckle_mm=0.4, seed=3)
    cameras = demo_cameras(image_size=(640, 480), field_mm=72.0)
    arrays = render_stereo(specimen, cameras, supersample=3, noise_std=0.0, seed=1, progress=False)
    images = tuple(Image.from_array(a, source=f"cam{k}") for k, a in enumerate(arrays))
    rotation = np.deg2rad(1.0) * np.array([1.0, 2.0, -1.0]) / np.sqrt(6.0)
    start = move_cameras_with_specimen(cameras, np.array([0.6, -0.48, 0.64]), rotation, np.zeros(3))
    if twelve:
        start[1] = move_cameras_with_specimen(start[1:], np.zeros(3),
                                              np.deg2rad(0.1) * np.array([0, 1.0, 0]),
                                              np.zeros(3))[0]
    mesh = rectangle_mesh(60.0, 40.0, 12, 8, family="Q4")

    def run(coupling: str):
        m = measure(mesh, images, start, DirectSolver(),
                    MeasurementSettings(scales=(2, 1, 0), calibrate=True, keep_stereo=not twelve,
                                        coupling=coupling))
        shape = shape_error_to_surface(m.nodes, specimen)
        stereo = stereo_correspondence_error(m.nodes, m.cameras, cameras, specimen)
        errors = (f"shape {1e3 * np.sqrt(np.mean(shape ** 2)):.2f} um, stereo "
                  f"{np.sqrt(np.mean(stereo ** 2)):.4f} px")
        return m, errors
    return run


def _part():
    from georeg_app.config import load_config
    from georeg_app.shape.pipeline import run_methods

    def run(coupling: str):
        import dataclasses
        config = load_config(ROOT / "examples/dic_challenge/specimen_part.toml")
        config = dataclasses.replace(config, method=dataclasses.replace(config.method,
                                                                          coupling=coupling))
        result = run_methods(config)
        m = result.results[0].measurement
        return m, "figures: examples/dic_challenge/analyse_part.py"
    return run


def _finest_trace(m) -> list[str]:
    finest = m.scales[-1].scale
    return [f"    {r.get('stage', ''):>11} fp {r.get('fixed_point', '')!s:>2} it "
            f"{r.get('iteration', '')!s:>2}: residual {r['residual_percent']:.4f} %, "
            f"step {r.get('step', float('nan')):.2e} mm"
            for r in m.history if r.get("scale") == finest]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", action="store_true", help="also the Stereo DIC Challenge part")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--trace", action="store_true", help="every finest-scale iteration")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.2f}")
    cases = {"plate6": _plate(False), "plate12": _plate(True)}
    if args.part:
        cases["part"] = _part()
    for name, run in cases.items():
        for coupling in COUPLINGS:
            times = []
            for _ in range(args.repeat if name != "part" else 1):
                t0 = time.perf_counter()
                m, errors = run(coupling)
                times.append(time.perf_counter() - t0)
            finest = [r for r in m.history if r.get("scale") == m.scales[-1].scale]
            print(f"{name:8} {coupling:9}: {statistics.median(times):7.1f} s, residual "
                  f"{m.residual_percent:.4f} % (noise floor {m.noise_percent:.3f} %), "
                  f"{m.iterations} iterations ({len(finest)} at the finest scale), "
                  f"{'ok' if m.ok else 'failed: ' + str(m.failure)}; {errors}")
            if args.trace:
                print("\n".join(_finest_trace(m)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
