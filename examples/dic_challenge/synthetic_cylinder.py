"""Does the method bias the radius of a bar? Synthetic images of the vertical bar, measured.

The real rig (pyvale's calibration posed by the landmarks of ``specimen.toml``) looks at a
rendered half-cylinder along the vertical bar's axis, speckle of about 7 px, noise of 1.5
gray levels (:mod:`fesdic_core.synthetic.render`, ray casting onto ``z = h(x, y)``; the renderer's
Newton does not follow the step from the bar down to the plate, so the plate shows the
background: only the bar is measured).
Two true radii are rendered: the laser's 6.38 mm (axis 0.23 mm below the plate) and
6.23 mm (axis at the plate). Each pair is measured with the package's own pieces
(:func:`adapters.fesdic_core.nominal_model`, :func:`fesdic_core.shape.driver.measure`, geometric
regularization over 3 spline levels, fixed point of calibration and shape, scales 3, 2, 1,
0; initial pose off by 0.3 mm and 0.1 degree) from two nominals: the exact NURBS cylinder
of radius 6.38 mm over 80 degrees of arc about the crest (the bar's crest face of the CAD,
``analysis.toml``'s ``cylinder_v``), and a flat patch at crest height (the method is then
given no radius); the least-squares cylinder of the measured surface is compared with the
truth.

Usage: ``python examples/dic_challenge/synthetic_cylinder.py`` (a few minutes).
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from adapters.fesdic_core import NominalModel, multilevel_for_mesh, nominal_model  # noqa: E402
from challenge import analysis                                           # noqa: E402
from challenge.config import Bar, Specimen, load_analysis                # noqa: E402
from fesdic_core.shape.driver import MeasurementSettings, measure              # noqa: E402
from fesdic_core.shape.gauge import move_cameras_with_specimen                 # noqa: E402
from fesdic_core.imaging.image import Image, read_image                          # noqa: E402
from fesdic_core.fe.mesh import node_normals                                # noqa: E402
from fesdic_core.synthetic.render import render_stereo, speckle_mm_for  # noqa: E402
from fesdic_core.synthetic.specimen import Specimen as Scene
from fesdic_core.cameras.rig import initial_rig_pose, read_pyvale_csv, stereo_transform  # noqa: E402
from georeg_plugin.spline.geometries import cylinder, quadrilateral, transformed  # noqa: E402
from georeg_plugin.spline.refine import refine_to_elements                      # noqa: E402
from georeg_plugin.levels.solver import GeometricRegularization                 # noqa: E402

#: window of the stored images around the vertical bar, both views (x0, y0, w, h) px
WINDOW = (1330, 80, 340, 760)
AXIS_X_MM = 40.89
#: the measurement (as the part's, specimen_part.toml, on one bar)
ELEMENTS = (8, 16)            # Q9 across x along
SPLINE_ELEMENTS = (1, 2)      # the coarsest spline level
LEVELS = 3
SETTINGS = MeasurementSettings(scales=(3, 2, 1, 0), calibrate=True, keep_stereo=True,
                               max_fixed_point=15, max_iter=20, points_per_px=1.0)
#: the flat nominal: crest height, 8.2 mm across the bar (corners x, y at z = CREST_MM)
CREST_MM = 6.15
FLAT_HALF_WIDTH_MM = 4.1


def bar_scene(radius_mm: float, axis_z_mm: float, speckle_mm: float) -> Scene:
    """A 101.6 mm plate with a half cylinder along y at ``x = AXIS_X_MM``."""
    def height(x, y):
        u = np.asarray(x, float) - AXIS_X_MM
        return np.maximum(0.0, axis_z_mm + np.sqrt(np.maximum(radius_mm ** 2 - u ** 2, 1e-6)))

    def gradient(x, y):
        u = np.asarray(x, float) - AXIS_X_MM
        on = height(x, y) > 0.0
        dz = np.where(on, -u / np.sqrt(np.maximum(radius_mm ** 2 - u ** 2, 1e-6)), 0.0)
        return dz, np.zeros_like(dz)

    return Scene(101.6, 101.6, height=height, height_gradient=gradient, speckle_mm=speckle_mm, seed=5)


def window_rig(specimen: Specimen) -> tuple[list[Image], list]:
    """The real pair cropped to ``WINDOW`` and the calibrated rig posed by the landmarks on it
    (both views, stereo relation kept; principal points shifted by the crop)."""
    x0, y0, w, h = WINDOW
    images = [Image.from_array(read_image(p).values[y0:y0 + h, x0:x0 + w], f"{p}[crop]")
              for p in (specimen.cam0, specimen.cam1)]
    cams = []
    for cam in read_pyvale_csv(specimen.pyvale_csv, (w, h)):
        K = np.array(cam.K)
        K[:2, 2] -= (x0, y0)
        cams.append(dataclasses.replace(cam, K=K))
    R, t = stereo_transform(*cams)
    xyz = np.array([lm.xyz_mm for lm in specimen.landmarks])
    px = [np.array([getattr(lm, f"cam{k}_px") for lm in specimen.landmarks]) - (x0, y0) for k in (0, 1)]
    return images, list(initial_rig_pose(cams[0], cams[1], xyz, px[0], px[1], R, t))


def nominals(bar: Bar) -> dict[str, NominalModel]:
    """The bar's cylindrical and flat nominals: spline of ``SPLINE_ELEMENTS``, Q9 mesh."""
    line = np.asarray(bar.axis_mm, float)
    axis = (line[1] - line[0]) / np.linalg.norm(line[1] - line[0])
    lateral = np.cross(axis, [0.0, 0.0, 1.0])
    lateral /= np.linalg.norm(lateral)
    patch = cylinder(bar.radius_mm, float(np.linalg.norm(line[1] - line[0])), bar.arc_deg, axis="y")
    R = np.column_stack([lateral, axis, np.cross(lateral, axis)])   # local (lateral, axis, up) -> world
    curved = transformed(patch, R, line.mean(axis=0))
    corners = [[*(end + side * FLAT_HALF_WIDTH_MM * lateral[:2]), CREST_MM] for end, side in
               ((line[0, :2], -1), (line[0, :2], 1), (line[1, :2], 1), (line[1, :2], -1))]
    flat = quadrilateral(corners)
    out = {}
    for name, p in ((f"cylinder {bar.radius_mm:g}", curved), ("flat", flat)):
        if p.n_elements != SPLINE_ELEMENTS:
            p, _ = refine_to_elements(p, *SPLINE_ELEMENTS)
        out[name] = nominal_model(p, ELEMENTS, "Q9", name=name)
    return out


