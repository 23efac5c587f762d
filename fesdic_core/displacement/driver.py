"""3-D displacement by FE stereo-DIC on the measured reference surface.

The shape measurement (:mod:`fesdic_core.shape.driver`) gives the reference surface (its nodes)
and the calibrated cameras. A deformed stereo pair is then correlated with the reference
pair, each camera with itself (:mod:`fesdic_core.displacement.residual`): the unknown is
the displacement ``U`` (3 per node, node-major dofs), both cameras in one Gauss-Newton.

For each image scale ``s``, coarse to fine (Remark 3; the field of scale ``s`` starts scale
``s - 1``), Gauss-Newton steps ``(H + mu diag H) d = b`` are solved by the
:class:`~fesdic_core.solve.solvers.StepSolver` hook (``solve(H, b, U, scale)``: plain FE, Tikhonov
on each component, a spline level per component), with the Levenberg-Marquardt guard
of the shape (:mod:`fesdic_core.solve.damping`): the residual never grows. The reference of each
scale (quadrature, reference gray levels) is computed once (:func:`displacement_reference`)
and serves every frame of a series.

By default (``jacobian = "reference"``) the Gauss-Newton is the modified one of FE-DIC
(Besnard, Hild and Roux 2006): the derivative of the residual is taken from the reference
images at the reference points (:func:`~fesdic_core.displacement.residual.reference_jacobian`),
so ``H`` of each scale is built once with the reference and factorized once per process
(:class:`~fesdic_core.solve.solvers.CachedFactorization` over the solver's ``factorize``); an
iteration is the deformed images' residual, ``b = J^T r`` and a back-substitution. That
``b`` is not the residual's gradient: the reference Jacobian ignores the displacement
gradient, the contrast change and the change of each camera's projection derivative, so its
fixed point is the residual's minimum only where these are small. At the finest scale the
full Gauss-Newton (``jacobian = "current"``: the deformed images' derivative at the current
state, ``H`` rebuilt at every iteration, steps stretched where they fall short) checks the
modified one's end: the fall of chi-square that a step along the residual's true gradient
would give (:func:`_decrement`). Below one unit the end is the minimum; otherwise the full
Gauss-Newton goes on from there. If the modified Gauss-Newton did not stagnate, or the full
one from its end does not, the frame is measured again with the full Gauss-Newton from its
start (GT4's ``large_motion``, 4 % strain: the modified one ends at a residual of 0.767 %
(VIC-3D calibration) or 0.776 % (DICe's), the full one from the start reaches 0.572 %; from
the modified one's end it does not converge).

A displacement is trusted only if, at the finest scale, the residual is consistent with the
images' noise, the deformed images show texture, the field stayed bounded and the
Gauss-Newton stagnated (:func:`displacement_verdict`, built on :func:`driver.judge`), and if
at most ``max_invalid_share`` of its nodes fail their local checks (:mod:`fesdic_core.displacement.validity`).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from fesdic_core.checks import MeasurementInputError, check_inputs, check_scales
from fesdic_core.displacement.settings import (DISPLACEMENT_MAX_INVALID_SHARE,
                                               DISPLACEMENT_PREFILTER_PX, JACOBIANS,
                                               DisplacementSettings)
from fesdic_core.displacement.residual import (DisplacementResidual, ReferenceView, chi_square,
                                               displacement_operators, displacement_residual,
                                               displacement_rhs, reference_view)
from fesdic_core.displacement.uncertainty import DisplacementUncertainty, displacement_uncertainty
from fesdic_core.displacement.validity import displacement_validity, residual_blocks
from fesdic_core.displacement.verdict import displacement_verdict, noise_floor
from fesdic_core.fe.mesh import SurfaceMesh
from fesdic_core.fe.quadrature import pixel_quadrature
from fesdic_core.imaging.image import Image, pyramid
from fesdic_core.residual.validity import NodeValidity
from fesdic_core.shape.operators import GaussNewtonLog
from fesdic_core.shape.settings import ScaleReport
from fesdic_core.solve.gauss_newton import damped_gauss_newton, predicted_change
from fesdic_core.solve.solvers import CachedFactorization, DirectSolver, StartScaleHook, StepSolver

logger = logging.getLogger(__name__)

#: a coarse scale whose elements hold fewer integration points than this (median) is left
#: out: the per-element normalisation of one point makes its residual identically zero (the
#: scale "converges" in 0 iterations at 0 %), and an element of a few pixels holds no texture
MIN_POINTS_PER_ELEMENT = 16

__all__ = ["JACOBIANS", "DISPLACEMENT_PREFILTER_PX", "DISPLACEMENT_MAX_INVALID_SHARE",
           "MIN_POINTS_PER_ELEMENT", "DisplacementSettings", "DisplacementReference",
           "DisplacementMeasurement", "DisplacementGNResult", "displacement_reference",
           "displacement_gauss_newton", "measure_displacement", "displacement_verdict"]


@dataclass(frozen=True, eq=False)
class DisplacementReference:
    """The reference state of a series: surface, cameras and one :class:`ReferenceView` per
    scale (coarse to fine, as ``settings.scales``). Built once, shipped once to workers."""

    mesh: SurfaceMesh
    cameras: tuple
    images: tuple
    views: tuple
    settings: DisplacementSettings

    def view(self, scale: int) -> ReferenceView:
        for v in self.views:
            if v.scale == scale:
                return v
        raise KeyError(f"no reference view of scale {scale} (scales {self.settings.scales})")


def displacement_reference(mesh: SurfaceMesh, images: Sequence[Image], cameras: Sequence,
                           settings: DisplacementSettings = DisplacementSettings()
                           ) -> DisplacementReference:
    """The reference of a series: ``mesh`` is the reference surface (measured nodes, mm),
    ``images`` and ``cameras`` the reference stereo pair and its calibrated cameras
    (full resolution). Raises :class:`MeasurementInputError` for inputs that do not fit.

    A coarse scale whose elements hold fewer than :data:`MIN_POINTS_PER_ELEMENT` points
    (median) is left out with a warning (the reference's ``settings.scales`` are those kept).
    """
    check_inputs(mesh, images, cameras)
    check_scales(images, settings.scales)
    pyramids = [pyramid(im, max(settings.scales) + 1) for im in images]
    views = []
    for scale in settings.scales:
        scaled = [c.scaled(scale) for c in cameras]
        quad = pixel_quadrature(mesh, scaled, settings.points_per_px)
        per_element = float(np.median(np.bincount(quad.element, minlength=quad.n_elements)))
        if per_element < MIN_POINTS_PER_ELEMENT and scale != settings.scales[-1]:
            logger.warning("displacement scale %d left out: its elements hold %.0f pixels "
                           "(median), fewer than %d (elements of %.2g px at this scale; coarsest "
                           "useful scale: fewer [displacement] scales)", scale, per_element,
                           MIN_POINTS_PER_ELEMENT, np.sqrt(per_element))
            continue
        normalisation = settings.normalisation if settings.jacobian == "reference" else None
        views.append(reference_view(quad, mesh.nodes, [p[scale] for p in pyramids], scaled, scale,
                                    normalisation=normalisation))
    kept = tuple(v.scale for v in views)
    if kept != tuple(settings.scales):
        settings = dataclasses.replace(settings, scales=kept)
    return DisplacementReference(mesh=mesh, cameras=tuple(cameras), images=tuple(images),
                                 views=tuple(views), settings=settings)


@dataclass(frozen=True)
class DisplacementGNResult:
    """End of a displacement Gauss-Newton (as :class:`fesdic_core.shape.operators.ShapeResult`)."""

    U: np.ndarray
    residual: DisplacementResidual
    iterations: int
    converged: bool
    damping: float = 0.0
    stop: str = ""
    blocks: np.ndarray | None = field(default=None, repr=False)   # (n, 3, 3) of the final H


def displacement_gauss_newton(U0: np.ndarray, ref: ReferenceView, images: Sequence,
                              solver: StepSolver, normalisation: str = "element",
                              max_iter: int = 30, tol_mm: float = 1e-4, max_damping: int = 8,
                              residual_rtol: float | None = None,
                              log: GaussNewtonLog | None = None,
                              context: dict | None = None,
                              jacobian: str = "current") -> DisplacementGNResult:
    """Minimise both cameras' residual over ``U`` (n, 3) at one scale, steps by ``solver``.

    The loop of the shape (:func:`fesdic_core.solve.gauss_newton.damped_gauss_newton`):
    Levenberg-Marquardt guard, convergence when the step is below ``tol_mm`` (largest
    component; the plain step is tested before the images are evaluated at its end), when it
    changes the fit by less than one unit of chi-square, or when no damped step lowers the
    residual; ``residual_rtol`` also stops a coarse scale whose residual stagnates.

    ``jacobian``: "current" (full Gauss-Newton: ``H`` and ``b`` from the deformed images'
    derivative at ``U``, every iteration) or "reference" (modified Gauss-Newton: the view's
    constant ``H``, the same object at every call so that a :class:`CachedFactorization`
    solver factorizes it once, and ``b = J^T r`` from :attr:`ReferenceView.dr_du`).
    """
    quad, scale = ref.quad, ref.scale
    if jacobian not in JACOBIANS:
        raise ValueError(f"jacobian must be one of {JACOBIANS}, got {jacobian!r}")
    frozen = jacobian == "reference"
    if frozen and (ref.hessian is None or ref.dr_du is None):
        raise ValueError("jacobian = 'reference' needs a reference view with its Jacobian "
                         "(displacement_reference with DisplacementSettings(jacobian='reference'))")

    def evaluate(U: np.ndarray) -> DisplacementResidual:
        return displacement_residual(U, ref, images, normalisation, not frozen)

    def operators(res: DisplacementResidual):
        if frozen and ref.dr_du is not None:         # the same H object at every iteration
            return ref.hessian, displacement_rhs(quad, ref.dr_du, res.r)
        return displacement_operators(quad, res)

    def on_step(it: int, std: float, res: DisplacementResidual, step: float, mu: float) -> None:
        if log is not None:
            log.add(**(context or {}), scale=scale, stage="displacement", iteration=it,
                    residual_percent=res.std_percent, step=step, damping=mu,
                    n_points=res.n_points)
        logger.debug("displacement GN scale %d it %d: residual %.4f%% -> %.4f%%, max|d| %.2e mm, "
                     "mu %.1e", scale, it, std, res.std_percent, step, mu)

    U = np.asarray(U0, float).reshape(-1)
    out = damped_gauss_newton(U, evaluate(U), evaluate, operators,
                              lambda H, b, U: solver.solve(H, b, U, scale),
                              lambda res: chi_square(res, quad), tol_mm, max_iter, max_damping,
                              residual_rtol, on_step, f"displacement GN scale {scale}",
                              stretch=True)
    blocks = None if frozen else residual_blocks(quad, out.residual)  # (the local checks')
    return DisplacementGNResult(U=out.q.reshape(-1, 3),
                                residual=dataclasses.replace(out.residual, dr_du=None),
                                iterations=out.iterations, converged=out.converged,
                                damping=out.damping, stop=out.stop, blocks=blocks)


@dataclass(frozen=True)
class DisplacementMeasurement:
    """A measured displacement field on the reference surface (world frame, mm).

    ``failure``: None for a trusted field, else one line saying what failed and by how much.
    ``converged``: no failure and every scale stagnated. ``U`` (n, 3) node-major.
    ``validity``: the local checks of every node at the finest scale
    (:func:`~fesdic_core.displacement.validity.displacement_validity`), whose :attr:`valid`
    and :attr:`residual_to_noise` are the measurement's. ``uncertainty``: the field's
    standard deviation and bias indicator per node and component
    (:mod:`fesdic_core.displacement.uncertainty`; None if ``settings.uncertainty`` is off).
    """

    U: np.ndarray
    nodes: np.ndarray
    residual: DisplacementResidual
    reference: ReferenceView = field(repr=False)
    history: tuple = field(repr=False)
    iterations: int = 0
    time_s: float = 0.0
    converged: bool = False
    noise_percent: float = float("nan")
    failure: str | None = None
    scales: tuple = ()
    validity: NodeValidity | None = field(default=None, repr=False)
    uncertainty: DisplacementUncertainty | None = field(default=None, repr=False)

    @property
    def residual_percent(self) -> float:
        return self.residual.std_percent

    @property
    def valid(self) -> np.ndarray:
        """(n,) bool: the node passed its local checks (all True without them)."""
        return np.ones(len(self.nodes), bool) if self.validity is None else self.validity.valid

    @property
    def residual_to_noise(self) -> np.ndarray:
        """(n,) the residual over each node's support against its local noise floor (NaN
        without the local checks, or for a node no point sees)."""
        v = self.validity
        return np.full(len(self.nodes), np.nan) if v is None else v.residual_to_noise

    @property
    def ok(self) -> bool:
        return self.failure is None

    def node_residual_percent(self) -> np.ndarray:
        """(n,) the residual map (:attr:`DisplacementResidual.point_percent`) at the nodes:
        the shape-function-weighted mean of the seen points (NaN for a node none sees)."""
        quad = self.reference.quad
        p = self.residual.point_percent
        seen = np.isfinite(p)
        weight = quad.to_nodes(np.where(seen, quad.weight_mm2, 0.0))
        total = quad.to_nodes(np.where(seen, quad.weight_mm2 * np.nan_to_num(p), 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(weight > 0, total / np.where(weight > 0, weight, 1.0), np.nan)


def _decrement(gn: DisplacementGNResult, view: ReferenceView, images: Sequence, solver,
               normalisation: str) -> float:
    """The fall of chi-square (in its units) that a step on the residual's true gradient
    would give from the modified Gauss-Newton's end, measured with the reference ``H``
    (factorized already): ``b^T H^-1 b`` for ``b`` from the deformed images' derivative. Below
    one unit the data cannot tell the end from the residual's minimum."""
    res = displacement_residual(gn.U, view, images, normalisation, True)
    _, b = displacement_operators(view.quad, res)
    U = gn.U.reshape(-1)
    d = solver.solve(view.hessian, b, U, view.scale)
    return float(predicted_change(view.hessian, b, d, chi_square(res, view.quad)))


