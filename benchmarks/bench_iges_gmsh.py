"""Check: IGES surfaces read by georeg_plugin.io.iges against gmsh's (OpenCASCADE's) own evaluation.

gmsh builds a B-spline surface (degrees 3 x 2), a rational one (2 x 3, translated), a
Bezier surface (4 x 3, rotated and translated) and a cylinder converted to NURBS (periodic
entity 128 under a trimmed 144), writes them as IGES, and evaluates them at 100 random
parameters in its parameter box: once before writing (the model in memory) and once after
reading the file back (the same numbers as our reader sees). Printed: the largest distance
(mm) between our patch and gmsh at the same parameters, and the reading time (median).

Run: ``python benchmarks/bench_iges_gmsh.py`` (needs ``gmsh``).
"""
from __future__ import annotations

import os
import platform
import tempfile
import time

import gmsh
import numpy as np

from georeg_plugin.io.iges import read_iges_surface_entity, read_iges_surfaces


def _points(rng) -> dict:
    gmsh.model.occ.synchronize()
    out = {}
    for _, tag in gmsh.model.getEntities(2):
        lo, hi = gmsh.model.getParametrizationBounds(2, tag)
        uv = lo + rng.uniform(size=(100, 2)) * (hi - lo)
        out[tag] = uv, np.reshape(gmsh.model.getValue(2, tag, uv.ravel()), (-1, 3))
    return out


def _net(occ):
    return [occ.addPoint(10.0 * i, 8.0 * j, 3.0 * np.sin(i + 0.7 * j))
            for j in range(4) for i in range(5)]


def main() -> None:
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"load {os.getloadavg()[0]:.1f}; gmsh {gmsh.__version__}")
    gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    occ, rng = gmsh.model.occ, np.random.default_rng(0)
    folder = tempfile.mkdtemp()
    a = occ.addBSplineSurface(_net(occ), 5, degreeU=3, degreeV=2)
    b = occ.addBSplineSurface(_net(occ), 5, degreeU=2, degreeV=3,
                              weights=list(rng.uniform(0.5, 2.0, 20)))
    occ.translate([(2, b)], 0.0, 0.0, 20.0)
    c = occ.addBezierSurface(_net(occ), 5)
    occ.rotate([(2, c)], 0, 0, 0, 1, 1, 0, 0.7)
    occ.translate([(2, c)], 60.0, 0.0, 0.0)
    before = _points(rng)
    path = os.path.join(folder, "three.igs")
    gmsh.write(path)
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        surfaces = read_iges_surfaces(path)
        times.append(time.perf_counter() - t0)
    gmsh.clear()
    gmsh.open(path)
    after = _points(rng)
    print("| surface | vs gmsh reading the file (mm) | vs gmsh before writing (mm) |")
    print("|---|---|---|")
    for s, tag, name in zip(surfaces, (a, b, c), ("B-spline 3 x 2", "rational 2 x 3, "
                            "translated", "Bezier 4 x 3, rotated and translated")):
        e1 = np.abs(s.patch.evaluate(after[tag][0]) - after[tag][1]).max()
        e0 = np.abs(s.patch.evaluate(before[tag][0]) - before[tag][1]).max()
        print(f"| {name} (entity {s.entity_type}, DE {s.directory_entry}) | {e1:.1e} | "
              f"{e0:.1e} |")
    gmsh.clear()
    occ.addCylinder(0, 0, 0, 0, 0, 10, 3)
    occ.synchronize()
    occ.convertToNURBS(gmsh.model.getEntities(3))
    occ.synchronize()
    path = os.path.join(folder, "cylinder.igs")
    gmsh.write(path)
    side = read_iges_surface_entity(path, 5)
    gmsh.clear()
    gmsh.open(path)
    uv, x = _points(rng)[gmsh.model.getEntities(2)[0][1]]
    print(f"| periodic cylinder side (entity 128, DE 5, base of a trimmed 144) | "
          f"{np.abs(side.patch.evaluate(uv) - x).max():.1e} | |")
    print(f"read_iges_surfaces of three.igs (3 surfaces, 64 entities): median "
          f"{1e3 * np.median(times):.1f} ms over {len(times)} runs")
    gmsh.finalize()


if __name__ == "__main__":
    main()
