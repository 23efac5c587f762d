"""The Levenberg-Marquardt guard shared by the shape (Eq. 7) and calibration (Eq. 6) steps.

A Gauss-Newton step is taken with the damping factor ``mu`` in force (``mu = 0``: the
plain step). A step that raises the residual by more than :data:`ACCEPT_RTOL` is refused
and proposed again with ``mu`` ten times larger; after an accepted step ``mu`` shrinks
tenfold (:func:`relaxed`). The residual therefore never grows: this is the divergence guard.
"""
from __future__ import annotations

from typing import Callable, TypeVar

__all__ = ["ACCEPT_RTOL", "MU_START", "damped_step", "relaxed"]

#: a step is accepted unless it raises the residual by more than this fraction: below it,
#: differences are round-off and the per-element normalisation that Gauss-Newton does not
#: differentiate (Remark 2), not a worse fit
ACCEPT_RTOL = 1e-6
#: the first non-zero damping factor
MU_START = 1e-4

Step = TypeVar("Step", bound=tuple)


def damped_step(propose: Callable[[float], Step | None], std_percent: float, mu: float,
                max_damping: int,
                cost: Callable[[object], float] | None = None) -> tuple[Step | None, float]:
    """First step of ``propose(mu)``, ``propose(10 mu)``, ... that does not raise the residual.

    ``propose(mu)`` returns a tuple whose last item is the residual at the step's end (a
    :class:`~fesdic_core.residual.graylevel.GrayLevelResidual`), or None for an unusable step.
    ``cost(residual)``: what must not grow, and ``std_percent`` its value at the start
    (default: the residual's ``std_percent``).
    Returns the accepted step and the ``mu`` it was taken with, or ``(None, mu)`` when
    ``max_damping`` increases did not find one (the state is stagnant).
    """
    for _ in range(max_damping + 1):
        step = propose(mu)
        value = None if step is None else (step[-1].std_percent if cost is None
                                           else cost(step[-1]))
        if value is not None and value <= std_percent * (1.0 + ACCEPT_RTOL):
            return step, mu
        mu = max(10.0 * mu, MU_START)
    return None, mu


def relaxed(mu: float) -> float:
    """The damping after an accepted step: ten times smaller, down to 0 (Gauss-Newton)."""
    return mu / 10.0 if mu > 1e-8 else 0.0
