"""Benchmark: our shape measurement against pyvale's subset stereo DIC on the same images.

Issue 13, item 4. pyvale (PyPI ``pyvale``, MIT, Computer Aided Validation Laboratory) is a
C++ subset-based stereo DIC: ZNSSD affine subsets matched between the two cameras, then
triangulated (DLT) in camera 0's frame. It is a benchmark peer only, never a dependency:
install it in a separate venv and run this script with that venv's python::

    python -m venv --system-site-packages /work/venv-pyvale
    /work/venv-pyvale/bin/pip install pyvale
    PYTHONPATH=. /work/venv-pyvale/bin/python benchmarks/bench_vs_pyvale.py [--repeat 3]

Without pyvale the script prints "skipped" and exits with status 0 (but ``--real
--shapes --steps``, ours only on the real pair, runs).

Cases (synthetic, known truth, the same rendered pair for both codes):

- ``flat``, ``smooth``, ``narrow``: the shape family at the demo's scale
  (``tests/scenes.py`` FAMILY_DEMO_SCALE: a 96 x 80 mm plate, 1200 x 1000 px, 0.1 mm/px,
  two cameras at 25 deg, 4 px speckle): flat, and a 0.5 mm Gaussian bump of sigma 16 mm
  (W/5) and 4 mm (W/20);
- ``twisted``: the demo's specimen (``georeg_app.shape.demo.DEMO``): the 180 x 50 mm open-hole
  plate seen over 100 mm, 1 mm twist at the view's corners and a 0.2 mm waviness, images of
  1224 x 816 px (0.09 mm/px);

each noise-free and with 2 gray levels of Gaussian noise (``--noise``), rendered by the
core's ray caster (``--supersample`` rays per pixel side) or by riley-raster
(``--renderer riley``, see benchmarks/bench_levels.py's ``riley_render``).

``--real`` adds the real Stereo DIC Challenge 1.0 pair (``data/dic_challenge_stereo``, the
PNGs cropped from the original frames, 1760 x 1664 px): pyvale with its own example's ROI
polygon and seeds (``ex10_dic_chal``, shifted by the crop) and the calibration of the data
(principal points shifted by the crop), against ``examples/dic_challenge``: the specimen
measured as one part from its CAD, ``georeg measure examples/dic_challenge/specimen_part.toml``
(in process: ``georeg_app.shape.pipeline.run_methods``; whole process: the command line), and
its figures taken by ``analyse_part.py`` (the regions of ``analysis.toml``). No truth
there: the figures are the flatness of the base plate in the data README's region (RMS to
the best-fit plane and quadric, pyvale's points selected by their camera-0 subset centre in
the README's quadrilateral, ours by the same region in mm) and of the block top (RMS to its
plane; pyvale: the README's block-top quadrilateral, ours: analysis.toml's block top).
``--real --shapes --steps`` (no shapes, no pyvale steps) runs ours only, without pyvale.

What each code is given: the two 8-bit images; the EXACT cameras (pyvale: its calibration
``Calib`` with camera 1 placed by the exact stereo transform; ours: the JSON camera file of
the exact cameras); the region of the specimen: pyvale's ROI mask is the set of camera-0
pixels whose ray meets the nominal plane z = 0 inside the nominal region (the view of the
plate, minus the hole), our nominal model is the same region. pyvale: subset 27 px, step 4
and 10 px, its defaults otherwise (ZNSSD, affine, B-spline, Gaussian prefilter 5 px / 1 px,
correlation threshold 0.9, multi-window reliability-guided scan from one seed at the ROI's
centre, whole subsets inside the ROI), binary output. Ours: ``georeg measure``'s defaults
(method georeg, automatic spline levels, 3 image scales, fixed point of calibration and
shape, 0.5 px prefilter, about 1000 Q9 elements), plus FE and Tikhonov 5 mm on the same
mesh with ``--methods``.

Columns: RMS distance to the true surface after the best rigid alignment (bounded to 2 deg
and 2 mm, ``tests/shape_truth.py``; each point set aligned on its own) over all delivered
points ("all") and over the region where pyvale can deliver points ("same region": where a
whole 27 px subset centred on the point's camera-0 pixel lies inside the ROI); pyvale's
points are its triangulated subset centres, brought from camera 0's frame to the world by
the exact camera 0; ours are the mesh nodes. "points": points delivered (pyvale: finite
subset points; ours: mesh nodes, a continuous surface between them). "in-process": median
wall time of ``--repeat`` interleaved runs of pyvale's ``calculate_3d`` (arrays in memory;
it writes its result file) and of our measurement (``Image.from_array`` of both images +
``georeg_app.shape.pipeline.run_methods`` with the method of ``georeg measure``), ``--threads``
threads each. "whole": median wall time of one full python process per run (pyvale: a
script reading the PNGs, the calibration CSV and the ROI, running ``calculate_3d`` and
reading its points back; ours: ``python -m georeg_app measure CONFIG.toml`` writing all its
outputs: VTU, figures, report). The machine, its load and the versions are printed.

Measured (PROPOSED_README / README "Side by side with pyvale", 2 cores under a load of 9-16):
in the same region georeg is below pyvale on the flat and twisted plates at both noise
levels and on the noise-free bumps; pyvale is below georeg on the noisy smooth bump and over
all points (our boundary band), and faster on every case (step 4: 1.7-2.8 times in
process), though the load slows our measurement far more than pyvale's C++.

Run: ``python benchmarks/bench_vs_pyvale.py [--repeat 3] [--shapes flat twisted smooth
narrow] [--noise 0 2] [--steps 4 10] [--methods georeg fe tikhonov] [--renderer core|riley]
[--no-whole] [--real] [--workdir DIR]``
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHAPES = {"flat": None, "smooth": 5, "narrow": 20, "twisted": "twisted"}   # divisor of the width
SUBSET_PX = 27
TIKHONOV_MM = 5.0
SKIP_MESSAGE = ("bench_vs_pyvale: skipped: pyvale is not importable by this python ({python}). "
                "It is a benchmark peer, not a dependency: python -m venv --system-site-packages "
                "VENV && VENV/bin/pip install pyvale, then run this script with VENV/bin/python.")


# ----------------------------------------------------------------------------- pyvale
def pyvale_calib(cameras):
    """pyvale's ``Calib`` of an exact rig: intrinsics of both cameras and the stereo transform
    ``x1 = R x0 + t``, ``R = Rz(psi) Ry(phi) Rx(theta)`` (its convention, angles in degrees)."""
    from pyvale import calib
    from fesdic_core.cameras.rig import stereo_transform
    R, t = stereo_transform(*cameras)

    def intrinsics(c):
        K = np.asarray(c.K, float)
        return calib.CamIntrinsics(fx=K[0, 0], fy=K[1, 1], fs=K[0, 1], cx=K[0, 2], cy=K[1, 2],
                                   distortion=np.asarray(c.dist, float).ravel()[:5].copy())
    angles = np.degrees([np.arctan2(R[2, 1], R[2, 2]), -np.arcsin(R[2, 0]), np.arctan2(R[1, 0], R[0, 0])])
    return calib.Calib(cam0=intrinsics(cameras[0]), cam1=intrinsics(cameras[1]),
                       translation=np.asarray(t, float).copy(), rotation=angles)


def pyvale_points(arrays, calibration, roi, seed, step: int, threads: int, out_dir: Path):
    """Run pyvale's stereo DIC on the reference pair; returns (points (n, 3) in camera 0's
    frame, finite only; seconds of ``calculate_3d``)."""
    from pyvale import dic
    out_dir.mkdir(parents=True, exist_ok=True)
    for old in out_dir.glob("dic_results_*"):
        old.unlink()
    images = [np.ascontiguousarray(a, dtype=np.uint8) for a in arrays]
    t0 = time.perf_counter()
    dic.calculate_3d(reference=images, deformed=images, calibration=calibration, roi_mask=roi,
                     seed=list(seed), subset_size=SUBSET_PX, subset_step=step, num_threads=threads,
                     output_basepath=out_dir, output_binary=True, print_level=0)
    seconds = time.perf_counter() - t0
    s = dic.import_3d(data=str(out_dir / "dic_results_*"), delimiter=",", binary=True,
                      layout="column", print_level=0).stereo
    X = np.column_stack([np.ravel(s.x_mm[0]), np.ravel(s.y_mm[0]), np.ravel(s.z_mm[0])])
    return X[np.all(np.isfinite(X), axis=1)], seconds


def pyvale_worker(folder: Path, step: int, threads: int) -> None:
    """The whole-process run of pyvale: what a user's script does (read, correlate, read back)."""
    import cv2
    from pyvale import calib
    arrays = [cv2.imread(str(folder / f"cam{k}.png"), cv2.IMREAD_GRAYSCALE) for k in (0, 1)]
    seed = json.loads((folder / "seed.json").read_text())
    X, _ = pyvale_points(arrays, calib.loadtxt(folder / "calibration.csv"),
                         np.load(folder / "roi.npy"), seed, step, threads, folder / f"pyvale_{step}")
    np.save(folder / f"pyvale_{step}" / "points.npy", X)


