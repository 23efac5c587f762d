"""Geometric regularization that chooses its own level: the search, driven through the core.

1. The paper's coarse-to-fine run (section 3.3): image scale ``s`` on spline level
   ``start + s`` of the whole ladder of nested levels, from the coarse nominal spline down
   to the spline the FE mesh is extracted from (``C_FE``, Eq. 17).
2. At the finest image scale, the level moves to where the balancing principle points
   (:mod:`georeg_plugin.levels.risk`): from the converged Gauss-Newton system, the optimum
   of every other level, finer or coarser, is predicted (Eq. 21 at the level: the levels are
   nested, Eq. 13, no restart from scratch), and the coarsest level whose shape agrees with
   every finer level's to within two standard deviations of their difference (in the node
   metric, modulo the rigid normal motions) is iterated from its predicted optimum; the
   prediction is renewed from its converged system. A level is iterated at most once: where
   the search points to a level it has measured, it ends there. Each level's expected RMS
   error at the nodes, bias plus noise, is estimated against the next finer level (Stein's
   unbiased risk estimate in the metric of the node values). Below the nominal
   spline it also looks at the bilinear level of its parameter domain
   (:func:`~georeg_plugin.spline.refine.linear_patch`, 4 dofs of which 3 are a plane's rigid
   normal motions): a flat specimen is not left with the nominal's other dofs of noise. The
   Hannan-Quinn criterion (:mod:`georeg_plugin.levels.selection`) is still recorded.
3. If another level was chosen: the search's last Gauss-Newton is the measurement, and the
   core's :func:`~fesdic_core.shape.driver.conclude` gives its verdict and uncertainty. With
   calibration by the joint Gauss-Newton (``coupling = "joint"``), each level is iterated on
   the poses and the shape together (:func:`~fesdic_core.shape.joint.joint_gauss_newton`), so
   no second measurement is needed; with the fixed point (``"alternate"``), one more fixed
   point of calibration and shape at that level (the core's
   :func:`~fesdic_core.shape.driver.measure`).

The noise variance of the estimate is the core's noise model ``kappa`` (:mod:`fesdic_core.shape.uncertainty`:
image noise through the image model, scaled to the residual the FE model leaves), or the
larger share per dof of the image model's misfit, measured on the dofs that the FE mesh
adds beyond the finest spline level (:func:`effective_variance`).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from fesdic_core.cameras.rig import stereo_transform
from fesdic_core.fe.mesh import nodal_areas, node_normals
from fesdic_core.imaging.image import pyramid
from fesdic_core.shape.driver import Measurement, MeasurementSettings, conclude, measure
from fesdic_core.shape.gauge import rigid_normal_modes
from fesdic_core.shape.joint import joint_gauss_newton
from fesdic_core.shape.operators import shape_gauss_newton
from fesdic_core.shape.uncertainty import linearised_state
from fesdic_core.solve.solvers import seen_dofs
from georeg_plugin.levels.multipatch import part_space
from georeg_plugin.levels.operators import MultilevelSpace, gluing_matrix, nested_space
from georeg_plugin.levels.risk import (agreement, balanced_level, level_risks, node_metric,
                                       shape_variance)
from georeg_plugin.levels.selection import (LevelTrial, information_criterion, noise_gain,
                                            predicted_fit)
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.levels.support import ZERO_PIVOT, mesh_seen
from georeg_plugin.spline.refine import insert_knots, linear_patch, refine_uniform

from adapters.fesdic_core import (NominalModel, elements_per_span, is_curved,
                                  legacy_mesh_holds, scalar_holds_rigid_motions)

logger = logging.getLogger(__name__)

__all__ = ["LevelSearch", "below_nominal", "fixed_level", "ladder", "measure_auto_levels",
           "seen_level_dofs"]


@dataclasses.dataclass(frozen=True)
class LevelSearch:
    """What the level search did: one :class:`LevelTrial` per level looked at, in order.

    ``chosen``/``start``: level indices in the ladder (0 = the spline of the FE mesh);
    ``n_levels``: levels in the ladder; ``variance``: the images' noise variance ``kappa``;
    ``time_s``: the time the search added to the fixed-level run.
    """

    trials: tuple
    chosen: int
    start: int
    n_levels: int
    variance: float
    time_s: float

    def as_dict(self) -> dict:
        chosen = [t.dofs for t in self.trials if t.chosen]
        return {"chosen_level": self.chosen, "chosen_dofs": chosen[0] if chosen else None,
                "start_level": self.start, "n_levels": self.n_levels,
                "noise_variance": self.variance, "time_s": self.time_s,
                "trials": [dataclasses.asdict(t) for t in self.trials]}


def _element_breaks(model: NominalModel) -> tuple[np.ndarray, np.ndarray]:
    """The knot values (u, v) of the spline the FE mesh is extracted from (its element
    corners, Eq. 17)."""
    corners = np.concatenate([b.connectivity[:, :4].ravel() for b in model.mesh.blocks])
    uv = model.uv[np.unique(corners)]
    # with the nominal's own breaks: a welded seam node keeps one of its two parameters
    return tuple(np.unique(np.round(np.concatenate([uv[:, d], model.patch.breaks[d]]), 12))
                 for d in (0, 1))


def _missing(breaks: np.ndarray, present: np.ndarray) -> np.ndarray:
    """The values of ``breaks`` that are not in ``present`` (to 1e-9)."""
    if not present.size:
        return breaks
    return breaks[np.min(np.abs(breaks[:, None] - present[None, :]), axis=1) > 1e-9]


def _halved(breaks: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Every other break, the ends and the breaks of ``keep`` (the nominal's) kept."""
    return np.unique(np.round(np.concatenate([breaks[::2], breaks[-1:], keep]), 12))


