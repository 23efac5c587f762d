"""Benchmark: 3-D displacement FE stereo-DIC (issue 12): accuracy, iteration time, Dask.

``--accuracy`` (default): the demo's scale, 0.1 mm/px (two cameras at 25 deg, 400 mm,
800 x 600 px over 80 mm), a flat 76 x 56 mm plate, 4 px speckle, noise of 2 gray levels in
every image (independent seeds), the reference surface its central 60 x 40 mm as a Q9 mesh
made from the nominal spline (12 x 8 elements of 5 mm = 50 px). Frames, each measured from
rest over the image scales (2, 1, 0):

- rigid: a translation (0.3, -0.2, 0.1) mm and a rotation (2, 3, -2) mrad;
- bending: u_z = 0.5 mm (2 x / 76 mm)**2 (0.31 mm at the mesh's ends);
- stretch: 0.5 % along x (E_xx = 0.0050125);
- twist: the same paint rendered flat, then on the twisted plate z = k x y (1 mm at the
  plate's corners, 0.56 mm at the mesh's): two independent renders, u = (0, 0, k x y).

``--jacobian current`` measures the table with the full Gauss-Newton instead of the default
modified one. Printed per case and method (FE, Tikhonov of 10 mm on each component, georeg with 3
spline levels per component): RMS error of the in-plane components (x and y pooled) and of
the out-of-plane one at the nodes (um), the RMS error of the surface Green-Lagrange strain
(E_xx, E_yy, E_xy pooled, microstrain) at the nodes against the exact one, by the patch
recovery (the default) and by the nodal average; iterations and time.
Targets of the issue: <= 1 um in plane, <= 2 um out of plane, <= 100 microstrain.

``--iteration``: one full-resolution Gauss-Newton iteration at 2448 x 2048 px (5 Mpx) with
36 x 28 = 1008 Q9 elements, median of ``--repeat``: the modified Gauss-Newton (``jacobian =
"reference"``, the default: ``b = J^T r``, back-substitution with the factor of the
reference's H, the residual of both cameras at the new state), after the once-per-series
reference and factorization (timed once), then the full one (``"current"``: assembly of H and
b, sparse solve of the 3n dofs, the residual with its derivative at the new state). Target
of the issue: under 1.5 s on 2 cores.

``--workers N [N ...]``: frames per minute of a series of ``--frames`` pairs of the accuracy
scene (independent frames) serially and on a local Dask cluster of N worker processes
(needs ``distributed``).

Run: ``python benchmarks/bench_displacement.py [--accuracy] [--iteration] [--workers 1 2]``
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def _machine() -> str:
    load = os.getloadavg()
    return (f"{platform.platform()}, {platform.processor() or platform.machine()}, "
            f"{os.cpu_count()} cpus, python {platform.python_version()}, numpy {np.__version__}, "
            f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")


SCENE = dict(image_size=(800, 600), field_mm=80.0, plate_mm=(76.0, 56.0), mesh_mm=(60.0, 40.0),
             elements=(12, 8), noise_std=2.0, speckle_px=4.0, seed=3)


def _scene():
    from fesdic_core.synthetic.render import demo_cameras, speckle_mm_for
    from fesdic_core.synthetic.specimen import flat_plate
    cameras = demo_cameras(image_size=SCENE["image_size"], field_mm=SCENE["field_mm"])
    plate = flat_plate(*SCENE["plate_mm"], speckle_mm=speckle_mm_for(cameras[0], SCENE["speckle_px"]),
                       seed=SCENE["seed"])
    return cameras, plate


def _model():
    from adapters.fesdic_core import nominal_model
    from georeg_plugin.spline.geometries import rectangle
    return nominal_model(rectangle(*SCENE["mesh_mm"]), SCENE["elements"], "Q9", name="plate")


def _images(arrays, tag):
    from fesdic_core.imaging.image import Image
    return tuple(Image.from_array(a, source=f"{tag} cam{k}") for k, a in enumerate(arrays))


def accuracy(levels: int, length_mm: float, jacobian: str = "reference") -> None:
    from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                                 measure_displacement)
    from fesdic_core.displacement.strain import surface_green_lagrange
    from fesdic_core.synthetic.motion import BendingMotion, RigidMotion, StretchMotion
    from fesdic_core.synthetic.render import render_stereo
    from fesdic_core.synthetic.specimen import twisted_plate
    from georeg_app.series.track import displacement_solver

    cameras, plate = _scene()
    model = _model()
    mesh = model.mesh
    render = dict(supersample=3, noise_std=SCENE["noise_std"], progress=False)
    t = time.perf_counter()
    reference = _images(render_stereo(plate, cameras, seed=1, **render), "reference")
    twisted = twisted_plate(*SCENE["plate_mm"], corner_mm=1.0, speckle_mm=plate.speckle_mm,
                            seed=SCENE["seed"])
    k = twisted.height(np.array(1.0), np.array(1.0))                     # z = k x y
    cases = {
        "rigid": (RigidMotion((0.3, -0.2, 0.1), rvec=(0.002, 0.003, -0.002)), None),
        "bending": (BendingMotion(0.5, SCENE["plate_mm"][0]), None),
        "stretch": (StretchMotion(0.005), None),
        "twist": (lambda X: np.column_stack([0 * X[:, 0], 0 * X[:, 0], k * X[:, 0] * X[:, 1]]),
                  twisted),
    }
    frames = {}
    for i, (name, (motion, specimen)) in enumerate(cases.items(), start=2):
        if specimen is None:
            arrays = render_stereo(plate, cameras, seed=i, motion=motion, **render)
        else:
            arrays = render_stereo(specimen, cameras, seed=i, **render)
        frames[name] = _images(arrays, name)
    print(f"rendered 5 pairs of {SCENE['image_size'][0]} x {SCENE['image_size'][1]} px in "
          f"{time.perf_counter() - t:.0f} s; {mesh.n_nodes} nodes, {mesh.n_elements} Q9 elements")
    settings = DisplacementSettings(scales=(2, 1, 0), jacobian=jacobian)
    ref = displacement_reference(mesh, reference, cameras, settings)
    print(f"Gauss-Newton: jacobian = {jacobian!r}")
    methods = {"FE": ("fe", {}), f"Tikhonov {length_mm:g} mm": ("tikhonov", {}),
               f"georeg {levels} levels": ("georeg", {})}
    print()
    print("| case | method | in-plane RMS (um) | out-of-plane RMS (um) | strain RMS (microstrain) "
          "| strain RMS, nodal average (microstrain) | iterations | time (s) | verdict |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, (motion, _) in cases.items():
        truth = motion(mesh.nodes)
        # the exact strain at the nodes: Q9 holds every motion here, so the elements' own
        # strain at their nodes is the closed form's (the recoveries are compared to it)
        strain_truth = surface_green_lagrange(mesh, truth, recovery="nodal")
        for label, (method, _) in methods.items():
            solver = displacement_solver(method, mesh, model, length_mm, levels)
            t = time.perf_counter()
            m = measure_displacement(ref, frames[name], solver)
            elapsed = time.perf_counter() - t
            error = m.U - truth
            in_plane = 1e3 * np.sqrt(np.mean(error[:, :2] ** 2))
            out_of_plane = 1e3 * np.sqrt(np.mean(error[:, 2] ** 2))
            strain, nodal = (1e6 * np.sqrt(np.mean((surface_green_lagrange(mesh, m.U, recovery)
                                                    - strain_truth) ** 2))
                             for recovery in ("patch", "nodal"))
            print(f"| {name} | {label} | {in_plane:.2f} | {out_of_plane:.2f} | {strain:.0f} | "
                  f"{nodal:.0f} | "
                  f"{m.iterations} | {elapsed:.1f} | {'ok' if m.ok else 'FAILED: ' + m.failure} |")
    print(f"\n(max |u_z| of the twist at the nodes: {1e3 * np.abs(k * mesh.nodes[:, 0] * mesh.nodes[:, 1]).max():.0f} um)")


def iteration(repeat: int) -> None:
    from fesdic_core.displacement.driver import displacement_reference, DisplacementSettings
    from fesdic_core.displacement.residual import (displacement_operators, displacement_residual,
                                                   displacement_rhs)
    from fesdic_core.fe.mesh import rectangle_mesh
    from fesdic_core.solve.solvers import CachedFactorization, DirectSolver, sparse_solve
    from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
    from fesdic_core.synthetic.specimen import flat_plate

    cams = demo_cameras(image_size=(2448, 2048), stereo_angle_deg=25.0, field_mm=80.0)
    plate = flat_plate(90.0, 75.0, speckle_mm=speckle_mm_for(cams[0], 4.0), seed=1)
    t = time.perf_counter()
    reference = _images(render_stereo(plate, cams, supersample=1, noise_std=2.0, seed=1,
                                      progress=False), "reference")
    deformed = _images(render_stereo(plate, cams, supersample=1, noise_std=2.0, seed=2,
                                     progress=False), "deformed")
    print(f"rendered 2 pairs of 2448 x 2048 px in {time.perf_counter() - t:.0f} s")
    mesh = rectangle_mesh(72.0, 56.0, 36, 28, family="Q9")
    t = time.perf_counter()
    ref = displacement_reference(mesh, reference, cams, DisplacementSettings(scales=(0,)))
    t_ref = time.perf_counter() - t
    view = ref.view(0)
    U = np.zeros(3 * mesh.n_nodes)
    print(f"{view.quad.n_points} integration points, {mesh.n_elements} Q9 elements, "
          f"{3 * mesh.n_nodes} dofs")
    # the modified Gauss-Newton (jacobian = "reference", the default): once per series and
    # scale the reference (its Jacobian and H, in displacement_reference) and the
    # factorization of H (the first solve); then an iteration is the residual of both
    # cameras at the new state (no derivative), b = J^T r and a back-substitution
    solver = CachedFactorization(DirectSolver())
    t = time.perf_counter()
    solver.solve(view.hessian, np.zeros(3 * mesh.n_nodes), U, 0)
    t_factor = time.perf_counter() - t
    print(f"\nonce per series (jacobian = 'reference'): reference state with its Jacobian and H "
          f"{t_ref:.2f} s, factorization of H {t_factor:.2f} s")
    res = displacement_residual(U, view, deformed, jacobian=False)

    def modified(res):
        b = displacement_rhs(view.quad, view.dr_du, res.r)
        yield
        d = solver.solve(view.hessian, b, U, 0)
        yield
        yield displacement_residual(U + d, view, deformed, jacobian=False)

    _stages("reference", ("b = J^T r", "back-substitution (3n dofs)", "residual (no derivative)"),
            modified, res, repeat)
    # one Gauss-Newton iteration as displacement_gauss_newton runs it: the operators of the
    # current residual, the solve, and the residual with its derivative at the new state
    # (which the next iteration's operators use)
    del view, ref, solver                                 # (memory: the full GN's own below)
    ref = displacement_reference(mesh, reference, cams,
                                 DisplacementSettings(scales=(0,), jacobian="current"))
    view = ref.view(0)

    def full(res):
        H, b = displacement_operators(view.quad, res)
        yield
        d = sparse_solve(H, b)
        yield
        yield displacement_residual(U + d, view, deformed)

    _stages("current", ("assembly of H, b", "sparse solve (3n dofs)", "residual + derivative"),
            full, displacement_residual(U, view, deformed), repeat)


def _stages(jacobian: str, names, iteration, res, repeat: int) -> None:
    """Median times of the three stages of ``iteration(res)`` (a generator that yields after
    each stage, the new residual last) and of the whole, over ``repeat`` iterations."""
    stages = {name: [] for name in (*names, "one iteration")}
    for _ in range(repeat):
        times = [time.perf_counter()]
        for res in iteration(res):
            times.append(time.perf_counter())
        for key, dt in zip(stages, (*np.diff(times), times[-1] - times[0])):
            stages[key].append(dt)
    print(f"median of {repeat} (threads: FESDIC_THREADS={os.environ.get('FESDIC_THREADS', 'default')}), "
          f"jacobian = {jacobian!r}:")
    for key, times in stages.items():
        print(f"  {key:28s} {statistics.median(times):7.3f} s")


def workers(counts, n_frames: int) -> None:
    import cv2

    from fesdic_core.synthetic.motion import RigidMotion
    from fesdic_core.synthetic.render import render_stereo
    from georeg_app import cli

    cameras, plate = _scene()
    folder = Path(tempfile.mkdtemp(prefix="bench_displacement_"))
    clean = render_stereo(plate, cameras, supersample=2, bit_depth=None, progress=False,
                          motion=RigidMotion((0.2, -0.1, 0.05)))
    ref = render_stereo(plate, cameras, supersample=2, noise_std=2.0, seed=1, progress=False)
    rng = np.random.default_rng(0)
    for k, a in enumerate(ref):
        cv2.imwrite(str(folder / f"ref_cam{k}.png"), a.astype(np.uint8))
    (folder / "frames").mkdir()
    for i in range(1, n_frames + 1):
        for k, a in enumerate(clean):
            noisy = np.clip(np.rint(a + rng.normal(0, 2.0, a.shape)), 0, 255).astype(np.uint8)
            cv2.imwrite(str(folder / "frames" / f"f{i}_cam{k}.png"), noisy)
    model = _model()
    from fesdic_core.cameras.rig import write_cameras_json
    from fesdic_core.fe.mesh_io import write_mesh
    import json
    shape = folder / "shape_out"
    shape.mkdir()
    write_mesh(shape / "fe.vtu", model.mesh)
    write_cameras_json(shape / "fe_cameras.json", cameras)
    (shape / "summary.json").write_text(json.dumps({"methods": [{"label": "FE", "status": "ok",
                                                                "mesh_file": "fe.vtu"}]}))
    (folder / "track.toml").write_text(
        '[images]\ncam0 = "ref_cam0.png"\ncam1 = "ref_cam1.png"\n[series]\n'
        'cam0 = "frames/f*_cam0.png"\ncam1 = "frames/f*_cam1.png"\n[displacement]\n'
        'method = "fe"\nincremental = false\n[reference]\ndir = "shape_out"\n')
    print(f"\n{n_frames} frames of {SCENE['image_size'][0]} x {SCENE['image_size'][1]} px, "
          f"{model.mesh.n_elements} Q9 elements, each from rest (incremental = false)")
    print("| scheduler | workers | wall time (s) | frames per minute |")
    print("| --- | --- | --- | --- |")
    runs = [("serial", None)] + [("processes", n) for n in counts]
    for scheduler, n in runs:
        out = folder / f"out_{scheduler}_{n}"
        argv = ["-q", "track", str(folder / "track.toml"), "--out", str(out), "--scheduler", scheduler]
        if n:
            argv += ["--workers", str(n)]
        t = time.perf_counter()
        code = cli.main(argv)
        wall = time.perf_counter() - t
        print(f"| {scheduler} | {n or 1} | {wall:.1f} | {60 * n_frames / wall:.1f} |"
              + ("" if code == 0 else " (FAILED)"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--accuracy", action="store_true")
    parser.add_argument("--iteration", action="store_true")
    parser.add_argument("--workers", type=int, nargs="*", default=None)
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--levels", type=int, default=3)
    parser.add_argument("--tikhonov-mm", type=float, default=10.0)
    parser.add_argument("--jacobian", choices=("reference", "current"), default="reference",
                        help="the accuracy table's Gauss-Newton (default: reference)")
    args = parser.parse_args()
    print(f"machine: {_machine()}")
    if not (args.iteration or args.workers is not None) or args.accuracy:
        accuracy(args.levels, args.tikhonov_mm, args.jacobian)
    if args.iteration:
        iteration(args.repeat)
    if args.workers is not None:
        workers(args.workers or [1, 2], args.frames)


if __name__ == "__main__":
    main()