# ----------------------------------------------------------------------------- cases
@dataclasses.dataclass(frozen=True)
class Case:
    name: str
    specimen: object
    cameras: tuple
    geometry: object          # georeg_app.config.measure.GeometryConfig: the nominal region
    noise_seed: int

    def inside(self, xy: np.ndarray) -> np.ndarray:
        """Plate coordinates (n, 2) inside the nominal region."""
        g = self.geometry
        ok = (np.abs(xy[:, 0]) <= g.length_mm / 2) & (np.abs(xy[:, 1]) <= g.width_mm / 2)
        if g.hole_radius_mm is not None:
            ok &= np.hypot(xy[:, 0], xy[:, 1]) >= g.hole_radius_mm
        return ok


def build_case(shape: str) -> Case:
    sys.path[:0] = [str(REPO), str(REPO / "tests")]   # the packages before tests/, whose folders mirror them
    import scenes
    from fesdic_core.synthetic.render import demo_cameras, speckle_mm_for
    from georeg_app.config.measure import GeometryConfig
    from georeg_app.shape.demo import DEMO, demo_specimen
    if shape == "twisted":                                 # as georeg_app.shape.demo.demo_config
        d = DEMO
        cameras = demo_cameras(image_size=d["image_size"], stereo_angle_deg=d["stereo_angle_deg"],
                               field_mm=d["field_mm"])
        specimen = dataclasses.replace(demo_specimen(), speckle_mm=speckle_mm_for(cameras[0], 4.0))
        geometry = GeometryConfig(kind="plate_with_hole", length_mm=d["view_mm"],
                                  width_mm=d["width_mm"], hole_radius_mm=d["hole_radius_mm"])
        return Case("twisted plate", specimen, tuple(cameras), geometry, 11)
    family = scenes.FAMILY_DEMO_SCALE
    cameras = scenes.family_cameras(family)
    divisor = SHAPES[shape]
    specimen = scenes.family_specimen(divisor, speckle_mm_for(cameras[0], family["speckle_px"]), family)
    name = "flat plate" if divisor is None else \
        f"bump sigma {scenes.family_sigma(divisor, family):g} mm"
    geometry = GeometryConfig(kind="rectangle", length_mm=family["length_mm"], width_mm=family["width_mm"])
    return Case(name, specimen, tuple(cameras), geometry, family["noise_seed"])


