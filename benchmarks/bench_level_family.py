"""Benchmark: the automatic level against every fixed level, on renders that favour no level.

Issue 23, item 4. A family of shapes with known truth at the demo's scale (1200 x 1000 px,
0.1 mm/px, two cameras at 25 deg, exact cameras; ``tests/scenes.py`` FAMILY_DEMO_SCALE):

- ``wavy``: a 96 x 80 mm plate with a central hole of 12 mm radius, twisted by 1 mm at its
  corners, carrying a waviness ``a cos(2 pi (x - x0) / L) cos(2 pi (y - y0) / L)`` of
  wavelength ``L`` (``--wavelengths``, 15 to 100 mm) and amplitude ``a`` (``--amplitudes``,
  10 to 100 um), its crest off the hole (``x0, y0 = L / 5, L / 7``); measured with the NURBS
  plate with a hole (:func:`georeg_plugin.spline.geometries.plate_with_hole`, 4 refinements,
  about 1000 Q9 elements);
- ``flat``, ``bump16``, ``bump4``: the flat plate and 0.5 mm Gaussian bumps of sigma 16 mm
  (W/5) and 4 mm (W/20) of the family, on the rectangle (48 x 40 Q9 of 2 mm);

each at ``--noise`` gray levels (0, 2, 4) and ``--speckle`` px (4 and 6), rendered by the
core's ray caster (``--renderer core``, 6 x 6 rays per pixel) or by the independent
riley-raster (``--renderer riley``, benchmarks/bench_levels.py; install riley in a separate
venv). Scales (1, 0).

Per case: the RMS error (um) of the measured nodes to the true surface after the bounded
rigid alignment (tests/shape_truth.py) for plain FE, Tikhonov at 5, 10, 20 mm and "auto", and
georeg at EVERY level of the automatic search's ladder held fixed at the finest scale (the
oracle: "L<k> (dofs)", with the coarse-to-fine start one level coarser per image scale, never
below the nominal), and georeg ``levels = "auto"``
(:func:`adapters.level_search.measure_auto_levels`, 3 start levels) with its choice and its
own estimate of its error (``LevelTrial.error_mm``). Verdicts: auto within 10 % (or 0.05 um)
of the best fixed level; the coverage of the combined uncertainty ``shape_uncertainty_mm``
(share of the nodes with ``|error| <= 2 uncertainty``, target 90-98 %) and of the std alone.

Run: ``PYTHONPATH=. python benchmarks/bench_level_family.py [--renderer core|riley]
[--shapes wavy flat bump16 bump4] [--wavelengths 15 30 60 100] [--amplitudes 0.01 0.05 0.1]
[--noise 2] [--speckle 4]``. A case takes 1-3 minutes on 2 cores.
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import platform
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "benchmarks")]
import scenes  # noqa: E402
from bench_levels import Case, render  # noqa: E402
from shape_truth import bounded_shape_error, rms  # noqa: E402

from adapters.fesdic_core import nominal_model  # noqa: E402
from adapters.level_search import fixed_level, ladder, measure_auto_levels  # noqa: E402
from fesdic_core.shape.driver import MeasurementSettings, measure  # noqa: E402
from fesdic_core.solve.tikhonov import TikhonovSolver  # noqa: E402
from fesdic_core.synthetic.render import speckle_mm_for  # noqa: E402
from fesdic_core.synthetic.specimen import Specimen  # noqa: E402
from georeg_plugin.spline.geometries import plate_with_hole, rectangle  # noqa: E402

FAMILY = scenes.FAMILY_DEMO_SCALE
PLATE = dict(length_mm=96.0, width_mm=80.0, hole_radius_mm=12.0, corner_mm=1.0, refine=4)
TIKHONOV_MM = (5.0, 10.0, 20.0)
SETTINGS = MeasurementSettings(scales=(1, 0))


def _wavy_height(x, y, k, a, L):
    x0, y0 = L / 5.0, L / 7.0
    return k * x * y + a * np.cos(2 * np.pi * (x - x0) / L) * np.cos(2 * np.pi * (y - y0) / L)


def _wavy_gradient(x, y, k, a, L):
    x0, y0 = L / 5.0, L / 7.0
    u, v = 2 * np.pi * (x - x0) / L, 2 * np.pi * (y - y0) / L
    w = 2 * np.pi / L
    return k * y - a * w * np.sin(u) * np.cos(v), k * x - a * w * np.cos(u) * np.sin(v)


def wavy_plate(wavelength_mm: float, amplitude_mm: float, speckle_mm: float) -> Specimen:
    """The family's twisted open-hole plate with a waviness of one wavelength."""
    p = PLATE
    k = p["corner_mm"] / (0.25 * p["length_mm"] * p["width_mm"])
    params = dict(k=k, a=amplitude_mm, L=wavelength_mm)
    return Specimen(length_mm=p["length_mm"], width_mm=p["width_mm"],
                    hole_radius_mm=p["hole_radius_mm"], height=partial(_wavy_height, **params),
                    height_gradient=partial(_wavy_gradient, **params), speckle_mm=speckle_mm,
                    seed=FAMILY["seed"])


