"""The science of ``georeg track``: a displacement field per deformed stereo pair.

The reference is frame 0: the measured surface and calibrated cameras of the reference pair
(``[images]``), either measured here first (as ``georeg measure`` does) or read from a
``georeg measure`` output folder (``[reference]``). Each frame of ``[series]`` is then
correlated with the reference pair (:func:`fesdic_core.displacement.driver.measure_displacement`):
the displacement of every node of the reference surface, its surface Green-Lagrange strain
and the residual. With ``incremental = true`` a frame starts from the field of the last
frame that succeeded (the reference stays frame 0); a frame that fails its checks is marked
and the series goes on from the last good frame.

The reference state (images, quadratures, cameras, operators) is built once
(:class:`SeriesReference`) and, with Dask (:mod:`georeg_app.series.dask`), shipped once to
every worker.
"""
from __future__ import annotations

import copy
import dataclasses
import json
import logging
import time
from pathlib import Path
from typing import Callable, Sequence

import cv2
import numpy as np

from adapters.fesdic_core import NominalModel, component_space_for_mesh
from fesdic_core.displacement.driver import (DisplacementReference, DisplacementSettings,
                                      displacement_reference, measure_displacement)
from fesdic_core.displacement.solvers import ComponentTikhonovSolver, componentwise
from fesdic_core.displacement.strain import surface_green_lagrange
from fesdic_core.imaging.image import Image, read_image
from fesdic_core.fe.mesh import SurfaceMesh
from fesdic_core.fe.mesh_io import read_mesh
from fesdic_core.cameras.rig import read_cameras_json
from fesdic_core.solve.solvers import CachedFactorization, DirectSolver
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.io.spline_io import read_spline_json

from georeg_app.config.measure import Config, OutputConfig
from georeg_app.config.track import TrackConfig

logger = logging.getLogger(__name__)

__all__ = ["SeriesReference", "FrameResult", "TrackRun", "load_reference", "check_frames",
           "displacement_solver",
           "series_reference", "measure_frame", "run_series", "run_track"]


@dataclasses.dataclass(frozen=True, eq=False)
class SeriesReference:
    """Everything a frame needs, built once: the displacement reference (surface, cameras,
    reference pyramids and quadratures, with ``jacobian = "reference"`` the reference
    Jacobian and H of each scale) and the step solver's prototype (copied per frame: a
    Tikhonov solver keeps per-scale state; a :class:`CachedFactorization`, the modified
    Gauss-Newton's, is shared: its factors of the reference's H serve every frame)."""

    displacement: DisplacementReference
    solver: object | None
    prefilter_px: float
    label: str
    interpolation_order: int = 3
    element_face: np.ndarray | None = None       # a CAD part's face of each element


@dataclasses.dataclass(frozen=True, eq=False)
class FrameResult:
    """One deformed pair's outcome (``U``, ``strain``, ``residual_node``: None if the frame
    raised before any field; ``failure``: None for a trusted field)."""

    index: int
    cam0: str
    cam1: str
    U: np.ndarray | None
    strain: np.ndarray | None
    residual_node: np.ndarray | None
    residual_percent: float
    noise_percent: float
    iterations: int
    converged: bool
    failure: str | None
    time_s: float
    start_frame: int

    @property
    def ok(self) -> bool:
        return self.failure is None


@dataclasses.dataclass(frozen=True, eq=False)
class TrackRun:
    config: TrackConfig
    mesh: SurfaceMesh
    frames: tuple
    reference_label: str
    scheduler: str
    time_s: float
    element_face: np.ndarray | None = None       # a CAD part's face of each element


# ----------------------------------------------------------------------------- reference
def _reference_images(config: TrackConfig) -> tuple[Image, Image]:
    prefilter, order = config.method.prefilter_px, config.method.interpolation_order
    return tuple(read_image(p, prefilter_px=prefilter, order=order) for p in (config.images.cam0,
                                                                               config.images.cam1))