def render(case: Case, renderer: str, supersample: int, cache: Path) -> list:
    """Noise-free, unquantized renders (cached as .npy): the noise is added by :func:`noisy`."""
    key = f"{case.name.replace(' ', '_')}_{renderer}_{supersample}"
    files = [cache / f"{key}_cam{k}.npy" for k in (0, 1)]
    if all(f.is_file() for f in files):
        return [np.load(f) for f in files]
    t0 = time.perf_counter()
    if renderer == "core":
        from fesdic_core.synthetic.render import render_stereo
        arrays = render_stereo(case.specimen, case.cameras, supersample=supersample, noise_std=0.0,
                               bit_depth=None, progress=False)
    else:
        sys.path.insert(0, str(REPO / "benchmarks"))
        from bench_levels import riley_render
        arrays, _ = riley_render(case.specimen, case.cameras, 0.0, 0)
    print(f"  rendered {case.name} ({renderer}) in {time.perf_counter() - t0:.0f} s", flush=True)
    cache.mkdir(parents=True, exist_ok=True)
    for f, a in zip(files, arrays):
        np.save(f, a)
    return arrays


def noisy(arrays, noise_std: float, seed: int) -> list:
    """8-bit images with seeded Gaussian noise, exactly as ``render_stereo(noise_std, seed)``."""
    rng = np.random.default_rng(seed)
    out = []
    for a in arrays:
        a = a + rng.normal(0.0, noise_std, a.shape) if noise_std > 0 else a
        out.append(np.clip(np.rint(a), 0.0, 255.0).astype(np.uint8))
    return out


