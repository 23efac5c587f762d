"""The science behind ``georeg``: build the nominal model, run each method, compare.

One run measures the same stereo pair with several methods (section 4 of the paper):
FE without regularization, Tikhonov (Eq. 10) at several lengths, and the geometric
regularization over ``levels`` spline levels coupled with ``scales`` image scales
(section 3.3), each one with the fixed point of calibration and shape (section 2.2).
Everything reaches the core through the adapters; the plugin never sees the core.
"""
from __future__ import annotations

import dataclasses
import datetime
import hashlib
import logging
import math
import shutil
import sys
import tempfile
import weakref
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm.auto import tqdm

from adapters.fesdic_core import (NominalModel, georeg_solver, measured_spline,
                                  measured_spline_std, nominal_model)
from adapters.level_search import LevelSearch, measure_auto_levels
from fesdic_core.synthetic.accuracy import shape_error_to_surface
from fesdic_core.shape.driver import (Measurement, MeasurementInputError, MeasurementSettings,
                                check_scales, measure)
from fesdic_core.shape.gauge import best_fit_plane_distance, move_cameras_with_specimen
from fesdic_core.imaging.image import Image, read_image
from fesdic_core.fe.mesh import MeshError, SurfaceMesh, validate_mesh
from fesdic_core.fe.mesh_io import read_mesh
from fesdic_core.synthetic.render import Specimen, demo_cameras, render_stereo, speckle_mm_for, twisted_plate
from fesdic_core.cameras.rig import (initial_rig_pose, read_cameras_json, read_pyvale_csv,
                             stereo_transform, write_cameras_json)
from fesdic_core.solve.tikhonov import TikhonovSolver
from georeg_plugin.spline.geometries import plate_with_hole, rectangle
from georeg_plugin.spline.patch import SplinePatch
from georeg_plugin.spline.refine import refine_to_elements

from georeg_app import installed_version
from georeg_app.inputs.cad import cad_faces, cad_model, cad_refinements
from georeg_app.shape.visibility import scene_occluders, visibility_settings
from georeg_app.config.measure import (AUTO, CamerasConfig, Config, GeometryConfig, ImagesConfig, MethodConfig,
                     OutputConfig)
from georeg_app.shape.methods import MethodSpec, default_specs  # noqa: F401 (the pipeline's contract)

logger = logging.getLogger(__name__)

#: the demo specimen (paper, section 4: 180 x 50 mm plate, hole 28 mm, seen over 100 mm)
DEMO = dict(length_mm=180.0, width_mm=50.0, view_mm=100.0, hole_radius_mm=14.0,
            corner_mm=1.0, waviness_mm=0.2, noise_std=2.0, image_size=(1224, 816),
            field_mm=112.0, stereo_angle_deg=25.0, pose_error_deg=0.5, pose_error_mm=0.5)


@dataclasses.dataclass(frozen=True, eq=False)
class MethodResult:
    """One method's outcome. ``status`` is "ok" or "failed"; a failed method says why in
    ``failure`` and carries its (untrusted) measurement, or None if it gave no state at all.
    ``shape_error_mm``: per-node distance to the true surface after the best rigid
    alignment (None without a truth). ``level_search``: the record of georeg's automatic
    level choice; ``spline_std``: the standard deviation of the measured spline's control
    values (mm); ``regularization``: what the method chose (Tikhonov lengths per scale).
    A part of several faces (``[geometry] kind = "cad"``): ``spline`` is a tuple of patches
    (one per face), ``element_face`` each element's face, ``face_names`` their names."""

    spec: MethodSpec
    measurement: Measurement | None
    mesh: SurfaceMesh
    distance_to_bfp_mm: np.ndarray | None
    shape_rms_error_mm: float | None
    spline: SplinePatch | None = None
    spline_values: np.ndarray | None = None
    status: str = "ok"
    failure: str | None = None
    shape_error_mm: np.ndarray | None = None
    level_search: LevelSearch | None = None
    spline_std: np.ndarray | None = None
    regularization: dict | None = None
    element_face: np.ndarray | None = None
    face_names: tuple = ()

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@dataclasses.dataclass(frozen=True, eq=False)
class RunResult:
    """All methods of a run, with what produced them (config, input checksums, version)."""

    results: tuple
    truth_available: bool
    images: tuple
    one_fine_iteration_s: float
    config: Config | None = None
    inputs: tuple = ()
    version: str = "unknown"
    started: str = ""


