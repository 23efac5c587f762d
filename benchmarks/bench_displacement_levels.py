"""Benchmark: the displacement's spline levels chosen from the data, and its uncertainty,
against every fixed level on a family of rendered motions with a known truth.

Each case is a flat 60 x 40 mm plate rendered, then the same paint on the twisted plate
``z = k x y`` (1 mm at the corners) carrying a waviness
``a cos(2 pi (x - L/5) / L) cos(2 pi (y - L/7) / L)`` (wavelength ``L``, amplitude ``a``):
the displacement ``u = (0, 0, z(x, y))``. Cameras and mesh as the tests' (tests/scenes.py
``TWIST_WAVE``: two cameras at 25 deg, 320 x 240 px over 72 mm; the mesh the central
44 x 30 mm as 24 x 16 Q9 from the nominal rectangle), scales (2, 1, 0) where the elements
hold enough pixels. Renderers: ``core`` (fesdic_core.synthetic.render, 3 x 3 rays per pixel)
and ``riley`` (riley-raster, PyPI, an independent rasteriser: Catmull-Rom texture sampling,
4 x 4 sub-pixels; benchmark environment only, ``benchmarks/bench_levels.py`` has its camera
conversion).

Printed per case: the out-of-plane RMS error at the nodes (um) of plain FE and of georeg at
every fixed number of levels, the levels chosen on the frame
(:func:`adapters.displacement_levels.choose_displacement_levels`), the chosen level's error
over the best fixed level's, and the coverage of the uncertainty (share of node components
within two ``displacement_uncertainty_mm`` of the truth) for FE and for the chosen levels.
Targets (issue 23): the chosen within 10 % (or 0.05 um) of the best fixed level; coverage
90-98 %.

Run: ``python benchmarks/bench_displacement_levels.py [--renderer core|riley|both]
[--wavelengths 20 60] [--amplitudes 0.05] [--noise 2]`` (``--wavelengths 0``: the twist
alone). With riley: the benchmark venv's python (``pip install riley-raster``).
"""
from __future__ import annotations

import argparse
import logging
import os
import platform
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import scenes  # noqa: E402
from adapters.displacement_levels import (choose_displacement_levels,  # noqa: E402
                                          max_displacement_levels)
from adapters.fesdic_core import nominal_model  # noqa: E402
from fesdic_core.displacement.driver import (DisplacementSettings,  # noqa: E402
                                             displacement_reference, measure_displacement)
from fesdic_core.imaging.image import Image  # noqa: E402
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for  # noqa: E402
from fesdic_core.synthetic.specimen import Specimen  # noqa: E402
from georeg_app.series.reference import displacement_solver  # noqa: E402
from georeg_plugin.spline.geometries import rectangle  # noqa: E402

PLATE_MM, MESH_MM, CORNER_MM = (60.0, 40.0), (44.0, 30.0), 1.0


def _height(x, y, k, L, a):
    if L <= 0:
        return k * x * y
    return k * x * y + a * np.cos(2 * np.pi * (x - L / 5) / L) * np.cos(2 * np.pi * (y - L / 7) / L)


def _gradient(x, y, k, L, a):
    if L <= 0:
        return k * y, k * x
    u, v, w = 2 * np.pi * (x - L / 5) / L, 2 * np.pi * (y - L / 7) / L, 2 * np.pi / L
    return k * y - a * w * np.sin(u) * np.cos(v), k * x - a * w * np.cos(u) * np.sin(v)


def _render(renderer, specimen, cameras, noise, seed):
    if renderer == "core":
        arrays = render_stereo(specimen, cameras, supersample=3, noise_std=noise, seed=seed,
                               progress=False)
    else:
        from bench_levels import riley_render
        arrays, _ = riley_render(specimen, cameras, noise, seed)
    return tuple(Image.from_array(a, f"{renderer} cam{k}") for k, a in enumerate(arrays))


def _rms_z(m, truth):
    return float(np.sqrt(np.mean((m.U[:, 2] - truth[:, 2]) ** 2)))