def roi_and_seed(case: Case) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """pyvale's ROI (camera-0 pixels seeing the nominal region on z = 0), the same eroded
    by a subset (centres of whole subsets inside it) and a seed where the ROI is deepest."""
    import cv2
    from fesdic_core.synthetic.rays import pixel_rays
    cam = case.cameras[0]
    w, h = cam.image_size
    y, x = np.mgrid[0:h, 0:w]
    origin, directions = pixel_rays(cam, np.column_stack([x.ravel(), y.ravel()]))
    lam = -origin[2] / directions[:, 2]
    xy = origin[:2] + lam[:, None] * directions[:, :2]
    roi = case.inside(xy).reshape(h, w)
    inner = cv2.erode(roi.astype(np.uint8), np.ones((SUBSET_PX, SUBSET_PX), np.uint8),
                      borderValue=0).astype(bool)
    depth = cv2.distanceTransform(inner.astype(np.uint8), cv2.DIST_L2, 5)
    y0, x0 = np.unravel_index(np.argmax(depth), depth.shape)     # the farthest from its edges
    return roi, inner, (int(x0), int(y0))


def in_region(points_world: np.ndarray, camera, inner: np.ndarray) -> np.ndarray:
    """Points whose camera-0 pixel is the centre of a whole subset inside the ROI."""
    px = np.rint(camera.project(points_world)).astype(int)
    h, w = inner.shape
    ok = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
    ok[ok] = inner[px[ok, 1], px[ok, 0]]
    return ok


# ----------------------------------------------------------------------------- ours
def write_inputs(case: Case, arrays, roi, seed, folder: Path, edge_margin: float | None = None
                 ) -> None:
    """The files both whole-process runs read: PNGs, cameras (ours: JSON; pyvale: CSV), ROI,
    seed, and one ``georeg measure`` configuration per method (``edge_margin``: its
    ``edge_margin_px``, None: the default)."""
    import cv2
    from pyvale import calib
    from fesdic_core.cameras.rig import write_cameras_json
    folder.mkdir(parents=True, exist_ok=True)
    for k, a in enumerate(arrays):
        cv2.imwrite(str(folder / f"cam{k}.png"), a)
    write_cameras_json(folder / "cameras.json", case.cameras)
    calib.savetxt(pyvale_calib(case.cameras), folder / "calibration.csv")
    np.save(folder / "roi.npy", roi)
    (folder / "seed.json").write_text(json.dumps(list(seed)))
    g = case.geometry
    geometry = f'kind = "{g.kind}"\nlength_mm = {g.length_mm}\nwidth_mm = {g.width_mm}\n' + \
        ("" if g.hole_radius_mm is None else f"hole_radius_mm = {g.hole_radius_mm}\n")
    methods = {"georeg": "", "fe": 'name = "fe"\n',
               "tikhonov": f'name = "tikhonov"\ntikhonov_length_mm = [{TIKHONOV_MM}]\n'}
    margin = "" if edge_margin is None else f"edge_margin_px = {edge_margin:g}\n"
    for name, method in methods.items():
        method += margin
        (folder / f"{name}.toml").write_text(
            '[images]\ncam0 = "cam0.png"\ncam1 = "cam1.png"\n\n[cameras]\nfile = "cameras.json"\n\n'
            f"[geometry]\n{geometry}\n[method]\n{method}\n[output]\ndir = \"{name}_out\"\n")


def ours(folder: Path, method: str, arrays):
    """``georeg measure``'s work in process: the configuration, the image models of both
    images and the run; returns (measurement or None, seconds, status)."""
    from fesdic_core.imaging.image import Image
    from georeg_app.config.measure import load_config
    from georeg_app.shape.methods import measure_specs
    from georeg_app.shape.pipeline import run_methods
    t0 = time.perf_counter()
    config = load_config(folder / f"{method}.toml")
    images = tuple(Image.from_array(np.asarray(a, float), source=f"cam{k}",
                                    prefilter_px=config.method.prefilter_px,
                                    order=config.method.interpolation_order)
                   for k, a in enumerate(arrays))
    result = run_methods(config, measure_specs(config), images=images).results[0]
    seconds = time.perf_counter() - t0
    status = "ok" if result.ok else f"FAILED ({result.failure})"
    if result.level_search is not None:
        status += f", level {result.level_search.chosen}/{result.level_search.n_levels}"
    return result.measurement, seconds, status


