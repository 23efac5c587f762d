"""Benchmark: georeg with automatic spline levels against FE, Tikhonov and fixed levels.

Issue 10, item 4 ("never worse than plain FE"). Shapes with known truth (tests/scenes.py):

- the demo's twisted open-hole plate with waviness (1 mm twist at the corners of the
  100 mm view, 0.2 mm waviness, noise of 2 gray levels), measured with the NURBS plate
  with a hole: default the demo itself (1224 x 816 px, 1024 Q9 elements, the paper's mesh),
  ``--quick`` the tests' small demo (500 x 333 px, 256 elements);
- the family ``scenes.FAMILY_DEMO_SCALE`` (default: a 96 x 80 mm plate, 1200 x 1000 px at
  0.1 mm/px, 48 x 40 Q9 elements of 2 mm) or ``scenes.FAMILY`` (``--quick``, the tests'
  family: 60 x 60 mm, 704 x 736 px, 40 x 40 elements of 1.5 mm): flat, and a 0.5 mm
  Gaussian bump of sigma = width / 2, 5, 10, 20. Elements of half the narrowest sigma,
  16 px or more per element, 4 px speckle, noise of 2 gray levels, 25 deg stereo angle.

Methods, on the same mesh, images, exact cameras and settings (scales (2, 1, 0) for the
twisted plate, (1, 0) for the family): plain FE, Tikhonov at 5, 10, 20 mm (and the core's
length "auto" when ``TikhonovSolver(mesh, "auto")`` exists), georeg with 2, 3, 4 fixed levels
(where the mesh refines the finest level) and georeg with automatic levels
(:func:`adapters.level_search.measure_auto_levels`, 3 start levels), with its chosen level
(0 = the spline of the FE mesh) and spline dofs. Error: RMS distance (um) of the measured
nodes to the true surface after the bounded rigid alignment (tests/shape_truth.py). FE
and Tikhonov run without the shape uncertainty (it does not change the shape; the FE's
inverts H densely); georeg runs with it (the level search needs its noise model).

Column "gain": the search's statistic, the largest fall of the cost per added dof in units of
the noise variance kappa over the levels it predicted or measured (Cp takes a finer level
above 2; noise alone gives about 1).

Column "misfit": ``b^T H^-1 b / (n kappa)`` at the true shape (:func:`truth_misfit`): 1
when the images differ from the truth's image model by their noise only; above, the FE
mesh can fit a systematic misfit of the synthetic images (pixel integration by a few point
samples, texture sampling), which Mallows' Cp then counts as shape.

Timing: the median of ``--repeat`` runs of georeg auto and of georeg with 3 fixed levels
(the same coarse-to-fine start); the search's added time is their difference ("added",
relative to G3), and "search" is the time the search itself reports (``LevelSearch.time_s``:
the predictions, the iterations at finer levels and the final measurement at the chosen
level) relative to G3. Under a shared machine's load the difference is the noisier one.

Renderers (``--renderer``): ``core`` (fesdic_core.synthetic.render: ray casting onto z = h(x, y),
bilinear texture, ``--supersample`` rays per pixel, default the family's 6 x 6) and ``riley`` (riley-raster, PyPI, a Zig
rasteriser of FE surface meshes for DIC uncertainty studies: the surface as a fine quad9
mesh with nodes on the truth, element maps inverted by Newton per sub-pixel, Catmull-Rom
texture sampling, 4 x 4 sub-pixels per pixel, box pixel), the same speckle texture, the
same noise. Riley is not a dependency of the project: install it in a separate venv
(``python -m venv --system-site-packages VENV && VENV/bin/pip install riley-raster``) and
run this script with that venv's python. With ``riley`` the script first checks the
camera conversion: a flat plate rendered by riley with bilinear sampling and the core's
sub-pixel grid must equal the core's render.

Measured: the tests' scale (``--quick``, core renderer) is the table of
tests/adapters/test_never_worse_than_fe.py and README "Level choice"; the riley table at the
demo's scale (``--renderer riley --repeat 1 --shapes twisted 10 20 --noise 0 2``) is in README
too. Both on the search that moves both ways, with the 2 px edge margin.

Run: ``python benchmarks/bench_levels.py [--quick] [--renderer core|riley|both] [--repeat 3]
[--shapes twisted flat 2 5 10 20] [--noise 0 2] [--supersample 6] [--riley-subsample 4]``
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import platform
import statistics
import sys
import time
from typing import Sequence
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parents[1] / "tests")]   # the packages before tests/, whose folders mirror them
import scenes  # noqa: E402
from shape_truth import bounded_shape_error, rms  # noqa: E402

from adapters.fesdic_core import georeg_solver, nominal_model  # noqa: E402
from adapters.level_search import measure_auto_levels  # noqa: E402
from fesdic_core.shape.driver import MeasurementSettings, measure  # noqa: E402
from fesdic_core.fe.elements import family_from_meshio, gauss_rule  # noqa: E402
from fesdic_core.imaging.image import Image  # noqa: E402
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for, speckle_texture, true_normal_offset
from fesdic_core.synthetic.specimen import twisted_plate
from fesdic_core.solve.tikhonov import TikhonovSolver  # noqa: E402
from fesdic_core.solve.solvers import seen_dofs  # noqa: E402
from fesdic_core.shape.uncertainty import linearised_state  # noqa: E402
from georeg_plugin.spline.geometries import plate_with_hole, rectangle  # noqa: E402

TIKHONOV_MM = (5.0, 10.0, 20.0)
FIXED_LEVELS = (2, 3, 4)
START_LEVELS = 3
DEMO = dict(scenes.SMALL_DEMO, image_size=(1224, 816))     # georeg_app.shape.demo.DEMO's scene


@dataclasses.dataclass
class Case:
    name: str
    specimen: object
    cameras: tuple
    model: object
    settings: MeasurementSettings
    renderer_note: str = ""


# ----------------------------------------------------------------------------- riley
def _euler_zyx(R: np.ndarray) -> tuple[float, float, float]:
    """Riley's rotation angles (alpha_z, beta_y, gamma_x), R = Rz(alpha) Ry(beta) Rx(gamma)."""
    return (float(np.arctan2(R[1, 0], R[0, 0])), float(np.arcsin(-R[2, 0])),
            float(np.arctan2(R[2, 1], R[2, 2])))


