"""Benchmark: the visibility mask (:mod:`fesdic_core.residual.visibility`), its time.

A corrugated sheet ``z = A sin(2 pi x / wavelength)`` (100 x 100 mm, A = 4 mm, wavelength
10 mm: slopes up to 68 deg, so the crests hide part of the troughs from the cameras) meshed
with Q9 elements split into 8 triangles each (5 k triangles: 25 x 25 elements; 20 k:
50 x 50), seen by the demo's two cameras (25 deg stereo angle, 400 mm). ``--points`` points
(default 1 M) at random parametric positions on the current surface.

Times (median of ``--repeat`` runs): ``occluded`` for one camera (numpy; embree when trimesh
and embreex are importable; margin 0, no own-element rule) and the whole ``visibility_mask``
(both cameras, grazing angle and self-occlusion; numpy with the default margin of 1 px and
the own-element rule, embree with margin 0), with the share of points kept.

``--demo``: instead, the mask's time on the demo's mesh (1024 Q9, 8 192 triangles) and cameras
at the image scales 2, 1, 0 (what a demo measurement adds per scale; nothing is masked).

``--view-angles``: instead, the choice of the grazing-angle cut-off. A 24 x 40 mm plate tilted
about y by beta (z = x tan beta, 40 to 70 deg) carries a 4 px speckle painted on the surface
(so the cameras foreshorten it), rendered for the rig of ``tests/scenes.py``'s bump scene
(480 x 320 px, 0.15 mm/px, 25 deg stereo angle, 3 x 3 rays per pixel, noise 2 gray levels);
FE (12 x 16 Q9, scales (1, 0), exact cameras, no visibility) measures it. The nominal is the
true plane, so ``q`` is the error; its RMS is printed per 5 deg bin of the nodes' larger view
angle (the angle between the normal and the direction to either camera).

Run: ``python benchmarks/bench_visibility.py [--points 1000000] [--repeat 5] [--demo]
[--view-angles]``
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
from fesdic_core.fe.mesh import rectangle_mesh  # noqa: E402
from fesdic_core.fe.quadrature import ElementGroup, PixelQuadrature  # noqa: E402
from fesdic_core.synthetic.render import demo_cameras  # noqa: E402
from fesdic_core.residual.visibility import (DEFAULT_MARGIN_PX, VisibilitySettings,  # noqa: E402
                                    embree_available, median_edge_mm, occluded,
                                    surface_triangles, visibility_mask)


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
    ap.add_argument("--view-angles", action="store_true")
    args = ap.parse_args()
    cams = demo_cameras()
    if args.demo:
        return demo(args.repeat)
    if args.view_angles:
        return view_angles()
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
            # embree tests the exact triangles, without the own-element rule: margin 0
            settings = VisibilitySettings(engine=engine, margin_px=0.0 if engine == "embree"
                                          else DEFAULT_MARGIN_PX)
            t2, keep = median_time(lambda: visibility_mask(mesh, quad, mesh.nodes, cams, settings,
                                                           X=X), args.repeat)
            print(f"{len(soup):>9} {len(X):>9} {engine:>7} {t1:>17.3f} {t2:>14.3f} "
                  f"{100 * keep.mean():>7.1f}")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


def demo(repeat: int) -> None:
    import tempfile
    from fesdic_core.fe.quadrature import pixel_quadrature
    from georeg_app.inputs.nominal import build_model
    from georeg_app.shape.demo import DEMO, demo_config
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


def view_angles(tilts=(40.0, 50.0, 55.0, 60.0, 65.0, 70.0)) -> None:
    from fesdic_core.imaging.image import Image
    from fesdic_core.shape.driver import MeasurementSettings, measure
    from fesdic_core.synthetic.render import render_stereo, speckle_mm_for, speckle_texture
    from fesdic_core.synthetic.specimen import Specimen
    cams = demo_cameras(image_size=(480, 320), field_mm=72.0)
    speckle = speckle_mm_for(cams[0], 4.0)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"load average {os.getloadavg()[0]:.2f}")
    angles, errors = [], []
    for beta in tilts:
        t = np.tan(np.radians(beta))
        base = speckle_texture(Specimen(24.0 / np.cos(np.radians(beta)) + 2, 40.0,
                                        speckle_mm=speckle, seed=3))
        specimen = Specimen(24.0, 40.0, height=lambda x, y: t * x,
                            height_gradient=lambda x, y: (np.full_like(x, t), np.zeros_like(y)),
                            speckle_mm=speckle, seed=3,
                            texture=lambda x, y: base.evaluate(x * np.sqrt(1 + t * t), y))
        arrays = render_stereo(specimen, cams, supersample=3, noise_std=2.0, seed=2, progress=False)
        images = [Image.from_array(a, source=f"tilt {beta:g} cam{k}") for k, a in enumerate(arrays)]
        mesh = rectangle_mesh(24.0, 40.0, 12, 16, "Q9")
        X = mesh.nodes.copy()
        X[:, 2] = t * X[:, 0]
        mesh = mesh.with_nodes(X)
        m = measure(mesh, images, cams, settings=MeasurementSettings(scales=(1, 0), uncertainty=False))
        n = np.array([-np.sin(np.radians(beta)), 0.0, np.cos(np.radians(beta))])
        view = np.max([np.degrees(np.arccos(np.abs((np.asarray(c.center) - X) @ n)
                                            / np.linalg.norm(np.asarray(c.center) - X, axis=1)))
                       for c in cams], axis=0)
        angles.append(view)
        errors.append(m.q)
        print(f"tilt {beta:4.0f} deg: view angles {view.min():.1f} to {view.max():.1f} deg, "
              f"RMS error {1e3 * np.sqrt(np.mean(m.q ** 2)):.1f} um, residual "
              f"{m.residual_percent:.2f}% (noise {m.noise_percent:.2f}%)", flush=True)
    angles, errors = np.concatenate(angles), np.concatenate(errors)
    print(f"{'view angle deg':>15} {'nodes':>6} {'RMS error um':>13}")
    for lo in np.arange(45.0, 90.0, 5.0):
        sel = (angles >= lo) & (angles < lo + 5)
        if sel.any():
            print(f"{lo:>7.0f} - {lo + 5:<5.0f} {sel.sum():>6} "
                  f"{1e3 * np.sqrt(np.mean(errors[sel] ** 2)):>13.1f}")


if __name__ == "__main__":
    main()