def whole_process(command: list, threads: int) -> float:
    """Wall time (s) of one python process; raises on a non-zero exit with its stderr."""
    env = dict(os.environ, FESDIC_THREADS=str(threads), OMP_NUM_THREADS=str(threads),
               PYTHONPATH=os.pathsep.join([str(REPO)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    t0 = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, command))}: exit {done.returncode}: "
                           f"{done.stderr.strip().splitlines()[-1:]}")
    return seconds


# ----------------------------------------------------------------------------- the real pair
#: the PNG pair of data/dic_challenge_stereo is the original frames cropped at (384, 128)
CROP_PX = (384.0, 128.0)
#: cam0 quadrilaterals (original frames, px) of the data README: base plate region, block top
README_REGIONS_PX = {"base": [(1121, 967), (1982, 996), (2002, 1701), (1130, 1716)],
                     "block_top": [(714, 1039), (1058, 1040), (1060, 1373), (714, 1377)]}


def real_inputs(folder: Path):
    """The Stereo DIC Challenge pair as both codes get it: the cropped PNGs, pyvale's
    calibration with the principal points shifted by the crop, pyvale's own ROI and seeds
    (its example ``ex10_dic_chal``) shifted by the crop. Returns (arrays, Calib, roi, seeds)."""
    import shutil
    import cv2
    import yaml
    from pyvale import calib, data, dic
    src = REPO / "data" / "dic_challenge_stereo"
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("cam0.png", "cam1.png"):
        shutil.copy(src / name, folder / name)
    shutil.copy(src / "calibration_cropped.csv", folder / "calibration.csv")
    arrays = [cv2.imread(str(folder / f"cam{k}.png"), cv2.IMREAD_GRAYSCALE) for k in (0, 1)]
    entries = yaml.safe_load(Path(data.dic_ex10_dic_chal_roi()).read_text())
    for e in entries:
        if e["type"] == "PolyLineROI":
            e["points"] = [[float(x - CROP_PX[0]), float(y - CROP_PX[1])] for x, y in e["points"]]
        else:
            e["pos"] = [float(e["pos"][0] - CROP_PX[0]), float(e["pos"][1] - CROP_PX[1])]
    (folder / "roi.yaml").write_text(yaml.safe_dump(entries))
    roi = dic.RegionOfInterest(arrays[0])
    roi.read_yaml(folder / "roi.yaml")
    np.save(folder / "roi.npy", roi.mask)
    (folder / "seed.json").write_text(json.dumps([int(v) for v in roi.seed]))
    return arrays, calib.loadtxt(folder / "calibration.csv"), roi.mask, [int(v) for v in roi.seed]


def pyvale_faces_um(folder: Path) -> dict:
    """pyvale's points of its last run in ``folder``: RMS (um) to the best-fit plane and quadric
    over the README base region, to the plane over the README block top (subset centres in
    the quadrilaterals), and the points delivered."""
    from pyvale import dic
    sys.path.insert(0, str(REPO / "examples" / "dic_challenge"))
    from challenge import analysis
    res = dic.import_3d(data=str(folder / "dic_results_*"), delimiter=",", binary=True,
                        layout="column", print_level=0)
    s = res.stereo
    X = np.column_stack([np.ravel(s.x_mm[0]), np.ravel(s.y_mm[0]), np.ravel(s.z_mm[0])])
    px = np.column_stack([np.ravel(res.ss_x), np.ravel(res.ss_y)]) + np.array(CROP_PX)
    ok = np.all(np.isfinite(X), axis=1)
    out = {"points": int(ok.sum())}
    for name, quad in README_REGIONS_PX.items():
        P = X[ok & analysis.inside_polygon(px, np.array(quad, float))]
        out[name] = (1e3 * analysis.rms(analysis.plane_residuals(P)),
                     1e3 * analysis.rms(analysis.quadric_residuals(P)), len(P))
    return out


