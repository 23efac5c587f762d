"""Benchmark: where the time of one shape measurement goes, and its end-to-end median.

The measurement is the one of ``georeg measure`` with fixed levels: the geometric
regularization (3 spline levels), image scales (2, 1, 0), calibration of the extrinsics
(the fixed point of section 2.2) and the end-of-measurement uncertainty
(:mod:`fesdic_core.shape.uncertainty`). Scenes (rendered once, pixel-area integrated):

- ``demo``: the demo's twisted open-hole plate with waviness (georeg_app.shape.demo.DEMO),
  1224 x 816 px, noise of 2 gray levels, poses perturbed by 0.5 deg / 0.5 mm;
- ``bump``: the shape family at the demo's scale (tests/scenes.py ``FAMILY_DEMO_SCALE``),
  1200 x 1000 px, a 96 x 80 mm plate with a bump of sigma = width / 5, 48 x 40 Q9 elements,
  exact cameras, noise of 2 gray levels.

Printed: the machine and load; per scene, the median wall time of ``measure()`` over
``--repeat`` runs (everything inside it, the image pyramid included), the shape error
against the truth (RMS after the best rigid alignment), the iterations per scale and stage,
and the breakdown of the median run into exclusive stage times (per image scale, plus the
uncertainty at the end): building the quadrature, the image pyramid, the noise floor, the
residual evaluations (by the derivative they carry), the assembly of ``H`` and ``b``
(Eq. 8), the step solve, the calibration's own algebra, and what is left.

Run: ``python benchmarks/bench_measure_speed.py [--repeat 5] [--scenes demo,bump]``
(with ``PYTHONPATH`` at the worktree to time a worktree).
"""
from __future__ import annotations

import argparse
import collections
import contextlib
import os
import pickle
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]   # the packages before tests/, whose folders mirror them

from adapters.fesdic_core import georeg_solver, nominal_model  # noqa: E402
from fesdic_core.shape import driver, operators as shape, uncertainty  # noqa: E402
from fesdic_core.shape import calibration  # noqa: E402
from fesdic_core.synthetic.accuracy import shape_error_to_surface  # noqa: E402
from fesdic_core.shape.driver import MeasurementSettings, measure  # noqa: E402


# ----------------------------------------------------------------------------- scenes
def demo_scene():
    from georeg_app.inputs.cameras import load_cameras
    from georeg_app.inputs.nominal import build_model
    from georeg_app.shape.demo import demo_config
    config, images, truth = demo_config("demo_out")              # nothing is written there
    cameras = load_cameras(config.cameras, images)
    return build_model(config.geometry, 3), images, cameras, truth.specimen


def bump_scene():
    from georeg_plugin.spline.geometries import rectangle
    from scenes import FAMILY_DEMO_SCALE, family_scene
    family = FAMILY_DEMO_SCALE
    scene = family_scene(5, family)
    model = nominal_model(rectangle(family["length_mm"], family["width_mm"]),
                          family["elements"], "Q9", name="family")
    return model, scene.images, list(scene.cameras), scene.specimen


SCENES = {"demo": demo_scene, "bump": bump_scene}


def load_scene(name: str, cache: Path | None):
    """The scene ``name``, rendered, or read from ``cache`` when it was rendered before."""
    path = None if cache is None else cache / f"bench_measure_speed_{name}.pkl"
    if path is not None and path.is_file():
        with open(path, "rb") as f:
            return pickle.load(f)
    scene = SCENES[name]()
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as f:
            pickle.dump(scene, f)
    return scene


