"""Benchmark: real parts from their CAD (issue 11), accuracy and the curved formulation.

Part 1, the operators: on a cylindrical NURBS panel (R 100 mm, 30 degrees, 40 mm) and a
doubly curved bi-quadratic patch (40 x 30 mm), 4 levels over a 16 x 16 Q9 mesh, the
vector formulation (:mod:`georeg_plugin.levels.curved`) against the first formula tried
(``R_J(xi_I) (n_I . n_J)``) and the flat plates' scalar ``R_J(xi_I)``: nesting residual ``max |C_c^T - P_f C_c^T|`` (``P_f`` the
projector on the fine range), rigid normal modes left outside the range (relative), rank.

Part 2, the done-means renders of ``tests/scenes.py`` (``CAD_PARTS``: a cylindrical panel
and a folded plate, 480 x 320 px, noise of 2 gray levels, nominal CAD given as an IGES
file written by ``write_iges``), through ``georeg_app.shape.pipeline.run_methods``: RMS error
(normal distance to the true surface after the best small rigid motion, um) of FE,
Tikhonov 2 / 5 / 10 mm and "auto", georeg 2 and 3 levels; scales (1, 0), calibrated.
Last two columns: georeg with the scalar space ``R_J(xi_I)`` instead (``curved=False``,
same settings; for the panel only: a part of several faces is always vector).

Run: ``python benchmarks/bench_cad_parts.py [--elements 64]``
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parents[1] / "tests")]   # the packages before tests/, whose folders mirror them
import scenes  # noqa: E402
from shape_truth import bounded_shape_error, rms  # noqa: E402

from georeg_app.config.measure import (CamerasConfig, Config, GeometryConfig, ImagesConfig,  # noqa: E402
                               MethodConfig, OutputConfig)
from georeg_app.shape.methods import MethodSpec, georeg_spec, tikhonov_spec  # noqa: E402
from adapters.fesdic_core import georeg_solver  # noqa: E402
from fesdic_core.shape.driver import MeasurementSettings, measure  # noqa: E402
from georeg_app.inputs.nominal import build_model  # noqa: E402
from georeg_app.shape.demo import Truth
from georeg_app.shape.pipeline import run_methods
from georeg_plugin.spline.fe_mesh import fe_mesh_from_spline  # noqa: E402
from georeg_plugin.spline.geometries import cylinder  # noqa: E402
from georeg_plugin.levels.operators import extraction_operator, multilevel_space  # noqa: E402
from georeg_plugin.spline.patch import SplinePatch  # noqa: E402
from georeg_plugin.spline.refine import refine_uniform  # noqa: E402
from georeg_plugin.io.spline_io import write_iges  # noqa: E402
from fesdic_core.cameras.rig import write_cameras_json  # noqa: E402


def dome() -> SplinePatch:
    U, V = np.meshgrid(np.linspace(-20, 20, 3), np.linspace(-15, 15, 3), indexing="ij")
    k = np.array([0, 0, 0, 1, 1, 1.0])
    return SplinePatch((2, 2), (k, k), np.stack([U, V, 0.004 * U ** 2 + 0.006 * V ** 2
                                                 + 0.002 * U * V], -1))


def operators_table() -> None:
    print("| surface | formulation | level ranks (fine -> coarse) | nesting residual | "
          "rigid modes outside |")
    print("|---|---|---|---|---|")
    for name, coarse in (("cylinder panel", cylinder(100.0, 40.0, 30.0)), ("dome", dome())):
        fine, _ = refine_uniform(coarse, 4)
        mesh = fe_mesh_from_spline(fine, "Q9")
        n = fine.normals(mesh.uv)
        X = mesh.nodes
        rigid = np.column_stack([n] + [np.einsum("kd,kd->k", n, np.cross(e, X)) for e in np.eye(3)])
        space = multilevel_space(coarse, 4, X, node_normals=n, uv=mesh.uv)
        vector = [C.toarray() for C in space.operators]
        first = [extraction_operator(p, mesh.uv, n).toarray() for p in reversed(space.patches)]
        scalar = [extraction_operator(p, mesh.uv).toarray() for p in reversed(space.patches)]
        for label, ops in (("vector (curved.py)", vector), ("R_J (n_I . n_J)", first),
                           ("R_J (scalar, flat)", scalar)):
            bases = [np.linalg.qr(C.T)[0] for C in ops]
            nest = max(np.abs(ops[s + 1].T - Q @ (Q.T @ ops[s + 1].T)).max()
                       / np.abs(ops[s + 1]).max() for s, Q in enumerate(bases[:-1]))
            out = max(np.abs(rigid - Q @ (Q.T @ rigid)).max() / np.abs(rigid).max() for Q in bases)
            print(f"| {name} | {label} | {[C.shape[0] for C in ops]} | {nest:.1e} | {out:.1e} |")


def parts_table(elements: int) -> None:
    scales = (1, 0)
    print("\n| part | FE | Tik 2 mm | Tik 5 mm | Tik 10 mm | Tik auto | georeg 2 | georeg 3 | "
          "georeg auto | scalar 2 | scalar 3 |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for part in ("panel", "folded"):
        scene = scenes.cad_scene(part)
        folder = Path(tempfile.mkdtemp(prefix="bench_cad_"))
        faces = scenes.cad_nominal(part)
        write_iges(folder / "part.igs", faces)
        write_cameras_json(folder / "cameras.json", scene.cameras)
        row = []
        for levels in (2, 3, "auto"):
            config = Config(images=ImagesConfig(folder / "0.png", folder / "1.png"),
                            cameras=CamerasConfig(file=folder / "cameras.json"),
                            geometry=GeometryConfig(kind="cad", file=folder / "part.igs",
                                                    elements=elements),
                            method=MethodConfig(levels=levels, scales=2),
                            output=OutputConfig(folder / "out"), source=None)
            specs = [georeg_spec(levels, scales)]
            if levels == 2:
                specs = [MethodSpec("fe", None, scales, "FE")] + [
                    tikhonov_spec(t, scales) for t in (2.0, 5.0, 10.0, "auto")] + specs
            run = run_methods(config, specs, images=scene.images,
                              truth=Truth(scene.specimen, scene.cameras))
            for r in run.results:
                error = None if r.measurement is None else \
                    rms(bounded_shape_error(r.measurement.nodes, scene.specimen))
                row.append("failed" if error is None else f"{error * 1e3:.2f}")
            mesh = run.results[0].mesh
        for levels in (2, 3):
            if part != "panel":
                row.append("-")
                continue
            model = build_model(config.geometry, levels)
            method = config.method
            settings = MeasurementSettings(scales=scales, calibrate=method.calibrate,
                                           keep_stereo=method.keep_stereo,
                                           normalisation=method.normalisation,
                                           max_fixed_point=method.max_fixed_point,
                                           edge_margin_px=method.edge_margin_px)
            m = measure(model.mesh, scene.images, scene.cameras,
                        georeg_solver(model, levels, curved=False), settings)
            row.append(f"{rms(bounded_shape_error(m.nodes, scene.specimen)) * 1e3:.2f}")
        print(f"| {part} ({mesh.n_elements} Q9) | " + " | ".join(row) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--elements", type=int, default=64)
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"load {os.getloadavg()[0]:.1f}")
    operators_table()
    parts_table(args.elements)


if __name__ == "__main__":
    main()