def _riley_camera(riley, camera, sub_sample: int):
    """The core's OpenCV pinhole (K, R, t, no distortion) as a riley camera (OpenGL axes:
    camera-to-world rotation, y up, looking along -z; principal point at the image centre,
    pixel centres at i + 1/2, i.e. the core's (w - 1) / 2 with centres at integers)."""
    import cv2
    K = np.asarray(camera.K, float)
    w, h = (int(v) for v in camera.image_size)
    if (abs(K[0, 2] - 0.5 * (w - 1)) > 1e-9 or abs(K[1, 2] - 0.5 * (h - 1)) > 1e-9 or K[0, 1] != 0
            or np.any(np.asarray(camera.dist, float) != 0)):
        raise ValueError("riley cameras here: principal point at the image centre, no skew, "
                         "no distortion")
    R = cv2.Rodrigues(np.asarray(camera.rvec, float).reshape(3, 1))[0]
    R_gl = R.T @ np.diag([1.0, -1.0, -1.0])
    centre = -R.T @ np.asarray(camera.tvec, float).ravel()
    return riley.Camera(pixels_num=(w, h), pixels_size=(1.0 / K[0, 0], 1.0 / K[1, 1]),
                        pos_world=tuple(float(c) for c in centre), rot_world=_euler_zyx(R_gl),
                        roi_cent_world=(0.0, 0.0, 0.0), focal_length=1.0, sub_sample=sub_sample,
                        coord_sys=riley.CameraCoordSys.opengl)


