"""Benchmark: who is right on sub-pixel motion (issue 27, item 4): renders with known truth
that reproduce the real GT4 images' statistics, measured by us and by pyvale.

The real series (``../shared/data/stereo_dic_sample3``, frames 0001-0005: at most 0.12 px)
gives, at DICe's subset centres, out-of-plane medians that differ by +-12 % between codes.
This script settles what can be settled on images whose truth is known.

``--stats``: the GT4 statistics, measured on the real frame 0000 (mean gray and standard
deviation over the specimen's ROI of examples/gt4_roi/specimen.toml, the median 25 px subset
contrast, the speckle's autocorrelation width) and the temporal noise from frames 0000 vs 0001
(std of the difference / sqrt 2; the motion between them is at most 0.01 px).

``--renders``: a GT4-like rig on a CROP-SIZED sensor (480 x 360 px, to stay fast): focal
6600 px, principal point at the centre, two cameras 390 mm from a flat plate at a stereo angle
of 18.2 deg (baseline 123.3 mm), the plate's speckle sized to GT4's autocorrelation width and
its gray levels mapped to GT4's mean and standard deviation, Gaussian noise (``--noise``,
default the measured temporal noise 0.8 and DICe's NOISE_LEVEL figure 4 gray levels), 8 bits.
Motions: rigid translations of 0.01, 0.02, 0.05, 0.1, 0.2 and 2.5 px in plane (x; 1 px =
Z / f = 0.0591 mm) and out of plane (w such that each camera's image moves that many pixels
sideways: w = s Z / (f sin(angle / 2))), and a homogeneous stretch of 3 % along x. Renderers:
the core's ray caster (``fesdic_core.synthetic.render``) and riley-raster (``riley``,
Catmull-Rom texture sampling, the mesh's nodes moved by the motion; camera conversion of
benchmarks/bench_levels.py) when importable. Textures (``--speckle``): "smooth" (3.5 px dots,
3 x 3 rays per pixel: camera 0's autocorrelation FWHM, but a third of GT4's spectral energy
near Nyquist) and "sharp" (2.5 px dots, one ray per pixel, aliased: camera 1's FWHM and
near-Nyquist energy; the share of energy at 0.35-0.5 cycles/px is printed for both). Ours: the library
(``fesdic_core.displacement``, the defaults of ``georeg track``: scales (2, 1, 0), modified
Gauss-Newton, element normalisation, image model prefilter 0.5 px, cubic B-spline) on the TRUE
mesh (a flat 19.2 x 14.4 mm Q9 mesh of 8 x 6 elements, about 41 px), methods fe, tikhonov
(10 mm) and georeg (2 levels), and for fe the variants interpolation order 5, prefilter 0 and
1 px, full Gauss-Newton. pyvale (``calculate_3d``, subset 27, step 4, its defaults otherwise:
ZNSSD, affine, B-spline, Gaussian prefilter 5 px / sigma 1) on the same images and exact
cameras, when importable (its points' coordinates are their deformed positions: the
reference ones are taken as x - u). Recovered rigid motion: the field's mean over the surface
(ours: area-weighted over the integration points; the mean over the nodes over-weights the
boundary's nodes and hides part of the bias; pyvale: over its points on the mesh's rectangle)
and over ``--seeds`` noise seeds; stretch: the weighted slope of u_x over x. Bias in % of the truth and in px (out of plane: the sideways image motion it makes).

``--texture``: GT4's own texture with known truth: the real frame-0000 pair shifted in Fourier
space (exact for a band-limited image) by the left and right image motions DICe reports at
frame 5 scaled by 0.1, 0.5 and 1 (a near-rigid motion of the real specimen), fresh noise of
0.8 gray levels; ours (``georeg track``'s reference: the shape measured from frame 0000 by
``georeg measure examples/gt4_roi/specimen.toml``, VIC-3D cameras) for prefilter 0, 0.5, 1 px,
and pyvale's 2-D DIC of camera 0 (subset 25, step 20): the left image motion at DICe's subset
centres (median) against the imposed shift.

``--real``: the real frames 1-5 from frame 0000, ours as above (prefilter 0.5 and 1 px), at
DICe's subset centres: the median displacement along the specimen's normal (the frame of
``georeg measure``'s best-fit plane) and the left image motion, beside DICe's gold
(``reference_dice/DICe_solution.e``) and pyvale's 2-D DIC of camera 0.

Run: ``PYTHONPATH=. /work/venv-bench/bin/python benchmarks/bench_subpixel.py [--stats]
[--renders] [--texture] [--real] [--noise 0.8 4] [--seeds 2] [--renderers core riley]
[--workdir DIR]`` (no flag: all four; without the data: ``--renders`` only; without riley or
pyvale: their rows are skipped). Figures: README / report of issue 27.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "benchmarks")]
DATA = REPO.parent / "shared" / "data" / "stereo_dic_sample3"

DISTANCE_MM, FOCAL_PX, ANGLE_DEG, SIZE = 390.0, 6600.0, 18.2, (480, 360)
MESH_MM, ELEMENTS = (19.2, 14.4), (8, 6)
GT4 = dict(mean=71.6, std=28.5, noise=0.8, fwhm_px=3.6)   # measured by --stats (camera 0)
#: textures: (dot size px, rays (riley: sub-pixels) per pixel side): "smooth" has GT4 camera 0's
#: autocorrelation FWHM (3.6 px) but a third of its energy near Nyquist; "sharp" (point-sampled,
#: aliased) has camera 1's FWHM (2.9 px) and its energy near Nyquist (5 % in 0.35-0.5 cycles/px)
TEXTURES = {"smooth": (3.5, 3), "sharp": (2.5, 1)}
SHIFTS_PX = (0.01, 0.02, 0.05, 0.1, 0.2, 2.5)
STRETCH = 0.03
SUBSET, STEP = 27, 4
VARIANTS = {"fe": {}, "fe, order 5": dict(order=5), "fe, prefilter 0": dict(prefilter=0.0),
            "fe, prefilter 1": dict(prefilter=1.0), "fe, full GN": dict(jacobian="current"),
            "tikhonov 10 mm": dict(method="tikhonov"), "georeg 2 levels": dict(method="georeg")}


def has(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


def load() -> str:
    return f"load average {os.getloadavg()[0]:.1f}"


# ----------------------------------------------------------------------------- GT4 statistics
def roi_mask(shape=(1200, 1920)) -> np.ndarray:
    """Camera 0's ROI of examples/gt4_roi/specimen.toml (the D minus its cut-out), eroded 10 px."""
    import cv2
    import tomllib
    g = tomllib.loads((REPO / "examples" / "gt4_roi" / "specimen.toml").read_text())["geometry"]
    m = np.zeros(shape, np.uint8)
    cv2.fillPoly(m, [np.array(g["polygon_px"], np.int32)], 1)
    for hole in g.get("exclude_px", []):
        cv2.fillPoly(m, [np.array(hole, np.int32)], 0)
    return cv2.erode(m, np.ones((21, 21), np.uint8)).astype(bool)


