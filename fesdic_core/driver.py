"""The drivers: fixed point of section 2.2 inside the multiscale loop of Remark 3.

For each image scale ``s``, coarse to fine (the solution of scale ``s`` starts scale
``s - 1``):

    repeat until (p, q) stagnate:                    (fixed point, section 2.2)
        p <- argmin_p j(S, p)      calibration, Eq. 6 (if asked)
        q <- argmin_q j(L^T q, p)  shape, Eq. 7, each step by the StepSolver hook
        gauge: rigid normal part of q -> camera poses (if calibrating; see gauge.py)

Scale ``s`` uses the images aggregated ``s`` times (2x2 pixel means) and the matching
cameras; the step solver is told ``s`` so that it can regularize accordingly.

A measurement is trusted only if, at the finest scale, the gray-level residual is
consistent with the images' own noise (:mod:`fesdic_core.noise`), the shape stayed
bounded and the fixed point stagnated; otherwise :attr:`Measurement.failure` says what
failed and by how much, and :func:`measure` does not call it converged.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from .calibration import calibrate_extrinsics
from .edges import DEFAULT_EDGE_MARGIN_PX, edge_margin_mask
from .gauge import (pose_directions, rigid_normal_modes, tangential_motions,
                    transfer_rigid_part)
from .image import Image, pyramid
from .mesh import SurfaceMesh, nodal_areas, node_normals, validate_mesh
from .noise import CONSISTENCY_FACTOR, MIN_TEXTURE_RATIO, residual_noise_floor
from .quadrature import PixelQuadrature, pixel_quadrature
from .residual import NORMALISATIONS, GrayLevelResidual, gray_level_residual
from .rig import stereo_transform
from .shape import (GaussNewtonLog, ShapeResult, chi_square_change, current_nodes,
                    shape_gauss_newton)
from .solvers import DirectSolver, StepSolver
from .uncertainty import LinearisedState, NoiseModel, linearised_state, noise_model, shape_std
from .visibility import VisibilitySettings, visibility_mask

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class MeasurementSettings:
    """How to run a measurement.

    scales : image scales coarse to fine, e.g. (2, 1, 0); 0 is the full resolution.
    calibrate : run the fixed point with calibration of the extrinsics (Eq. 6).
    tol_mm, fixed_point_tol_mm : stagnation of q at scale 0 (mm); at scale s they are
        multiplied by 2**s (a coarse pixel is 2**s fine pixels).
    fixed_point_tol_px : stagnation of the poses: largest shift of the projected nodes
        between two fixed-point iterations, in pixels of the current scale. The fixed point
        has also stagnated when two iterations fit the images equally well (chi-square
        changes by less than 1, :func:`~fesdic_core.shape.chi_square_change`): p and q
        then move within their own noise; and when the calibration of a later iteration
        takes no step (its step is stagnant before it is evaluated), since the shape that
        ended the previous iteration already sits at its optimum for these poses. The
        calibration inside the fixed point does not damp a step that would move the points
        by less than ``fixed_point_tol_px``: if that step does not lower the residual, the
        poses have stagnated (such a step cannot change the fixed point's verdict).
    fixed_point_rtol : at a coarse scale (not the finest), the shape Gauss-Newton and the
        fixed point also hand over to the next scale when the residual falls by less than
        this fraction in an iteration (a coarse scale only starts the next, Remark 3); at
        the finest scale only the stagnation of p and q ends them.
    keep_stereo : when calibrating, keep the stereo relation of the initial cameras
        (6 unknowns) instead of freeing both cameras (12 unknowns).
    consistency_factor : the final residual may be at most this many times the noise
        floor of the images (:data:`fesdic_core.noise.CONSISTENCY_FACTOR`).
    max_shape_fraction : the correction may reach at most this fraction of the mesh's
        diagonal; a larger one is a diverged measurement (checked at the end of every scale:
        a coarse scale beyond it raises :class:`ShapeDivergedError`).
    uncertainty : at the end, estimate the noise model and the shape's standard deviation
        and bias indicator (:mod:`fesdic_core.uncertainty`); costs about two Gauss-Newton
        iterations at the finest scale.
    edge_margin_px : at the finest scale of ``scales``, leave out the points that project
        within this many pixels (of the full-resolution images, scaled to that scale) of the
        mesh's boundary in either camera, where the image model mixes the speckle with what
        lies beyond the edge (:mod:`fesdic_core.edges`); 0 keeps them. The coarser scales
        keep every point: they only start the next scale, and their elements are a few
        pixels wide, so a margin there took most of a boundary element's points and threw
        the boundary nodes of plain FE off by tenths of a millimetre.
    visibility : at every scale, leave out the points that either camera does not see on
        the current surface (self-occlusion, extra occluders, grazing angle;
        :func:`~fesdic_core.visibility.visibility_mask`); None: every point is kept. Combined
        with the ``visibility`` callable of :func:`measure` when both are given.
    """

    scales: tuple[int, ...] = (0,)
    calibrate: bool = False
    keep_stereo: bool = True
    normalisation: str = "element"
    max_fixed_point: int = 10
    max_iter: int = 20
    tol_mm: float = 1e-4
    fixed_point_tol_mm: float = 2e-3
    fixed_point_tol_px: float = 1e-2
    fixed_point_rtol: float = 1e-4
    points_per_px: float = 1.0
    consistency_factor: float = CONSISTENCY_FACTOR
    max_shape_fraction: float = 0.25
    uncertainty: bool = True
    edge_margin_px: float = DEFAULT_EDGE_MARGIN_PX
    visibility: VisibilitySettings | None = None

    def __post_init__(self):
        if not self.scales or any(int(s) != s or s < 0 for s in self.scales):
            raise ValueError(f"scales must be non-negative integers, got {self.scales!r}")
        if list(self.scales) != sorted(self.scales, reverse=True):
            raise ValueError(f"scales must go coarse to fine (decreasing), got {self.scales!r}")
        if self.normalisation not in NORMALISATIONS:
            raise ValueError(f"normalisation must be one of {NORMALISATIONS}, got {self.normalisation!r}")
        if not self.edge_margin_px >= 0:
            raise ValueError(f"edge_margin_px must be >= 0, got {self.edge_margin_px!r}")
        if self.visibility is not None and not isinstance(self.visibility, VisibilitySettings):
            raise ValueError(f"visibility must be a VisibilitySettings or None, got "
                             f"{self.visibility!r}")


@dataclass(frozen=True)
class ScaleReport:
    """How one image scale ended.

    ``shape_converged``: the last shape Gauss-Newton stopped before its iteration limit (q
    stagnated; at a coarse scale, or the residual did); ``fixed_point_converged``: the
    fixed point likewise (p and q; True when not calibrating); ``noise_percent``: the
    residual the images' noise explains at this scale (:mod:`fesdic_core.noise`).
    """

    scale: int
    residual_percent: float
    noise_percent: float
    fixed_point_iterations: int
    shape_converged: bool
    fixed_point_converged: bool
    n_points: int

    @property
    def converged(self) -> bool:
        return self.shape_converged and self.fixed_point_converged


@dataclass(frozen=True)
class Measurement:
    """Result of a shape measurement (world coordinates of the final cameras, mm).

    ``failure``: None for a trusted measurement, else one line saying what failed and by
    how much (residual against the noise floor, an unbounded shape, no stagnation at the
    finest scale). ``converged``: no failure and every scale stagnated (a coarse scale
    that stopped on its iteration limit only starts the next one, Remark 3, but is
    reported here). ``scales``: one :class:`ScaleReport` per scale, coarse to fine.
    """

    q: np.ndarray
    nodes: np.ndarray
    normals: np.ndarray
    cameras: tuple
    residual: GrayLevelResidual
    quadrature: PixelQuadrature
    history: tuple = field(repr=False)
    iterations: int = 0
    time_s: float = 0.0
    converged: bool = True
    noise_percent: float = float("nan")
    failure: str | None = None
    scales: tuple = ()
    shape_std_mm: np.ndarray | None = field(default=None, repr=False)
    shape_bias_mm: np.ndarray | None = field(default=None, repr=False)
    noise: NoiseModel | None = None
    state: LinearisedState | None = field(default=None, repr=False)

    @property
    def residual_percent(self) -> float:
        return self.residual.std_percent

    @property
    def ok(self) -> bool:
        """True when the measurement can be trusted (``failure`` is None)."""
        return self.failure is None


#: a rigid normal part of q below this (mm) is round-off: left in q, not handed to the poses
#: (the state, and the residual evaluated there, stay as they are)
_NO_RIGID_PART_MM = 1e-10


class MeasurementInputError(ValueError):
    """Inputs of a measurement that do not fit together (sizes, visibility)."""


def check_inputs(mesh: SurfaceMesh, images: Sequence[Image], cameras: Sequence) -> None:
    """Raise :class:`MeasurementInputError` naming the image or camera at fault.

    The mesh is validated too (:class:`~fesdic_core.mesh.MeshError` names a degenerate or
    inverted element).
    """
    validate_mesh(mesh)
    if len(images) != 2 or len(cameras) != 2:
        raise MeasurementInputError(f"a stereo pair needs 2 images and 2 cameras, got "
                                    f"{len(images)} and {len(cameras)}")
    if images[0].shape != images[1].shape:
        raise MeasurementInputError(
            f"images of different sizes in one stereo pair: {images[0].source} is "
            f"{images[0].shape[1]} x {images[0].shape[0]} px, {images[1].source} is "
            f"{images[1].shape[1]} x {images[1].shape[0]} px")
    models = [(getattr(im, "prefilter_px", 0.0), getattr(im, "order", 3)) for im in images]
    if models[0] != models[1]:                   # the residual compares the two interpolants
        raise MeasurementInputError(
            f"images of different image models in one stereo pair: {images[0].source} has "
            f"prefilter_px {models[0][0]:g}, order {models[0][1]}; {images[1].source} has "
            f"prefilter_px {models[1][0]:g}, order {models[1][1]}")
    for image, cam in zip(images, cameras):
        w, h = cam.image_size
        if (h, w) != tuple(image.shape):
            raise MeasurementInputError(
                f"{image.source}: image is {image.shape[1]} x {image.shape[0]} px but camera "
                f"{cam.name} expects {w} x {h} px")
        x = cam.project(mesh.nodes)
        seen = cam.in_front(mesh.nodes) & image.inside(x)
        if not np.any(seen):
            raise MeasurementInputError(
                f"mesh {mesh.name!r} projects entirely outside {image.source} (camera {cam.name}): "
                "check the camera poses (landmarks) and the mesh units (mm)")


def _report_coverage(quad: PixelQuadrature, res: GrayLevelResidual, scale: int) -> None:
    """Log the integration points outside an image, and elements left without any."""
    if res.n_dropped:
        logger.info("scale %d: %d of %d integration points fall outside an image (or are masked)"
                    " and are dropped", scale, res.n_dropped, quad.n_points)
    seen = quad.element_sum(res.mask.astype(float))
    empty = np.flatnonzero(seen == 0)
    if empty.size:
        logger.warning("scale %d: %d element(s) lost all their integration points (first: %s); "
                       "their nodes are held by the neighbours or the regularization",
                       scale, empty.size, ", ".join(map(str, empty[:5])))


def _projected_shift_px(cameras_a, X_a: np.ndarray, cameras_b, X_b: np.ndarray) -> float:
    """Largest move (px) of the nodes' images between two states (cameras, node positions).

    Gauge invariant: a rigid motion handed from q to the poses moves neither image.
    """
    return max(float(np.max(np.linalg.norm(a.project(X_a) - b.project(X_b), axis=1)))
               for a, b in zip(cameras_a, cameras_b))


def check_scales(images: Sequence[Image], scales: Sequence[int], min_px: int = 32) -> None:
    """Raise :class:`MeasurementInputError` if the coarsest scale leaves too small an image."""
    h, w = images[0].shape
    s = max(scales)
    if min(h, w) >> s < min_px:
        raise MeasurementInputError(
            f"image scale {s} is too coarse for {images[0].source} ({w} x {h} px): the coarsest "
            f"image would be {w >> s} x {h >> s} px after {s} halvings, at least {min_px} px a "
            f"side are needed; use at most {max(0, int(np.log2(min(h, w) / min_px)))} halvings")


def check_texture(X: np.ndarray, mask: np.ndarray, images: Sequence[Image], cameras: Sequence) -> None:
    """Raise :class:`MeasurementInputError` if an image shows no texture above its noise
    over the region the points ``X`` cover (full-resolution images and cameras)."""
    floor = residual_noise_floor(X, mask, images, cameras)
    for image, ratio, contrast, sigma in zip(images, floor.texture_ratio(), floor.contrast,
                                             floor.sigma_gray):
        if not ratio >= MIN_TEXTURE_RATIO:
            raise MeasurementInputError(
                f"{image.source}: no texture to correlate over the specimen: contrast "
                f"{contrast:.3g} gray levels against noise {sigma:.3g} (ratio {ratio:.3g}, at least "
                f"{MIN_TEXTURE_RATIO:g} needed): a uniform or pure-noise image, or the wrong image")


class ShapeDivergedError(RuntimeError):
    """The shape left its bounds at a coarse scale: the next scale is not started (its pixel
    quadrature would follow a surface metres wide)."""


def _diverged(q: np.ndarray, nodes: np.ndarray, settings: MeasurementSettings) -> str | None:
    """Why the correction ``q`` is unbounded (``max_shape_fraction`` of the mesh), or None."""
    size = float(np.linalg.norm(np.ptp(nodes, axis=0)))
    largest = float(np.max(np.abs(q))) if q.size else 0.0
    if not np.isfinite(largest) or largest > settings.max_shape_fraction * size:
        return (f"the shape diverged: a correction of {largest:.3g} mm, more than "
                f"{settings.max_shape_fraction:g} of the mesh size ({size:.3g} mm)")
    return None


def judge(residual_percent: float, noise_percent: float, q: np.ndarray, nodes: np.ndarray,
          finest: ScaleReport, settings: MeasurementSettings) -> str | None:
    """Why a measurement cannot be trusted, or None (see the module docstring)."""
    if not np.isfinite(residual_percent):
        return "no integration point is seen by both cameras at the finest scale"
    diverged = _diverged(q, nodes, settings)
    if diverged is not None:
        return diverged
    ratio = residual_percent / noise_percent if noise_percent > 0 else np.inf
    if not ratio <= settings.consistency_factor:
        return (f"the residual {residual_percent:.3g}% is {ratio:.3g} times the {noise_percent:.3g}% "
                f"that the image noise explains (at most {settings.consistency_factor:g}): the "
                "images do not match the surface and cameras (wrong or swapped cameras, wrong "
                "poses or specimen, a wrong minimum, or a regularization too strong for the shape)")
    if not finest.converged:
        what = "shape Gauss-Newton" if not finest.shape_converged else "fixed point"
        return (f"the {what} did not stagnate at the finest scale (scale {finest.scale}) "
                "within its iteration limit")
    return None


def measure(mesh: SurfaceMesh, images: Sequence[Image], cameras: Sequence,
            solver: StepSolver | None = None, settings: MeasurementSettings = MeasurementSettings(),
            q0: np.ndarray | None = None, normals: np.ndarray | None = None,
            visibility: Callable[[np.ndarray, Sequence], np.ndarray] | None = None,
            progress: Callable[[int, int, ScaleReport], None] | None = None) -> Measurement:
    """Measure the shape correction of ``mesh`` from a stereo pair.

    Parameters
    ----------
    mesh : nominal surface mesh (mm, world frame)
    images : the two full-resolution images
    cameras : the two full-resolution cameras (initial poses when calibrating)
    solver : the step solver hook (default :class:`DirectSolver`)
    settings : MeasurementSettings
    q0 : initial correction (default 0)
    normals : nominal node normals (default :func:`node_normals`)
    visibility : optional ``f(X (g,3), cameras) -> bool (g,)``, points to keep (e.g. faces
        hidden from one camera are masked, not fitted)
    progress : optional ``f(k, n, report)`` called after scale ``k`` of ``n`` (1-based)

    Returns
    -------
    Measurement
        Always returned when the inputs fit; check :attr:`Measurement.failure` (or
        :attr:`Measurement.ok`) before trusting it.
    """
    check_inputs(mesh, images, cameras)
    check_scales(images, settings.scales)
    solver = DirectSolver() if solver is None else solver
    normals = node_normals(mesh) if normals is None else normals
    q = np.zeros(mesh.nodes.shape[0]) if q0 is None else np.asarray(q0, float).copy()
    cams = list(cameras)
    stereo = stereo_transform(*cams) if (settings.calibrate and settings.keep_stereo) else None
    pyramids = [pyramid(im, max(settings.scales) + 1) for im in images]
    log = GaussNewtonLog()
    t0 = time.perf_counter()
    node_weights = nodal_areas(mesh)          # positive for every family (T6 corners too)
    total_iterations, reports = 0, []
    result = final = None       # final: the last residual with dr_dX, if at the final state
    for k, scale in enumerate(settings.scales, start=1):
        imgs = [p[scale] for p in pyramids]
        scaled = [c.scaled(scale) for c in cams]
        nodes_now = current_nodes(mesh.nodes, normals, q)
        quad = pixel_quadrature(mesh, scaled, settings.points_per_px, nodes=nodes_now)
        if settings.calibrate:
            slides, centre = tangential_motions(mesh.nodes, normals, node_weights)
        X_now = quad.points(nodes_now)
        mask = None if visibility is None else visibility(X_now, scaled)
        if settings.visibility is not None and settings.visibility.active:   # the current shape
            seen = visibility_mask(mesh, quad, nodes_now, scaled, settings.visibility, X=X_now)
            logger.info("scale %d: %d of %d integration points unseen by a camera (hidden or "
                        "grazing) are left out", scale, seen.size - seen.sum(), seen.size)
            if not seen.all():        # all seen: the mask stays as it was (bit-identical)
                mask = seen if mask is None else mask & seen
        if settings.edge_margin_px > 0 and k == len(settings.scales):   # the finest scale:
            keep = edge_margin_mask(X_now, quad, mesh, nodes_now, scaled,  # the image model's
                                    settings.edge_margin_px / 2.0 ** scale)  # band at the edge
            mask = keep if mask is None else mask & keep
        # the first residual of the scale also starts its first calibration (or shape) step
        first = gray_level_residual(X_now, quad, imgs, scaled, settings.normalisation,
                                    "extrinsic" if settings.calibrate and stereo is None
                                    else "point", mask)
        _report_coverage(quad, first, scale)
        if k == 1:
            check_texture(X_now, first.mask, images, cams)
        noise = residual_noise_floor(X_now, first.mask, imgs, scaled)
        if callable(getattr(solver, "start_scale", None)):      # a solver that chooses from data
            state = linearised_state(mesh.nodes, normals, q, quad, imgs, scaled,
                                     settings.normalisation, mask, residual=first)
            solver.start_scale(scale, noise_model(state, X_now, quad, imgs, scaled, normals,
                                                  noise.sigma_gray, scale, settings.normalisation,
                                                  mask))
        coarse = 2.0 ** scale
        finest = scale == settings.scales[-1]
        fixed_point_converged, previous_residual = not settings.calibrate, np.inf
        previous_fit, known = None, first   # known: the residual at the current state
        for fp in range(1, settings.max_fixed_point + 1):
            context = {"fixed_point": fp}
            q_before, cams_before = q.copy(), list(cams)
            if settings.calibrate:
                X = quad.points(current_nodes(mesh.nodes, normals, q))
                frozen = pose_directions(cams, slides, centre, stereo is not None)
                cal = calibrate_extrinsics(X, quad, imgs, scaled, stereo=stereo, frozen=frozen,
                                           normalisation=settings.normalisation,
                                           max_iter=settings.max_iter, extra_mask=mask,
                                           tol_rad=1e-7 * coarse, tol_mm=1e-5 * coarse,
                                           undamped_px=settings.fixed_point_tol_px,
                                           log=log, context={**context, "scale": scale},
                                           start=known)
                cams = [c.with_extrinsics(s.extrinsics) for c, s in zip(cams, cal.cameras)]
                scaled = [c.scaled(scale) for c in cams]
                known = cal.residual
                if fp > 1 and cal.steps == 0 and shape.converged and known.dr_dX is not None:
                    # the poses did not move: the shape Gauss-Newton that ended the previous
                    # iteration already stagnated at these cameras (up to the gauge), p and q
                    # stagnate (section 2.2); the calibration's residual is the final state's
                    logger.info("scale %d fixed point %d: the poses stagnate at the shape's "
                                "optimum", scale, fp)
                    shape = ShapeResult(q=q, residual=known, iterations=0, converged=True,
                                        stop="fixed point")
                    result, final = (shape.residual, quad), known
                    fixed_point_converged = True
                    break
            shape = shape_gauss_newton(mesh.nodes, normals, q, quad, imgs, scaled, solver, scale,
                                       settings.normalisation, settings.max_iter,
                                       settings.tol_mm * coarse,
                                       residual_rtol=None if finest else settings.fixed_point_rtol,
                                       log=log, extra_mask=mask, context=context,
                                       start=known, keep_derivative=True)
            q, final, known = shape.q, shape.residual, None
            total_iterations += shape.iterations
            result = (shape.residual, quad)
            if not settings.calibrate:
                break
            q_moved, cams_moved = transfer_rigid_part(q, mesh.nodes, normals, node_weights, cams)
            if np.max(np.abs(q_moved - q), initial=0.0) > _NO_RIGID_PART_MM:
                q, cams = q_moved, cams_moved
                final = None                     # the state moved (by the gauge) since
            scaled = [c.scaled(scale) for c in cams]
            X_nodes = current_nodes(mesh.nodes, normals, q)
            dq = float(np.max(np.abs(q - q_before)))
            dp = _projected_shift_px([c.scaled(scale) for c in cams_before],
                                     current_nodes(mesh.nodes, normals, q_before), scaled, X_nodes)
            logger.info("scale %d fixed point %d: residual %.3f%%, max|dq| %.2e mm, pose shift %.2e px",
                        scale, fp, shape.residual.std_percent, dq, dp)
            if dq < settings.fixed_point_tol_mm * coarse and dp < settings.fixed_point_tol_px:
                fixed_point_converged = True                     # p and q stagnate (section 2.2)
                break
            if previous_fit is not None and abs(chi_square_change(previous_fit, shape.residual,
                                                                  quad)) < 1.0:
                logger.info("scale %d: p and q move within their noise (chi-square changes by "
                            "less than 1)", scale)
                fixed_point_converged = True     # the data cannot tell the two states apart
                break
            previous_fit = shape.residual
            residual = shape.residual.std_percent
            if not finest and previous_residual - residual <= settings.fixed_point_rtol * residual:
                logger.info("scale %d: the residual stagnates; the next scale goes on", scale)
                fixed_point_converged = True  # a coarse scale only starts the next (Remark 3)
                break
            previous_residual = residual
        report = ScaleReport(scale=scale, residual_percent=shape.residual.std_percent,
                             noise_percent=noise.percent, fixed_point_iterations=fp,
                             shape_converged=shape.converged,
                             fixed_point_converged=fixed_point_converged,
                             n_points=int(shape.residual.mask.sum()))
        reports.append(report)
        if not report.converged:
            # a coarse scale only starts the next one (Remark 3): said, not warned
            logger.info("scale %d: the %s did not stagnate within its iteration limit", scale,
                        "shape Gauss-Newton" if not shape.converged else "fixed point")
        logger.info("scale %d: residual %.3f%% (noise floor %.3f%%)", scale,
                    report.residual_percent, report.noise_percent)
        diverged = None if finest else _diverged(q, mesh.nodes, settings)
        if diverged is not None:                 # the finest scale's verdict says it (judge)
            raise ShapeDivergedError(f"{diverged} at image scale {scale}; the finer scales "
                                     "were not started")
        if progress is not None:
            progress(k, len(settings.scales), report)
    residual, quad = result
    return conclude(mesh, imgs, cams, solver, settings, q, quad, normals, residual, tuple(reports),
                    noise.sigma_gray, mask=mask, final=final, history=tuple(log.records),
                    iterations=total_iterations, time_s=time.perf_counter() - t0)


def conclude(mesh: SurfaceMesh, images: Sequence[Image], cameras: Sequence, solver,
             settings: MeasurementSettings, q: np.ndarray, quad: PixelQuadrature,
             normals: np.ndarray, residual: GrayLevelResidual, reports: tuple, sigma_gray,
             mask=None, final: GrayLevelResidual | None = None, history: tuple = (),
             iterations: int = 0, time_s: float = 0.0) -> Measurement:
    """The verdict (:func:`judge`), the uncertainty and the :class:`Measurement` of a state
    reached at the finest scale.

    ``images``: the two images at the finest scale of ``settings``; ``cameras``: the final
    cameras at full resolution;
    ``residual``: the residual at ``q`` on ``quad`` (``final``: the same with ``dr_dX``, if
    kept); ``reports``: one :class:`ScaleReport` per scale, the finest last; ``sigma_gray``:
    the images' noise (:func:`~fesdic_core.noise.residual_noise_floor`); ``mask``: the points
    left out at the finest scale. Used by :func:`measure`, and by a caller that moved the
    state at the finest scale itself (a level search).
    """
    failure = judge(reports[-1].residual_percent, reports[-1].noise_percent, q, mesh.nodes,
                    reports[-1], settings)
    if failure is not None:
        logger.info("measurement failed: %s", failure)     # the caller reads m.failure
    extras = {}
    finest = settings.scales[-1]
    if settings.uncertainty and np.all(np.isfinite(q)):
        extras = _uncertainty(mesh, normals, nodal_areas(mesh), q, quad, images,
                              [c.scaled(finest) for c in cameras], solver, settings,
                              mask, sigma_gray, final)
    return Measurement(q=q, nodes=current_nodes(mesh.nodes, normals, q), normals=normals,
                       cameras=tuple(cameras), residual=dataclasses.replace(residual, dr_dX=None),
                       quadrature=quad, history=history, iterations=iterations, time_s=time_s,
                       converged=failure is None and all(r.converged for r in reports),
                       noise_percent=reports[-1].noise_percent, failure=failure,
                       scales=tuple(reports), **extras)


def _uncertainty(mesh: SurfaceMesh, normals: np.ndarray, node_weights: np.ndarray, q: np.ndarray,
                 quad: PixelQuadrature, images: Sequence[Image], cameras: Sequence, solver,
                 settings: MeasurementSettings, mask, sigma_gray, final=None) -> dict:
    """The shape's standard deviation and bias indicator at the final state (finest scale);
    ``final``: the residual (with ``dr_dX``) at that state, if the iterations left it."""
    scale = settings.scales[-1]
    state = linearised_state(mesh.nodes, normals, q, quad, images, cameras,
                             settings.normalisation, mask, residual=final)
    X = quad.points(current_nodes(mesh.nodes, normals, q))
    noise = noise_model(state, X, quad, images, cameras, normals, sigma_gray, scale,
                        settings.normalisation, mask)
    modes = None
    if settings.calibrate:                   # the rigid normal part belongs to the poses (gauge)
        modes, _ = rigid_normal_modes(mesh.nodes, normals)
    std = shape_std(state.H, noise.variance, solver, scale, modes, node_weights)
    bias = None
    if callable(getattr(solver, "bias_step", None)):
        bias = np.abs(solver.bias_step(state.H, state.b, q, scale))
    if std is not None:
        logger.info("shape uncertainty: std median %.3g um, max %.3g um (noise model kappa %.3g)",
                    1e3 * np.nanmedian(std), 1e3 * np.nanmax(std), noise.variance)
    return dict(shape_std_mm=std, shape_bias_mm=bias, noise=noise, state=state)