def ours_real(out: Path):
    """``georeg measure specimen_part.toml`` in process (``run_methods``, as the command line
    runs it), its outputs written to ``out``, and the part's comparison by analyse_part.py;
    returns (comparison, part, seconds of the measurement)."""
    example = REPO / "examples" / "dic_challenge"
    sys.path.insert(0, str(example))
    import analyse_part
    from challenge.comparison import compare
    from georeg_app.config.measure import load_config
    from georeg_app.shape.methods import measure_specs
    from georeg_app.shape.outputs import write_all
    from georeg_app.shape.pipeline import run_methods
    config = load_config(example / "specimen_part.toml").with_output_dir(out)
    t0 = time.perf_counter()
    run = run_methods(config, measure_specs(config), progress=False)
    seconds = time.perf_counter() - t0
    write_all(out, run, overwrite=True)
    part = analyse_part.load_part(out)
    return compare(part), part, seconds


def run_real(args, folder: Path) -> list[dict]:
    """pyvale (steps of ``--steps``) and our example (examples/dic_challenge: the part) on the
    real pair; flatness figures in the README's regions, points, times."""
    folder.mkdir(parents=True, exist_ok=True)
    if args.steps:
        arrays, calibration, roi, seeds = real_inputs(folder)
    keys = [f"pyvale {s}" for s in args.steps] + ["ours"]
    times, whole, figures = {k: [] for k in keys}, {k: [] for k in keys}, {}
    for r in range(args.repeat):
        for step in args.steps:
            out = folder / f"inproc_{step}"
            _, seconds = pyvale_points(arrays, calibration, roi, seeds, step, args.threads, out)
            times[f"pyvale {step}"].append(seconds)
            figures[f"pyvale {step}"] = pyvale_faces_um(out)
        c, part, seconds = ours_real(folder / f"ours_inproc_{r}")
        times["ours"].append(seconds)
        figures["ours"] = {"points": sum(len(P) for P in part.points.values()),
                           "base": (1e3 * c.base_plane_rms_mm, 1e3 * c.base_quadric_rms_mm, None),
                           "block_top": (1e3 * c.block.top_rms_plane_mm, np.nan, c.block.n_top)}
        if args.whole:
            for step in args.steps:
                whole[f"pyvale {step}"].append(whole_process(
                    [sys.executable, __file__, "--pyvale-worker", str(folder), "--steps", str(step),
                     "--threads", str(args.threads)], args.threads))
            whole["ours"].append(whole_process(
                [sys.executable, "-m", "georeg_app", "--quiet", "measure",
                 str(REPO / "examples" / "dic_challenge" / "specimen_part.toml"),
                 "--out", str(folder / f"ours_out_{r}"), "--overwrite"], args.threads))
    rows = []
    for key in keys:
        f = figures[key]
        label = f"pyvale, subset {SUBSET_PX} px, step {key.split()[1]}" if key.startswith("pyvale") \
            else "ours (georeg measure specimen_part.toml, the part; points sampled 4 x 4 per element)"
        rows.append(dict(method=label, base_plane_um=f["base"][0], base_quadric_um=f["base"][1],
                         block_top_um=f["block_top"][0], points=f["points"],
                         inproc_s=statistics.median(times[key]),
                         whole_s=statistics.median(whole[key]) if whole[key] else np.nan))
    print("  | method | base plate, README region: RMS to plane / quadric (um) | block top: RMS to "
          "its plane (um) | points | in-process (s) | whole process (s) |")
    print("  |---|---|---|---|---|---|")
    for r in rows:
        print(f"  | {r['method']} | {r['base_plane_um']:.2f} / {r['base_quadric_um']:.2f} | "
              f"{r['block_top_um']:.2f} | {r['points']} | {r['inproc_s']:.1f} | {r['whole_s']:.1f} |",
              flush=True)
    return rows


# ----------------------------------------------------------------------------- the run
def errors_um(points_world: np.ndarray, case: Case, camera, inner) -> tuple[float, float]:
    """RMS distance (um) to the truth after the bounded rigid alignment: all points, and the
    points of the region pyvale can measure (aligned on their own)."""
    sys.path[:0] = [str(REPO), str(REPO / "tests")]   # the packages before tests/, whose folders mirror them
    from shape_truth import bounded_shape_error, rms
    same = in_region(points_world, camera, inner)
    return (1e3 * rms(bounded_shape_error(points_world, case.specimen)),
            1e3 * rms(bounded_shape_error(points_world[same], case.specimen)) if same.any() else np.nan)