def load_reference(config: TrackConfig, progress: bool = False
                   ) -> tuple[SurfaceMesh, tuple, tuple, NominalModel | None, str]:
    """The reference surface, calibrated cameras, reference images, the spline model (for
    the georeg displacement) and a label saying where they come from."""
    images = _reference_images(config)
    if config.reference is not None:
        ref = config.reference
        mesh = read_mesh(ref.mesh)
        cameras = tuple(read_cameras_json(ref.cameras))
        model = None
        if ref.spline is not None:
            if "faces" in json.loads(Path(ref.spline).read_text()):
                raise ValueError(f"{ref.spline}: the reference is a part of several faces, which "
                                 "a [reference] folder does not rebuild (its nodes' face "
                                 "parameters are not saved); give the part's [geometry] "
                                 '(kind = "cad") and its [cameras] instead, without [reference], '
                                 "to measure the reference shape in the run")
            model = NominalModel(patch=read_spline_json(ref.spline), mesh=mesh, uv=None)
        return mesh, cameras, images, model, f"{ref.dir} ({ref.label})"
    from georeg_app.shape.methods import measure_specs
    from georeg_app.shape.pipeline import build_model, run_methods
    shape_config = Config(images=config.images, cameras=config.cameras, geometry=config.geometry,
                          method=config.method, output=OutputConfig(config.output.dir),
                          source=config.source)
    specs = measure_specs(shape_config)[:1]
    logger.info("reference shape: %s on the reference pair", specs[0].label)
    run = run_methods(shape_config, specs, images=images, progress=progress)
    result = run.results[0]
    if not result.ok:
        raise RuntimeError(f"the shape measurement of the reference pair failed "
                           f"({result.spec.label}): {result.failure}")
    m = result.measurement
    mesh = result.mesh.with_nodes(np.asarray(m.nodes, float))
    nominal = build_model(config.geometry, config.method.fixed_levels)
    model = dataclasses.replace(nominal, mesh=mesh)        # a part keeps its faces
    return mesh, tuple(m.cameras), images, model, f"measured here ({result.spec.label})"


def displacement_solver(method: str, mesh: SurfaceMesh, model: NominalModel | None = None,
                        tikhonov_length_mm: float = 10.0, levels: int = 2):
    """The step solver of a displacement method on the node-major dofs: None (plain FE),
    Tikhonov on each component, or the spline levels of ``model`` on each component
    (``kron(C_s, I3)``, image scale s -> level min(s, levels - 1))."""
    if method == "fe":
        return None
    if method == "tikhonov":
        return ComponentTikhonovSolver(mesh, tikhonov_length_mm)
    if method != "georeg":
        raise ValueError(f"unknown displacement method {method!r}")
    if model is None:
        raise ValueError("[displacement] method = \"georeg\" needs the spline of the reference")
    space = component_space_for_mesh(model, levels)
    vector_space = dataclasses.replace(space, operators=tuple(componentwise(C)
                                                              for C in space.operators),
                                       refinement=(), gluing=())
    return GeometricRegularization(vector_space)


def check_frames(config: TrackConfig, size: tuple[int, int]) -> None:
    """Refuse, before any computing, a frame that cannot be read or whose size (h, w)
    differs from the reference pair's (the error names the file)."""
    for k, (p0, p1) in enumerate(zip(config.series.cam0, config.series.cam1), start=1):
        for path in (p0, p1):
            a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if a is None:
                raise ValueError(f"frame {k}: cannot read image file {path} (not an image "
                                 "OpenCV can decode)")
            if tuple(a.shape[:2]) != tuple(size):
                raise ValueError(f"frame {k}: {path} is {a.shape[1]} x {a.shape[0]} px but the "
                                 f"reference images are {size[1]} x {size[0]} px")


def series_reference(config: TrackConfig, progress: bool = False) -> SeriesReference:
    """Load or measure the reference and build the displacement reference and solver."""
    mesh, cameras, images, model, label = load_reference(config, progress)
    d = config.displacement
    settings = DisplacementSettings(scales=d.scale_sequence,
                                    normalisation=config.method.normalisation,
                                    jacobian=d.jacobian)
    reference = displacement_reference(mesh, images, cameras, settings)
    solver = displacement_solver(d.method, mesh, model, d.tikhonov_length_mm, d.levels)
    if d.jacobian == "reference":      # H of each scale factorized once for the whole series
        solver = CachedFactorization(DirectSolver() if solver is None else solver)
    return SeriesReference(displacement=reference, solver=solver,
                           prefilter_px=config.method.prefilter_px, label=label,
                           interpolation_order=config.method.interpolation_order,
                           element_face=None if model is None else model.element_face)


