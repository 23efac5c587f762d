"""Benchmark: the image model's Gaussian prefilter, end to end, on shapes with a known truth.

Issue 13 ("lower the floor"): the image model is a Gaussian prefilter of ``prefilter_px``
pixels (sigma) followed by the core's cubic B-spline (:mod:`fesdic_core.imaging.image`). This
measures what the prefilter does to the RMS shape error against the true surface
(:func:`fesdic_core.synthetic.accuracy.shape_error_to_surface`, through ``georeg_app.shape.pipeline``)
of FE (no regularization), Tikhonov 5 mm and georeg (multiscale, its fixed spline levels: not the level search), and
to their time:

- ``demo``: the demo of ``georeg demo`` (``georeg_app.shape.demo.DEMO``): twisted open-hole
  plate with waviness, 1224 x 816 px, 4 px speckle, 2 gray levels of noise, specimen pose
  perturbed by 0.5 deg / 0.5 mm, calibration, scales (2, 1, 0), 3 spline levels, the
  pipeline's mesh (1024 Q9).
- ``bump``: the flat 60 x 40 mm plate with a 0.3 mm Gaussian bump of sigma 2 mm
  (``tests/scenes.py``), 480 x 320 px (0.15 mm/px), 4 px speckle, NO noise (8-bit
  rounding only), exact cameras, no calibration, scales (2, 1, 0), 5 spline levels
  (the finest, 32 x 16 knot spans, is the FE mesh: 512 Q9 elements of 1.9 x 2.5 mm).
- ``bump-noise``: the same with 2 gray levels of noise.
- ``flat`` (not in the default ``--cases``): the same plate without the bump, no noise:
  what the prefilter does where there is no shape to measure.

The images are rendered once per scene without noise and without rounding; run ``k``
(of ``--repeat``) adds the noise of seed ``seed + k`` and rounds to 8 bits exactly as
:func:`fesdic_core.synthetic.render.render_stereo` does (run 0 of ``demo`` and ``bump-noise`` are
the images of ``georeg demo`` and of the tests' ``bump_scene``). Errors are the median
over the runs (over noise realisations; the noise-free case is the same every run),
times the median of ``Measurement.time_s``; the image model's own cost (prefilter +
spline coefficients of both images) is printed apart.

``--orders 3 5`` measures each prefilter with each B-spline order of the interpolant
(``Image.from_array(..., order=)``: 3 = cubic, the default, 5 = quintic); the relative
errors are then taken against (order 3, prefilter 0), and the sum of the errors over the
(case, method) pairs is printed per (order, prefilter).

``--coarse`` chooses how the pyramid's coarse scales are modelled, for measuring it:
``same`` (the core's: 2x2 means of the raw values, then the same sigma in coarse
pixels), ``none`` (no prefilter at coarse scales) or ``half`` (sigma / 2 in coarse
pixels, i.e. the fine sigma carried to the coarse grid).

``--terms`` measures instead the share of two other error terms on the noise-free bump,
FE on the same mesh and scales through :func:`fesdic_core.shape.driver.measure`: the Riemann
sum with one point per pixel against 2 x 2 (``MeasurementSettings(points_per_px=2)``),
and the brightness normalisation per element against one for the whole region
(``normalisation="global"``), at each prefilter; full scale only (exact cameras, no
noise: nothing for coarse scales to do; on this fine mesh they can throw a node of the
specimen's edge off by millimetres, which would swamp the all-node RMS).

Run: ``python benchmarks/bench_image_model.py [--quick] [--repeat 3]
[--prefilters 0,0.5,0.7,0.9,1.2] [--orders 3 5] [--cases demo,bump,bump-noise] [--edge-margin 2]
[--coarse same] [--terms]``
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]   # the packages before tests/, whose folders mirror them

from fesdic_core.synthetic.accuracy import shape_error_to_surface            # noqa: E402
from fesdic_core.shape.driver import MeasurementSettings, measure          # noqa: E402
from fesdic_core.shape.gauge import move_cameras_with_specimen          # noqa: E402
from fesdic_core.imaging.image import COMPILED_KERNEL, Image                # noqa: E402
from fesdic_core.fe.mesh import boundary_nodes                         # noqa: E402
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for  # noqa: E402
from fesdic_core.synthetic.specimen import Specimen
from fesdic_core.cameras.rig import write_cameras_json                      # noqa: E402
from georeg_app.config.measure import (CamerasConfig, Config, GeometryConfig, ImagesConfig,  # noqa: E402
                               MethodConfig, OutputConfig)
from georeg_app.shape.methods import default_specs, georeg_spec               # noqa: E402
from georeg_app.inputs.nominal import build_model  # noqa: E402
from georeg_app.shape.demo import DEMO, Truth, demo_specimen
from georeg_app.shape.pipeline import run_methods
from scenes import bump_specimen                                     # noqa: E402

METHODS = ("FE (multiscale)", "Tikhonov 5 mm", "georeg (multiscale)")


@dataclasses.dataclass
class Scene:
    """A rendered scene: noise-free float images, truth, initial cameras, config pieces."""

    name: str
    clean: list                  # two (h, w) float images, not rounded
    noise_std: float
    seed: int
    truth: Truth
    initial: tuple               # the cameras the measurement starts from
    geometry: GeometryConfig
    method: MethodConfig


def demo_scene() -> Scene:
    cams = demo_cameras(image_size=DEMO["image_size"], stereo_angle_deg=DEMO["stereo_angle_deg"],
                        field_mm=DEMO["field_mm"])
    specimen = dataclasses.replace(demo_specimen(), speckle_mm=speckle_mm_for(cams[0], 4.0))
    clean = render_stereo(specimen, cams, supersample=3, bit_depth=None, progress=False)
    rotation = np.radians(DEMO["pose_error_deg"]) * np.array([0.6, -0.48, 0.64])   # as demo_config
    translation = DEMO["pose_error_mm"] * np.array([0.48, 0.64, -0.6])
    initial = move_cameras_with_specimen(cams, translation, rotation, np.zeros(3))
    geometry = GeometryConfig(kind="plate_with_hole", length_mm=DEMO["view_mm"], width_mm=DEMO["width_mm"],
                              hole_radius_mm=DEMO["hole_radius_mm"])
    return Scene("demo", clean, DEMO["noise_std"], 11, Truth(specimen, tuple(cams)), tuple(initial),
                 geometry, MethodConfig(levels=3, tikhonov_length_mm=(5.0,)))


def bump_scene(noise_std: float, flat: bool = False) -> Scene:
    cams = demo_cameras(image_size=(480, 320), field_mm=72.0)
    specimen = bump_specimen(speckle_mm_for(cams[0], 4.0))
    if flat:
        specimen = Specimen(60.0, 40.0, speckle_mm=specimen.speckle_mm, seed=specimen.seed)
    clean = render_stereo(specimen, cams, supersample=3, bit_depth=None, progress=False)
    geometry = GeometryConfig(kind="rectangle", length_mm=60.0, width_mm=40.0, elements=500)
    method = MethodConfig(levels=5, tikhonov_length_mm=(5.0,), calibrate=False)
    return Scene("flat" if flat else "bump-noise" if noise_std else "bump", clean, noise_std, 2,
                 Truth(specimen, tuple(cams)), tuple(cams), geometry, method)


def pixels(scene: Scene, run: int) -> list[np.ndarray]:
    """The 8-bit images of run ``run``: noise of seed ``scene.seed + run``, as render_stereo."""
    rng = np.random.default_rng(scene.seed + run)
    out = []
    for clean in scene.clean:
        image = clean + rng.normal(0.0, scene.noise_std, clean.shape) if scene.noise_std > 0 else clean
        out.append(np.clip(np.rint(image), 0.0, 255.0))
    return out


def coarse_variant(rule: str) -> type:
    """An Image whose coarse scales use another prefilter rule (``same`` is the core's)."""
    factor = {"same": 1.0, "half": 0.5, "none": 0.0}[rule]

    @dataclasses.dataclass(frozen=True, eq=False)
    class Variant(Image):
        def coarsen(self) -> Image:
            h, w = self.values.shape
            v = self.values[: h - h % 2, : w - w % 2]
            coarse = v.reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))
            return Variant.from_array(coarse, f"{self.source} /2", prefilter_px=factor * self.prefilter_px,
                                      order=self.order)
    return Variant