def part_levels(model: NominalModel) -> int:
    """The most dyadic levels a part's FE mesh holds (Eq. 16): ``k`` with ``4^(k-1)`` FE
    elements per coarse knot span on the face that has fewest (:func:`part_model` meshes
    have ``4^r`` after ``r`` refinements: ``r + 1`` levels; a trimmed face counts by its
    elements' spacing, :func:`~adapters.fesdic_core.elements_per_span`)."""
    ratios = [elements_per_span(model, f, face) for f, face in enumerate(model.faces)]
    return 1 + max(0, int(np.floor(np.log(min(ratios)) / np.log(4.0) + 1e-9)))


def ladder(model: NominalModel, curved: bool | None = None,
           linear: bool = False) -> MultilevelSpace:
    """The nested levels from the nominal spline to the spline of the FE mesh (``C_FE``).

    From the spline whose knot spans are the FE elements (Eq. 17) down: each coarser level
    keeps every other knot (and the nominal's own knots), until the nominal spline is
    reached; single knots are inserted from level to level, so the levels are nested
    (Eq. 13) whatever the number of elements (a dyadic mesh gives the paper's levels of
    Eq. 28; 40 elements give 40, 20, 10, 5 spans and the nominal). For a legacy mesh (no
    node parameters): dyadic refinements of the nominal with at most a quarter as many
    dofs as the mesh has nodes (a Q9 mesh has about four nodes per spline dof). A part of
    several faces (:func:`part_model`): every face refined dyadically together, glued
    (:func:`~georeg_plugin.levels.multipatch.part_space`), up to the mesh's resolution.

    ``curved``: the formulation, as :func:`~adapters.fesdic_core.multilevel_for_mesh`'s; None
    (default): scalar on a flat face or one whose scalar space holds the rigid normal motions
    (a cylinder), else the vector formulation.

    ``linear``: one more level below the nominal, the bilinear patch of its parameter domain
    (:func:`~georeg_plugin.spline.refine.linear_patch`), where the nominal is a single open
    B-spline patch of degree above 1 and the formulation is scalar; see :func:`below_nominal`.
    """
    if model.is_part:                      # several faces: dyadic levels of every face
        return part_space(model.faces, part_levels(model), model.uv, model.node_face,
                          node_normals(model.mesh))
    patches, refinements = [model.patch], []
    if model.uv is None:
        while len(patches) < 12:
            finer, C_r = refine_uniform(patches[-1], 1)
            if not legacy_mesh_holds(finer.n_dofs, model.mesh.n_nodes):
                break
            patches.append(finer)
            refinements.append(C_r)
    else:
        nominal = model.patch.breaks
        chain = [_element_breaks(model)]                          # finest first
        while any(_missing(b, n).size for b, n in zip(chain[-1], nominal)):
            coarser = tuple(_halved(b, n) for b, n in zip(chain[-1], nominal))
            if all(c.size == b.size for c, b in zip(coarser, chain[-1])):
                break
            chain.append(coarser)
        for breaks in reversed(chain):
            new = [_missing(b, p) for b, p in zip(breaks, patches[-1].breaks)]
            if any(n.size for n in new):
                finer, C_r = insert_knots(patches[-1], new[0], new[1])
                patches.append(finer)
                refinements.append(C_r)
    family = model.mesh.blocks[0].family.name if model.uv is not None else None
    space = nested_space(patches, refinements, model.mesh.nodes, None, model.uv, family=family)
    if curved is None:                     # as multilevel_for_mesh: scalar on a flat face or
        curved = is_curved(model) and not scalar_holds_rigid_motions(model, space)  # a cylinder
    if not curved:
        if linear and _has_linear_level(model):
            bilinear, C_r = linear_patch(model.patch)
            space = nested_space([bilinear] + patches, [C_r] + refinements, model.mesh.nodes,
                                 None, model.uv, family=family)
        return space
    return nested_space(patches, refinements, model.mesh.nodes, node_normals(model.mesh),
                        model.uv, family=family)