def autocorrelation_fwhm(window: np.ndarray) -> float:
    """Full width at half maximum (px, along x) of the window's autocorrelation."""
    w = window - window.mean()
    ac = np.fft.fftshift(np.real(np.fft.ifft2(np.abs(np.fft.fft2(w)) ** 2)))
    r, c = np.array(ac.shape) // 2
    p = ac[r, c:c + 16] / ac[r, c]
    i = int(np.argmax(p < 0.5))
    return float(2 * (i - 1 + (p[i - 1] - 0.5) / (p[i - 1] - p[i])))


def nyquist_share(window: np.ndarray) -> float:
    """Share of the window's spectral energy at 0.35-0.5 cycles/px (radial frequency)."""
    w = window - window.mean()
    power = np.abs(np.fft.fft2(w)) ** 2
    r = np.hypot(np.fft.fftfreq(w.shape[0])[:, None], np.fft.fftfreq(w.shape[1])[None, :])
    return float(power[(r > 0.35) & (r <= 0.5)].sum() / power.sum())


def gt4_stats() -> None:
    import cv2
    im = lambda n, c: cv2.imread(str(DATA / "images" / f"GT4-{n}_{c}.png"), 0).astype(float)
    m = roi_mask()
    for c in (0, 1):
        f, g = im("0000", c), im("0001", c)
        mask = m if c == 0 else np.zeros_like(m)
        if c == 1:
            mask[500:800, 700:1300] = True          # (no ROI for camera 1: its central block)
        mu = cv2.blur(f, (25, 25))
        local = np.sqrt(np.maximum(cv2.blur(f * f, (25, 25)) - mu ** 2, 0))
        window = f[460:716, 1300:1556] if c == 0 else f[550:806, 900:1156]
        print(f"  camera {c}: mean {f[mask].mean():.1f}, std {f[mask].std():.1f}, median 25 px subset "
              f"std {np.median(local[mask]):.1f}, speckle autocorrelation FWHM "
              f"{autocorrelation_fwhm(window):.2f} px, energy at 0.35-0.5 cycles/px "
              f"{100 * nyquist_share(window):.1f} %, temporal noise (0001 - 0000) / sqrt 2: "
              f"{(g - f)[mask].std() / np.sqrt(2):.2f} gray levels")