def run_case(case: Case, arrays, noise: float, args, folder: Path) -> list[dict]:
    """Both codes on one rendered pair: rows (method, errors, points, times)."""
    import cv2
    roi, inner, seed = roi_and_seed(case)
    write_inputs(case, arrays, roi, seed, folder, args.edge_margin)
    calibration = pyvale_calib(case.cameras)
    R0 = cv2.Rodrigues(np.asarray(case.cameras[0].rvec, float).reshape(3, 1))[0]
    t0 = np.asarray(case.cameras[0].tvec, float).ravel()
    keys = [f"pyvale {s}" for s in args.steps] + list(args.methods)
    times = {k: [] for k in keys}
    whole = {k: [] for k in keys}
    results = {}
    for r in range(args.repeat):
        for step in args.steps:
            try:
                X, seconds = pyvale_points(arrays, calibration, roi, seed, step, args.threads,
                                           folder / f"inproc_{step}")
            except RuntimeError as err:                   # e.g. its seed did not converge
                results[f"pyvale {step}"] = (None, None, f"FAILED ({err})")
                continue
            times[f"pyvale {step}"].append(seconds)
            results[f"pyvale {step}"] = ((X - t0) @ R0, case.cameras[0], "ok")   # to the world
        for method in args.methods:
            if r > 0 and method != "georeg":
                continue                                  # FE and Tikhonov: one run
            m, seconds, status = ours(folder, method, arrays)
            times[method].append(seconds)
            results[method] = (None if m is None else m.nodes, None if m is None else m.cameras[0], status)
        if args.whole:
            for step in args.steps:
                if results[f"pyvale {step}"][0] is not None:
                    whole[f"pyvale {step}"].append(whole_process(
                        [sys.executable, __file__, "--pyvale-worker", str(folder), "--steps",
                         str(step), "--threads", str(args.threads)], args.threads))
            if "georeg" in args.methods:
                whole["georeg"].append(whole_process(
                    [sys.executable, "-m", "georeg_app", "--quiet", "measure",
                     str(folder / "georeg.toml"), "--out", str(folder / "georeg_out"), "--overwrite"],
                    args.threads))
    rows = []
    for key in keys:
        points, camera, status = results[key]
        all_um, same_um = errors_um(points, case, camera, inner) if points is not None else (np.nan, np.nan)
        label = f"pyvale, subset {SUBSET_PX} px, step {key.split()[1]}" if key.startswith("pyvale") \
            else {"georeg": "georeg measure (auto levels)", "fe": "FE (ours, unregularized)",
                  "tikhonov": f"Tikhonov {TIKHONOV_MM:g} mm (ours)"}[key]
        rows.append(dict(case=case.name, noise=noise, method=label, all_um=all_um, same_um=same_um,
                         points=0 if points is None else len(points), status=status,
                         inproc_s=statistics.median(times[key]) if times[key] else np.nan,
                         runs=len(times[key]),
                         whole_s=statistics.median(whole[key]) if whole[key] else np.nan))
    return rows


def print_rows(rows: list[dict], markdown: bool = False) -> None:
    if markdown:
        print("| case | noise (gray levels) | method | RMS error, all (um) | RMS error, same region (um) "
              "| points | in-process (s) | whole process (s) |")
        print("|---|---|---|---|---|---|---|---|")
        for r in rows:
            whole = "" if not np.isfinite(r["whole_s"]) else f"{r['whole_s']:.1f}"
            flag = "" if r["status"].startswith("ok") else f" ({r['status']})"
            print(f"| {r['case']} | {r['noise']:g} | {r['method']}{flag} | {r['all_um']:.2f} | "
                  f"{r['same_um']:.2f} | {r['points']} | {r['inproc_s']:.1f} | {whole} |")
        return
    print(f"  {'method':34s} {'all um':>8s} {'same um':>8s} {'points':>7s} {'in-proc s':>9s} "
          f"{'whole s':>8s}  status")
    for r in rows:
        print(f"  {r['method']:34s} {r['all_um']:8.2f} {r['same_um']:8.2f} {r['points']:7d} "
              f"{r['inproc_s']:9.2f} {r['whole_s']:8.2f}  {r['status']} (runs {r['runs']})", flush=True)