def _grid_quad9(length_mm: float, width_mm: float, element_mm: float):
    nx, ny = (int(np.ceil(s / element_mm)) for s in (length_mm, width_mm))
    X, Y = np.meshgrid(np.linspace(-length_mm / 2, length_mm / 2, 2 * nx + 1),
                       np.linspace(-width_mm / 2, width_mm / 2, 2 * ny + 1), indexing="ij")
    index = np.arange(X.size).reshape(X.shape)
    i, j = (a.ravel() for a in np.meshgrid(2 * np.arange(nx), 2 * np.arange(ny), indexing="ij"))

    def n(di, dj):
        return index[i + di, j + dj]
    # gmsh / VTK quad9 order: corners counter-clockwise (normal +z), edges 01 12 23 30, centre
    connect = np.column_stack([n(0, 0), n(2, 0), n(2, 2), n(0, 2), n(1, 0), n(2, 1), n(1, 2),
                               n(0, 1), n(1, 1)])
    return np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)]), connect


def riley_surface(specimen, element_mm: float = 0.5):
    """Quad9 mesh (coords, connect) of the specimen's surface, nodes on the truth; a plate
    with a hole is meshed from the NURBS plate with a hole (elements of at most ~1.6 mm).
    Returns also the largest distance (mm) of the mesh's surface to the truth at the 3 x 3
    Gauss points of every element."""
    if specimen.hole_radius_mm is None:
        coords, connect = _grid_quad9(specimen.length_mm, specimen.width_mm, element_mm)
    else:
        fe = nominal_model(plate_with_hole(specimen.length_mm, specimen.width_mm,
                                           specimen.hole_radius_mm), 7, "Q9").mesh
        coords, connect = fe.nodes.copy(), fe.blocks[0].connectivity
    if specimen.material is not None:     # an outline of any shape: the elements on material
        corners = coords[connect]
        connect = connect[specimen.contains(corners[..., 0], corners[..., 1]).all(axis=1)]
    coords[:, 2] = specimen.height(coords[:, 0], coords[:, 1])
    family = family_from_meshio("quad9")
    xi, _ = gauss_rule(family, 3)
    P = np.einsum("mi,eid->emd", family.shape_functions(xi), coords[connect]).reshape(-1, 3)
    deviation = float(np.max(np.abs(P[:, 2] - specimen.height(P[:, 0], P[:, 1]))))
    return coords, connect, deviation


def riley_render(specimen, cameras, noise_std: float, seed: int, sub_sample: int = 4,
                 sample: str = "cubic_catmull_rom", background: float = 10.0):
    """Render the stereo pair with riley (8-bit, seeded noise as the core's render_stereo)."""
    import riley
    texture = speckle_texture(specimen)
    coords, connect, deviation = riley_surface(specimen)
    rows, cols = texture.values.shape
    uvs = np.column_stack([(coords[:, 0] - texture.origin_mm[0]) / (texture.texel_mm * (cols - 1)),
                           (coords[:, 1] - texture.origin_mm[1]) / (texture.texel_mm * (rows - 1))])
    shader = riley.TextureShader(uvs=uvs, texture=texture.values.astype(np.float64)[None],
                                 sample=getattr(riley.TextureSample, sample))
    convention = riley.ConnectConvention(riley.EElemType.QUAD9, riley.EConnectAxis.ROW, 0,
                                         riley.ENodeOrder.VTK)
    mesh = riley.create_mesh(convention=convention, mesh_type=riley.MeshType.quad9,
                             coords=coords, connect=connect, shader=shader)
    config = riley.RasterConfig(parallel=os.cpu_count() or 1,
                                save_strategy=riley.SaveStrategy.memory, report=0)
    config.background_value = background
    out = riley.raster([mesh], [_riley_camera(riley, c, sub_sample) for c in cameras], config)
    rng = np.random.default_rng(seed)
    arrays = []
    for k in range(len(cameras)):
        image = np.array(np.squeeze(out[k]), float)
        if noise_std > 0:
            image += rng.normal(0.0, noise_std, image.shape)
        arrays.append(np.clip(np.rint(image), 0.0, 255.0))
    return arrays, deviation


