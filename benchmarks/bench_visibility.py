"""Benchmark: the visibility mask (:mod:`fesdic_core.visibility`), its time.

A corrugated sheet ``z = A sin(2 pi x / wavelength)`` (100 x 100 mm, A = 4 mm, wavelength
10 mm: slopes up to 68 deg, so the crests hide part of the troughs from the cameras) meshed
with Q9 elements split into 8 triangles each (5 k triangles: 25 x 25 elements; 20 k:
50 x 50), seen by the demo's two cameras (25 deg stereo angle, 400 mm). ``--points`` points
(default 1 M) at random parametric positions on the current surface.

Times (median of ``--repeat`` runs): ``occluded`` for one camera (numpy; embree when trimesh
and embreex are importable) and the whole ``visibility_mask`` (both cameras, grazing angle
and self-occlusion), with the share of points kept.

``--demo``: instead, the mask's time on the demo's mesh (1024 Q9, 8 192 triangles) and cameras
at the image scales 2, 1, 0 (what a demo measurement adds per scale; nothing is masked).

Run: ``python benchmarks/bench_visibility.py [--points 1000000] [--repeat 5] [--demo]``
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1])]
from fesdic_core.mesh import rectangle_mesh  # noqa: E402
from fesdic_core.quadrature import ElementGroup, PixelQuadrature  # noqa: E402
from fesdic_core.render import demo_cameras  # noqa: E402
from fesdic_core.visibility import (VisibilitySettings, embree_available, median_edge_mm,  # noqa: E402
                                    occluded, surface_triangles, visibility_mask)


def corrugated(n_elements: int, amplitude: float = 4.0, wavelength: float = 10.0):
    mesh = rectangle_mesh(100.0, 100.0, n_elements, n_elements, "Q9")
    X = mesh.nodes.copy()
    X[:, 2] = amplitude * np.sin(2 * np.pi * X[:, 0] / wavelength)
    return mesh.with_nodes(X)


def random_quadrature(mesh, n_points: int, seed: int = 0) -> PixelQuadrature:
    """n_points points (one parametric sub-grid per element, shared by all elements)."""
    block = mesh.blocks[0]
    E = block.n_elements
    m = max(1, n_points // E)
    xi = np.random.default_rng(seed).uniform(-1, 1, (m, 2))
    N = block.family.shape_functions(xi)
    group = ElementGroup(start=0, elements=np.arange(E), connectivity=block.connectivity, N=N)
    return PixelQuadrature(element=np.repeat(np.arange(E), m), xi=np.tile(xi, (E, 1)),
                           weight_mm2=np.ones(E * m), groups=(group,), n_elements=E,
                           n_nodes=mesh.n_nodes)


def median_time(f, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--demo", action="store_true")
    args = ap.parse_args()
    cams = demo_cameras()
    if args.demo:
        return demo(args.repeat)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}")
    print(f"{'triangles':>9} {'points':>9} {'engine':>7} {'occluded 1 cam s':>17} "
          f"{'mask 2 cams s':>14} {'kept %':>7}")
    for n in (25, 50):
        mesh = corrugated(n)
        quad = random_quadrature(mesh, args.points)
        X = quad.points(mesh.nodes)
        soup = surface_triangles(mesh)
        tol = 0.25 * median_edge_mm(soup)
        engines = ["numpy"] + (["embree"] if embree_available() else [])
        for engine in engines:
            t1, _ = median_time(lambda: occluded(X, cams[0], soup, tol, engine), args.repeat)
            settings = VisibilitySettings(engine=engine)
            t2, keep = median_time(lambda: visibility_mask(mesh, quad, mesh.nodes, cams, settings,
                                                           X=X), args.repeat)
            print(f"{len(soup):>9} {len(X):>9} {engine:>7} {t1:>17.3f} {t2:>14.3f} "
                  f"{100 * keep.mean():>7.1f}")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


def demo(repeat: int) -> None:
    import tempfile
    from fesdic_core.quadrature import pixel_quadrature
    from georeg_app.pipeline import DEMO, build_model, demo_config
    config, _, _ = demo_config(tempfile.mkdtemp())
    mesh = build_model(config.geometry, config.method.fixed_levels).mesh
    cams = demo_cameras(image_size=DEMO["image_size"], stereo_angle_deg=DEMO["stereo_angle_deg"],
                        field_mm=DEMO["field_mm"])
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}")
    print(f"demo mesh: {mesh.n_elements} elements, {len(surface_triangles(mesh))} triangles")
    print(f"{'scale':>5} {'points':>8} {'mask 2 cams s':>14} {'kept %':>7}")
    for scale in (2, 1, 0):
        scaled = [c.scaled(scale) for c in cams]
        quad = pixel_quadrature(mesh, scaled)
        X = quad.points(mesh.nodes)
        t, keep = median_time(lambda: visibility_mask(mesh, quad, mesh.nodes, scaled, X=X), repeat)
        print(f"{scale:>5} {quad.n_points:>8} {t:>14.3f} {100 * keep.mean():>7.1f}")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