# ----------------------------------------------------------------------------- renders
def scene(texture: str = "smooth"):
    from adapters.fesdic_core import nominal_model
    from fesdic_core.synthetic.render import demo_cameras, speckle_mm_for
    from fesdic_core.synthetic.specimen import flat_plate
    from georeg_plugin.spline.geometries import rectangle
    cams = demo_cameras(image_size=SIZE, stereo_angle_deg=ANGLE_DEG, distance_mm=DISTANCE_MM,
                        focal_px=FOCAL_PX)
    plate = flat_plate(26.0, 20.0, speckle_mm=speckle_mm_for(cams[0], TEXTURES[texture][0]),
                       seed=5)
    return cams, plate, nominal_model(rectangle(*MESH_MM), ELEMENTS, "Q9")


def motions() -> dict:
    """name -> (motion, truth kind, true value (mm or strain), image motion in px)."""
    from fesdic_core.synthetic.motion import RigidMotion, StretchMotion
    mm_px = DISTANCE_MM / FOCAL_PX
    w_px = mm_px / np.sin(np.radians(ANGLE_DEG / 2))
    out = {f"in-plane {s:g} px": (RigidMotion((s * mm_px, 0, 0)), 0, s * mm_px, s) for s in SHIFTS_PX}
    out.update({f"out-of-plane {s:g} px": (RigidMotion((0, 0, s * w_px)), 2, s * w_px, s)
                for s in SHIFTS_PX})
    out[f"stretch {100 * STRETCH:g} %"] = (StretchMotion(STRETCH), "strain", STRETCH,
                                            STRETCH * MESH_MM[0] / 2 / mm_px)
    return out


def riley_frame(plate, cams, motion=None, sub_sample: int = 4) -> list:
    import riley
    from bench_levels import _riley_camera, riley_surface
    from fesdic_core.synthetic.render import speckle_texture
    texture = speckle_texture(plate)
    coords, connect, _ = riley_surface(plate)
    rows, cols = texture.values.shape
    uvs = np.column_stack([(coords[:, 0] - texture.origin_mm[0]) / (texture.texel_mm * (cols - 1)),
                           (coords[:, 1] - texture.origin_mm[1]) / (texture.texel_mm * (rows - 1))])
    if motion is not None:                              # affine motions: exact on the Q9 nodes
        coords = coords + motion(coords)
    mesh = riley.create_mesh(
        convention=riley.ConnectConvention(riley.EElemType.QUAD9, riley.EConnectAxis.ROW, 0,
                                           riley.ENodeOrder.VTK),
        mesh_type=riley.MeshType.quad9, coords=coords, connect=connect,
        shader=riley.TextureShader(uvs=uvs, texture=texture.values.astype(np.float64)[None],
                                   sample=riley.TextureSample.cubic_catmull_rom))
    config = riley.RasterConfig(parallel=os.cpu_count() or 1,
                                save_strategy=riley.SaveStrategy.memory, report=0)
    config.background_value = 10.0
    out = riley.raster([mesh], [_riley_camera(riley, c, sub_sample) for c in cams], config)
    return [np.array(np.squeeze(out[k]), float) for k in range(2)]