# ----------------------------------------------------------------------------- frames
def measure_frame(reference: SeriesReference, index: int, paths: Sequence[Path],
                  U0: np.ndarray | None, start_frame: int) -> FrameResult:
    """Measure one deformed pair (a plain function of picklable arguments: a Dask task).
    An error inside the measurement marks the frame failed instead of raising."""
    t0 = time.perf_counter()
    names = [str(p) for p in paths]
    try:
        images = [read_image(p, prefilter_px=reference.prefilter_px, order=reference.interpolation_order)
                  for p in paths]
        solver = copy.deepcopy(reference.solver)
        m = measure_displacement(reference.displacement, images, solver, U0)
    except (ArithmeticError, RuntimeError, ValueError, np.linalg.LinAlgError) as err:
        failure = " ".join(str(err).split()) or type(err).__name__
        logger.info("frame %d failed: %s", index, failure)
        return FrameResult(index, names[0], names[1], None, None, None, float("nan"),
                           float("nan"), 0, False, failure, time.perf_counter() - t0, start_frame)
    mesh = reference.displacement.mesh
    return FrameResult(index=index, cam0=names[0], cam1=names[1], U=m.U,
                       strain=surface_green_lagrange(mesh, m.U),
                       residual_node=m.node_residual_percent(),
                       residual_percent=float(m.residual_percent),
                       noise_percent=float(m.noise_percent), iterations=int(m.iterations),
                       converged=bool(m.converged), failure=m.failure,
                       time_s=time.perf_counter() - t0, start_frame=start_frame)


def _log_frame(frame: FrameResult, total: int) -> None:
    if frame.ok:
        mean = np.mean(frame.U, axis=0) * 1e3
        logger.info("frame %d of %d: residual %.3f%% (noise floor %.3f%%), mean displacement "
                    "(%.1f, %.1f, %.1f) um, %d iterations, %.1f s", frame.index, total,
                    frame.residual_percent, frame.noise_percent, *mean, frame.iterations,
                    frame.time_s)
    else:
        logger.warning("frame %d of %d FAILED: %s", frame.index, total, frame.failure)


def run_series(reference: SeriesReference, frames: Sequence[tuple[Path, Path]],
               incremental: bool, on_frame: Callable[[FrameResult], None] | None = None
               ) -> list[FrameResult]:
    """The frames in order, in this process. ``incremental``: each frame starts from the
    field of the last frame that succeeded (frame 0, the reference: zero)."""
    results, last_good, last_index = [], None, 0
    for index, paths in enumerate(frames, start=1):
        U0 = last_good if incremental else None
        frame = measure_frame(reference, index, paths, U0, last_index if incremental else 0)
        if frame.ok:
            last_good, last_index = frame.U, index
        results.append(frame)
        if on_frame is not None:
            on_frame(frame)
    return results


def run_track(config: TrackConfig, scheduler: str = "serial", progress: bool = False,
              workers: int | None = None) -> TrackRun:
    """Run the whole series: reference, frames (serially or over Dask), in order."""
    from tqdm.auto import tqdm
    t0 = time.perf_counter()
    reference = series_reference(config, progress)
    check_frames(config, reference.displacement.images[0].shape)
    frames = list(zip(config.series.cam0, config.series.cam1))
    logger.info("reference: %s; %d nodes; %d frames, displacement method %s, scales %s, %s",
                reference.label, reference.displacement.mesh.n_nodes, len(frames),
                config.displacement.method, config.displacement.scale_sequence,
                "incremental" if config.displacement.incremental else "each from rest")
    with tqdm(total=len(frames), desc="frames", unit="frame", disable=not progress) as bar:
        def on_frame(frame: FrameResult) -> None:
            _log_frame(frame, len(frames))
            bar.update(1)
        if scheduler == "serial":
            results = run_series(reference, frames, config.displacement.incremental, on_frame)
        else:
            from georeg_app.series.dask import run_series_dask
            results = run_series_dask(reference, frames, config.displacement.incremental,
                                      scheduler, on_frame, workers=workers)
    return TrackRun(config=config, mesh=reference.displacement.mesh, frames=tuple(results),
                    reference_label=reference.label, scheduler=scheduler,
                    time_s=time.perf_counter() - t0, element_face=reference.element_face)