def _has_linear_level(model: NominalModel) -> bool:
    patch = model.patch
    gluing = gluing_matrix(patch)
    return (patch.weights is None and max(patch.degrees) > 1
            and gluing.shape[0] == gluing.shape[1])                   # open: no seam to glue


def below_nominal(space: MultilevelSpace, model: NominalModel) -> int:
    """Levels of ``space`` below the nominal spline: 1 if :func:`ladder` added the bilinear
    level (``ladder(..., linear=True)``), else 0."""
    if model.is_part:
        return 0
    return int(space.patch(space.n_levels - 1).degrees != model.patch.degrees)


def seen_level_dofs(space: MultilevelSpace, level: int, H=None) -> int:
    """The dofs of a level that the data sees (:mod:`georeg_plugin.levels.support`): its rows
    of ``C_s`` not zero on the mesh and, given ``H`` (n_fe, n_fe), with a nonzero diagonal of
    ``C_s H C_s^T``; the dofs the criterion counts (those outside the outline are not solved)."""
    C = space.operators[level]
    seen = mesh_seen(C)
    if H is not None and seen.any():
        diag = np.abs(np.asarray((C @ sps.csr_matrix(H)).multiply(C).sum(axis=1)).ravel())
        seen &= diag > ZERO_PIVOT * diag[seen].max()
    return int(np.count_nonzero(seen))


def _trial(level: int, space: MultilevelSpace, chi_square: float, reference: tuple, variance: float,
           residual_percent: float, measured: bool, n_points: int, H=None) -> LevelTrial:
    dofs = seen_level_dofs(space, level, H)
    return LevelTrial(level=level, dofs=dofs, chi_square=chi_square,
                      criterion=information_criterion(chi_square, dofs, variance, n_points),
                      residual_percent=residual_percent,
                      measured=measured, gain=noise_gain(*reference, chi_square, dofs, variance)
                      if reference else float("nan"), variance=variance)


def effective_variance(H, b: np.ndarray, kappa: float, finest_step: np.ndarray | None,
                       finest_dofs: int) -> float:
    """The noise variance of the criterion: ``kappa`` of the images, or more if the data say so.

    The image model's misfit (interpolation of the finest texture, a render's or a
    sensor's pixel integration) is not white: it is correlated at the speckle scale and
    acts on the shape like noise of larger variance, which finer levels fit as they fit
    noise. Its share per dof is measured where no shape is expected, on the dofs that the
    FE mesh adds beyond the finest spline level (elements of 16 px or more; like the
    finest wavelet coefficients in wavelet shrinkage): ``(fall to FE - fall to the finest
    spline) / (FE dofs - spline dofs)``, predicted from the current system ``(H, b)`` (Eq. 8;
    ``finest_step`` the step to the finest level's optimum, ``finest_dofs`` its seen dofs).
    """
    seen = seen_dofs(H)
    if finest_step is None or not seen.any():
        return kappa
    fall_fe = float(b[seen] @ spla.splu(sps.csc_matrix(H[seen][:, seen])).solve(b[seen]))
    added = int(np.count_nonzero(seen)) - int(finest_dofs)
    if added <= 0:
        return kappa
    misfit = (fall_fe - float(np.dot(b, finest_step))) / added
    return max(kappa, misfit)


def fixed_level(space: MultilevelSpace, model: NominalModel, level: int,
                scales: Sequence[int]) -> GeometricRegularization:
    """georeg held at ``level`` of the search's ladder at the finest image scale, one level
    coarser per coarser scale, never coarser than the nominal (the search's own start
    schedule): the oracle a level choice is measured against."""
    nominal = space.n_levels - 1 - below_nominal(space, model)
    finest = min(scales)
    return GeometricRegularization(space, {s: max(level, min(level + s - finest, nominal))
                                           for s in scales})


