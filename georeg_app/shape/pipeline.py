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
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from tqdm.auto import tqdm

from adapters.fesdic_core import NominalModel, georeg_solver, measured_spline, measured_spline_std
from adapters.level_search import LevelSearch, measure_auto_levels
from fesdic_core.fe.mesh import MeshError, SurfaceMesh
from fesdic_core.imaging.image import Image, read_image
from fesdic_core.shape.driver import (Measurement, MeasurementInputError, MeasurementSettings,
                                      check_scales, measure)
from fesdic_core.shape.gauge import best_fit_plane_distance
from fesdic_core.solve.tikhonov import TikhonovSolver
from fesdic_core.synthetic.accuracy import shape_error_to_surface
from georeg_plugin.spline.patch import SplinePatch

from georeg_app.config.measure import AUTO, Config, GeometryConfig
from georeg_app.errors import InputError
from georeg_app.inputs.cameras import load_cameras
from georeg_app.inputs.nominal import (MIN_PX_PER_ELEMENT, coarse_faces, refinements,
                                      specimen_setup)
from georeg_app.inputs.placement import placement_check
from georeg_app.shape.demo import Truth
from georeg_app.shape.methods import MethodSpec
from georeg_app.shape.visibility import scene_occluders, visibility_settings
from georeg_app.version import installed_version

logger = logging.getLogger(__name__)

__all__ = ["MethodResult", "RunResult", "check_sizes", "describe_mesh", "check_levels", "input_files",
           "run_methods"]


@dataclasses.dataclass(frozen=True, eq=False)
class MethodResult:
    """One method's outcome. ``status`` is "ok" or "failed"; a failed method says why in
    ``failure`` and carries its (untrusted) measurement, or None if it gave no state at all.
    ``shape_error_mm``: per-node distance to the true surface after the best rigid
    alignment (None without a truth). ``level_search``: the record of georeg's automatic
    level choice; ``spline_std``: the standard deviation of the measured spline's control
    values (mm); ``regularization``: what the method chose (Tikhonov lengths per scale).
    A part of several faces (``[geometry] kind = "cad"``): ``spline`` is a tuple of patches
    (one per face), ``element_face`` each element's face, ``face_names`` their names.
    ``dropped_dofs``: georeg's spline levels solved at, level -> the counts of
    :class:`~georeg_plugin.levels.support.LevelSupport` (dofs outside the mesh's outline or
    seen by no integration point, removed; slivers). ``nominal``: the nominal model measured
    (a part's faces and its nodes' face parameters go to the outputs: a folder that
    ``georeg track`` takes as ``[reference]``)."""

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
    dropped_dofs: dict | None = None
    nominal: NominalModel | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@dataclasses.dataclass(frozen=True, eq=False)
class RunResult:
    """All methods of a run, with what produced them (config, input checksums, version);
    ``specimen``: for ``[geometry] kind = "roi"``, the specimen frame in the calibration's
    frame and the surface fit (:meth:`georeg_app.inputs.roi.RoiSpecimen.summary`); for a CAD
    part with a ``pose``, the pose the ICP found
    (:meth:`georeg_app.inputs.cad_pose.CadPose.summary`)."""

    results: tuple
    truth_available: bool
    images: tuple
    one_fine_iteration_s: float
    config: Config | None = None
    inputs: tuple = ()
    version: str = "unknown"
    started: str = ""
    specimen: dict | None = None      # kind "roi": the frame and the fit; "cad" + pose: the pose


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
        raise InputError(f"[method] scales = {config.method.scales}: {err}") from None
    if config.geometry.kind in ("mesh", "roi"):      # sizes known once the mesh is built
        return
    levels = config.method.fixed_levels
    coarse = sum(int(np.prod(f.n_elements)) for f in coarse_faces(config.geometry))
    asked = config.geometry.elements
    if asked is not None and coarse * 4 ** (levels - 1) > 2 * asked:
        raise InputError(
            f"[geometry] elements = {asked}: {levels} spline levels need an FE mesh of at least "
            f"{coarse * 4 ** (levels - 1)} elements (each level halves the knot spans of the "
            f"next); ask for more elements or fewer levels")
    elements = coarse * 4 ** refinements(config.geometry, levels)
    if elements > (w * h) / MIN_PX_PER_ELEMENT:
        largest = max(1, int(math.log((w * h) / MIN_PX_PER_ELEMENT / coarse, 4)) + 1)
        raise InputError(
            f"[method] levels = {levels} with [geometry] elements = {config.geometry.elements}: "
            f"the FE mesh would have {elements} elements, more than the {w} x {h} px images "
            f"can measure (at least {MIN_PX_PER_ELEMENT} px an element); use at most "
            f"{largest} levels")