# ----------------------------------------------------------------------------- timing
class StageTimer:
    """Exclusive wall time per (scale, stage): nested stages are subtracted from their caller."""

    def __init__(self) -> None:
        self.times = collections.defaultdict(float)
        self.calls = collections.Counter()
        self.stack: list[list] = []
        self.scale = "setup"

    @contextlib.contextmanager
    def stage(self, name: str):
        frame = [name, time.perf_counter(), 0.0]          # name, start, time of nested stages
        self.stack.append(frame)
        try:
            yield
        finally:
            elapsed = time.perf_counter() - frame[1]
            self.stack.pop()
            key = (self.scale, name)
            self.times[key] += elapsed - frame[2]
            self.calls[key] += 1
            if self.stack:
                self.stack[-1][2] += elapsed

    def wrap(self, fn, name):
        def wrapped(*args, **kwargs):
            label = name(*args, **kwargs) if callable(name) else name
            with self.stage(label):
                return fn(*args, **kwargs)
        return wrapped


@contextlib.contextmanager
def instrumented(timer: StageTimer, scales):
    """Patch the core's stages with timers (restored on exit)."""
    patches = []

    def patch(module, attr, name):
        original = getattr(module, attr)
        patches.append((module, attr, original))
        setattr(module, attr, timer.wrap(original, name))

    order = iter(scales)

    def quadrature_of_next_scale(*args, **kwargs):
        timer.scale = f"scale {next(order)}"
        with timer.stage("quadrature"):
            return original_quadrature(*args, **kwargs)

    def residual_name(*args, **kwargs):
        jacobian = args[5] if len(args) > 5 else kwargs.get("jacobian", "point")
        return f"residual ({jacobian or 'value'})"

    def uncertainty_stage(*args, **kwargs):
        timer.scale = "end"
        with timer.stage("uncertainty (rest)"):
            return original_uncertainty(*args, **kwargs)

    original_quadrature = driver.pixel_quadrature
    original_uncertainty = driver._uncertainty
    patches += [(driver, "pixel_quadrature", original_quadrature),
                (driver, "_uncertainty", original_uncertainty)]
    driver.pixel_quadrature = quadrature_of_next_scale
    driver._uncertainty = uncertainty_stage
    patch(driver, "pyramid", "image pyramid")
    patch(driver, "residual_noise_floor", "noise floor")
    patch(driver, "check_texture", "noise floor")
    patch(driver, "calibrate_extrinsics", "calibration (algebra)")
    patch(driver, "shape_gauss_newton", "shape GN (rest)")
    patch(driver, "transfer_rigid_part", "gauge")
    for module in (driver, shape, calibration, uncertainty):
        patch(module, "gray_level_residual", residual_name)
    for module in (shape, uncertainty):
        patch(module, "shape_operators", "assembly H, b")
    patch(shape, "chi_square", "chi-square")
    patch(uncertainty, "noise_model", "noise model (bootstrap)")
    patch(uncertainty, "shape_std", "shape std")
    patch(driver, "noise_model", "noise model (bootstrap)")
    patch(driver, "shape_std", "shape std")
    patch(driver, "linearised_state", "linearised state")
    try:
        yield
    finally:
        for module, attr, original in reversed(patches):
            setattr(module, attr, original)


class TimedSolver:
    """A step solver that times its hooks (and forwards the optional ones)."""

    def __init__(self, solver, timer: StageTimer) -> None:
        self._solver, self._timer = solver, timer

    def solve(self, H, b, q, scale):
        with self._timer.stage("solve"):
            return self._solver.solve(H, b, q, scale)

    def __getattr__(self, name):
        return getattr(self._solver, name)


# ----------------------------------------------------------------------------- run
def one_run(model, images, cameras, specimen, settings, timed: bool):
    timer = StageTimer()
    solver = georeg_solver(model, 3)
    context = instrumented(timer, settings.scales) if timed else contextlib.nullcontext()
    with context:
        t = time.perf_counter()
        m = measure(model.mesh, images, cameras, TimedSolver(solver, timer) if timed else solver,
                    settings)
        wall = time.perf_counter() - t
    error = shape_error_to_surface(m.nodes, specimen)
    return wall, m, float(np.sqrt(np.mean(error ** 2))), timer


