"""Benchmark: one full-scale shape Gauss-Newton iteration of the core, and the interpolation.

Scene: a 2448 x 2048 px stereo pair (two cameras at 25 deg, 80 mm field, distortion as the
Stereo DIC Challenge rig, 4 px speckle, noise of 2 gray levels) of a twisted 72 x 60 mm plate
that covers most of each image, meshed with 36 x 28 = 1008 Q9 elements.

Printed: the machine; integration points; the median wall time of ``--repeat`` iterations
split into its stages (points X_g, residual = projection + interpolation + pull-back +
normalisation, assembly of H_FE and b_FE (Eq. 8), sparse solve), and the process's peak
resident memory; then the interpolation alone (value + gradient) of 5 million points with
the compiled kernel, its numpy twin and, for reference, ``scipy.ndimage.map_coordinates``
(value only); and the interpolation error on a known smooth image
``f = 128 + 100 sin(2 pi x / L) cos(2 pi y / L)`` for wavelengths L of 4, 8 and 16 px.
The interpolation part is run for each B-spline order of ``--orders`` (3 cubic, the default;
5 quintic, its own compiled 6 x 6 kernel); ``--interpolation-only`` skips the iteration.

Run: ``python benchmarks/bench_core_iteration.py [--repeat 5] [--threads N] [--orders 3 5]
[--interpolation-only]``
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import resource
import statistics
import time

import numpy as np

from fesdic_core import parallel


def _machine() -> str:
    return (f"{platform.platform()}, {platform.processor() or platform.machine()}, "
            f"{os.cpu_count()} cpus, python {platform.python_version()}, numpy {np.__version__}")


def _median_time(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def iteration(repeat: int) -> None:
    from fesdic_core.fe.mesh import node_normals, rectangle_mesh
    from fesdic_core.fe.quadrature import pixel_quadrature
    from fesdic_core.imaging.image import Image
    from fesdic_core.residual.graylevel import gray_level_residual
    from fesdic_core.shape.operators import current_nodes, shape_operators
    from fesdic_core.solve.solvers import DirectSolver
    from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
    from fesdic_core.synthetic.specimen import twisted_plate

    dist = np.array([-0.06, 0.1, 0.0, 0.0, 0.0])
    cams = demo_cameras(image_size=(2448, 2048), stereo_angle_deg=25.0, field_mm=80.0, dist=dist)
    specimen = twisted_plate(90.0, 75.0, corner_mm=0.5)
    specimen = dataclasses.replace(specimen, speckle_mm=speckle_mm_for(cams[0], 4.0))
    t = time.perf_counter()
    arrays = render_stereo(specimen, cams, supersample=1, noise_std=2.0, seed=1, progress=False)
    images = [Image.from_array(a, f"cam{k}") for k, a in enumerate(arrays)]
    print(f"render + prefilter: {time.perf_counter() - t:.1f} s")
    mesh = rectangle_mesh(72.0, 60.0, 36, 28, "Q9")
    normals = node_normals(mesh)
    t_quad, quad = _median_time(lambda: pixel_quadrature(mesh, cams), repeat)
    print(f"mesh: {mesh.n_elements} Q9 elements, {mesh.n_nodes} nodes; "
          f"integration points: {quad.n_points:,} (quadrature built in {t_quad:.2f} s)")
    q = np.zeros(mesh.n_nodes)
    solver = DirectSolver()
    stages = {"points": [], "residual": [], "assembly": [], "solve": [], "total": []}
    for _ in range(repeat + 1):                                    # the first one warms up
        t = [time.perf_counter()]
        X = quad.points(current_nodes(mesh.nodes, normals, q))
        t.append(time.perf_counter())
        res = gray_level_residual(X, quad, images, cams, "element", "point")
        t.append(time.perf_counter())
        H, b = shape_operators(quad, normals, res)
        t.append(time.perf_counter())
        solver.solve(H, b, q, 0)
        t.append(time.perf_counter())
        for name, dt in zip(stages, list(np.diff(t)) + [t[-1] - t[0]]):
            stages[name].append(dt)
    seen = int(res.mask.sum())
    print(f"one shape Gauss-Newton iteration at full scale ({seen:,} points seen in both views), "
          f"median of {repeat}:")
    for name, values in stages.items():
        print(f"  {name:9s} {statistics.median(values[1:]):7.3f} s")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2   # kB -> GB (Linux)
    print(f"peak resident memory of the process: {peak:.2f} GB")


def interpolation(repeat: int, order: int = 3) -> None:
    from scipy import ndimage

    from fesdic_core.imaging import bspline3, bspline5, image as image_module
    from fesdic_core.imaging.image import Image

    h, w, n = 2048, 2448, 5_000_000
    rng = np.random.default_rng(0)
    image = Image.from_array(rng.uniform(0.0, 255.0, (h, w)), "random", order=order)
    xy = np.column_stack([rng.uniform(0, w - 1, n), rng.uniform(0, h - 1, n)])
    xy = xy[np.lexsort((xy[:, 0], np.floor(xy[:, 1] / 32.0)))]     # bands of rows, as elements
    compiled, twin = ((image_module.COMPILED_KERNEL5, bspline5.evaluate_numpy) if order == 5
                      else (image_module.COMPILED_KERNEL, bspline3.evaluate_numpy))
    print(f"\ninterpolation of {n:,} points in a {w} x {h} image, B-spline order {order} "
          f"(median of {repeat}, load average {os.getloadavg()[0]:.2f}):")
    if compiled:
        t, _ = _median_time(lambda: image.evaluate_with_gradient(xy), repeat)
        print(f"  compiled kernel, value + gradient: {t:.3f} s ({image_module.__name__}, "
              f"{parallel.default_pool().threads} threads)")
    value, grad = np.empty(n), np.empty((n, 2))
    t, _ = _median_time(lambda: twin(image._padded, h, w, xy, value, grad), max(1, repeat // 2))
    print(f"  numpy twin, value + gradient:      {t:.3f} s (one thread)")
    t, _ = _median_time(lambda: ndimage.map_coordinates(image.coefficients, [xy[:, 1], xy[:, 0]],
                                                        order=order, prefilter=False, mode="mirror"),
                        max(1, repeat // 2))
    print(f"  scipy map_coordinates, value only: {t:.3f} s (one thread)")
    print("\ninterpolation error on f = 128 + 100 sin(2 pi x / L) cos(2 pi y / L), "
          "1e6 random points, in gray levels (gradient in gray levels / px):")
    yy, xx = np.mgrid[0:512, 0:512].astype(float)
    pts = np.column_stack([rng.uniform(8, 503, 1_000_000), rng.uniform(8, 503, 1_000_000)])
    for L in (4.0, 8.0, 16.0):
        k = 2 * np.pi / L
        smooth = Image.from_array(128 + 100 * np.sin(k * xx) * np.cos(k * yy), f"L={L:g}", order=order)
        v, g = smooth.evaluate_with_gradient(pts)
        x, y = pts[:, 0], pts[:, 1]
        exact = 128 + 100 * np.sin(k * x) * np.cos(k * y)
        gx, gy = 100 * k * np.cos(k * x) * np.cos(k * y), -100 * k * np.sin(k * x) * np.sin(k * y)
        ev, eg = v - exact, np.hypot(g[:, 0] - gx, g[:, 1] - gy)
        print(f"  L = {L:4.0f} px: value max {np.abs(ev).max():.2e} rms {np.sqrt(np.mean(ev ** 2)):.2e};"
              f" gradient max {eg.max():.2e} rms {np.sqrt(np.mean(eg ** 2)):.2e} "
              f"(amplitude 100, gradient amplitude {100 * k:.0f})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--threads", type=int, default=None,
                        help="threads of the core (default: FESDIC_THREADS, else all CPUs)")
    parser.add_argument("--orders", type=int, nargs="+", default=[3], choices=(3, 5),
                        help="B-spline orders of the interpolation timing (3 cubic, 5 quintic)")
    parser.add_argument("--interpolation-only", action="store_true", help="skip the iteration")
    args = parser.parse_args()
    if args.threads is not None:
        parallel.set_threads(args.threads)
    print(f"machine: {_machine()}; threads: {parallel.default_pool().threads}")
    if not args.interpolation_only:
        iteration(args.repeat)
    for order in dict.fromkeys(args.orders):
        interpolation(args.repeat, order)


if __name__ == "__main__":
    main()
