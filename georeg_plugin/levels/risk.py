"""The expected shape error of each spline level, estimated from one Gauss-Newton system.

An information criterion (:mod:`georeg_plugin.levels.selection`) asks which level is true;
a user asks which estimate is closest. This module estimates, for every level ``s`` of the
nested space (Eq. 13), the expected squared error of its shape at the FE nodes, bias plus
variance, in the node metric (area-weighted mean square, modulo the rigid normal motions
that a comparison of shapes leaves out), and the level of least estimated error is chosen.

With the noise model ``Cov(b) = v H`` of the host code and the step map
``G_s = C_s^T (C_s H C_s^T)^-1 C_s`` (Eqs. 18-21), a level's optimum predicted from the
current state is ``q_s = G_s H q_r`` for any finer level ``r`` (the levels are nested: ``G_s
H G_r = G_s``), so that

    Cov(q_s) = v G_s,        Cov(q_s - q_r) = v (G_r - G_s).

For a node metric ``|x|_M^2 = x^T M x`` the expected error of level ``s`` against the truth
``q*`` is ``|bias_s|_M^2 + v tr(M G_s)``, and the change to the finer reference level is an
unbiased measure of the bias once its own noise is taken off (Stein's unbiased risk
estimate, C. M. Stein, Ann. Statist. 9, 1981, 1135-1151; Mallows' Cp, Technometrics 15,
1973, 661-675, written in the metric of the node values instead of that of the gray levels):

    R_s = |q_s - q_r|_M^2 - v tr(M (G_r - G_s)) + v tr(M G_s)            (estimated risk)

exact in expectation when the reference level ``r`` holds the truth (its own bias is left
out: the reference is the finest level of the space). ``M = W - W U (U^T W U)^-1 U^T W`` with
``W`` the nodes' area weights over their sum and ``U`` the rigid normal modes: the
W-orthogonal projection out of the rigid motions, then the weighted mean square.
"""
from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

__all__ = ["NodeMetric", "estimated_risk", "node_metric"]


@dataclasses.dataclass(frozen=True)
class NodeMetric:
    """The node metric ``M = W - Y Y^T`` of the shape error.

    weights : (n,) the nodes' area weights over their sum (``W = diag(weights)``).
    Y : (n, k) ``W^1/2 Q`` with ``Q`` an orthonormal basis of ``W^1/2 U`` (``U`` the rigid
        normal modes); ``Y Y^T`` is the weighted mean square's rigid part.
    """

    weights: np.ndarray
    Y: np.ndarray

    def norm2(self, d: np.ndarray) -> float:
        """``d^T M d``: the weighted mean square of the nodal field ``d`` (n,) once its rigid
        normal part is taken off (mm^2)."""
        d = np.asarray(d, dtype=float)
        return float(np.dot(self.weights * d, d) - np.sum((self.Y.T @ d) ** 2))

    def trace(self, diag: np.ndarray, apply: Callable[[np.ndarray], np.ndarray]) -> float:
        """``tr(M G)`` for a symmetric ``G`` (n, n) given by its diagonal and its action
        ``V -> G V`` (the ``step_covariance`` of a step solver)."""
        return float(np.dot(self.weights, diag) - np.sum(self.Y * apply(self.Y)))


def node_metric(weights: np.ndarray, modes: np.ndarray | None = None) -> NodeMetric:
    """The metric of :class:`NodeMetric` from nodal weights (n,) (areas) and optional modes
    (n, k) to leave out (the rigid normal motions; rank-deficient sets are reduced)."""
    w = np.asarray(weights, dtype=float)
    if w.ndim != 1 or not np.all(np.isfinite(w)) or np.any(w < 0) or not w.sum() > 0:
        raise ValueError("node_metric: the weights must be finite, non-negative, not all zero")
    w = w / w.sum()
    if modes is None:
        return NodeMetric(w, np.zeros((w.size, 0)))
    sw = np.sqrt(w)
    Q, sv, _ = np.linalg.svd(np.asarray(modes, float) * sw[:, None], full_matrices=False)
    Q = Q[:, sv > 1e-10 * sv.max()] if sv.size and sv.max() > 0 else Q[:, :0]
    return NodeMetric(w, Q * sw[:, None])


def estimated_risk(change: np.ndarray, trace_level: float, trace_reference: float,
                   variance: float, metric: NodeMetric) -> tuple[float, float]:
    """The estimated mean square shape error of a level and its variance part (mm^2).

    Parameters
    ----------
    change : (n,) ``q_s - q_r``, the level's optimum minus the reference level's.
    trace_level, trace_reference : ``tr(M G_s)`` and ``tr(M G_r)`` per unit noise.
    variance : ``v`` of ``Cov(b) = v H``.
    metric : the node metric ``M``.

    Returns
    -------
    (risk, variance part): ``R_s`` of the module docstring and ``v tr(M G_s)``. The bias
    part ``R_s - v tr(M G_s)`` is clipped at zero: a negative estimate of a square says
    only that the bias is below the noise of its measure.
    """
    spread = float(variance) * float(trace_level)
    bias2 = metric.norm2(change) - float(variance) * (float(trace_reference) - float(trace_level))
    return spread + max(bias2, 0.0), spread