def build_cases(args) -> list[tuple[Case, dict]]:
    cameras = scenes.family_cameras(FAMILY)
    plate = nominal_model(plate_with_hole(PLATE["length_mm"], PLATE["width_mm"],
                                          PLATE["hole_radius_mm"]), PLATE["refine"], "Q9")
    rect = nominal_model(rectangle(FAMILY["length_mm"], FAMILY["width_mm"]), FAMILY["elements"],
                         "Q9")
    cases = []
    for speckle_px in args.speckle:
        speckle = speckle_mm_for(cameras[0], speckle_px)
        specimens = []
        if "wavy" in args.shapes:
            specimens += [(f"wavy L {L:g} mm a {1e3 * a:g} um", wavy_plate(L, a, speckle), plate)
                          for L in args.wavelengths for a in args.amplitudes]
        for shape, divisor in (("flat", None), ("bump16", 5), ("bump4", 20)):
            if shape in args.shapes:
                specimens.append((shape, scenes.family_specimen(divisor, speckle, FAMILY), rect))
        for name, specimen, model in specimens:
            for std in args.noise:
                label = f"{name}, noise {std:g}, speckle {speckle_px:g} px"
                cases.append((Case(label, specimen, cameras, model, SETTINGS),
                              dict(noise_std=float(std), seed=FAMILY["noise_seed"])))
    return cases


def run_case(case: Case, images) -> dict:
    truth, mesh, cams = case.specimen, case.model.mesh, case.cameras
    plain = dataclasses.replace(case.settings, uncertainty=False)

    def error(m) -> float:
        value = 1e3 * rms(bounded_shape_error(m.nodes, truth))
        return value if m.ok else -value                       # negative: the verdict failed

    row: dict = {"FE": error(measure(mesh, images, cams, None, plain))}
    for length in TIKHONOV_MM + ("auto",):
        name = f"T{length:g}" if length != "auto" else "Tauto"
        row[name] = error(measure(mesh, images, cams, TikhonovSolver(mesh, length), plain))
    space = ladder(case.model, None, linear=True)
    fixed = {}
    for level in range(space.n_levels):
        m = measure(mesh, images, cams, fixed_level(space, case.model, level, SETTINGS.scales), plain)
        fixed[level] = (error(m), int(space.operators[level].shape[0]))
    row["fixed"] = fixed
    t0 = time.perf_counter()
    m, _, search = measure_auto_levels(case.model, images, cams, case.settings, start_levels=3)
    row["t_auto"] = time.perf_counter() - t0
    row["auto"] = error(m)
    chosen = [t for t in search.trials if t.chosen]
    row["level"] = search.chosen
    row["estimate"] = 1e3 * chosen[0].error_mm if chosen else float("nan")
    signed = np.abs(bounded_shape_error(m.nodes, truth))
    for key, spread in (("cov_u", m.shape_uncertainty_mm), ("cov_std", m.shape_std_mm)):
        row[key] = float(np.mean(signed <= 2.0 * np.asarray(spread))) if spread is not None \
            else float("nan")
    return row


def print_row(name: str, row: dict) -> bool:
    fixed = row["fixed"]
    valid = {k: v for k, (v, _) in fixed.items() if v >= 0}
    best_level = min(valid, key=valid.get) if valid else None
    best = valid[best_level] if valid else float("nan")
    ok = row["auto"] >= 0 and row["auto"] <= max(1.1 * best, best + 0.05)
    tik = min((v for k, v in row.items() if k.startswith("T") and isinstance(v, float) and v >= 0),
              default=float("nan"))
    levels = " ".join(f"L{k}({d})={v:.2f}" for k, (v, d) in fixed.items())
    print(f"{name}\n  FE {row['FE']:.2f}  best Tikhonov {tik:.2f} (auto {row['Tauto']:.2f})  "
          f"fixed: {levels}\n  auto {row['auto']:.2f} at L{row['level']} (its estimate "
          f"{row['estimate']:.2f}), best fixed {best:.2f} at L{best_level}: "
          f"{'within' if ok else 'NOT within'} 10 %; coverage of the uncertainty "
          f"{100 * row['cov_u']:.1f} %, of the std alone {100 * row['cov_std']:.1f} %; "
          f"auto {row['t_auto']:.1f} s", flush=True)
    return ok


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--renderer", choices=("core", "riley"), default="core")
    parser.add_argument("--shapes", nargs="+", default=["wavy", "flat", "bump16", "bump4"])
    parser.add_argument("--wavelengths", nargs="+", type=float, default=[15.0, 30.0, 60.0, 100.0])
    parser.add_argument("--amplitudes", nargs="+", type=float, default=[0.01, 0.05, 0.1],
                        help="waviness amplitudes (mm)")
    parser.add_argument("--noise", nargs="+", type=float, default=[2.0])
    parser.add_argument("--speckle", nargs="+", type=float, default=[4.0], help="speckle size (px)")
    parser.add_argument("--supersample", type=int, default=6)
    parser.add_argument("--riley-subsample", type=int, default=4)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    import os
    print(f"machine: {platform.platform()}, {os.cpu_count()} cpus, load average "
          f"{os.getloadavg()[0]:.1f} at start; renderer {args.renderer}")
    print("RMS error to the truth (um, after the bounded rigid alignment; negative: the "
          "measurement's verdict failed); L<k>(dofs): georeg at level k of the ladder, fixed")
    met = []
    for case, recipe in build_cases(args):
        images, _ = render(case, recipe, args.renderer, args.supersample, args.riley_subsample)
        met.append(print_row(case.name, run_case(case, images)))
    print(f"auto within 10 % (or 0.05 um) of the best fixed level: {sum(met)} of {len(met)} cases")


if __name__ == "__main__":
    main()