def render_all(renderer: str, cams, plate, cache: Path, texture: str) -> dict:
    """Noise-free float renders {name: [cam0, cam1]} of the reference ("reference") and every
    motion, cached as .npy."""
    from fesdic_core.synthetic.render import render_stereo
    cache.mkdir(parents=True, exist_ok=True)
    frames = {}
    for name, spec in [("reference", None), *motions().items()]:
        files = [cache / f"{renderer}_{texture}_{name.replace(' ', '_')}_cam{k}.npy" for k in (0, 1)]
        if all(f.is_file() for f in files):
            frames[name] = [np.load(f) for f in files]
            continue
        motion = None if spec is None else spec[0]
        rays = TEXTURES[texture][1]
        frames[name] = (render_stereo(plate, cams, supersample=rays, bit_depth=None, progress=False,
                                      motion=motion) if renderer == "core"
                        else riley_frame(plate, cams, motion, rays))
        for f, a in zip(files, frames[name]):
            np.save(f, a)
    return frames


def gray_map(reference: list, cams) -> tuple[float, float]:
    """(a, b) with ``a render + b`` at GT4's mean and standard deviation over camera 0's view
    of the mesh (a linear map of the render is the render of the linearly mapped texture)."""
    w, h = SIZE
    a = reference[0][h // 2 - 110:h // 2 + 110, w // 2 - 150:w // 2 + 150]
    scale = GT4["std"] / a.std()
    return scale, GT4["mean"] - scale * a.mean()


def quantized(image, ab, noise, rng) -> np.ndarray:
    return np.clip(np.rint(ab[0] * image + ab[1] + rng.normal(0.0, noise, image.shape)), 0, 255)


def ours(frames: dict, noisy: dict, cams, model, variant: dict) -> tuple[dict, float]:
    """Our measurement of every motion: {name: (points X_g (g, 3), u_g (g, 3), weights (g,))
    per seed}, median seconds per frame."""
    from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                                 measure_displacement)
    from fesdic_core.imaging.image import Image
    from georeg_app.series.reference import displacement_solver
    mesh = model.mesh
    settings = DisplacementSettings(scales=(2, 1, 0), jacobian=variant.get("jacobian", "reference"))
    img = lambda a: Image.from_array(a, prefilter_px=variant.get("prefilter", 0.5),
                                     order=variant.get("order", 3))
    out, times = {}, []
    for seed, pairs in noisy.items():
        ref = displacement_reference(mesh, [img(a) for a in pairs["reference"]], cams, settings)
        for name in motions():
            solver = displacement_solver(variant.get("method", "fe"), mesh, model, 10.0, 2)
            t = time.perf_counter()
            m = measure_displacement(ref, [img(a) for a in pairs[name]], solver)
            times.append(time.perf_counter() - t)
            U = m.U if m.ok else np.full_like(m.U, np.nan)
            quad = m.reference.quad                      # the field at the integration points
            out.setdefault(name, []).append((quad.points(mesh.nodes), quad.points(U), quad.weight_mm2))
    return out, statistics.median(times)


def pyvale_run(noisy: dict, cams, folder: Path) -> tuple[dict, float]:
    """pyvale's calculate_3d of every motion: {name: (points (p, 3), U (p, 3)) per seed}, in
    the world frame; median seconds per frame."""
    from bench_vs_pyvale import pyvale_calib
    from fesdic_core.synthetic.rays import pixel_rays
    from pyvale import dic
    import cv2
    w, h = SIZE
    y, x = np.mgrid[0:h, 0:w]
    origin, d = pixel_rays(cams[0], np.column_stack([x.ravel(), y.ravel()]))
    xy = origin[:2] + (-origin[2] / d[:, 2])[:, None] * d[:, :2]
    roi = ((np.abs(xy[:, 0]) <= MESH_MM[0] / 2) & (np.abs(xy[:, 1]) <= MESH_MM[1] / 2)).reshape(h, w)
    R0 = cv2.Rodrigues(np.asarray(cams[0].rvec, float).reshape(3, 1))[0]
    t0 = np.asarray(cams[0].tvec, float).ravel()
    names = list(motions())
    out, times = {}, []
    for seed, pairs in noisy.items():
        folder.mkdir(parents=True, exist_ok=True)
        for old in folder.glob("dic_results_*"):
            old.unlink()
        u8 = lambda a: np.ascontiguousarray(a, dtype=np.uint8)
        t = time.perf_counter()
        dic.calculate_3d(reference=[u8(a) for a in pairs["reference"]],
                         deformed=[np.stack([u8(pairs[n][k]) for n in names]) for k in (0, 1)],
                         calibration=pyvale_calib(cams), roi_mask=roi, seed=[w // 2, h // 2],
                         subset_size=SUBSET, subset_step=STEP, num_threads=2,
                         output_basepath=folder, output_binary=True, print_level=0)
        times.append((time.perf_counter() - t) / len(names))
        s = dic.import_3d(data=str(folder / "dic_results_*"), delimiter=",", binary=True,
                          layout="column", print_level=0).stereo
        for i, name in enumerate(names):
            X = np.column_stack([np.ravel(a[i]) for a in (s.x_mm, s.y_mm, s.z_mm)])
            U = np.column_stack([np.ravel(a[i]) for a in (s.u_mm, s.v_mm, s.w_mm)])
            ok = np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(U), axis=1)
            # (its coordinates are the deformed positions: the reference ones are X - U)
            out.setdefault(name, []).append(((X[ok] - U[ok] - t0) @ R0, U[ok] @ R0))
    return out, statistics.median(times)


