"""The expected shape error of each spline level, estimated from one Gauss-Newton system.

An information criterion (:mod:`georeg_plugin.levels.selection`) asks which level is true;
a user asks which estimate is closest. This module estimates, for every level ``s`` of the
nested space (Eq. 13), the expected squared error of its shape at the FE nodes, bias plus
variance, in the node metric (area-weighted mean square, modulo the rigid normal motions
that a comparison of shapes leaves out), and chooses the level (below).

With the noise model ``Cov(b) = v H`` of the host code and the step map
``G_s = C_s^T (C_s H C_s^T)^-1 C_s`` (Eqs. 18-21), a level's optimum predicted from the
current state is ``q_s = G_s H q_r`` for any finer level ``r`` (the levels are nested: ``G_s
H G_r = G_s``), so that

    Cov(q_s) = v G_s,        Cov(q_s - q_r) = v (G_r - G_s).

For a node metric ``|x|_M^2 = x^T M x`` the expected error of level ``s`` against the truth
``q*`` is ``|bias_s|_M^2 + v tr(M G_s)``, and the change to the finer reference level is an
unbiased measure of the bias once its own noise is taken off (Stein's unbiased risk
estimate, C. M. Stein, Ann. Statist. 9, 1981, 1135-1151; Mallows' Cp, Technometrics 15,
1973, 661-675, written in the metric of the node values instead of that of the gray levels)::

    R_s = |q_s - q_r|_M^2 - v tr(M (G_r - G_s)) + v tr(M G_s)            (estimated risk)

exact in expectation when the reference level ``r`` holds the truth and the noise model
holds. Measured on the demo's plate, it does not hold at the finest levels: their error is
a misfit of the image model, 2 to 4 times the noise the model predicts, so that the change
of any coarser level to them reads as that level's bias. Which of the two levels is off, a
change alone cannot tell. So the level is chosen by the balancing principle (O. V. Lepskii,
Theory Probab. Appl. 35, 1990, 454-466): the coarsest level whose shape agrees with every
finer level's to within ``tolerance`` (2) standard deviations of their difference
(:func:`agreement`, :func:`balanced_level`)::

    z_s = max_{r < s} |q_s - q_r|_M / sqrt(v tr(M (G_r - G_s))) <= 2        (agreement)

A level whose bias exceeds the noise of its change to a finer level fails; a finer level's
own misfit fails no coarser level unless it is large. The chosen level's error is estimated
against the next finer level (:func:`level_risks` with ``reference = "next"``), which agrees
with it: ``R_s`` above with ``r = s - 1``.

``M = W - W U (U^T W U)^-1 U^T W`` with ``W`` the nodes' area weights over their sum and
``U`` the rigid normal modes: the W-orthogonal projection out of the rigid motions, then the
weighted mean square.

**The variance in the node metric.** ``v`` comes from the gray levels (the images' noise,
or the share per dof of the image model's misfit, Eq. 7's metric). A misfit concentrated
where the dofs are poorly determined (mixed pixels along an outline or a hole, the
interpolation of the finest texture) costs little in gray levels but moves those nodes far:
measured on the demo's plate at half resolution, the finest level's error at its worst
nodes was 3 to 4 times its predicted std and the same for two draws of the noise (a misfit,
not noise). It is measured where no shape is expected, on the dofs that the FE mesh adds
beyond the finest spline level, in the metric of the risk itself (:func:`shape_variance`):
the change from that level to the FE step against its predicted variance.
"""
from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from georeg_plugin.levels.solver import _seen_dofs

__all__ = ["NodeMetric", "agreement", "balanced_level", "estimated_risk", "level_risks",
           "node_metric", "shape_variance"]

#: the balancing principle's tolerance: standard deviations of the change between two levels
AGREEMENT_TOLERANCE = 2.0


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