def _move_to(space: MultilevelSpace, level: int, H, b: np.ndarray, q: np.ndarray,
             scale: int, hold: bool = True) -> np.ndarray:
    """The step from ``q`` to the optimum of ``level`` by the Gauss-Newton model (Eq. 8):
    ``G_s (b + H q) - q``, ``G_s = C_s^T (C_s H C_s^T)^-1 C_s`` (Eqs. 18-21; a solver's step at
    its finest level), ``G_s b`` for a level that holds ``q`` (finer, nested: Eq. 13).
    ``hold``: dofs that no point sees keep their value (outside the outline, hidden regions)."""
    solver = GeometricRegularization(space, {scale: level}, hold_unseen=hold)
    return solver.solve(H, b, q, scale)


def measure_auto_levels(model: NominalModel, images: Sequence, cameras: Sequence,
                        settings: MeasurementSettings, start_levels: int = 3,
                        curved: bool | None = None,
                        progress: Callable | None = None
                        ) -> tuple[Measurement, GeometricRegularization, LevelSearch]:
    """Measure with the spline level chosen from the data (see the module docstring).

    Parameters
    ----------
    model : the nominal spline and FE mesh.
    images, cameras : the full-resolution stereo pair and the initial cameras.
    settings : the core's settings (scales, calibration, ...).
    start_levels : levels of the coarse-to-fine start (the paper's fixed choice): the
        finest image scale starts on the ladder's level ``start_levels - 1`` counted from
        the coarse nominal spline.
    progress : passed to the core's ``measure`` (scales of the start).

    Returns
    -------
    (measurement, solver, search): the measurement at the chosen level, the solve hook
    whose finest scale uses it, and the search's record.
    """
    space = ladder(model, curved, linear=True)
    n_levels = space.n_levels
    nominal = n_levels - 1 - below_nominal(space, model)     # the start never goes below it
    finest = settings.scales[-1]
    start = max(0, nominal + 1 - int(start_levels))
    schedule = {s: min(start + s - finest, nominal) for s in settings.scales}
    first = measure(model.mesh, images, cameras, GeometricRegularization(space, schedule),
                    settings, progress=progress)
    t0 = time.perf_counter()
    if first.state is None or first.noise is None or not np.all(np.isfinite(first.q)):
        logger.info("level search skipped: the start has no state to search from")
        return first, GeometricRegularization(space, schedule), LevelSearch(
            (), start, start, n_levels, float("nan"), 0.0)
    kappa = first.noise.variance
    joint = settings.calibrate and settings.coupling == "joint"
    stereo = stereo_transform(*first.cameras) if joint and settings.keep_stereo else None
    imgs = [p[finest] for p in (pyramid(im, finest + 1) for im in images)]
    cams = [c.scaled(finest) for c in first.cameras]
    quad, normals = first.quadrature, first.normals
    # the points of the start's final residual (the core's edge margin and the images' bounds
    # included): every level's cost is a sum over the same points, so the criteria compare
    mask = first.residual.mask

    def residual_of(chi: float, state) -> float:                 # std scales like sqrt(c)
        return state.residual.std_percent * np.sqrt(max(chi, 0.0) / state.chi_square)

    metric = node_metric(nodal_areas(model.mesh), rigid_normal_modes(model.mesh.nodes, normals)[0])

    traces: dict = {}        # tr(M G_s) per unit noise: from the start's H (a variance: the few
    #                          per cent by which H changes between the levels do not matter)

    def assess(state, q) -> tuple:
        """Every level's predicted optimum (Eq. 21 at the level, from the current system), the
        noise variance, every level's estimated shape error and its agreement with the finer
        levels (:mod:`~georeg_plugin.levels.risk`)."""
        moves = {other: _move_to(space, other, state.H, state.b, q, finest)
                 for other in range(n_levels)}
        variance = effective_variance(state.H, state.b, kappa, moves[0],
                                      seen_level_dofs(space, 0, state.H))
        if not traces:
            traces.update({other: metric.trace(*GeometricRegularization(space, {finest: other})
                                               .step_covariance(state.H, finest))
                           for other in range(n_levels)})
        in_nodes = shape_variance(state.H, state.b, moves[0], traces[0], variance, metric)
        return (moves, variance, level_risks(moves, traces, in_nodes, metric, reference="next"),
                agreement(moves, traces, in_nodes, metric))

    def record(other: int, state, chi: float, reference: tuple, assessed: tuple,
               measured: bool) -> LevelTrial:
        _, variance, risks, z = assessed
        trial = _trial(other, space, chi, reference, variance, residual_of(chi, state), measured,
                       state.n_points, state.H)
        risk, spread = risks[other]
        return dataclasses.replace(trial, error_mm=float(np.sqrt(risk)),
                                   std_mm=float(np.sqrt(spread)), agreement=float(z[other]))

    level, q, state, cams = start, first.q, first.state, cams
    assessed = assess(state, q)
    current = record(level, state, state.chi_square, (), assessed, True)
    trials, iterations, kept = [current], 0, None
    visited = {start: (q, state, cams, current, kept, assessed)}   # the levels iterated
    while True:
        reference = (current.chi_square, current.dofs)
        predictions = [record(other, state, predicted_fit(state.chi_square, state.b, d, state.H),
                              reference, assessed, False)
                       for other, d in assessed[0].items() if other not in visited]
        trials += predictions
        target = balanced_level(assessed[3])
        logger.info("level search: on level %d (%d dofs), estimated error %.3g um; agreement "
                    "with the finer levels (std) %s: level %d", level, current.dofs,
                    1e3 * current.error_mm, ", ".join(f"level {s}: {z:.3g}" for s, z in
                                                      sorted(assessed[3].items())), target)
        if target == level:
            break
        if target in visited:               # measured already: the search ends there
            level = target
            q, state, cams, current, kept, assessed = visited[target]
            break
        solver = GeometricRegularization(space, {finest: target})
        if joint:            # the poses move with the shape: no second measurement at the end
            shape = joint_gauss_newton(model.mesh.nodes, normals, q + assessed[0][target], quad,
                                       imgs, cams, solver, finest, stereo, nodal_areas(model.mesh),
                                       settings.normalisation, settings.max_joint_iter,
                                       settings.tol_mm * 2.0 ** finest,
                                       settings.fixed_point_tol_px, extra_mask=mask)
        else:
            shape = shape_gauss_newton(model.mesh.nodes, normals, q + assessed[0][target], quad,
                                       imgs, cams, solver, finest, settings.normalisation,
                                       settings.max_iter, settings.tol_mm * 2.0 ** finest,
                                       extra_mask=mask, keep_derivative=True)
        iterations += shape.iterations
        cams = list(shape.cameras) if joint else cams
        state = linearised_state(model.mesh.nodes, normals, shape.q, quad, imgs, cams,
                                 settings.normalisation, mask, residual=shape.residual)
        level, q, kept, assessed = target, shape.q, shape, assess(state, shape.q)
        current = record(level, state, state.chi_square, reference, assessed, True)
        trials.append(current)
        visited[level] = (q, state, cams, current, kept, assessed)
        logger.info("level search: level %d measured: residual %.4f%%", level,
                    current.residual_percent)
    solver = GeometricRegularization(space, {finest: level})
    if level != start and (joint or not settings.calibrate):
        # the cameras are fixed, or moved by the joint steps: the search's last Gauss-Newton is
        # the measurement at the chosen level; the verdict and the uncertainty are the core's
        report = dataclasses.replace(first.scales[-1], residual_percent=kept.residual.std_percent,
                                     shape_converged=kept.converged,
                                     n_points=int(kept.residual.mask.sum()))
        full = [c.with_extrinsics(s.extrinsics) for c, s in zip(first.cameras, cams)]
        final = conclude(model.mesh, imgs, full, solver, settings, q, quad, normals,
                         kept.residual, first.scales[:-1] + (report,), first.noise.sigma_gray,
                         mask=mask, final=kept.residual, history=first.history,
                         iterations=first.iterations + iterations,
                         time_s=first.time_s + (time.perf_counter() - t0))
    elif level != start:                # calibrating: one more fixed point at the chosen level
        final = measure(model.mesh, images, first.cameras, solver,
                        dataclasses.replace(settings, scales=(finest,)), q0=q)
        final = dataclasses.replace(final, history=first.history + final.history,
                                    iterations=first.iterations + iterations + final.iterations,
                                    time_s=first.time_s + (time.perf_counter() - t0),
                                    scales=first.scales[:-1] + final.scales)
    else:
        final = dataclasses.replace(first, time_s=first.time_s + (time.perf_counter() - t0))
        solver = GeometricRegularization(space, schedule)
    trials = [dataclasses.replace(t, chosen=t is current) for t in trials]
    search = LevelSearch(tuple(trials), level, start, n_levels, kappa,
                         final.time_s - first.time_s)
    logger.info("level search: chose level %d of %d (%d spline dofs; started on level %d), +%.2f s",
                level, n_levels, space.operators[level].shape[0], start, search.time_s)
    return final, solver, search
