"""An information criterion on the nested spline levels, recorded beside the estimated error.

The level search chooses the level of least estimated shape error
(:mod:`georeg_plugin.levels.risk`); this module gives the record it keeps per level, the
:class:`LevelTrial`, and the Hannan-Quinn criterion it chose by until then (it answers which
level is true, not which estimate is closest: on a plate whose waviness the next level holds
at 2.3 noise variances per added dof it kept the coarser level, 30 % farther from the truth).

The levels ``s = n - 1 (coarsest) .. 0 (finest)`` are nested (Eq. 13): a finer level holds
every shape of a coarser one, so the fit cost ``c_s`` (Eq. 7) can only fall as the level
gets finer, part of the fall being a fit of the noise. With the noise model
``Cov(b) = kappa H`` of the host code (``kappa`` estimated from the images), the fall that
the noise alone produces when going from ``m`` to ``m'`` spline dofs is ``kappa (m' - m)``
in expectation (``E[b^T G_s b] = kappa tr(G_s H) = kappa m_s`` for the step map
``G_s = C_s^T (C_s H C_s^T)^-1 C_s``). The level minimises the Hannan-Quinn information
criterion (E. J. Hannan and B. G. Quinn, "The determination of the order of an
autoregression", J. R. Stat. Soc. B 41, 1979),

    HQ_s = c_s + kappa m_s 2 ln(ln N),        N the number of integration points seen,

i.e. a finer level is taken when its fall of the cost per added dof exceeds
``2 ln ln N`` times ``kappa`` (about 5.2 for a megapixel pair; noise alone gives 1 with a
spread of ``sqrt(2 / added dofs)``). Like Schwarz's BIC (penalty ``ln N``, about 13.6) it
is consistent, it does not keep adding levels as the data grow, but its penalty is the
slowest-growing one that is. Mallows' Cp / AIC (penalty 2) minimise the error of
predicting the gray levels and would fit the image model's misfit as shape wherever that
misfit is structured. Measured on renders with known truth (``benchmarks/bench_levels.py``,
``benchmarks/bench_vs_pyvale.py``), once the points along the specimen's edges are left out
(:mod:`fesdic_core.residual.edges`) the image model's misfit no longer looks like shape: on a flat
plate the finer levels gain 0.3-1.3 ``kappa`` per dof, as noise does, while a real feature
at the noise's edge gains more (a smooth bump of sigma 16 mm under 2 gray levels of noise,
demo scale: 10 ``kappa`` per dof from 100 to 324 dofs), which BIC refused (0.99 um of shape
error against 0.34 um at the finer level) and Hannan-Quinn takes. Clear features gain
hundreds to hundreds of thousands.

The cost at every other level, finer or coarser, is first predicted from the current
Gauss-Newton system (``c_s' ~= c - b^T G_s' b`` for a finer level; for any level, the
quadratic model at the level's own optimum; exact for a linear problem); the level of
lowest predicted criterion is iterated and its measured criterion decides. A coarser
level is taken when the rise of the cost per removed dof is below ``2 ln ln N`` kappa: a
shape that a coarser space holds (a flat plate) is not left with the noise that finer
dofs fit.
"""
from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["LevelTrial", "information_criterion", "noise_gain", "penalty_per_dof", "predicted_fit"]


@dataclasses.dataclass(frozen=True)
class LevelTrial:
    """One spline level looked at by the search.

    level : index in the multilevel space (0 = finest).
    dofs : its number of spline dofs ``m_s``.
    chi_square : the fit cost ``c_s`` (Eq. 7), measured or predicted.
    criterion : the information criterion ``c_s + kappa m_s 2 ln(ln N)`` (Hannan-Quinn).
    residual_percent : the residual's standard deviation (measured, or predicted from ``c_s``).
    measured : True when iterated to convergence at this level, False when predicted.
    gain : the statistic: the fall of ``c`` from the level the search stood on, per added
        dof, in units of ``kappa`` (the criterion prefers the finer level when it exceeds
        ``2 ln ln N``; noise alone gives about 1); for a coarser level, the rise of ``c`` per
        removed dof (the coarser level is preferred when it is below ``2 ln ln N``). NaN for the
        starting level.
    chosen : the level the search ended on.
    variance : the noise variance ``kappa`` of ``criterion`` and ``gain``.
    error_mm : the estimated RMS shape error at the nodes, bias and noise (mm; modulo the
        rigid normal motions; :func:`~georeg_plugin.levels.risk.estimated_risk` against the
        next finer level).
    std_mm : its noise part, ``sqrt(v tr(M G_s))`` (mm).
    agreement : the largest change to a finer level in standard deviations of that change
        (:func:`~georeg_plugin.levels.risk.agreement`): the search chooses the coarsest level
        where it is at most 2.
    """

    level: int
    dofs: int
    chi_square: float
    criterion: float
    residual_percent: float
    measured: bool
    gain: float = float("nan")
    chosen: bool = False
    variance: float = float("nan")
    error_mm: float = float("nan")
    std_mm: float = float("nan")
    agreement: float = float("nan")


def penalty_per_dof(n_points: int) -> float:
    """``2 ln(ln N)``: the fall of the cost per added dof, in units of ``kappa``, that a finer
    level must exceed (Hannan-Quinn; noise alone gives about 1)."""
    return 2.0 * float(np.log(np.log(max(int(n_points), 16))))


def information_criterion(chi_square: float, dofs: int, variance: float, n_points: int) -> float:
    """``c + kappa m 2 ln(ln N)`` (the Hannan-Quinn information criterion, up to a constant)."""
    return float(chi_square) + penalty_per_dof(n_points) * float(variance) * int(dofs)


def predicted_fit(chi_square: float, b: np.ndarray, step: np.ndarray, H=None) -> float:
    """The cost after a step ``d`` from the current state, by the Gauss-Newton model of Eq. 8.

    ``c - 2 b.d + d^T H d`` for any ``d`` (``H`` given): a move to a coarser level, whose
    optimum is ``d = G_s (b + H q) - q``; without ``H``, ``d`` must be the Gauss-Newton
    step ``d = G_s b`` of a finer level, and the cost is ``c - b.d`` (``G H G = G``).
    """
    b, step = np.asarray(b, float), np.asarray(step, float)
    if H is None:
        return float(chi_square) - float(np.dot(b, step))
    return float(chi_square) - 2.0 * float(np.dot(b, step)) + float(np.dot(step, H @ step))


def noise_gain(chi_square_from: float, dofs_from: int, chi_square_to: float, dofs_to: int,
               variance: float) -> float:
    """The fall of ``c`` per added dof in units of ``kappa`` (see :class:`LevelTrial`); to a
    coarser level, the rise of ``c`` per removed dof (the criterion prefers the coarser level
    when it is below :func:`penalty_per_dof`)."""
    added = int(dofs_to) - int(dofs_from)
    if added == 0 or not variance > 0:
        return float("nan")
    return (float(chi_square_from) - float(chi_square_to)) / (float(variance) * added)