def riley_check() -> float:
    """Largest |riley - core| (gray levels) on a noise-free flat plate, riley with bilinear
    texture sampling and 3 x 3 sub-pixels like the core (the camera conversion's check)."""
    cameras = demo_cameras(image_size=(240, 200), field_mm=72.0)
    specimen = scenes.family_specimen(None, speckle_mm_for(cameras[0], 4.0),
                                      dict(scenes.FAMILY, length_mm=60.0, width_mm=40.0))
    core = render_stereo(specimen, cameras, supersample=3, noise_std=0.0, bit_depth=None,
                         progress=False)
    import riley
    texture = speckle_texture(specimen)
    coords, connect = _grid_quad9(specimen.length_mm, specimen.width_mm, 2.0)
    rows, cols = texture.values.shape
    uvs = np.column_stack([(coords[:, 0] - texture.origin_mm[0]) / (texture.texel_mm * (cols - 1)),
                           (coords[:, 1] - texture.origin_mm[1]) / (texture.texel_mm * (rows - 1))])
    mesh = riley.create_mesh(
        convention=riley.ConnectConvention(riley.EElemType.QUAD9, riley.EConnectAxis.ROW, 0,
                                           riley.ENodeOrder.VTK),
        mesh_type=riley.MeshType.quad9, coords=coords, connect=connect,
        shader=riley.TextureShader(uvs=uvs, texture=texture.values.astype(np.float64)[None],
                                   sample=riley.TextureSample.linear))
    config = riley.RasterConfig(parallel=1, save_strategy=riley.SaveStrategy.memory, report=0)
    config.background_value = 10.0
    out = riley.raster([mesh], [_riley_camera(riley, c, 3) for c in cameras], config)
    return float(max(np.max(np.abs(np.squeeze(out[k]) - core[k])) for k in range(2)))


# ----------------------------------------------------------------------------- cases
def build_cases(quick: bool, shapes, noise: Sequence[float] | None = None) -> list[tuple[Case, dict]]:
    """The shapes as (case, render recipe): specimen, cameras, model and settings.

    ``noise``: the noise levels (gray levels) each family shape is rendered with (default
    the family's 2 gray levels); the twisted plate keeps the demo's."""
    cases = []
    if "twisted" in shapes:
        d = scenes.SMALL_DEMO if quick else DEMO
        cameras = demo_cameras(image_size=d["image_size"], stereo_angle_deg=d["stereo_angle_deg"],
                               field_mm=d["field_mm"])
        specimen = twisted_plate(d["length_mm"], d["width_mm"], corner_mm=d["corner_mm"],
                                 hole_radius_mm=d["hole_radius_mm"], waviness_mm=d["waviness_mm"],
                                 view_length_mm=d["view_mm"],
                                 speckle_mm=speckle_mm_for(cameras[0], 4.0), seed=7)
        model = nominal_model(plate_with_hole(d["view_mm"], d["width_mm"], d["hole_radius_mm"]),
                              3 if quick else 4, "Q9")
        cases.append((Case("twisted", specimen, cameras, model, MeasurementSettings(scales=(2, 1, 0))),
                      dict(noise_std=d["noise_std"], seed=11)))
    family = scenes.FAMILY if quick else scenes.FAMILY_DEMO_SCALE
    cameras = scenes.family_cameras(family)
    model = nominal_model(rectangle(family["length_mm"], family["width_mm"]), family["elements"], "Q9")
    for shape in shapes:
        if shape == "twisted":
            continue
        divisor = None if shape == "flat" else int(shape)
        specimen = scenes.family_specimen(divisor, speckle_mm_for(cameras[0], family["speckle_px"]),
                                          family)
        name = "flat" if divisor is None else \
            f"sigma W/{divisor} ({scenes.family_sigma(divisor, family):g} mm)"
        for std in (family["noise_std"],) if noise is None else noise:
            label = name if noise is None else f"{name}, noise {std:g}"
            cases.append((Case(label, specimen, cameras, model, MeasurementSettings(scales=(1, 0))),
                          dict(noise_std=float(std), seed=family["noise_seed"])))
    return cases