def recovered(name: str, X: np.ndarray, U: np.ndarray, weight: np.ndarray | None = None) -> float:
    """The rigid component (weighted mean over the points: ours the area of the integration
    points, pyvale's regular grid of subsets uniform; a mean over the nodes would over-weight
    the boundary's nodes) or the stretch (weighted slope of u_x over x)."""
    _, kind, _, _ = motions()[name]
    w = np.ones(len(X)) if weight is None else np.asarray(weight, float)
    if not np.all(np.isfinite(U)):
        return float("nan")
    if kind == "strain":
        return float(np.polyfit(X[:, 0], U[:, 0], 1, w=np.sqrt(w))[0])
    return float(w @ U[:, kind] / w.sum())


def px_factor(name: str) -> float:
    """px per unit of the recovered value (in-plane mm, out-of-plane mm, strain)."""
    _, kind, _, _ = motions()[name]
    if kind == 0:
        return FOCAL_PX / DISTANCE_MM
    if kind == 2:
        return FOCAL_PX * np.sin(np.radians(ANGLE_DEG / 2)) / DISTANCE_MM
    return MESH_MM[0] / 2 * FOCAL_PX / DISTANCE_MM            # strain -> px at the mesh's ends


def print_rows(label: str, values: dict) -> None:
    """values: {motion: [recovered per seed]}: mean, bias % and px, and the seeds' spread."""
    print(f"  {label}:")
    for name, (_, _, truth, _) in motions().items():
        v = np.array(values[name], float)
        mean = float(np.nanmean(v))
        spread = float(np.nanstd(v, ddof=1) / np.sqrt(len(v))) if len(v) > 1 else float("nan")
        unit = "" if name.startswith("stretch") else " mm"
        failed = int(np.count_nonzero(~np.isfinite(v)))
        print(f"    {name:22s} true {truth:.6g}{unit}, recovered {mean:.6g}{unit}: bias "
              f"{100 * (mean - truth) / truth:+6.2f} %, {px_factor(name) * (mean - truth):+.4f} px "
              f"(+- {px_factor(name) * spread:.4f} px over seeds)"
              + (f" ({failed} of {len(v)} runs failed their verdict)" if failed else ""))


