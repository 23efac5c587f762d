"""Benchmark of the demo: the methods' accuracy and the multiscale claim (Fig. 11).

Renders the demo specimen once (twisted open-hole plate, two 1 Mpx cameras at 25 deg,
noise of 2 gray levels, specimen pose perturbed by 0.5 deg / 0.5 mm), then runs every
method of ``georeg compare`` ``--repeat`` times and prints, per method, the median wall
time, the final residual, the shape error against the truth and the iterations, then
the two claims of issue 4 evaluated on the run of median total time.

    python benchmarks/bench_demo.py [--repeat 3] [--methods all|georeg]
"""
from __future__ import annotations

import argparse
import logging
import os
import platform
import time

import numpy as np

from georeg_app.report.html import check_claims
from georeg_app.shape.demo import demo_config
from georeg_app.shape.methods import default_specs
from georeg_app.shape.pipeline import run_methods


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--methods", choices=("all", "georeg"), default="all",
                        help="all methods, or only georeg multiscale vs monoscale")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cpus")
    t = time.perf_counter()
    config, images, truth = demo_config("demo_out")          # nothing is written there
    print(f"render: {time.perf_counter() - t:.1f} s")
    specs = default_specs(config)
    if args.methods == "georeg":
        specs = [s for s in specs if s.name == "georeg"]
    runs, totals = [], []
    for k in range(args.repeat):
        t = time.perf_counter()
        runs.append(run_methods(config, specs, images=images, truth=truth))
        totals.append(time.perf_counter() - t)
        print(f"run {k + 1}/{args.repeat}: {totals[-1]:.1f} s")
    print(f"\n{'method':22s} {'time (s)':>9s} {'residual %':>11s} {'error (um)':>11s} "
          f"{'iterations':>10s}  verdict")
    for i, spec in enumerate(specs):
        results = [run.results[i] for run in runs]
        if any(r.measurement is None for r in results):
            print(f"{spec.label:22s} failed: {next(r.failure for r in results if r.measurement is None)}")
            continue
        verdicts = sorted({r.status if r.ok else f"failed: {r.failure}" for r in results})
        times = np.median([r.measurement.time_s for r in results])
        residual = np.median([r.measurement.residual_percent for r in results])
        error = np.median([r.shape_rms_error_mm for r in results]) * 1e3
        iterations = int(np.median([r.measurement.iterations for r in results]))
        print(f"{spec.label:22s} {times:9.1f} {residual:11.3f} {error:11.2f} {iterations:10d}  "
              f"{'; '.join(verdicts)}")
    median_run = runs[int(np.argsort(totals)[len(totals) // 2])]
    print(f"\nall methods: median {np.median(totals):.1f} s over {args.repeat} runs")
    for claim in check_claims(median_run):
        print(f"claim {claim.status}: {claim.name}\n    {claim.detail}")


if __name__ == "__main__":
    main()
