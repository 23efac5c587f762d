"""The drivers: poses and shape (section 2.2) inside the multiscale loop of Remark 3.

For each image scale ``s``, coarse to fine (the solution of scale ``s`` starts scale
``s - 1``), without calibration the shape Gauss-Newton of Eq. 7 (each step by the StepSolver
hook); with calibration either one Gauss-Newton on the poses and the shape together
(``coupling = "joint"``, the default, :mod:`fesdic_core.shape.joint`) or the paper's fixed
point (``coupling = "alternate"``)::

    repeat until (p, q) stagnate:                    (fixed point, section 2.2)
        p <- argmin_p j(S, p)      calibration, Eq. 6
        q <- argmin_q j(L^T q, p)  shape, Eq. 7, each step by the StepSolver hook
        gauge: rigid normal part of q -> camera poses (see gauge.py)

Scale ``s`` uses the images aggregated ``s`` times (2x2 pixel means) and the matching
cameras; the step solver is told ``s`` so that it can regularize accordingly.

A measurement is trusted only if, at the finest scale, the gray-level residual is
consistent with the images' own noise (:mod:`fesdic_core.imaging.noise`), the shape stayed
bounded and the fixed point stagnated; otherwise :attr:`Measurement.failure` says what
failed and by how much, and :func:`measure` does not call it converged.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Callable, Sequence

import numpy as np

from fesdic_core.cameras.rig import stereo_transform
from fesdic_core.checks import MeasurementInputError, check_inputs, check_scales, check_texture
from fesdic_core.fe.mesh import SurfaceMesh, nodal_areas, node_normals
from fesdic_core.fe.quadrature import PixelQuadrature, pixel_quadrature
from fesdic_core.imaging.image import Image, pyramid
from fesdic_core.imaging.noise import residual_noise_floor
from fesdic_core.residual.edges import edge_margin_mask
from fesdic_core.residual.graylevel import GrayLevelResidual, gray_level_residual
from fesdic_core.residual.visibility import visibility_mask
from fesdic_core.shape.calibration import calibrate_extrinsics
from fesdic_core.shape.gauge import (pose_directions, rigid_normal_modes, tangential_motions,
                                     transfer_rigid_part)
from fesdic_core.shape.joint import joint_gauss_newton
from fesdic_core.shape.operators import (GaussNewtonLog, ShapeResult, chi_square_change,
                                         current_nodes, shape_gauss_newton)
from fesdic_core.shape.settings import Measurement, MeasurementSettings, ScaleReport
from fesdic_core.shape.uncertainty import linearised_state, noise_model, shape_std
from fesdic_core.shape.validity import shape_validity
from fesdic_core.shape.verdict import ShapeDivergedError, _diverged, judge
from fesdic_core.solve.solvers import BiasStepHook, DirectSolver, StartScaleHook, StepSolver

logger = logging.getLogger(__name__)

__all__ = ["measure", "conclude", "Measurement", "MeasurementSettings", "ScaleReport",
           "MeasurementInputError", "ShapeDivergedError"]


#: a rigid normal part of q below this (mm) is round-off: left in q, not handed to the poses
#: (the state, and the residual evaluated there, stay as they are)
_NO_RIGID_PART_MM = 1e-10


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
    result: tuple[GrayLevelResidual, PixelQuadrature] | None = None
    final: GrayLevelResidual | None = None   # the last residual with dr_dX, if at the final state
    shape: ShapeResult                       # the last shape Gauss-Newton (set in the loop)
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
        if isinstance(solver, StartScaleHook):       # a solver that chooses from data
            state = linearised_state(mesh.nodes, normals, q, quad, imgs, scaled,
                                     settings.normalisation, mask, residual=first)
            solver.start_scale(scale, noise_model(state, X_now, quad, imgs, scaled, normals,
                                                  noise.sigma_gray, scale, settings.normalisation,
                                                  mask))
        coarse = 2.0 ** scale
        finest = scale == settings.scales[-1]
        fixed_point_converged, previous_residual = not settings.calibrate, np.inf
        previous_fit: GrayLevelResidual | None = None
        known: GrayLevelResidual | None = first   # the residual at the current state
        joint = settings.calibrate and settings.coupling == "joint"
        if joint:                   # poses and shape in one Gauss-Newton (joint.py)
            if k == 1:              # from the landmarks' pose: the poses first, at the nominal
                X = quad.points(nodes_now)                       # shape (section 2.2)
                cal = calibrate_extrinsics(X, quad, imgs, scaled, stereo=stereo,
                                           frozen=pose_directions(cams, slides, centre,
                                                                  stereo is not None),
                                           normalisation=settings.normalisation,
                                           max_iter=settings.max_iter, extra_mask=mask,
                                           tol_rad=1e-7 * coarse, tol_mm=1e-5 * coarse,
                                           undamped_px=settings.fixed_point_tol_px, log=log,
                                           context={"fixed_point": 0, "scale": scale},
                                           start=first)
                cams = [c.with_extrinsics(s.extrinsics) for c, s in zip(cams, cal.cameras)]
                scaled = [c.scaled(scale) for c in cams]
                first = cal.residual
            out = joint_gauss_newton(mesh.nodes, normals, q, quad, imgs, scaled, solver, scale,
                                     stereo, node_weights, settings.normalisation,
                                     settings.max_joint_iter, settings.tol_mm * coarse,
                                     settings.fixed_point_tol_px, residual_rtol=None if finest
                                     else settings.fixed_point_rtol, extra_mask=mask, log=log,
                                     context={"fixed_point": 1}, start=first,
                                     final_decrement=finest)
            q, cams = out.q, [c.with_extrinsics(s.extrinsics) for c, s in zip(cams, out.cameras)]
            shape = ShapeResult(q=q, residual=out.residual, iterations=out.iterations,
                                converged=out.converged, damping=out.damping, stop=out.stop)
            result, final, fp = (out.residual, quad), out.residual, 1
            total_iterations += out.iterations
            fixed_point_converged = out.converged
            logger.info("scale %d: joint Gauss-Newton, %d iterations, residual %.3f%% (%s; "
                        "predicted chi-square fall %.3g)", scale, out.iterations,
                        out.residual.std_percent, out.stop, out.decrement)
        alternations = 0 if joint else settings.max_fixed_point   # the fixed point (section 2.2)
        for fp in range(1, alternations + 1):
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
            residual_percent = shape.residual.std_percent
            if (not finest and previous_residual - residual_percent
                    <= settings.fixed_point_rtol * residual_percent):
                logger.info("scale %d: the residual stagnates; the next scale goes on", scale)
                fixed_point_converged = True  # a coarse scale only starts the next (Remark 3)
                break
            previous_residual = residual_percent
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
    if result is None:                  # (MeasurementSettings refuses an empty schedule)
        raise ValueError("measure: no image scale to measure at")
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
    the images' noise (:func:`~fesdic_core.imaging.noise.residual_noise_floor`); ``mask``: the points
    left out at the finest scale. Used by :func:`measure`, and by a caller that moved the
    state at the finest scale itself (a level search).
    """
    failure = judge(reports[-1].residual_percent, reports[-1].noise_percent, q, mesh.nodes,
                    reports[-1], settings)
    extras = {}
    finest = settings.scales[-1]
    scaled = [c.scaled(finest) for c in cameras]
    if settings.uncertainty and np.all(np.isfinite(q)):
        extras = _uncertainty(mesh, normals, nodal_areas(mesh), q, quad, images, scaled, solver,
                              settings, mask, sigma_gray, final)
    nodes = current_nodes(mesh.nodes, normals, q)
    validity = None
    if np.all(np.isfinite(q)):
        state = extras.get("state")
        validity = shape_validity(mesh, nodes, q, quad, residual, images, scaled,
                                  None if state is None else state.H, extras.get("shape_std_mm"))
        logger.info("shape: %d of %d nodes valid locally", int(validity.valid.sum()),
                    validity.valid.size)
        if failure is None:
            failure = validity.failure(nodes, settings.max_invalid_share)
    if failure is not None:
        logger.info("measurement failed: %s", failure)     # the caller reads m.failure
    return Measurement(q=q, nodes=nodes, normals=normals,
                       cameras=tuple(cameras), residual=dataclasses.replace(residual, dr_dX=None),
                       quadrature=quad, history=history, iterations=iterations, time_s=time_s,
                       converged=failure is None and all(r.converged for r in reports),
                       noise_percent=reports[-1].noise_percent, failure=failure,
                       scales=tuple(reports), validity=validity, **extras)


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
    if isinstance(solver, BiasStepHook):
        bias = np.abs(solver.bias_step(state.H, state.b, q, scale))
    if std is not None:
        logger.info("shape uncertainty: std median %.3g um, max %.3g um (noise model kappa %.3g)",
                    1e3 * np.nanmedian(std), 1e3 * np.nanmax(std), noise.variance)
    return dict(shape_std_mm=std, shape_bias_mm=bias, noise=noise, state=state)