def interior_nodes(mesh) -> np.ndarray:
    """(n,) bool: nodes of no element that touches the mesh boundary (edges, hole, view cut)."""
    keep = np.ones(mesh.n_nodes, bool)
    on_boundary = np.zeros(mesh.n_nodes, bool)
    on_boundary[boundary_nodes(mesh)] = True
    for block in mesh.blocks:
        touching = on_boundary[block.connectivity].any(axis=1)
        keep[block.connectivity[touching].ravel()] = False
    return keep


def run_case(scene: Scene, prefilter: float, run: int, image_class: type, workdir: Path,
             order: int = 3) -> dict:
    """Measure one scene (one noise realisation) with one prefilter and order: per-method results."""
    arrays = pixels(scene, run)
    t = time.perf_counter()
    images = tuple(image_class.from_array(a, f"{scene.name} cam{k}", prefilter_px=prefilter, order=order)
                   for k, a in enumerate(arrays))
    model_s = time.perf_counter() - t
    cameras_file = workdir / f"{scene.name}_cameras.json"
    if not cameras_file.exists():
        write_cameras_json(cameras_file, scene.initial)
    config = Config(images=ImagesConfig(cam0=workdir / "cam0 (in memory)", cam1=workdir / "cam1 (in memory)"),
                    cameras=CamerasConfig(file=cameras_file), geometry=scene.geometry, method=scene.method,
                    output=OutputConfig(dir=workdir / "out"), source=workdir / "bench (in memory)")
    specs = [s for s in default_specs(config) if s.label in METHODS[:2]]
    specs.append(georeg_spec(scene.method.fixed_levels, scene.method.scale_sequence))   # fixed levels
    result = run_methods(config, specs, images=images, truth=scene.truth)
    out = {"model_s": model_s}
    for r, label in zip(result.results, METHODS):
        assert r.spec.label.split()[0] == label.split()[0], (r.spec.label, label)
        m = r.measurement
        inner = (np.nan if r.shape_error_mm is None
                 else 1e3 * float(np.sqrt(np.mean(r.shape_error_mm[interior_nodes(r.mesh)] ** 2))))
        error = np.nan if r.shape_rms_error_mm is None else 1e3 * r.shape_rms_error_mm
        out[label] = dict(error_um=error, interior_um=inner,
                                 time_s=np.nan if m is None else m.time_s, ok=r.ok,
                                 ratio=np.nan if m is None else m.residual_percent / m.noise_percent)
    return out


