"""Choosing the spline level from the data: Mallows' Cp on the nested levels (Eq. 13).

The levels ``s = n - 1 (coarsest) .. 0 (finest)`` are nested (Eq. 13): a finer level holds
every shape of a coarser one, so the fit cost ``c_s`` (Eq. 7) can only fall as the level
gets finer, part of the fall being a fit of the noise. With the noise model
``Cov(b) = kappa H`` of the host code (``kappa`` estimated from the images), the fall that
the noise alone produces when going from ``m`` to ``m'`` spline dofs is ``kappa (m' - m)``
in expectation (``E[b^T G_s b] = kappa tr(G_s H) = kappa m_s`` for the step map
``G_s = C_s^T (C_s H C_s^T)^-1 C_s``). Mallows' Cp (C. L. Mallows, "Some comments on Cp",
Technometrics 15, 1973), the unbiased estimate of the prediction risk up to a constant,

    Cp_s = c_s + 2 kappa m_s,

is smallest at the level beyond which the data add less than twice the noise's share.
For the jump of ``dm`` dofs between two levels, noise alone passes the test
``c_s - c_s' > 2 kappa dm`` with probability ``P(chi2(dm) > 2 dm)``: 8 % for 9 dofs,
below 1e-3 from 60 dofs on; a real feature lowers ``c`` by far more than its dofs' share.

The fall to each finer level is first predicted from the current Gauss-Newton system
(``c_s' ~= c - b^T G_s' b``, exact for a linear problem); only the level with the
smallest predicted Cp is iterated and its measured Cp decides.
"""
from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["LevelTrial", "mallows_cp", "noise_gain", "predicted_fit"]


@dataclasses.dataclass(frozen=True)
class LevelTrial:
    """One spline level looked at by the search.

    level : index in the multilevel space (0 = finest).
    dofs : its number of spline dofs ``m_s``.
    chi_square : the fit cost ``c_s`` (Eq. 7), measured or predicted.
    cp : Mallows' Cp, ``c_s + 2 kappa m_s``.
    residual_percent : the residual's standard deviation (measured, or predicted from ``c_s``).
    measured : True when iterated to convergence at this level, False when predicted.
    gain : the statistic: the fall of ``c`` from the level the search stood on, per added
        dof, in units of ``kappa`` (Cp prefers the finer level when it exceeds 2; noise
        alone gives about 1). NaN for the starting level.
    chosen : the level the search ended on.
    variance : the noise variance ``kappa`` of ``cp`` and ``gain``.
    """

    level: int
    dofs: int
    chi_square: float
    cp: float
    residual_percent: float
    measured: bool
    gain: float = float("nan")
    chosen: bool = False
    variance: float = float("nan")


def mallows_cp(chi_square: float, dofs: int, variance: float) -> float:
    """``c + 2 kappa m`` (Mallows' Cp, up to a constant)."""
    return float(chi_square) + 2.0 * float(variance) * int(dofs)


def predicted_fit(chi_square: float, b: np.ndarray, step: np.ndarray) -> float:
    """The cost after the Gauss-Newton step ``step = G b`` (Eq. 8): ``c - b . d``
    (``c - 2 b.d + d^T H d`` with ``G H G = G``)."""
    return float(chi_square) - float(np.dot(b, step))


def noise_gain(chi_square_from: float, dofs_from: int, chi_square_to: float, dofs_to: int,
               variance: float) -> float:
    """The fall of ``c`` per added dof in units of ``kappa`` (see :class:`LevelTrial`)."""
    added = int(dofs_to) - int(dofs_from)
    if added <= 0 or not variance > 0:
        return float("nan")
    return (float(chi_square_from) - float(chi_square_to)) / (float(variance) * added)
