"""The spline levels of a displacement chosen from the data, once per series.

The displacement's geometric regularization solves each Gauss-Newton step in ``kron(C_s, I3)``
(the spline levels of one component, :func:`~adapters.fesdic_core.displacement_space`). Which
level a series needs depends on the loading: a twist holds in the coarse nominal spline, a
waviness needs finer levels. The choice follows the shape's (:mod:`adapters.level_search`,
:mod:`georeg_plugin.levels.risk`), on one frame:

1. The frame is measured with ``start_levels`` fixed levels (one more, up to the ladder's
   finest, while the measurement fails: a space too coarse for the field, e.g. a large strain,
   leaves a residual the noise does not explain); the Gauss-Newton system ``(H, b)`` of its
   last step at the finest image scale is kept (the solve hook sees it).
2. From that system the optimum of every level of the ladder (the nominal spline refined
   dyadically until the mesh no longer reproduces it, Eq. 16) is predicted (Eq. 21 at the
   level): ``d_s = G_s (b + H u) - u``.
3. The noise variance ``v`` of ``Cov(b) = v H`` is measured on the dofs that the FE mesh
   adds beyond the finest level (they hold no displacement, only noise and the image
   model's misfit): ``v = b^T (H^-1 - G_0) b / (n_FE - m_0)``, unbiased for pure noise
   (:func:`~adapters.level_search.effective_variance`).
4. The coarsest level whose field agrees with every finer level's to within two standard
   deviations of their change (node metric: area-weighted mean square over the nodes and
   the three components) is the series' level (:func:`~georeg_plugin.levels.risk.agreement`,
   the balancing principle).

A series stays on one space: the level is chosen on one frame and kept
(:func:`georeg_app.series.levels.with_chosen_levels` takes the series' last).
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import numpy as np
import scipy.sparse as sps

from fesdic_core.displacement.driver import DisplacementReference, measure_displacement
from fesdic_core.fe.mesh import nodal_areas
from georeg_plugin.levels.risk import (AGREEMENT_TOLERANCE, agreement, balanced_level,
                                       level_risks, node_metric)
from georeg_plugin.levels.solver import GeometricRegularization

from adapters.fesdic_core import NominalModel, displacement_space, legacy_mesh_holds
from adapters.level_search import effective_variance, seen_level_dofs

logger = logging.getLogger(__name__)

__all__ = ["DisplacementLevels", "choose_displacement_levels", "max_displacement_levels"]

#: the most levels tried for a ladder (the nominal and five dyadic refinements)
MAX_LEVELS = 6


@dataclasses.dataclass(frozen=True)
class DisplacementLevels:
    """The record of a displacement's level choice.

    levels : the chosen number of levels (the ``levels`` of a fixed run: its finest level is
        the nominal spline refined ``levels - 1`` times).
    start_levels : the levels the frame was measured with (the system the choice is made on).
    dofs : (n_levels,) spline dofs of each level of the ladder, coarse to fine.
    agreement : (n_levels,) each level's largest change to a finer level, in standard
        deviations of that change, coarse to fine.
    error_mm, std_mm : (n_levels,) each level's estimated RMS displacement error over the
        nodes and components (against the next finer level) and its noise part (mm).
    variance : the noise variance ``v`` of ``Cov(b) = v H``.
    frame : the frame the choice was made on (its cam0 file).
    """

    levels: int
    start_levels: int
    dofs: tuple
    agreement: tuple
    error_mm: tuple
    std_mm: tuple
    variance: float
    frame: str

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


class _LastSystem:
    """A step solver that remembers the last system it solved at each scale."""

    def __init__(self, solver):
        self.solver, self.systems = solver, {}

    def solve(self, H, b, q, scale):
        self.systems[int(scale)] = (H, np.asarray(b, float).copy(), np.asarray(q, float).copy())
        return self.solver.solve(H, b, q, scale)


def max_displacement_levels(model: NominalModel, cap: int = MAX_LEVELS) -> int:
    """The most dyadic levels whose finest the FE mesh reproduces (Eq. 16), at most ``cap``;
    on a legacy mesh (no node parameters, e.g. a region of interest's) the finest level has at
    most a quarter as many dofs per component as the mesh has nodes, as the shape's ladder
    (:func:`~adapters.fesdic_core.legacy_mesh_holds`)."""
    levels = 1
    for n in range(2, int(cap) + 1):
        try:
            space = displacement_space(model, n)
        except ValueError:
            break
        dofs = space.operators[0].shape[0] // 3                        # per component
        if model.uv is None and not legacy_mesh_holds(dofs, model.mesh.n_nodes):
            break
        levels = n
    return levels


def choose_displacement_levels(model: NominalModel, reference: DisplacementReference,
                               images: Sequence, start_levels: int = 2,
                               tolerance: float = AGREEMENT_TOLERANCE, frame: str = "",
                               U0: np.ndarray | None = None) -> DisplacementLevels:
    """Choose the displacement's spline levels on one deformed frame (module docstring).

    Parameters
    ----------
    model : the reference's nominal spline and FE mesh.
    reference : the displacement reference (surface, cameras, reference pair, settings).
    images : the frame's two deformed full-resolution images.
    start_levels : the fixed levels the frame is first measured with (then finer ones while
        the measurement fails).
    tolerance : the agreement tolerance (standard deviations).
    frame : the frame's name, for the record.
    U0 : (n, 3) the frame's starting field (default zero).

    Returns
    -------
    DisplacementLevels. If the measurement fails at every level up to the finest, the start
    levels are kept (the frame, not the space, is wrong; the log says why).
    """
    top = max_displacement_levels(model)
    quick = dataclasses.replace(reference, settings=dataclasses.replace(reference.settings,
                                                                         uncertainty=False))
    finest = reference.settings.scales[-1]
    first = min(int(start_levels), top)
    for start_levels in range(first, top + 1):
        recorder = _LastSystem(GeometricRegularization(displacement_space(model, start_levels)))
        m = measure_displacement(quick, images, recorder, U0)         # (its system, not its std)
        if m.ok or start_levels == top:
            break
        # the space may not hold the frame's field: the next finer one is measured
        logger.info("displacement levels: %d levels do not measure the frame (%s); trying %d",
                    start_levels, m.failure, start_levels + 1)
    if not m.ok or finest not in recorder.systems or top == 1:
        # no level measures it: the frame, not the space, is wrong; the series' start is kept
        logger.info("displacement levels: kept %d (%s)", first,
                    m.failure or "no finer level to choose from")
        return DisplacementLevels(first, first, (), (), (), (), float("nan"), frame)
    H, b, u = recorder.systems[finest]
    H = sps.csr_matrix(H)
    ladder = displacement_space(model, top)                  # level j: `levels` = top - j
    solvers = [GeometricRegularization(ladder, {finest: j}) for j in range(top)]
    moves = {j: s.solve(H, b, u, finest) for j, s in enumerate(solvers)}   # G_j (b + H u) - u
    # u lies in the finest level (the levels are nested, Eq. 13): moves[0] = G_0 b
    variance = effective_variance(H, b, 0.0, moves[0], seen_level_dofs(ladder, 0, H))
    metric = node_metric(np.repeat(nodal_areas(reference.mesh), 3))
    traces = {j: metric.trace(*s.step_covariance(H, finest)) for j, s in enumerate(solvers)}
    z = agreement(moves, traces, variance, metric)
    risks = level_risks(moves, traces, variance, metric, reference="next")
    chosen = balanced_level(z, tolerance)
    levels = top - chosen
    coarse_to_fine = list(range(top - 1, -1, -1))
    record = DisplacementLevels(
        levels, start_levels, tuple(int(ladder.operators[j].shape[0]) for j in coarse_to_fine),
        tuple(float(z[j]) for j in coarse_to_fine),
        tuple(float(np.sqrt(risks[j][0])) for j in coarse_to_fine),
        tuple(float(np.sqrt(risks[j][1])) for j in coarse_to_fine), float(variance), frame)
    logger.info("displacement levels: %d of %d (agreement with the finer levels, coarse to "
                "fine: %s std; noise variance %.3g)", levels, top,
                ", ".join(f"{a:.3g}" for a in record.agreement), variance)
    return record