def run_renders(args) -> None:
    cams, plate, model = scene(args.speckle)
    print(f"\nrenders: {SIZE[0]} x {SIZE[1]} px crop sensor, f {FOCAL_PX:g} px, {DISTANCE_MM:g} mm, "
          f"stereo angle {ANGLE_DEG:g} deg, baseline "
          f"{2 * DISTANCE_MM * np.sin(np.radians(ANGLE_DEG / 2)):.1f} mm; true mesh {MESH_MM[0]:g} x "
          f"{MESH_MM[1]:g} mm, {ELEMENTS[0]} x {ELEMENTS[1]} Q9; {load()}")
    for renderer in args.renderers:
        if renderer == "riley" and not has("riley"):
            print("  riley: not importable by this python, skipped")
            continue
        t = time.perf_counter()
        frames = render_all(renderer, cams, plate, args.workdir / "renders", args.speckle)
        ab = gray_map(frames["reference"], cams)
        ref0 = ab[0] * frames["reference"][0] + ab[1]
        w, h = SIZE
        print(f"\n{renderer} renderer, {args.speckle} texture ({time.perf_counter() - t:.0f} s): camera 0 mean "
              f"{ref0[h // 2 - 110:h // 2 + 110, w // 2 - 150:w // 2 + 150].mean():.1f}, std "
              f"{ref0[h // 2 - 110:h // 2 + 110, w // 2 - 150:w // 2 + 150].std():.1f}, "
              f"autocorrelation FWHM {autocorrelation_fwhm(ref0[60:300, 80:400]):.2f} px, energy at "
              f"0.35-0.5 cycles/px {100 * nyquist_share(ref0[60:300, 80:400]):.1f} %")
        for noise in args.noise:
            noisy = {}
            for seed in range(args.seeds):
                rng = np.random.default_rng(1000 * seed + int(10 * noise))
                noisy[seed] = {n: [quantized(a, ab, noise, rng) for a in pair]
                               for n, pair in frames.items()}
            print(f"\n {renderer}, noise {noise:g} gray levels, {args.seeds} seeds, {load()}")
            for label in args.variants:
                U, seconds = ours(frames, noisy, cams, model, VARIANTS[label])
                print_rows(f"ours, {label} ({seconds:.2f} s per frame)",
                           {n: [recovered(n, *u) for u in us] for n, us in U.items()})
            if has("pyvale"):
                P, seconds = pyvale_run(noisy, cams, args.workdir / f"pyvale_{renderer}_{noise:g}")
                print_rows(f"pyvale calculate_3d, subset {SUBSET}, step {STEP} ({seconds:.2f} s per frame)",
                           {n: [recovered(n, X, U) for X, U in ps] for n, ps in P.items()})
            else:
                print("  pyvale: not importable by this python, skipped")


# ----------------------------------------------------------------------------- real data
def dice_gold():
    """DICe's subset centres (p, 2) in camera 0 and its nodal variables (frame, p)."""
    from scipy.io import netcdf_file
    f = netcdf_file(str(DATA / "reference_dice" / "DICe_solution.e"), "r", mmap=False)
    names = [b"".join(n).decode().strip() for n in f.variables["name_nod_var"].data]
    var = {n: np.array(f.variables[f"vals_nod_var{i + 1}"].data) for i, n in enumerate(names)}
    return np.column_stack([var["COORDINATE_X"][0], var["COORDINATE_Y"][0]]), var


def real_reference(workdir: Path):
    """The reference of ``georeg track``: the shape of frame 0000 measured by
    ``georeg measure examples/gt4_roi/specimen.toml`` (run once into ``workdir``)."""
    import json
    import subprocess
    from fesdic_core.cameras.rig import read_cameras_json
    from fesdic_core.fe.mesh_io import read_mesh
    out = workdir / "gt4_shape"
    if not (out / "summary.json").is_file():
        subprocess.run([sys.executable, "-m", "georeg_app", "-q", "measure",
                        str(REPO / "examples" / "gt4_roi" / "specimen.toml"), "--out", str(out),
                        "--overwrite"], check=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    summary = json.loads((out / "summary.json").read_text())
    entry = next(m for m in summary["methods"] if m.get("status") == "ok")
    mesh = read_mesh(out / entry["mesh_file"])
    cams = read_cameras_json(out / entry["mesh_file"].replace(".vtu", "_cameras.json"))
    return mesh, cams, np.array(summary["specimen"]["frame_axes"])


def at_dice(mesh, cams, axes, U, px) -> tuple[np.ndarray, np.ndarray]:
    """Our field at DICe's subset centres: (displacement along the specimen's normal (p,),
    camera 0's image motion (p, 2)); NaN off the mesh."""
    from scipy.interpolate import LinearNDInterpolator
    p0 = cams[0].project(mesh.nodes)
    X = LinearNDInterpolator(p0, mesh.nodes)(px)
    u = LinearNDInterpolator(p0, U)(px)
    return (u @ axes.T)[:, 2], cams[0].project(X + u) - cams[0].project(X)


def pyvale_2d(reference: np.ndarray, deformed: list, px: np.ndarray, folder: Path
              ) -> tuple[np.ndarray, np.ndarray]:
    """pyvale's 2-D DIC of camera 0 (subset 25, step 20): its image motion at DICe's points
    (frames, p, 2) and the median over all its points (frames, 2)."""
    from pyvale import dic
    from scipy.interpolate import LinearNDInterpolator
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("dic_results_*"):
        old.unlink()
    dic.calculate_2d(reference=reference.astype(np.uint8), deformed=np.stack(deformed).astype(np.uint8),
                     roi_mask=roi_mask(), seed=[924, 524], subset_size=25, subset_step=20,
                     num_threads=2, output_basepath=folder, output_binary=True, print_level=0)
    r = dic.import_2d(data=str(folder / "dic_results_*"), delimiter=",", binary=True,
                      layout="column", print_level=0)
    P = np.column_stack([r.ss_x, r.ss_y])
    whole = np.column_stack([np.nanmedian(r.u_px, axis=1), np.nanmedian(r.v_px, axis=1)])
    return whole, np.stack([np.column_stack([LinearNDInterpolator(P, r.u_px[i])(px),
                                      LinearNDInterpolator(P, r.v_px[i])(px)])
                     for i in range(len(deformed))])


def ours_real(mesh, cams, pairs: list, prefilter: float) -> list:
    """Our default measurement (fe, as ``georeg track``) of each pair from frame 0000."""
    from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                                 measure_displacement)
    from fesdic_core.imaging.image import Image, read_image
    ref = displacement_reference(mesh, [read_image(DATA / "images" / f"GT4-0000_{c}.png",
                                                   prefilter_px=prefilter) for c in (0, 1)],
                                 cams, DisplacementSettings(scales=(2, 1, 0)))
    out = []
    for pair in pairs:
        m = measure_displacement(ref, [Image.from_array(a, prefilter_px=prefilter) for a in pair])
        out.append(m.U if m.ok else np.full_like(m.U, np.nan))
    return out