def level_risks(moves: dict, traces: dict, variance: float, metric: NodeMetric,
                reference: str = "all") -> dict[int, tuple[float, float]]:
    """Every level's estimated risk against finer levels.

    Parameters
    ----------
    moves : level -> (n,) step to its optimum from the current state (0 = the finest; a
        level ``r < s`` is finer than ``s`` and nested with it, Eq. 13).
    traces : level -> ``tr(M G_s)`` per unit noise.
    variance, metric : as for :func:`estimated_risk`.
    reference : ``"all"``: every finer level serves as the reference and the largest risk is
        kept (the finest level holds the most of the truth, but its noise can hide a bias
        that a less noisy finer level shows); ``"next"``: the next finer level only.

    Returns
    -------
    level -> (risk, variance part) (mm^2): :func:`estimated_risk` (the finest level: its
    variance alone).
    """
    if reference not in ("all", "next"):
        raise ValueError(f"level_risks: reference must be 'all' or 'next', got {reference!r}")
    levels = sorted(moves)
    out = {}
    for k, s in enumerate(levels):
        finer = levels[:k] if reference == "all" else levels[max(k - 1, 0):k]
        out[s] = max((estimated_risk(moves[s] - moves[r], traces[s], traces[r], variance, metric)
                      for r in finer), default=(float(variance) * float(traces[s]),) * 2)
    return out


def agreement(moves: dict, traces: dict, variance: float, metric: NodeMetric) -> dict[int, float]:
    """Each level's largest change to a finer level, in standard deviations of that change.

    Parameters
    ----------
    moves, traces, variance, metric : as for :func:`level_risks`.

    Returns
    -------
    level -> ``z_s = max_{r < s} |q_s - q_r|_M / sqrt(v tr(M (G_r - G_s)))`` (0 for the
    finest level; inf where a change has no predicted noise but is not zero).
    """
    levels = sorted(moves)
    out = {}
    for k, s in enumerate(levels):
        z = 0.0
        for r in levels[:k]:
            change = metric.norm2(moves[s] - moves[r])
            noise = float(variance) * (float(traces[r]) - float(traces[s]))
            z = max(z, float(np.sqrt(max(change, 0.0) / noise)) if noise > 0 else
                    (np.inf if change > 0 else 0.0))
        out[s] = z
    return out


def balanced_level(z: dict[int, float], tolerance: float = AGREEMENT_TOLERANCE) -> int:
    """The coarsest level whose :func:`agreement` ``z`` is at most ``tolerance`` (the
    balancing principle; the finest level always agrees with itself)."""
    return max(s for s, zs in z.items() if zs <= tolerance or s == min(z))


def shape_variance(H, b: np.ndarray, finest_step: np.ndarray, trace_finest: float,
                   variance: float, metric: NodeMetric, probes: int = 32,
                   seed: int = 0) -> float:
    """The noise variance seen in the node metric: ``v``, or more if the FE's own dofs say so.

    Parameters
    ----------
    H, b : (n, n) sparse, (n,) the Gauss-Newton system at the current state (Eq. 8).
    finest_step : (n,) the step to the finest spline level's optimum (``G_0 (b + H q) - q``).
    trace_finest : ``tr(M G_0)`` per unit noise.
    variance : ``v`` of the gray levels (the noise model, or the criterion's effective one).
    metric : the node metric ``M``.
    probes : Rademacher probes of the Hutchinson estimate of ``tr(M H^-1)`` (M. F. Hutchinson,
        Commun. Stat. Simul. 18, 1989, 1059-1076); its relative precision is a few percent.

    Returns
    -------
    ``v * max(1, |d_FE - d_0|_M^2 / (v tr(M (H^-1 - G_0))))`` with ``d_FE = H^-1 b`` the FE
    step over the dofs a point sees: the change to the FE mesh's dofs beyond the finest
    level is noise and misfit only (they hold no shape: sub-element oscillations), and its
    size in the node metric against the prediction scales the variance of every level.
    """
    H = sps.csc_matrix(H)
    seen = _seen_dofs(H)
    if not seen.any() or not variance > 0:
        return float(variance)
    lu = spla.splu(H[seen][:, seen])
    d_fe = np.zeros(H.shape[0])
    d_fe[seen] = lu.solve(np.asarray(b, float)[seen])
    rng = np.random.default_rng(seed)
    z = rng.choice([-1.0, 1.0], size=(int(np.count_nonzero(seen)), probes))
    sw = np.sqrt(metric.weights[seen])[:, None]
    trace_w = float(np.mean(np.sum(sw * z * lu.solve(sw * z), axis=0)))         # tr(W H^-1)
    Y = metric.Y[seen]
    trace_fe = trace_w - float(np.sum(Y * lu.solve(Y))) if Y.shape[1] else trace_w
    predicted = float(variance) * (trace_fe - float(trace_finest))
    if not predicted > 0:
        return float(variance)
    return float(variance) * max(1.0, metric.norm2(d_fe - finest_step) / predicted)
