"""pyxel-dic with and without the geometric-regularization plugin, on real images.

The open-hole composite pair and the Abaqus Q4 mesh of pyxel's example 1 (see
data/pyxel_composite/README.md). The mesh is a "legacy" mesh, not made from any
spline: the plugin locates its nodes on a flat B-spline rectangle covering the mesh by
point inversion, builds ``C_s`` at each level, and the adapter hands ``B = C_s^T`` to
pyxel's ``Correlate(..., Basis=B)``; pyxel itself is not modified.

Needs the optional extra:  python -m pip install -e ".[pyxel]"
Run:  python examples/pyxel_composite.py [--levels 5 --scales 3,2,1,0,0 --elements 3,1]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import logging
import pathlib
import time

import numpy as np

from adapters import pyxel as pyxel_adapter

DATA = pathlib.Path(__file__).resolve().parents[1] / "data" / "pyxel_composite"
CAMERA_P = [-1.573863, 0.081188, 0.096383, 0.000095]  # pyxel's example 1 (rz, tx, ty, tz)


def load_case(data: pathlib.Path):
    """(f, g, mesh, camera) of pyxel's example 1."""
    pyxel = pyxel_adapter.import_pyxel()
    paths = [data / "zoom-0053_1.tif", data / "zoom-0070_1.tif", data / "abaqus_q4_m.inp"]
    for path in paths:
        if not path.is_file():
            raise FileNotFoundError(f"missing data file {path}")
    f = pyxel.Image(str(paths[0])).Load()
    g = pyxel.Image(str(paths[1])).Load()
    with contextlib.redirect_stdout(io.StringIO()):  # pyxel prints
        m = pyxel.ReadMesh(str(paths[2]))
        m.Connectivity()
    cam = pyxel.Camera(2)
    cam.set_p(CAMERA_P)
    return f, g, m, cam


def displacement_px(m, cam, U: np.ndarray) -> np.ndarray:
    """Nodal displacements (n_used, 2) in pixels (pyxel's 2-D camera: tz = m / px)."""
    used = np.asarray(m.conn)[:, 0] >= 0
    return m.DOF2Nodes(U)[used] / cam.Get_pix2m()


def describe(name: str, u: np.ndarray) -> str:
    return (f"{name:>22s}: mean ({u[:, 0].mean():7.3f}, {u[:, 1].mean():7.3f}) px, "
            f"std ({u[:, 0].std():6.3f}, {u[:, 1].std():6.3f}) px, "
            f"range x [{u[:, 0].min():.2f}, {u[:, 0].max():.2f}], "
            f"y [{u[:, 1].min():.2f}, {u[:, 1].max():.2f}] px")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=pathlib.Path, default=DATA)
    parser.add_argument("--levels", type=int, default=5, help="spline levels")
    parser.add_argument("--scales", default="3,2,1,0,0",
                        help="image scale of each level, coarse to fine")
    parser.add_argument("--elements", default="3,1",
                        help="knot spans (u, v) of the coarsest spline (the mesh is 90 x 30 mm)")
    parser.add_argument("--degree", type=int, default=2)
    parser.add_argument("-v", "--verbose", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    scales = tuple(int(s) for s in args.scales.split(","))
    elements = tuple(int(s) for s in args.elements.split(","))

    f, g, m, cam = load_case(args.data)
    print(f"mesh: {len(m.n)} nodes, {sum(len(e) for e in m.e.values())} Q4 elements, "
          f"{m.ndof} dofs; images {f.pix.shape[1]} x {f.pix.shape[0]} px")

    t0 = time.perf_counter()
    U_fe, _ = pyxel_adapter.correlate_fe(f, g, m, cam, init_scales=(3, 2, 1))
    t_fe = time.perf_counter() - t0

    t0 = time.perf_counter()
    patch = pyxel_adapter.spline_for_mesh(m, degree=args.degree, elements=elements)
    U_s, _, history = pyxel_adapter.correlate_multilevel(f, g, m, cam, patch, args.levels,
                                                        scales=scales)
    t_s = time.perf_counter() - t0

    # both residuals with the same (full-scale) integration rule
    host = pyxel_adapter.PyxelAdapter(f, g, m, cam)
    std_fe, std_s = host.residual_std(U_fe), host.residual_std(U_s)
    print("\nspline levels (coarse to fine):")
    for h in history:
        print(f"  level {h.level}: image scale {h.image_scale}, {h.n_basis:5d} basis "
              f"functions, {h.n_iterations:2d} iterations, residual std "
              f"{h.residual_std:.3f} gray levels (at that scale)")
    print(f"\nresidual std, full images: pyxel alone {std_fe:.3f} gray levels "
          f"({m.ndof} dofs, {t_fe:.1f} s); with the plugin {std_s:.3f} gray levels "
          f"({history[-1].n_basis} spline dofs, {t_s:.1f} s)")
    u_fe, u_s = displacement_px(m, cam, U_fe), displacement_px(m, cam, U_s)
    print(describe("pyxel alone", u_fe))
    print(describe("pyxel + plugin", u_s))
    gap = np.linalg.norm(u_s - u_fe, axis=1)
    q = np.quantile(gap, [0.5, 0.9, 0.99])
    print(f"{'|difference|':>22s}: median {q[0]:.3f} px, 90% {q[1]:.3f} px, "
          f"99% {q[2]:.3f} px, max {gap.max():.2f} px")


if __name__ == "__main__":
    main()