def read_pair(frame: str) -> list:
    import cv2
    return [cv2.imread(str(DATA / "images" / f"GT4-{frame}_{c}.png"), 0).astype(float) for c in (0, 1)]


def run_texture(args) -> None:
    """GT4's texture moved by known Fourier shifts (see the module docstring)."""
    from scipy import ndimage
    px, var = dice_gold()
    mesh, cams, axes = real_reference(args.workdir)
    frame5 = [np.array([np.median(var["DISPLACEMENT_X"][5]), np.median(var["DISPLACEMENT_Y"][5])]),
              np.array([np.median(var["STEREO_DISPLACEMENT_X"][5]),
                        np.median(var["STEREO_DISPLACEMENT_Y"][5])])]
    frame5[1][1] = frame5[0][1]          # (the same vertical motion: consistent with the rig)
    ref, rng = read_pair("0000"), np.random.default_rng(7)
    scales = (0.1, 0.5, 1.0)
    pairs = []
    for s in scales:
        pair = []
        for c in (0, 1):
            shifted = np.real(np.fft.ifft2(ndimage.fourier_shift(np.fft.fft2(ref[c]),
                                                                 (s * frame5[c][1], s * frame5[c][0]))))
            pair.append(np.clip(np.rint(shifted + rng.normal(0, GT4["noise"], shifted.shape)), 0, 255))
        pairs.append(pair)
    print(f"\nGT4 texture, Fourier-shifted (left, right) = s x ({frame5[0].round(4)}, "
          f"{frame5[1].round(4)}) px, noise {GT4['noise']} gray levels; {load()}")
    rows = {}
    for prefilter in (0.0, 0.5, 1.0):
        t = time.perf_counter()
        for s, U in zip(scales, ours_real(mesh, cams, pairs, prefilter)):
            _, motion = at_dice(mesh, cams, axes, U, px)
            whole = np.median(cams[0].project(mesh.nodes + U) - cams[0].project(mesh.nodes), axis=0)
            rows.setdefault(s, []).append(
                f"ours prefilter {prefilter:g}: {whole[0]:+.4f} ({100 * (whole[0] / (s * frame5[0][0]) - 1):+.1f} %;"
                f" at DICe's points {np.nanmedian(motion[:, 0]):+.4f})")
        print(f"  ours, prefilter {prefilter:g} px: {(time.perf_counter() - t) / len(scales):.1f} s per frame")
    if has("pyvale"):
        whole, P = pyvale_2d(ref[0], [p[0] for p in pairs], px, args.workdir / "pyvale_texture")
        for s, w, motion in zip(scales, whole, P):
            rows[s].append(f"pyvale 2-D: {w[0]:+.4f} ({100 * (w[0] / (s * frame5[0][0]) - 1):+.1f} %; "
                           f"at DICe's points {np.nanmedian(motion[:, 0]):+.4f})")
    print("  (left u: the median over the mesh's nodes (pyvale: over its points), beside the median\n"
          "  at DICe's subset centres, whose random error is about 0.001 px at this noise)")
    for s in scales:
        print(f"  s = {s:g}: left u true {s * frame5[0][0]:+.4f} px; " + "; ".join(rows[s]))