@dataclasses.dataclass(frozen=True, eq=False)
class Truth:
    """What a synthetic run knows: the actual surface and the exact cameras."""

    specimen: Specimen
    cameras: tuple


# ----------------------------------------------------------------------------- inputs
def load_cameras(cameras: CamerasConfig, images: Sequence[Image]) -> list:
    """Initial cameras: the JSON file as is, or another tool's calibration (pyvale, OpenCV,
    VIC-3D, DICe) whose stereo relation is kept and posed by the landmarks."""
    from fesdic_core.cameras.io.formats import read_dice, read_opencv_stereo, read_vic3d
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


MIN_PX_PER_ELEMENT = 16     # pixels an FE element needs at full resolution (9 Q9 nodes)


def _coarse_faces(geometry: GeometryConfig) -> tuple:
    """The coarsest splines: the CAD's selected faces, or the plate's one patch."""
    if geometry.kind == "cad":
        return cad_faces(geometry.file, geometry.faces)[0]
    return (coarse_patch(geometry),)


def _refinements(geometry: GeometryConfig, levels: int) -> int:
    """Dyadic refinements from the coarsest spline to the FE mesh (see :func:`build_model`)."""
    return cad_refinements(_coarse_faces(geometry), geometry.elements, levels)


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
    if geometry.kind == "cad":
        return cad_model(geometry.file, geometry.faces, geometry.elements, levels)
    return nominal_model(coarse_patch(geometry), _refinements(geometry, levels), "Q9",
                         name=geometry.kind)


# ----------------------------------------------------------------------------- methods
def _solver(spec: MethodSpec, model: NominalModel):
    if spec.name == "fe":
        return None
    if spec.name == "tikhonov":
        return TikhonovSolver(model.mesh, spec.param)
    if spec.name == "georeg":
        return georeg_solver(model, int(spec.levels))
    raise ValueError(f"unknown method {spec.name!r}")


def _one_fine_iteration_s(results: Sequence[MethodResult]) -> float:
    """Median wall time of one shape iteration at scale 0 (Fig. 11's time unit)."""
    steps = []
    for r in results:
        if r.measurement is None:
            continue
        t = [h["time_s"] for h in r.measurement.history if h["scale"] == 0]
        steps += list(np.diff(t))
    return float(np.median(steps)) if steps else float("nan")


def check_sizes(config: Config, images: Sequence[Image]) -> None:
    """Refuse, before any computing, sizes that cannot work (named in the error).

    The FE mesh (``[geometry] elements`` and ``[method] levels``, which refine the nominal
    spline dyadically) must leave at least :data:`MIN_PX_PER_ELEMENT` pixels to each
    element in the image, and the coarsest image scale at least 32 px a side.
    """
    h, w = images[0].shape
    try:
        check_scales(images, config.method.scale_sequence)
    except MeasurementInputError as err:
        raise ValueError(f"[method] scales = {config.method.scales}: {err}") from None
    if config.geometry.kind == "mesh":
        return
    levels = config.method.fixed_levels
    coarse = sum(int(np.prod(f.n_elements)) for f in _coarse_faces(config.geometry))
    asked = config.geometry.elements
    if asked is not None and coarse * 4 ** (levels - 1) > 2 * asked:
        raise ValueError(
            f"[geometry] elements = {asked}: {levels} spline levels need an FE mesh of at least "
            f"{coarse * 4 ** (levels - 1)} elements (each level halves the knot spans of the "
            f"next); ask for more elements or fewer levels")
    elements = coarse * 4 ** _refinements(config.geometry, levels)
    if elements > (w * h) / MIN_PX_PER_ELEMENT:
        largest = max(1, int(math.log((w * h) / MIN_PX_PER_ELEMENT / coarse, 4)) + 1)
        raise ValueError(
            f"[method] levels = {levels} with [geometry] elements = {config.geometry.elements}: "
            f"the FE mesh would have {elements} elements, more than the {w} x {h} px images "
            f"can measure (at least {MIN_PX_PER_ELEMENT} px an element); use at most "
            f"{largest} levels")


