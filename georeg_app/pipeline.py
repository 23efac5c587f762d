"""The science behind ``georeg``: build the nominal model, run each method, compare.

One run measures the same stereo pair with several methods (section 4 of the paper):
FE without regularization, Tikhonov (Eq. 10) at several lengths, and the geometric
regularization over ``levels`` spline levels coupled with ``scales`` image scales
(section 3.3), each one with the fixed point of calibration and shape (section 2.2).
Everything reaches the core through the adapters; the plugin never sees the core.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import tempfile
from pathlib import Path
from typing import Sequence

import numpy as np

from adapters.fesdic_core import NominalModel, georeg_solver, measured_spline, nominal_model
from fesdic_core.accuracy import shape_error_to_surface
from fesdic_core.driver import Measurement, MeasurementSettings, measure
from fesdic_core.gauge import best_fit_plane_distance, move_cameras_with_specimen
from fesdic_core.image import Image, read_image
from fesdic_core.mesh import SurfaceMesh, validate_mesh
from fesdic_core.mesh_io import read_mesh
from fesdic_core.render import Specimen, demo_cameras, render_stereo, speckle_mm_for, twisted_plate
from fesdic_core.rig import (initial_rig_pose, read_cameras_json, read_pyvale_csv,
                             stereo_transform, write_cameras_json)
from fesdic_core.tikhonov import TikhonovSolver
from georeg_plugin.geometries import plate_with_hole, rectangle
from georeg_plugin.patch import SplinePatch
from georeg_plugin.refine import refine_to_elements

from .config import (CamerasConfig, Config, GeometryConfig, ImagesConfig, MethodConfig,
                     OutputConfig)

logger = logging.getLogger(__name__)

#: the demo specimen (paper, section 4: 180 x 50 mm plate, hole 28 mm, seen over 100 mm)
DEMO = dict(length_mm=180.0, width_mm=50.0, view_mm=100.0, hole_radius_mm=14.0,
            corner_mm=1.0, waviness_mm=0.2, noise_std=2.0, image_size=(1224, 816),
            field_mm=112.0, stereo_angle_deg=25.0, pose_error_deg=0.5, pose_error_mm=0.5)


@dataclasses.dataclass(frozen=True)
class MethodSpec:
    """One method of a comparison."""

    name: str                 # "fe" | "tikhonov" | "georeg"
    param: float | None       # Tikhonov length (mm) for "tikhonov", else None
    scales: tuple[int, ...]   # image scales, coarse to fine
    label: str


@dataclasses.dataclass(frozen=True, eq=False)
class MethodResult:
    spec: MethodSpec
    measurement: Measurement
    mesh: SurfaceMesh
    distance_to_bfp_mm: np.ndarray
    shape_rms_error_mm: float | None
    spline: SplinePatch | None = None
    spline_values: np.ndarray | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class RunResult:
    results: tuple
    truth_available: bool
    images: tuple
    one_fine_iteration_s: float


@dataclasses.dataclass(frozen=True, eq=False)
class Truth:
    """What a synthetic run knows: the actual surface and the exact cameras."""

    specimen: Specimen
    cameras: tuple


# ----------------------------------------------------------------------------- inputs
def load_cameras(cameras: CamerasConfig, images: Sequence[Image]) -> list:
    """Initial cameras: the JSON file as is, or another tool's calibration (pyvale, OpenCV,
    VIC-3D, DICe) whose stereo relation is kept and posed by the landmarks."""
    from fesdic_core.calibration_formats import read_dice, read_opencv_stereo, read_vic3d
    if cameras.file is not None:
        cams = read_cameras_json(cameras.file)
        if len(cams) != 2:
            raise ValueError(f"{cameras.file}: a stereo pair needs 2 cameras, got {len(cams)}")
        return cams
    size = [(im.shape[1], im.shape[0]) for im in images]
    if cameras.opencv is not None:
        cam0, cam1 = read_opencv_stereo(cameras.opencv, size)
    elif cameras.vic3d is not None:
        cam0, cam1 = read_vic3d(cameras.vic3d, size)
    elif cameras.dice is not None:
        cam0, cam1 = read_dice(cameras.dice)
    else:
        cam0, cam1 = read_pyvale_csv(cameras.pyvale_csv, size)
    R, t = stereo_transform(cam0, cam1)
    xyz = np.array([lm.xyz_mm for lm in cameras.landmarks])
    px0 = np.array([lm.cam0_px for lm in cameras.landmarks])
    px1 = np.array([lm.cam1_px for lm in cameras.landmarks])
    return list(initial_rig_pose(cam0, cam1, xyz, px0, px1, R, t))


def coarse_patch(geometry: GeometryConfig) -> SplinePatch:
    """The coarsest nominal spline (the CAD model) of ``[geometry]``."""
    if geometry.kind == "plate_with_hole":
        return plate_with_hole(geometry.length_mm, geometry.width_mm, geometry.hole_radius_mm)
    if geometry.kind == "rectangle":
        patch = rectangle(geometry.length_mm, geometry.width_mm)
        aspect = geometry.length_mm / geometry.width_mm
        n_u, n_v = (max(1, round(aspect)), 1) if aspect >= 1 else (1, max(1, round(1 / aspect)))
        return patch if (n_u, n_v) == (1, 1) else refine_to_elements(patch, n_u, n_v)[0]
    raise ValueError(f"[geometry] kind {geometry.kind!r} has no spline of its own")


def build_model(geometry: GeometryConfig, levels: int) -> NominalModel:
    """Nominal spline and analysis-suitable Q9 mesh (Eq. 17), or a legacy mesh read from file.

    The FE mesh refines the finest spline level dyadically until it has about
    ``geometry.elements`` elements (default: at least 1000, the paper's mesh).
    """
    if geometry.kind == "mesh":
        mesh = read_mesh(geometry.file)
        validate_mesh(mesh, str(geometry.file))                   # errors name the file
        lo, hi = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
        if hi[2] - lo[2] > 1e-6 * np.ptp(mesh.nodes[:, :2]):
            raise ValueError(f"{geometry.file}: kind = 'mesh' takes a flat mesh in z = 0 "
                             f"(z spans {lo[2]:g}..{hi[2]:g} mm)")
        size = hi - lo
        patch = rectangle(size[0], size[1], center=tuple((lo + hi)[:2] / 2))
        return NominalModel(patch=patch, mesh=mesh, uv=None)       # point inversion (Remark 6)
    patch = coarse_patch(geometry)
    target = geometry.elements or 1000
    refinements = max(levels - 1, math.ceil(math.log(target / np.prod(patch.n_elements), 4) - 1e-9))
    return nominal_model(patch, refinements, "Q9", name=geometry.kind)


# ----------------------------------------------------------------------------- methods
def default_specs(config: Config) -> list[MethodSpec]:
    """All methods on the same data: FE, Tikhonov x lengths, georeg multi- and monoscale."""
    scales = config.method.scale_sequence
    specs = [MethodSpec("fe", None, scales, "FE (multiscale)")]
    specs += [MethodSpec("tikhonov", float(length), scales, f"Tikhonov {length:g} mm")
              for length in config.method.tikhonov_length_mm]
    specs.append(MethodSpec("georeg", None, scales, "georeg (multiscale)"))
    if len(scales) > 1:
        specs.append(MethodSpec("georeg", None, (0,), "georeg (monoscale)"))
    return specs


def _solver(spec: MethodSpec, model: NominalModel, levels: int):
    if spec.name == "fe":
        return None
    if spec.name == "tikhonov":
        return TikhonovSolver(model.mesh, spec.param)
    if spec.name == "georeg":
        return georeg_solver(model, levels)
    raise ValueError(f"unknown method {spec.name!r}")


def _one_fine_iteration_s(results: Sequence[MethodResult]) -> float:
    """Median wall time of one shape iteration at scale 0 (Fig. 11's time unit)."""
    steps = []
    for r in results:
        t = [h["time_s"] for h in r.measurement.history if h["scale"] == 0]
        steps += list(np.diff(t))
    return float(np.median(steps)) if steps else float("nan")


def run_methods(config: Config, specs: Sequence[MethodSpec], *, images=None,
                truth: Truth | None = None, progress: bool = False) -> RunResult:
    """Measure the shape with each method of ``specs`` on the same images.

    Parameters
    ----------
    config : the run's configuration (images, cameras, geometry, method).
    specs : the methods (see :func:`default_specs`).
    images : the two images, if already loaded (else read from ``config.images``).
    truth : the known surface and cameras of a synthetic run (for the errors).
    """
    if images is None:
        images = (read_image(config.images.cam0), read_image(config.images.cam1))
    cameras = load_cameras(config.cameras, images)
    method = config.method
    model = build_model(config.geometry, method.levels)
    logger.info("nominal model: %s, %d Q9 nodes, %d elements", config.geometry.kind,
                model.mesh.n_nodes, model.mesh.n_elements)
    results = []
    for spec in specs:
        solver = _solver(spec, model, method.levels)
        settings = MeasurementSettings(scales=tuple(spec.scales), calibrate=method.calibrate,
                                       keep_stereo=method.keep_stereo,
                                       normalisation=method.normalisation,
                                       max_fixed_point=method.max_fixed_point, progress=progress)
        logger.info("%s ...", spec.label)
        m = measure(model.mesh, images, cameras, solver, settings)
        error = None
        if truth is not None:
            error = float(np.sqrt(np.mean(shape_error_to_surface(m.nodes, truth.specimen) ** 2)))
        spline = values = None
        if spec.name == "georeg":
            spline, values = measured_spline(solver, m.q, 0)
        results.append(MethodResult(spec=spec, measurement=m, mesh=model.mesh,
                                    distance_to_bfp_mm=best_fit_plane_distance(m.nodes),
                                    shape_rms_error_mm=error, spline=spline, spline_values=values))
        logger.info("%s: residual %.3f%%, %d iterations, %.1f s%s", spec.label, m.residual_percent,
                    m.iterations, m.time_s, "" if error is None else f", error {error * 1e3:.2f} um")
    return RunResult(results=tuple(results), truth_available=truth is not None,
                     images=tuple(im.values for im in images),
                     one_fine_iteration_s=_one_fine_iteration_s(results))


# ----------------------------------------------------------------------------- demo
def demo_specimen() -> Specimen:
    """The paper's twisted open-hole specimen (section 4.2), with a smooth waviness."""
    return twisted_plate(DEMO["length_mm"], DEMO["width_mm"], corner_mm=DEMO["corner_mm"],
                         hole_radius_mm=DEMO["hole_radius_mm"], waviness_mm=DEMO["waviness_mm"],
                         view_length_mm=DEMO["view_mm"], seed=7)


def demo_config(out_dir) -> tuple[Config, tuple, Truth]:
    """Render the demo stereo pair and return its config, images and truth.

    Two cameras at 25 degrees, about 1 Mpx each, 4 px speckle, noise of 2 gray levels.
    The cameras of the config are the exact ones with the specimen pose perturbed by
    0.5 degree and 0.5 mm (the fixed point must find it). Inputs are written to a
    temporary folder (the output folder only receives the results).
    """
    cams = demo_cameras(image_size=DEMO["image_size"], stereo_angle_deg=DEMO["stereo_angle_deg"],
                        field_mm=DEMO["field_mm"])
    specimen = dataclasses.replace(demo_specimen(), speckle_mm=speckle_mm_for(cams[0], 4.0))
    arrays = render_stereo(specimen, cams, supersample=3, noise_std=DEMO["noise_std"], seed=11,
                           progress=logger.isEnabledFor(logging.INFO))
    images = tuple(Image.from_array(a, source=f"demo cam{k}") for k, a in enumerate(arrays))
    rotation = np.radians(DEMO["pose_error_deg"]) * np.array([0.6, -0.48, 0.64])
    translation = DEMO["pose_error_mm"] * np.array([0.48, 0.64, -0.6])
    initial = move_cameras_with_specimen(cams, translation, rotation, np.zeros(3))
    inputs = Path(tempfile.mkdtemp(prefix="georeg_demo_"))
    write_cameras_json(inputs / "cameras.json", initial)
    config = Config(
        images=ImagesConfig(cam0=inputs / "cam0 (rendered in memory)", cam1=inputs / "cam1 (rendered in memory)"),
        cameras=CamerasConfig(file=inputs / "cameras.json"),
        geometry=GeometryConfig(kind="plate_with_hole", length_mm=DEMO["view_mm"],
                                width_mm=DEMO["width_mm"], hole_radius_mm=DEMO["hole_radius_mm"]),
        method=MethodConfig(),
        output=OutputConfig(dir=Path(out_dir)),
        source=inputs / "demo (embedded)")
    return config, images, Truth(specimen=specimen, cameras=tuple(cams))