def measured_points(model: NominalModel, images, start, reference, curved: bool) -> np.ndarray:
    """The seen integration points of the measured surface, put through the final camera 0 in
    the frame where camera 0 is ``reference`` (a rigid motion of rig and specimen together
    leaves the residual unchanged: the gauge of the fixed point)."""
    solver = GeometricRegularization(multilevel_for_mesh(model, LEVELS, curved), hold_unseen=True)
    m = measure(model.mesh, images, start, solver, SETTINGS, normals=node_normals(model.mesh))
    X = m.quadrature.points(m.nodes)[np.isfinite(np.asarray(m.residual.percent, float))]
    Xc = X @ m.cameras[0].R.T + m.cameras[0].tvec
    return (Xc - reference.tvec) @ reference.R


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    config = load_analysis(HERE / "analysis.toml")
    bar = next(b for b in config.bars if b.name == "cylinder_v")
    _, cameras = window_rig(config.specimen)
    speckle = speckle_mm_for(cameras[0], 7.0)
    start = move_cameras_with_specimen(cameras, np.array([0.3, -0.2, 0.1]),
                                       np.radians(0.1) * np.array([0.6, 0.8, 0.0]), np.zeros(3))
    models = nominals(bar)
    print(f"{'true radius':>12} {'nominal':>20} {'fitted radius':>14} {'error':>9} {'fit RMS':>8}")
    for radius, axis_z in ((6.38, -0.23), (6.23, 0.0)):
        arrays = render_stereo(bar_scene(radius, axis_z, speckle), cameras, supersample=3,
                               noise_std=1.5, seed=3, progress=False)
        images = [Image.from_array(a, f"synthetic cam{k}") for k, a in enumerate(arrays)]
        for label, model in models.items():
            P = measured_points(model, images, start, start[0], curved=label != "flat")
            fit = analysis.fit_cylinder(P, [0.0, 1.0, 0.0], 6.3)
            print(f"{radius:12.3f} {label:>20} {fit.radius_mm:14.4f} "
                  f"{1e3 * (fit.radius_mm - radius):7.1f}um {1e3 * fit.rms_mm:6.2f}um")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