def run_real(args) -> None:
    px, var = dice_gold()
    mesh, cams, axes = real_reference(args.workdir)
    pairs = [read_pair(f"000{k}") for k in range(1, 6)]
    print(f"\nreal GT4 frames 1-5 from 0000, at DICe's subset centres on our mesh (medians); {load()}")
    found = {pf: ours_real(mesh, cams, pairs, pf) for pf in (0.5, 1.0)}
    P = pyvale_2d(read_pair("0000")[0], [p[0] for p in pairs], px, args.workdir / "pyvale_real")[1] \
        if has("pyvale") else None
    on_mesh = np.isfinite(at_dice(mesh, cams, axes, found[0.5][0], px)[0])     # DICe: the same points
    print("  | frame | DICe w (um) | ours w, prefilter 0.5 / 1 (um) | DICe left (u, v) px | ours left "
          "(u, v), prefilter 0.5 | prefilter 1 | pyvale 2-D left (u, v) |")
    print("  |---|---|---|---|---|---|---|")
    for k in range(1, 6):
        cells = []
        for pf in (0.5, 1.0):
            w, motion = at_dice(mesh, cams, axes, found[pf][k - 1], px)
            cells.append((1e3 * np.nanmedian(w), np.nanmedian(motion, axis=0)))
        pv = "n/a" if P is None else "{:+.4f}, {:+.4f}".format(*np.nanmedian(P[k - 1][on_mesh], axis=0))
        dice = {n: np.median(var[n][k][on_mesh]) for n in ("MODEL_DISPLACEMENT_Z", "DISPLACEMENT_X",
                                                            "DISPLACEMENT_Y")}
        print(f"  | {k} | {1e3 * dice['MODEL_DISPLACEMENT_Z']:.2f} | {cells[0][0]:.2f} / "
              f"{cells[1][0]:.2f} | {dice['DISPLACEMENT_X']:+.4f}, "
              f"{dice['DISPLACEMENT_Y']:+.4f} | {cells[0][1][0]:+.4f}, {cells[0][1][1]:+.4f} | "
              f"{cells[1][1][0]:+.4f}, {cells[1][1][1]:+.4f} | {pv} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for flag in ("stats", "renders", "texture", "real"):
        p.add_argument(f"--{flag}", action="store_true")
    p.add_argument("--noise", nargs="+", type=float, default=[GT4["noise"], 4.0])
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--renderers", nargs="+", default=["core", "riley"], choices=["core", "riley"])
    p.add_argument("--speckle", choices=list(TEXTURES), default="smooth",
                   help="the renders' texture (see TEXTURES)")
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    p.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "bench_subpixel")
    args = p.parse_args(argv)
    if not (args.stats or args.renders or args.texture or args.real):
        args.stats = args.renders = args.texture = args.real = True
    import logging
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    print(f"machine: {platform.platform()}, {os.cpu_count()} cpus, python {platform.python_version()}, "
          f"numpy {np.__version__}; riley {'yes' if has('riley') else 'no'}, pyvale "
          f"{'yes' if has('pyvale') else 'no'}; {load()} at start")
    data = (DATA / "images" / "GT4-0000_0.png").is_file()
    if args.stats and data:
        print("\nGT4 statistics (frame 0000; noise from 0001 - 0000):")
        gt4_stats()
    if args.renders:
        run_renders(args)
    if args.texture and data:
        run_texture(args)
    if args.real and data:
        run_real(args)
    if not data and (args.stats or args.texture or args.real):
        print(f"\n(no GT4 data at {DATA}: --stats, --texture and --real skipped)")
    print(f"\n{load()} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
