"""Benchmark: building the operators C_s (Eq. 28) and one projection C_s H C_s^T (Eq. 18).

The plate with a hole of the paper (100 x 50 mm, hole radius 14 mm), 3 spline levels
(4x1 -> 8x2, 16x4, 32x8 Bezier elements) and a Q9 FE mesh of 64 x 16 = 1024 elements.
H_FE has the Q9 nodal adjacency pattern (nodes sharing an element) with random SPD values.

For the ratio asked by the plugin issue, the core then assembles the real H_FE and b_FE
(Eq. 8) on the same mesh, from a rendered stereo pair of the twisted plate with a hole
(the demo's rig, 1224 x 816 px and 2448 x 2048 px): the time of ``shape_operators``
alone (the assembly proper) and with the gray-level residual and its derivative that
feed it (what one Gauss-Newton iteration spends before the solve).

Run: ``python benchmarks/bench_operators.py [--repeat 5]``.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np
import scipy.sparse as sps

from fesdic_core.fe.elements import FAMILIES
from fesdic_core.fe.mesh import CellBlock, SurfaceMesh, node_normals
from fesdic_core.fe.quadrature import pixel_quadrature
from fesdic_core.imaging.image import Image
from fesdic_core.residual.graylevel import gray_level_residual
from fesdic_core.shape.operators import shape_operators
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import twisted_plate
from georeg_plugin.levels.operators import multilevel_space
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.spline.fe_mesh import fe_mesh_from_spline
from georeg_plugin.spline.geometries import plate_with_hole
from georeg_plugin.spline.refine import refine_uniform


def q9_hessian(connectivity: np.ndarray, n_nodes: int, seed: int = 0) -> sps.csr_matrix:
    """Random SPD matrix with the nodal adjacency pattern of the mesh, csr (n, n)."""
    rng = np.random.default_rng(seed)
    nn = connectivity.shape[1]
    rows = np.repeat(connectivity, nn, axis=1).ravel()
    cols = np.tile(connectivity, (1, nn)).ravel()
    A = sps.csr_matrix((rng.uniform(-1, 1, rows.size), (rows, cols)), shape=(n_nodes,) * 2)
    A = A + A.T
    dominance = np.asarray(abs(A).sum(axis=1)).ravel() + 1.0
    return sps.csr_matrix(A + sps.diags(dominance))


def median_time(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()

    coarse, _ = refine_uniform(plate_with_hole(100.0, 50.0, 14.0), 1)   # 8 x 2
    fine, _ = refine_uniform(coarse, 3)                                  # 64 x 16
    mesh = fe_mesh_from_spline(fine, "Q9")
    build = lambda: multilevel_space(coarse, 3, mesh.nodes, uv=mesh.uv)  # noqa: E731
    t_build = median_time(build, args.repeat)
    t_invert = median_time(lambda: multilevel_space(coarse, 3, mesh.nodes), args.repeat)
    space = build()
    reg = GeometricRegularization(space)
    H = q9_hessian(mesh.connectivity, mesh.n_nodes)
    b = np.random.default_rng(1).standard_normal(mesh.n_nodes)
    q = np.zeros(mesh.n_nodes)

    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cpus, python {platform.python_version()}")
    print(f"FE mesh: {mesh.n_elements} Q9 elements, {mesh.n_nodes} nodes, "
          f"H_FE nnz {H.nnz}")
    print(f"spline dofs per level (s = 0 finest): {[C.shape[0] for C in space.operators]}")
    print(f"build all C_s, node parameters known : {1e3 * t_build:8.2f} ms (median of "
          f"{args.repeat})")
    print(f"build all C_s, with point inversion  : {1e3 * t_invert:8.2f} ms")
    for s in range(space.n_levels):
        t_proj = median_time(lambda: reg.project(H, b, s), args.repeat)
        t_solve = median_time(lambda: reg.solve(H, b, q, s), args.repeat)
        print(f"level {s}: C_s H C_s^T {1e3 * t_proj:7.2f} ms, full step (Eqs. 18-21) "
              f"{1e3 * t_solve:7.2f} ms, C_s nnz {space.operators[s].nnz}")


    t_projection = median_time(lambda: reg.project(H, b, 0), args.repeat)
    core = SurfaceMesh(mesh.nodes, (CellBlock(FAMILIES["Q9"], mesh.connectivity),))
    normals = node_normals(core)
    for size, field_mm in (((1224, 816), 112.0), ((2448, 2048), 112.0)):
        cams = demo_cameras(image_size=size, stereo_angle_deg=25.0, field_mm=field_mm)
        specimen = twisted_plate(180.0, 50.0, corner_mm=1.0, hole_radius_mm=14.0,
                                 view_length_mm=100.0, speckle_mm=speckle_mm_for(cams[0], 4.0))
        arrays = render_stereo(specimen, cams, supersample=1, noise_std=2.0, seed=1, progress=False)
        images = [Image.from_array(a) for a in arrays]
        quad = pixel_quadrature(core, cams)
        X = quad.points(core.nodes)
        res = gray_level_residual(X, quad, images, cams, "element", "point")
        t_asm = median_time(lambda: shape_operators(quad, normals, res), args.repeat)
        t_full = median_time(lambda: shape_operators(quad, normals, gray_level_residual(
            X, quad, images, cams, "element", "point")), args.repeat)
        print(f"core on the same mesh, {size[0]} x {size[1]} px ({quad.n_points:,} points): "
              f"assembly of H_FE, b_FE {1e3 * t_asm:7.1f} ms, with the residual {1e3 * t_full:7.1f} ms;"
              f" C_0 H C_0^T / assembly = {100 * t_projection / t_asm:.1f}%, "
              f"/ (residual + assembly) = {100 * t_projection / t_full:.1f}%")


if __name__ == "__main__":
    main()