def _check_frame(images: Sequence[Image], reference: DisplacementReference) -> None:
    if len(images) != 2:
        raise MeasurementInputError(f"a deformed stereo pair needs 2 images, got {len(images)}")
    for image, ref_image in zip(images, reference.images):
        if image.shape != ref_image.shape:
            raise MeasurementInputError(
                f"{image.source}: image is {image.shape[1]} x {image.shape[0]} px but the "
                f"reference {ref_image.source} is {ref_image.shape[1]} x {ref_image.shape[0]} px")


def measure_displacement(reference: DisplacementReference, images: Sequence[Image],
                         solver: StepSolver | None = None, U0: np.ndarray | None = None,
                         progress: Callable[[int, int, ScaleReport], None] | None = None
                         ) -> DisplacementMeasurement:
    """Measure the displacement of the reference surface in the deformed pair ``images``.

    Parameters
    ----------
    reference : :func:`displacement_reference` (surface, cameras, reference pair, settings)
    images : the two deformed full-resolution images (cam0, cam1)
    solver : the step solver hook on the node-major dofs (default :class:`DirectSolver`)
    U0 : (n, 3) initial displacement (default 0; the previous frame's in a series)
    progress : optional ``f(k, n, report)`` called after scale ``k`` of ``n``

    Returns
    -------
    DisplacementMeasurement
        Check :attr:`~DisplacementMeasurement.failure` before trusting it.
    """
    _check_frame(images, reference)
    settings = reference.settings
    solver = given = DirectSolver() if solver is None else solver
    if settings.jacobian == "reference" and not isinstance(solver, CachedFactorization):
        solver = CachedFactorization(solver)             # H of each scale factorized once
    n = reference.mesh.n_nodes
    U = np.zeros((n, 3)) if U0 is None else np.asarray(U0, float).reshape(n, 3).copy()
    pyramids = [pyramid(im, max(settings.scales) + 1) for im in images]
    log, t0 = GaussNewtonLog(), time.perf_counter()
    reports, total_iterations, gn, noise_percent, ratios = [], 0, None, float("nan"), [np.inf] * 2
    contrast = [1.0, 1.0]
    for k, scale in enumerate(settings.scales, start=1):
        view, imgs = reference.view(scale), [p[scale] for p in pyramids]
        if isinstance(solver, StartScaleHook):       # (not a CachedFactorization)
            solver.start_scale(scale, None)
        finest = scale == settings.scales[-1]
        gn = displacement_gauss_newton(U, view, imgs, solver, settings.normalisation,
                                       settings.max_iter, settings.tol_mm * 2.0 ** scale,
                                       settings.max_damping,
                                       residual_rtol=None if finest else settings.residual_rtol,
                                       log=log, jacobian=settings.jacobian)
        if finest and settings.jacobian == "reference":
            decrement = _decrement(gn, view, imgs, solver, settings.normalisation) \
                if gn.converged else float("inf")
            if gn.converged and decrement >= 1.0:    # stagnated off the minimum: on to it
                modified = gn
                gn = displacement_gauss_newton(gn.U, view, imgs, given, settings.normalisation,
                                               settings.max_iter, settings.tol_mm * 2.0 ** scale,
                                               settings.max_damping, log=log, jacobian="current")
                logger.info("displacement scale %d: the modified Gauss-Newton stagnated off the "
                            "residual's minimum (the full step would lower chi-square by %.3g "
                            "units); %d full iterations: residual %.4f%% -> %.4f%%", scale,
                            decrement, gn.iterations, modified.residual.std_percent,
                            gn.residual.std_percent)
                gn = dataclasses.replace(gn, iterations=modified.iterations + gn.iterations,
                                         stop=f"{modified.stop}, then {gn.stop} (full)")
            if not gn.converged:           # it wandered: the full Gauss-Newton from the start
                logger.info("displacement scale %d: the Gauss-Newton did not stagnate (%s): the "
                            "frame again with the full Gauss-Newton", scale, gn.stop)
                full = dataclasses.replace(settings, jacobian="current")
                again = measure_displacement(dataclasses.replace(reference, settings=full),
                                             images, given, U0, progress)
                return dataclasses.replace(again, time_s=time.perf_counter() - t0, iterations=(
                    total_iterations + gn.iterations + again.iterations))
        U, total_iterations = gn.U, total_iterations + gn.iterations
        noise_percent, ratios, contrast = noise_floor(view, gn.residual, imgs)
        report = ScaleReport(scale=scale, residual_percent=gn.residual.std_percent,
                             noise_percent=noise_percent, fixed_point_iterations=1,
                             shape_converged=gn.converged, fixed_point_converged=True,
                             n_points=gn.residual.n_points)
        reports.append(report)
        logger.info("displacement scale %d: residual %.3f%% (noise floor %.3f%%), %d iterations, "
                    "stop: %s", scale, report.residual_percent, noise_percent, gn.iterations,
                    gn.stop)
        if progress is not None:
            progress(k, len(settings.scales), report)
    if gn is None:                      # (DisplacementSettings refuses an empty schedule)
        raise ValueError("measure_displacement: no image scale to measure at")
    validity = displacement_validity(view, gn.residual, U, reference.mesh.nodes, imgs, contrast,
                                     gn.blocks)
    logger.info("displacement: %d of %d nodes valid locally", int(validity.valid.sum()),
                validity.valid.size)
    # the divergence is the Gauss-Newton's own excursion: a large motion's start is none
    start = 0.0 if U0 is None else np.asarray(U0, float).reshape(n, 3)
    failure = displacement_verdict(reports[-1].residual_percent, noise_percent, U - start,
                                   reference.mesh.nodes, ratios, [im.source for im in images],
                                   reports[-1], settings, validity)
    if failure is not None:
        logger.info("displacement failed: %s", failure)
    hooks = given.solver if isinstance(given, CachedFactorization) else given   # (the hooks')
    uncertainty = None
    if settings.uncertainty and failure is None:
        try:                      # a field is not failed by its uncertainty's linear algebra
            uncertainty = displacement_uncertainty(U, view, imgs, hooks, settings.normalisation)
        except (ArithmeticError, RuntimeError, ValueError, np.linalg.LinAlgError) as err:
            logger.warning("displacement uncertainty not computed: %s", err)
    return DisplacementMeasurement(U=U, nodes=reference.mesh.nodes, residual=gn.residual,
                                   reference=reference.view(settings.scales[-1]),
                                   history=tuple(log.records), iterations=total_iterations,
                                   time_s=time.perf_counter() - t0,
                                   converged=failure is None and all(r.converged for r in reports),
                                   noise_percent=noise_percent, failure=failure,
                                   scales=tuple(reports), validity=validity,
                                   uncertainty=uncertainty)