def render(case: Case, recipe: dict, renderer: str, supersample: int, riley_subsample: int) -> tuple:
    t0 = time.perf_counter()
    if renderer == "core":
        arrays = render_stereo(case.specimen, case.cameras, supersample=supersample,
                               noise_std=recipe["noise_std"], seed=recipe["seed"], progress=False)
        note = f"{time.perf_counter() - t0:.1f} s"
    else:
        arrays, deviation = riley_render(case.specimen, case.cameras, recipe["noise_std"], recipe["seed"],
                                         sub_sample=riley_subsample)
        note = f"{time.perf_counter() - t0:.1f} s, mesh off the truth by <= {1e3 * deviation:.2g} um"
    images = tuple(Image.from_array(a, source=f"{renderer} cam{k}") for k, a in enumerate(arrays))
    return images, note


# ----------------------------------------------------------------------------- methods
def _tikhonov_solvers(mesh) -> dict:
    solvers = {f"T{length:g}": TikhonovSolver(mesh, length) for length in TIKHONOV_MM}
    try:
        solvers["Tauto"] = TikhonovSolver(mesh, "auto")
    except (TypeError, ValueError):
        pass
    return solvers


def truth_misfit(case: Case, images, measurement, variance: float) -> float:
    """``b^T H^-1 b / (n kappa)`` at the TRUE shape: the fall of the cost that one FE step
    from the truth would buy, per FE dof, in units of the noise model's ``kappa`` (the
    level search's). 1 when the images differ from the truth's image model by noise only
    (it is how ``kappa`` is defined); above 1, the FE mesh can fit a systematic misfit of
    the images (pixel integration, texture sampling), and Mallows' Cp will count it as shape.
    """
    mesh = case.model.mesh
    q_true = true_normal_offset(case.specimen, mesh.nodes, measurement.normals)
    state = linearised_state(mesh.nodes, measurement.normals, q_true, measurement.quadrature,
                             images, case.cameras, case.settings.normalisation)
    seen = seen_dofs(state.H)
    b = state.b[seen]
    return float(b @ spla.spsolve(state.H[seen][:, seen].tocsc(), b)) / np.count_nonzero(seen) / variance


def run_case(case: Case, images, repeat: int) -> dict:
    truth, mesh, cams = case.specimen, case.model.mesh, case.cameras

    def error(m):
        value = 1e3 * rms(bounded_shape_error(m.nodes, truth))
        return value if m.ok else -value                      # negative: the verdict failed

    reference = dataclasses.replace(case.settings, uncertainty=False)
    row = {"FE": error(measure(mesh, images, cams, None, reference))}
    for name, solver in _tikhonov_solvers(mesh).items():
        row[name] = error(measure(mesh, images, cams, solver, reference))
    times = {"G3": [], "auto": [], "search": []}
    for n in FIXED_LEVELS:
        try:
            solver = georeg_solver(case.model, n)
        except ValueError:
            row[f"G{n}"] = None                              # the mesh does not refine it
            continue
        for _ in range(repeat if n == 3 else 1):
            t0 = time.perf_counter()
            m = measure(mesh, images, cams, solver, case.settings)
            if n == 3:
                times["G3"].append(time.perf_counter() - t0)
        row[f"G{n}"] = error(m)
    for _ in range(repeat):
        t0 = time.perf_counter()
        m, solver, search = measure_auto_levels(case.model, images, cams, case.settings,
                                                start_levels=START_LEVELS)
        times["auto"].append(time.perf_counter() - t0)
        times["search"].append(search.time_s)
    row["auto"] = error(m)
    row["misfit"] = truth_misfit(case, images, m, search.variance)
    row["level"] = f"{search.chosen}/{search.n_levels} ({solver.operator(search.chosen).shape[0]})"
    row["gain"] = max((t.gain for t in search.trials if np.isfinite(t.gain)), default=float("nan"))
    for key, values in times.items():
        row["t_" + key] = statistics.median(values) if values else float("nan")
    return row