def _coverage(m, truth):
    u = None if m.uncertainty is None else m.uncertainty.uncertainty_mm
    return np.mean(np.abs(m.U - truth) <= 2.0 * u, axis=0) if u is not None else np.full(3, np.nan)


def run_case(renderer, cameras, model, L, a, noise):
    speckle = speckle_mm_for(cameras[0], 4.0)
    k = CORNER_MM / (0.25 * PLATE_MM[0] * PLATE_MM[1])
    flat = Specimen(*PLATE_MM, speckle_mm=speckle, seed=3)
    params = dict(k=k, L=L, a=a)
    bent = Specimen(*PLATE_MM, height=partial(_height, **params),
                    height_gradient=partial(_gradient, **params), speckle_mm=speckle, seed=3)
    reference_pair = _render(renderer, flat, cameras, noise, 1)
    deformed = _render(renderer, bent, cameras, noise, 2)
    reference = displacement_reference(model.mesh, reference_pair, cameras,
                                       DisplacementSettings(scales=(2, 1, 0)))
    nodes = model.mesh.nodes
    truth = np.zeros_like(nodes)
    truth[:, 2] = _height(nodes[:, 0], nodes[:, 1], **params)
    fe = measure_displacement(reference, deformed, None)
    fixed, measured = {}, {}
    for levels in range(1, max_displacement_levels(model) + 1):
        m = measure_displacement(reference, deformed,
                                 displacement_solver("georeg", model.mesh, model, 10.0, levels))
        if m.ok:
            fixed[levels], measured[levels] = _rms_z(m, truth), m
    record = choose_displacement_levels(model, reference, deformed, start_levels=2)
    best = min(fixed.values())
    chosen = fixed.get(record.levels, float("nan"))
    ok = chosen <= max(1.1 * best, best + 5e-5)
    return dict(fe=_rms_z(fe, truth), fe_cov=_coverage(fe, truth), fixed=fixed,
                levels=record.levels, ratio=chosen / best, ok=ok,
                cov=_coverage(measured[record.levels], truth) if record.levels in measured
                else np.full(3, np.nan))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--renderer", choices=("core", "riley", "both"), default="core")
    p.add_argument("--wavelengths", type=float, nargs="+", default=[0.0, 20.0, 60.0, 100.0])
    p.add_argument("--amplitudes", type=float, nargs="+", default=[0.05])
    p.add_argument("--noise", type=float, nargs="+", default=[2.0])
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    load = os.getloadavg()
    print(f"# {platform.platform()}, {os.cpu_count()} cpus, python {platform.python_version()}, "
          f"load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    d = scenes.TWIST_WAVE
    cameras = tuple(demo_cameras(image_size=d["image_size"], field_mm=d["field_mm"]))
    model = nominal_model(rectangle(*MESH_MM), (24, 16), "Q9")
    renderers = ("core", "riley") if args.renderer == "both" else (args.renderer,)
    print("renderer | L (mm) | a (um) | noise | FE z (um) | georeg z per levels (um) | chosen | "
          "chosen / best | coverage chosen x/y/z (%) | coverage FE x/y/z (%) | time (s)")
    failures = 0
    for renderer in renderers:
        for L in args.wavelengths:
            for a in (args.amplitudes if L > 0 else [0.0]):
                for noise in args.noise:
                    t0 = time.perf_counter()
                    r = run_case(renderer, cameras, model, L, a, noise)
                    failures += not r["ok"]
                    fixed = ", ".join(f"{n}: {1e3 * e:.2f}" for n, e in r["fixed"].items())
                    cov = " / ".join(f"{100 * c:.1f}" for c in r["cov"])
                    fe_cov = " / ".join(f"{100 * c:.1f}" for c in r["fe_cov"])
                    miss = "" if r["ok"] else " MISS"
                    print(f"{renderer} | {L:g} | {1e3 * a:g} | {noise:g} | {1e3 * r['fe']:.2f} | "
                          f"{fixed} | {r['levels']} | {r['ratio']:.3f}{miss} | "
                          f"{cov} | {fe_cov} | {time.perf_counter() - t0:.0f}", flush=True)
    print(f"# {failures} case(s) where the chosen levels miss the best fixed level by more than "
          "10 % (and 0.05 um)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