def check_levels(model: NominalModel, levels: int, geometry: GeometryConfig) -> None:
    """Refuse spline levels whose finest one has more dofs than the FE mesh has nodes
    (the projection ``C H C^T`` would be singular, and the operators needlessly large)."""
    k = 2 ** (levels - 1)
    dofs = sum((p.n_elements[0] * k + p.degrees[0]) * (p.n_elements[1] * k + p.degrees[1])
               for p in model.patches)
    if dofs > model.mesh.n_nodes:
        where = f"[geometry] file = {geometry.file}" if geometry.file else "[geometry]"
        raise ValueError(f"[method] levels = {levels}: the finest spline level would have {dofs} "
                         f"dofs for the {model.mesh.n_nodes} nodes of the FE mesh ({where}); "
                         "use fewer levels or a finer mesh")


def _checksum(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def input_files(config: Config) -> tuple:
    """``(label, path, sha256)`` of each input file of ``config`` that exists on disk."""
    entries = [("image cam0", config.images.cam0), ("image cam1", config.images.cam1)]
    cams = config.cameras
    for key in ("file", "pyvale_csv", "opencv", "vic3d", "dice"):
        if getattr(cams, key, None) is not None:
            entries.append((f"cameras ({key})", getattr(cams, key)))
    if config.geometry.file is not None:
        entries.append(("geometry", config.geometry.file))
    if config.source is not None:
        entries.append(("configuration", config.source))
    return tuple((label, str(path), _checksum(path)) for label, path in entries
                 if path is not None and Path(path).is_file())


def _measure_one(spec: MethodSpec, model: NominalModel, images, cameras, config: Config,
                 truth: Truth | None, progress, occluders: np.ndarray | None = None
                 ) -> MethodResult:
    """Run one method; a failure (untrusted measurement, or an error) is returned, not raised."""
    method = config.method
    settings = MeasurementSettings(scales=tuple(spec.scales), calibrate=method.calibrate,
                                   keep_stereo=method.keep_stereo,
                                   normalisation=method.normalisation,
                                   max_fixed_point=method.max_fixed_point,
                                   edge_margin_px=method.edge_margin_px,
                                   visibility=visibility_settings(method, model, occluders))
    search = None
    try:
        if spec.name == "georeg" and spec.levels == AUTO:
            m, solver, search = measure_auto_levels(model, images, cameras, settings,
                                                    method.start_levels, progress=progress)
        else:
            solver = _solver(spec, model)
            m = measure(model.mesh, images, cameras, solver, settings, progress=progress)
    except (MeasurementInputError, MeshError):
        raise                                  # the inputs are wrong for every method
    except (ArithmeticError, RuntimeError, ValueError, np.linalg.LinAlgError) as err:
        logger.info("%s failed: %s", spec.label, err)
        return MethodResult(spec=spec, measurement=None, mesh=model.mesh, distance_to_bfp_mm=None,
                            shape_rms_error_mm=None, status="failed",
                            failure=" ".join(str(err).split()) or type(err).__name__)
    errors = rms = None
    if truth is not None:
        errors = shape_error_to_surface(m.nodes, truth.specimen)
        rms = float(np.sqrt(np.mean(errors ** 2)))
    spline = values = spline_std = None
    if spec.name == "georeg" and m.ok:
        level = solver.level(spec.scales[-1])
        spline, values = measured_spline(solver, m.q, level)
        if m.state is not None and m.noise is not None:
            spline_std = measured_spline_std(solver, m.state.H, m.noise.variance, level)
    chosen = getattr(solver, "chosen_lengths_mm", None)
    return MethodResult(spec=spec, measurement=m, mesh=model.mesh,
                        distance_to_bfp_mm=best_fit_plane_distance(m.nodes),
                        shape_rms_error_mm=rms, spline=spline, spline_values=values,
                        status="ok" if m.ok else "failed", failure=m.failure,
                        shape_error_mm=errors, level_search=search, spline_std=spline_std,
                        regularization={"tikhonov_length_mm": {int(k): float(v) for k, v in
                                                               chosen.items()}} if chosen else None,
                        element_face=model.element_face, face_names=model.face_names)


def run_methods(config: Config, specs: Sequence[MethodSpec], *, images=None,
                truth: Truth | None = None, progress: bool = False) -> RunResult:
    """Measure the shape with each method of ``specs`` on the same images.

    A method that fails (its measurement judged untrustworthy, or an error inside it) is
    marked failed and the others go on; wrong inputs (sizes, visibility, the mesh) stop
    the run.

    Parameters
    ----------
    config : the run's configuration (images, cameras, geometry, method).
    specs : the methods (see :func:`default_specs`).
    images : the two images, if already loaded (else read from ``config.images``).
    truth : the known surface and cameras of a synthetic run (for the errors).
    progress : show a progress bar of the scales of each method (tqdm).
    """
    started = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    if images is None:
        images = tuple(read_image(path, prefilter_px=config.method.prefilter_px,
                                  order=config.method.interpolation_order)
                       for path in (config.images.cam0, config.images.cam1))
    check_sizes(config, images)
    cameras = load_cameras(config.cameras, images)
    method = config.method
    model = build_model(config.geometry, method.fixed_levels)
    check_levels(model, method.fixed_levels, config.geometry)
    occluders = scene_occluders(config.geometry) if method.self_occlusion else None
    logger.info("nominal model: %s, %d Q9 nodes, %d elements%s", config.geometry.kind,
                model.mesh.n_nodes, model.mesh.n_elements,
                "" if occluders is None else f", {len(occluders)} occluder triangles")
    results = []
    for k, spec in enumerate(specs, start=1):
        logger.info("method %d of %d: %s ...", k, len(specs), spec.label)
        with tqdm(total=len(spec.scales), desc=f"{k}/{len(specs)} {spec.label}", unit="scale",
                  disable=not progress, leave=False) as bar:
            def on_scale(done: int, total: int, report) -> None:
                bar.set_postfix(residual=f"{report.residual_percent:.2f}%")
                bar.update(1)
            result = _measure_one(spec, model, images, cameras, config, truth, on_scale, occluders)
        results.append(result)
        m = result.measurement
        if m is not None:
            error = result.shape_rms_error_mm
            logger.info("%s: %s, residual %.3f%% (noise floor %.3f%%), %d iterations, %.1f s%s",
                        spec.label, result.status, m.residual_percent, m.noise_percent,
                        m.iterations, m.time_s, "" if error is None else f", error {error * 1e3:.2f} um")
    return RunResult(results=tuple(results), truth_available=truth is not None,
                     images=tuple(im.values for im in images),
                     one_fine_iteration_s=_one_fine_iteration_s(results), config=config,
                     inputs=input_files(config), version=installed_version(), started=started)


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
    0.5 degree and 0.5 mm (the fixed point must find it). They are written to a temporary
    folder (the output folder only receives the results) that belongs to the returned
    ``config.cameras`` (shared by copies such as ``config.with_output_dir``): it is removed
    when that is no longer referenced (at the end of the run), at the latest at exit.
    """
    cams = demo_cameras(image_size=DEMO["image_size"], stereo_angle_deg=DEMO["stereo_angle_deg"],
                        field_mm=DEMO["field_mm"])
    specimen = dataclasses.replace(demo_specimen(), speckle_mm=speckle_mm_for(cams[0], 4.0))
    arrays = render_stereo(specimen, cams, supersample=3, noise_std=DEMO["noise_std"], seed=11,
                           progress=logger.isEnabledFor(logging.INFO) and sys.stderr.isatty())
    method = MethodConfig()
    images = tuple(Image.from_array(a, source=f"demo cam{k}", prefilter_px=method.prefilter_px,
                                    order=method.interpolation_order) for k, a in enumerate(arrays))
    rotation = np.radians(DEMO["pose_error_deg"]) * np.array([0.6, -0.48, 0.64])
    translation = DEMO["pose_error_mm"] * np.array([0.48, 0.64, -0.6])
    initial = move_cameras_with_specimen(cams, translation, rotation, np.zeros(3))
    inputs = Path(tempfile.mkdtemp(prefix="georeg_demo_"))
    try:
        write_cameras_json(inputs / "cameras.json", initial)
    except BaseException:
        shutil.rmtree(inputs, ignore_errors=True)
        raise
    config = Config(
        images=ImagesConfig(cam0=inputs / "cam0 (rendered in memory)", cam1=inputs / "cam1 (rendered in memory)"),
        cameras=CamerasConfig(file=inputs / "cameras.json"),
        geometry=GeometryConfig(kind="plate_with_hole", length_mm=DEMO["view_mm"],
                                width_mm=DEMO["width_mm"], hole_radius_mm=DEMO["hole_radius_mm"]),
        method=method,
        output=OutputConfig(dir=Path(out_dir)),
        source=inputs / "demo (embedded)")
    weakref.finalize(config.cameras, shutil.rmtree, inputs, ignore_errors=True)  # kept by copies
    return config, images, Truth(specimen=specimen, cameras=tuple(cams))