def print_table(title: str, rows: list[tuple[str, dict, str]]) -> None:
    methods = ["FE", "T5", "T10", "T20"] + (["Tauto"] if any("Tauto" in r for _, r, _ in rows) else []) \
        + [f"G{n}" for n in FIXED_LEVELS] + ["auto"]
    print(f"\n{title}\nRMS error to the truth (um; negative: the measurement's verdict failed; "
          "-: levels the mesh does not refine)")
    head = f"{'shape':22s}" + "".join(f"{m:>7s}" for m in methods) + \
        f"  {'auto level (dofs)':>18s} {'gain':>8s} {'misfit':>6s}  {'t G3':>6s} {'t auto':>6s} {'added':>6s} {'search':>6s}"
    print(head)
    print("-" * len(head))
    for name, row, _ in rows:
        cells = "".join("      -" if row.get(m) is None else f"{row[m]:7.2f}" for m in methods)
        added = row["t_auto"] / row["t_G3"] - 1.0
        print(f"{name:22s}{cells}  {row['level']:>18s} {row['gain']:8.1f} {row['misfit']:6.2f}  {row['t_G3']:6.1f} "
              f"{row['t_auto']:6.1f} {100 * added:5.0f}% {100 * row['t_search'] / row['t_G3']:5.0f}%")
    for name, row, note in rows:
        best = min((v, k) for k, v in row.items() if k in methods and k.startswith("T") and v is not None
                   and v > 0)
        verdict = ("<= FE" if 0 <= row["auto"] <= row["FE"] else "> FE") + ", " + \
            ("<=" if 0 <= row["auto"] <= best[0] else ">") + f" best Tikhonov ({best[1]} {best[0]:.2f})"
        print(f"  {name}: auto {verdict}; search {row['t_search']:.1f} s; render {note}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="the tests' scale: small demo (500 x 333 px), family at 704 x 736 px")
    parser.add_argument("--renderer", choices=("core", "riley", "both"), default="core")
    parser.add_argument("--repeat", type=int, default=3, help="runs timed for georeg (median)")
    parser.add_argument("--shapes", nargs="+", default=["twisted", "flat", "2", "5", "10", "20"],
                        help="twisted, flat and divisors of the width for the bump's sigma")
    parser.add_argument("--noise", type=float, nargs="+", default=None,
                        help="noise levels (gray levels) of the family's shapes (default: 2)")
    parser.add_argument("--supersample", type=int, default=scenes.FAMILY["supersample"],
                        help="rays per pixel side of the core's renderer")
    parser.add_argument("--riley-subsample", type=int, default=4,
                        help="sub-pixels per pixel side of riley's render")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cpus, load average {os.getloadavg()[0]:.1f} at start")
    renderers = ("core", "riley") if args.renderer == "both" else (args.renderer,)
    if "riley" in renderers:
        import riley  # noqa: F401  (fails here, before any work, when it is not installed)
        from importlib.metadata import version
        print(f"riley-raster {version('riley-raster')}: flat plate, bilinear, 3 x 3 sub-pixels: "
              f"max |riley - core| = {riley_check():.2g} gray levels")
    cases = build_cases(args.quick, args.shapes, args.noise)
    for renderer in renderers:
        rows = []
        for case, recipe in cases:
            images, note = render(case, recipe, renderer, args.supersample, args.riley_subsample)
            t0 = time.perf_counter()
            row = run_case(case, images, args.repeat)
            rows.append((case.name, row, note))
            print(f"[{renderer}] {case.name}: {time.perf_counter() - t0:.0f} s", flush=True)
        title = ("renderer: core (ray casting, bilinear texture, "
                 f"{args.supersample} x {args.supersample} rays per pixel)" if renderer == "core"
                 else "renderer: riley-raster (quad9 surface mesh, Catmull-Rom texture, "
                      f"{args.riley_subsample} x {args.riley_subsample} sub-pixels)")
        scale = "tests' scale (--quick)" if args.quick else "demo scale"
        print_table(f"{title}; {scale}; median of {args.repeat} runs for the times (s)", rows)


if __name__ == "__main__":
    main()