def iterations_per_scale(m) -> str:
    count = collections.Counter((h["scale"], h["stage"][:3]) for h in m.history)
    parts = []
    for s in sorted({k[0] for k in count}, reverse=True):
        parts.append(f"s{s}: fp {next(r.fixed_point_iterations for r in m.scales if r.scale == s)} "
                     f"cal {count[(s, 'cal')]} shape {count[(s, 'sha')]}")
    return "; ".join(parts)


def breakdown(timer: StageTimer, wall: float) -> None:
    scales = list(dict.fromkeys(k[0] for k in timer.times))
    stages = list(dict.fromkeys(k[1] for k in timer.times))
    print(f"  {'stage':26s}" + "".join(f"{s:>16s}" for s in scales) + f"{'total':>9s}")
    for name in stages:
        row = [(timer.times.get((s, name), 0.0), timer.calls.get((s, name), 0)) for s in scales]
        total = sum(t for t, _ in row)
        cells = "".join(f"{t:9.3f} s ({n:2d})" if n else f"{'':16s}" for t, n in row)
        print(f"  {name:26s}{cells}{total:9.3f}")
    per_scale = [sum(t for (s, _), t in timer.times.items() if s == sc) for sc in scales]
    print(f"  {'all stages':26s}" + "".join(f"{t:9.3f} s     " for t in per_scale)
          + f"{sum(per_scale):9.3f}  (wall {wall:.3f} s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--scenes", default="demo,bump")
    parser.add_argument("--no-uncertainty", action="store_true")
    parser.add_argument("--coupling", default="joint", choices=("joint", "alternate"),
                        help="poses and shape: one joint Gauss-Newton, or the fixed point")
    parser.add_argument("--cache", type=Path, default=None,
                        help="folder where the rendered scenes are kept between runs (pickle)")
    args = parser.parse_args()
    from fesdic_core.imaging.image import COMPILED_KERNEL
    from fesdic_core.parallel import default_threads
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cpus, {default_threads()} threads, python {platform.python_version()}, "
          f"numpy {np.__version__}, compiled kernel {COMPILED_KERNEL}")
    print(f"code: {Path(driver.__file__).parents[1]}")
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    settings = MeasurementSettings(scales=(2, 1, 0), calibrate=True, coupling=args.coupling,
                                   uncertainty=not args.no_uncertainty)
    for name in args.scenes.split(","):
        t = time.perf_counter()
        model, images, cameras, specimen = load_scene(name, args.cache)
        print(f"\n== {name}: {images[0].shape[1]} x {images[0].shape[0]} px, "
              f"{model.mesh.n_elements} elements, {model.mesh.n_nodes} nodes "
              f"(render {time.perf_counter() - t:.1f} s)")
        one_run(model, images, cameras, specimen, settings, timed=False)          # warm up
        runs = [one_run(model, images, cameras, specimen, settings, timed=False)
                for _ in range(args.repeat)]
        walls = [r[0] for r in runs]
        wall, m, error, _ = runs[int(np.argsort(walls)[len(walls) // 2])]
        print(f"  measure(): median {statistics.median(walls):.3f} s over {args.repeat} runs "
              f"(min {min(walls):.3f}, max {max(walls):.3f}); error {error * 1e3:.3f} um; "
              f"residual {m.residual_percent:.4f}%; {'ok' if m.ok else 'FAILED: ' + m.failure}")
        if m.shape_std_mm is not None:
            print(f"  shape std: median {1e3 * np.nanmedian(m.shape_std_mm):.4f} um, "
                  f"kappa {m.noise.variance:.4g}")
        print(f"  iterations: {iterations_per_scale(m)}")
        timed = [one_run(model, images, cameras, specimen, settings, timed=True)
                 for _ in range(max(1, args.repeat // 2))]
        wall_t, _, _, timer = timed[int(np.argsort([r[0] for r in timed])[len(timed) // 2])]
        print("  breakdown of the median instrumented run (exclusive seconds, (calls)):")
        breakdown(timer, wall_t)
    print(f"\nload average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