def other_terms(prefilters: list[float], repeat: int) -> None:
    """FE on the noise-free bump: points per pixel 1 vs 2, normalisation element vs global."""
    scene = bump_scene(0.0)
    mesh = build_model(scene.geometry, scene.method.levels).mesh
    inner = interior_nodes(mesh)
    arrays = pixels(scene, 0)
    variants = [(1.0, "element"), (2.0, "element"), (1.0, "global")]
    print(f"\nFE on the noise-free bump ({mesh.n_elements} Q9, scale 0 only, exact cameras): "
          "RMS error all nodes / interior (um) / time (s, median of runs)")
    print("| prefilter (px) | " + " | ".join(f"{p:g} pt/px, {n}" for p, n in variants) + " |")
    print("|---|" + "---|" * len(variants))
    for pf in prefilters:
        images = tuple(Image.from_array(a, f"bump cam{k}", prefilter_px=pf) for k, a in enumerate(arrays))
        cells = []
        for per_px, norm in variants:
            settings = MeasurementSettings(scales=(0,), points_per_px=per_px, normalisation=norm)
            times, m = [], None
            for _ in range(repeat):
                m = measure(mesh, images, scene.truth.cameras, None, settings)
                times.append(m.time_s)
            e = shape_error_to_surface(m.nodes, scene.truth.specimen)
            cells.append(f"{1e3 * np.sqrt(np.mean(e ** 2)):.2f} / {1e3 * np.sqrt(np.mean(e[inner] ** 2)):.2f}"
                         f" / {np.median(times):.1f}" + ("" if m.ok else " (failed)"))
        print(f"| {pf:g} | " + " | ".join(cells) + " |", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--prefilters", nargs="+", default=["0,0.5,0.7,0.9,1.2"],
                   help="Gaussian prefilter sigmas (px), separated by commas or spaces")
    p.add_argument("--orders", type=int, nargs="+", default=[3], choices=(3, 5),
                   help="B-spline orders of the interpolant (3 cubic, 5 quintic)")
    p.add_argument("--cases", default="demo,bump,bump-noise")
    p.add_argument("--edge-margin", type=float, default=None,
                   help="[method] edge_margin_px of every case (default: the config's default)")
    p.add_argument("--max-view-angle", type=float, default=None,
                   help="[method] max_view_angle_deg of every case (default: the config's; 90: "
                        "no grazing cut-off)")
    p.add_argument("--repeat", type=int, default=3, help="runs per case (noise seeds)")
    p.add_argument("--coarse", choices=("same", "none", "half"), default="same",
                   help="prefilter of the coarse scales (same sigma in coarse px, none, sigma / 2)")
    p.add_argument("--quick", action="store_true", help="prefilters 0, 0.5 and 0.9, bump cases, 1 run")
    p.add_argument("--terms", action="store_true",
                   help="instead: points per pixel and normalisation on the noise-free bump (FE)")
    args = p.parse_args()
    if args.quick:
        args.prefilters, args.cases, args.repeat = ["0,0.5,0.9"], "bump,bump-noise", 1
    logging.basicConfig(level=logging.WARNING)
    prefilters = [float(v) for v in ",".join(args.prefilters).split(",") if v]
    orders = list(dict.fromkeys(args.orders))
    cases = args.cases.split(",")
    t0 = time.perf_counter()
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cpus, python {platform.python_version()}, compiled kernel {COMPILED_KERNEL}, "
          f"load average {os.getloadavg()[0]:.2f}")
    margin = MethodConfig().edge_margin_px if args.edge_margin is None else args.edge_margin
    print(f"prefilters {prefilters} px, orders {orders}, coarse scales: {args.coarse}, "
          f"{args.repeat} run(s) per case, edge margin {margin:g} px")
    if args.terms:
        other_terms(prefilters, args.repeat)
        print(f"\nelapsed {time.perf_counter() - t0:.0f} s, load average {os.getloadavg()[0]:.2f}")
        return
    image_class = coarse_variant(args.coarse)
    makers = {"demo": demo_scene, "bump": lambda: bump_scene(0.0), "bump-noise": lambda: bump_scene(2.0),
              "flat": lambda: bump_scene(0.0, flat=True)}
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_image_model_") as tmp:
        for case in cases:
            t = time.perf_counter()
            scene = makers[case]()
            if args.edge_margin is not None:
                scene.method = dataclasses.replace(scene.method, edge_margin_px=args.edge_margin)
            if args.max_view_angle is not None:
                scene.method = dataclasses.replace(scene.method,
                                                   max_view_angle_deg=args.max_view_angle)
            print(f"\n{case}: rendered in {time.perf_counter() - t:.1f} s", flush=True)
            for order, pf in [(o, p) for o in orders for p in prefilters]:
                runs = [run_case(scene, pf, k, image_class, Path(tmp), order) for k in range(args.repeat)]
                row = dict(case=case, order=order, prefilter=pf,
                           model_s=np.median([r["model_s"] for r in runs]))
                for label in METHODS:
                    row[label] = {key: np.median([r[label][key] for r in runs])
                                  for key in ("error_um", "interior_um", "time_s", "ratio")}
                    row[label]["spread"] = (np.min([r[label]["error_um"] for r in runs]),
                                            np.max([r[label]["error_um"] for r in runs]))
                    row[label]["ok"] = all(r[label]["ok"] for r in runs)
                rows.append(row)
                print(f"  order {order}, prefilter {pf:g}: " + ", ".join(
                    f"{label} {row[label]['error_um']:.2f} um {row[label]['time_s']:.1f} s"
                    f"{'' if row[label]['ok'] else ' FAILED'}" for label in METHODS), flush=True)
    print("\nRMS shape error over all nodes / over the interior nodes (um, medians over runs) / "
          "measurement time (s, median) per method;\nresidual/noise floor of georeg; image model "
          "time (s, both images); interior: nodes of no element touching the mesh boundary")
    print("| case | order | prefilter (px) | FE | Tikhonov 5 mm | georeg | georeg residual/floor | model (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        cells = [f"{row[m]['error_um']:.2f} / {row[m]['interior_um']:.2f} / {row[m]['time_s']:.1f}"
                 + ("" if row[m]["ok"] else " (failed)") for m in METHODS]
        print(f"| {row['case']} | {row['order']} | {row['prefilter']:g} | " + " | ".join(cells)
              + f" | {row[METHODS[2]]['ratio']:.2f} | {row['model_s']:.2f} |")
    if args.repeat > 1:
        print("\nerror spread over runs (min..max, um):")
        for row in rows:
            print(f"  {row['case']:10s} order {row['order']} {row['prefilter']:3g}: " + ", ".join(
                f"{m.split()[0]} {row[m]['spread'][0]:.2f}..{row[m]['spread'][1]:.2f}" for m in METHODS))
    base_order = orders[0]
    for key, what in (("error_um", "all nodes"), ("interior_um", "interior nodes")):
        print(f"\nerror ({what}) relative to order {base_order}, prefilter 0, per method (geometric "
              "mean over cases), and over every case and method; sum of the errors (um):")
        base = {(r["case"], m): r[m][key] for r in rows
                if r["prefilter"] == 0 and r["order"] == base_order for m in METHODS}
        for order, pf in [(o, p) for o in orders for p in prefilters]:
            mine = [r for r in rows if r["prefilter"] == pf and r["order"] == order]
            logs = {m: [np.log(r[m][key] / base[r["case"], m]) for r in mine
                        if (r["case"], m) in base] for m in METHODS}
            total = sum(r[m][key] for r in mine for m in METHODS)
            rel = (", ".join(f"{m.split()[0]} {np.exp(np.mean(v)):.3f}" for m, v in logs.items())
                   + f"; all {np.exp(np.mean(sum(logs.values(), []))):.3f}; " if any(logs.values()) else "")
            print(f"  order {order}, prefilter {pf:3g}: " + rel + f"sum {total:.2f}")
    print(f"\nelapsed {time.perf_counter() - t0:.0f} s, load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
