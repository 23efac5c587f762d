"""Benchmark: the edge margin (``MeasurementSettings.edge_margin_px``), end to end.

Issue 13 ("lower the floor"). The image model spreads the step at the specimen's edges
over about two pixels, differently in the two views (:mod:`fesdic_core.residual.edges`). This
measures what leaving out the points within ``margin`` px of the mesh's projected
boundary does to the RMS shape error against the true surface, over all nodes and over
the interior nodes (farther than 3 mm from the plate's edges), on the family of
``tests/scenes.py`` (``FAMILY``: 60 x 60 mm, 704 x 736 px, 40 x 40 Q9 elements of 1.5 mm;
``--demo-scale``: ``FAMILY_DEMO_SCALE``, 96 x 80 mm at 0.1 mm/px, 1200 x 1000 px, 48 x 40
elements of 2 mm), rendered by the core's ray caster (6 x 6 rays per pixel, 4 px
speckle), exact cameras, scales (1, 0), noise 0 (8-bit rounding only) and 2 gray levels.

Methods: FE (no regularization) and georeg with 3 fixed levels (the paper's), at margins
0, 1, 2, 3, 4 px (``--margins``).

Run: ``python benchmarks/bench_edges.py [--demo-scale] [--shapes flat 5] [--noise 0 2]
[--margins 0 1 2 3 4]``
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parents[1] / "tests")]   # the packages before tests/, whose folders mirror them
import scenes  # noqa: E402
from shape_truth import bounded_shape_error, rms  # noqa: E402

from adapters.fesdic_core import georeg_solver, nominal_model  # noqa: E402
from fesdic_core.shape.driver import MeasurementSettings, measure  # noqa: E402
from fesdic_core.imaging.image import Image  # noqa: E402
from fesdic_core.synthetic.render import render_stereo, speckle_mm_for  # noqa: E402
from georeg_plugin.spline.geometries import rectangle  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demo-scale", action="store_true", help="FAMILY_DEMO_SCALE (1200 x 1000 px)")
    parser.add_argument("--shapes", nargs="+", default=["flat", "5"],
                        help="flat and divisors of the width for the bump's sigma")
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 2.0])
    parser.add_argument("--margins", type=float, nargs="+", default=[0.0, 1.0, 2.0, 3.0, 4.0])
    args = parser.parse_args()
    family = scenes.FAMILY_DEMO_SCALE if args.demo_scale else scenes.FAMILY
    print(f"machine: {platform.platform()}, {os.cpu_count()} cpus, "
          f"load average {os.getloadavg()[0]:.1f} at start")
    cameras = scenes.family_cameras(family)
    model = nominal_model(rectangle(family["length_mm"], family["width_mm"]), family["elements"], "Q9")
    nodes = model.mesh.nodes
    interior = (np.abs(nodes[:, 0]) < family["length_mm"] / 2 - 3.0) & \
        (np.abs(nodes[:, 1]) < family["width_mm"] / 2 - 3.0)
    print(f"{'shape':>8s} {'noise':>5s} {'margin':>6s}  {'FE all':>7s} {'FE int':>7s}  "
          f"{'G3 all':>7s} {'G3 int':>7s}  (um)   time FE / G3 (s)")
    for shape in args.shapes:
        divisor = None if shape == "flat" else int(shape)
        specimen = scenes.family_specimen(divisor, speckle_mm_for(cameras[0], family["speckle_px"]),
                                          family)
        for noise in args.noise:
            arrays = render_stereo(specimen, cameras, supersample=family["supersample"],
                                   noise_std=noise, seed=family["noise_seed"], progress=False)
            images = [Image.from_array(a) for a in arrays]
            for margin in args.margins:
                settings = MeasurementSettings(scales=(1, 0), uncertainty=False, edge_margin_px=margin)
                cells, times = [], []
                for solver in (None, georeg_solver(model, 3)):
                    t0 = time.perf_counter()
                    m = measure(model.mesh, images, cameras, solver, settings)
                    times.append(time.perf_counter() - t0)
                    e = 1e3 * bounded_shape_error(m.nodes, specimen)
                    flag = "" if m.ok else "!"
                    cells += [f"{rms(e):6.2f}{flag or ' '}", f"{rms(e[interior]):6.2f} "]
                print(f"{shape:>8s} {noise:5.1f} {margin:6.1f}  {cells[0]} {cells[1]}  {cells[2]} "
                      f"{cells[3]}        {times[0]:.1f} / {times[1]:.1f}", flush=True)
    print("(! : the measurement's verdict failed)")


if __name__ == "__main__":
    main()