def describe_mesh(kind: str, mesh: SurfaceMesh) -> str:
    """``"<kind>, <n> <family> nodes, <m> elements"``, the mesh's real element families
    (``Q4``, ``Q9``, ``T3/Q4`` for a mixed mesh)."""
    families = "/".join(sorted({b.family.name for b in mesh.blocks}))
    return f"{kind}, {mesh.n_nodes} {families} nodes, {mesh.n_elements} elements"


def check_levels(model: NominalModel, levels: int, geometry: GeometryConfig) -> None:
    """Refuse spline levels whose finest one has more dofs than the FE mesh has nodes
    (the projection ``C H C^T`` would be singular, and the operators needlessly large)."""
    k = 2 ** (levels - 1)
    dofs = sum((p.n_elements[0] * k + p.degrees[0]) * (p.n_elements[1] * k + p.degrees[1])
               for p in model.patches)
    if dofs > model.mesh.n_nodes:
        where = f"[geometry] file = {geometry.file}" if geometry.file else "[geometry]"
        raise InputError(f"[method] levels = {levels}: the finest spline level would have {dofs} "
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
                                   coupling=method.coupling,
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
                            failure=" ".join(str(err).split()) or type(err).__name__,
                            nominal=model)
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
    supports = getattr(solver, "supports", None)
    dropped = {str(level): v.as_dict() for level, v in sorted(supports.items())} \
        if supports else None
    return MethodResult(spec=spec, measurement=m, mesh=model.mesh,
                        distance_to_bfp_mm=best_fit_plane_distance(m.nodes),
                        shape_rms_error_mm=rms, spline=spline, spline_values=values,
                        status="ok" if m.ok else "failed", failure=m.failure,
                        shape_error_mm=errors, level_search=search, spline_std=spline_std,
                        regularization={"tikhonov_length_mm": {int(k): float(v) for k, v in
                                                               chosen.items()}} if chosen else None,
                        element_face=model.element_face, face_names=model.face_names,
                        dropped_dofs=dropped, nominal=model)


def run_methods(config: Config, specs: Sequence[MethodSpec], *, images=None,
                truth: Truth | None = None,
                progress: bool | Callable[[str, int, int], None] = False) -> RunResult:
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
    progress : True: a progress bar of the scales of each method (tqdm); a callable:
        ``progress(label, done, total)`` after each scale of the method ``label``.
    """
    started = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    if images is None:
        images = tuple(read_image(path, prefilter_px=config.method.prefilter_px,
                                  order=config.method.interpolation_order)
                       for path in (config.images.cam0, config.images.cam1))
    check_sizes(config, images)
    cameras = load_cameras(config.cameras, images)
    method = config.method
    model, cameras, roi = specimen_setup(config.geometry, method.fixed_levels, cameras, images)
    check_levels(model, method.fixed_levels, config.geometry)
    occluders = scene_occluders(config.geometry) if method.self_occlusion else None
    logger.info("nominal model: %s%s", describe_mesh(config.geometry.kind, model.mesh),
                "" if occluders is None else f", {len(occluders)} occluder triangles")
    if config.geometry.kind != "roi":            # an ROI is placed by the rig itself
        placement_check(model.mesh, cameras, images)   # a loud warning if they disagree
    results = []
    for k, spec in enumerate(specs, start=1):
        logger.info("method %d of %d: %s ...", k, len(specs), spec.label)
        with tqdm(total=len(spec.scales), desc=f"{k}/{len(specs)} {spec.label}", unit="scale",
                  disable=progress is not True, leave=False) as bar:
            def on_scale(done: int, total: int, report, label: str = spec.label) -> None:
                bar.set_postfix(residual=f"{report.residual_percent:.2f}%")
                bar.update(1)
                if callable(progress):
                    progress(label, done, total)
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
                     inputs=input_files(config), version=installed_version(), started=started,
                     specimen=None if roi is None else roi.summary())