def describe_machine(args) -> None:
    from importlib.metadata import version
    from georeg_app.version import installed_version
    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip() or "?"
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cpus, load average {os.getloadavg()[0]:.1f} at start; "
          f"{args.threads} threads per code")
    pyvale = version("pyvale") if importlib.util.find_spec("pyvale") is not None else "not installed"
    print(f"python {platform.python_version()}, numpy {np.__version__}, pyvale {pyvale}, "
          f"georeg {installed_version()} (code of {REPO}, commit {commit})")


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     epilog="Without pyvale installed the script prints 'skipped' "
                                            "and exits 0 (but --real --shapes --steps: ours only).")
    parser.add_argument("--repeat", type=int, default=3, help="interleaved timed runs (median)")
    parser.add_argument("--shapes", nargs="*", default=list(SHAPES), choices=list(SHAPES),
                        help="synthetic cases (none: only --real)")
    parser.add_argument("--real", action="store_true",
                        help="also the real Stereo DIC Challenge pair (data/dic_challenge_stereo)")
    parser.add_argument("--noise", nargs="+", type=float, default=[0.0, 2.0],
                        help="noise levels (gray levels, std)")
    parser.add_argument("--steps", nargs="*", type=int, default=[4, 10],
                        help="pyvale subset steps (px); none: our methods only")
    parser.add_argument("--edge-margin", type=float, default=None,
                        help="[method] edge_margin_px of our methods (default: the config's)")
    parser.add_argument("--methods", nargs="+", default=["georeg"], choices=["georeg", "fe", "tikhonov"],
                        help="our methods (FE and Tikhonov: one in-process run each)")
    parser.add_argument("--threads", type=int, default=2, help="threads of each code")
    parser.add_argument("--renderer", choices=("core", "riley"), default="core")
    parser.add_argument("--supersample", type=int, default=6, help="rays per pixel side (core renderer)")
    parser.add_argument("--no-whole", dest="whole", action="store_false",
                        help="skip the whole-process timings")
    parser.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "bench_vs_pyvale",
                        help="renders (cached) and the files of the runs")
    parser.add_argument("--pyvale-worker", type=Path, default=None, help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.pyvale_worker is not None:
        pyvale_worker(args.pyvale_worker, args.steps[0], args.threads)
        return 0
    if (args.steps or args.shapes) and importlib.util.find_spec("pyvale") is None:
        print(SKIP_MESSAGE.format(python=sys.executable))      # (ours only: --real --shapes --steps)
        return 0
    import logging
    from fesdic_core.parallel import set_threads
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    set_threads(args.threads)
    describe_machine(args)
    rows = []
    for shape in args.shapes:
        case = build_case(shape)
        clean = render(case, args.renderer, args.supersample, args.workdir / "renders")
        for noise in args.noise:
            arrays = noisy(clean, noise, case.noise_seed)
            print(f"\n{case.name}, noise {noise:g} gray levels, {arrays[0].shape[1]} x "
                  f"{arrays[0].shape[0]} px ({args.renderer} renderer), load {os.getloadavg()[0]:.1f}",
                  flush=True)
            try:
                case_rows = run_case(case, arrays, noise, args, args.workdir / f"{shape}_{noise:g}")
            except (RuntimeError, ValueError, ArithmeticError, OSError) as err:   # the next case
                print(f"  FAILED: {type(err).__name__}: {err}", flush=True)
                continue
            print_rows(case_rows)
            rows += case_rows
            (args.workdir / "rows.json").write_text(json.dumps(rows, indent=1))
    if args.real:
        print(f"\nStereo DIC Challenge 1.0, real pair (1760 x 1664 px), load {os.getloadavg()[0]:.1f}",
              flush=True)
        run_real(args, args.workdir / "real")
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end; in-process: median of {args.repeat} "
          "interleaved runs (FE and Tikhonov: one run); whole process: median of "
          f"{args.repeat if args.whole else 0} runs\n")
    if rows:
        print_rows(rows, markdown=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
