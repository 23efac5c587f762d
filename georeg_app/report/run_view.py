"""What the report and the figures read from a run, tolerant of failed methods.

A method of a run (``georeg_app.shape.pipeline.MethodResult``) has ``status`` "ok" or "failed"
and a one-line ``failure``; a failed method may have no measurement at all
(``measurement=None``) or carry its best, untrustworthy one. Results without these
fields (older pipelines, the tests' fakes) count as "ok".

- :func:`is_failed`, :func:`failure`, :func:`succeeded`, :func:`measured`: the status;
- :func:`colour_range`: the symmetric colour scale of a map, set by the successful
  methods only (median over methods of the 99th percentile of the absolute values);
- :func:`best_method`: the method highlighted in the report, and by which criterion;
- :func:`rms_error_um`, :func:`node_errors_um`: errors against the truth in micrometres.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

__all__ = ["UM_PER_MM", "is_failed", "failure", "succeeded", "measured", "colour_range",
           "rms_error_um", "node_errors_um", "best_method", "georeg_pair", "georeg_main"]

UM_PER_MM = 1e3


def is_failed(result) -> bool:
    """True if the method failed (``status == "failed"``) or has no measurement."""
    return getattr(result, "status", "ok") == "failed" or result.measurement is None


def failure(result) -> str:
    """The one-line reason of a failed method ("" for a successful one)."""
    if not is_failed(result):
        return ""
    reason = getattr(result, "failure", None)
    if reason:
        return " ".join(str(reason).split())
    return "no measurement" if result.measurement is None else "no reason given"


def succeeded(results: Sequence) -> list:
    """The methods that did not fail (each has a measurement)."""
    return [r for r in results if not is_failed(r)]


def measured(results: Sequence) -> list:
    """The methods that have a measurement to draw (successful or failed with a best state)."""
    return [r for r in results if r.measurement is not None]


def colour_range(results: Sequence, field: Callable[[object], np.ndarray | None],
                 percentile: float = 99.0) -> float:
    """Half-width ``v`` of the symmetric colour scale ``[-v, v]`` of a map.

    The median over the successful methods of the ``percentile`` of ``|field(result)|``
    (non-finite values and None fields skipped): the noise floor of the good methods
    shows, a poor method saturates, and a failed method never sets the scale.
    Returns 1.0 when no successful method gives a positive value.
    """
    tops = []
    for r in succeeded(results):
        values = field(r)
        if values is None:
            continue
        values = np.abs(np.asarray(values, float))
        values = values[np.isfinite(values)]
        if values.size:
            tops.append(float(np.percentile(values, percentile)))
    top = float(np.median(tops)) if tops else 0.0
    return top if top > 0 and math.isfinite(top) else 1.0


def _finite(value) -> bool:
    return value is not None and math.isfinite(float(value))


def rms_error_um(result) -> float | None:
    """RMS shape error against the truth in micrometres (None when unknown)."""
    value = getattr(result, "shape_rms_error_mm", None)
    return float(value) * UM_PER_MM if _finite(value) else None


def node_errors_um(result) -> np.ndarray | None:
    """Per-node signed error against the truth (um), from the optional ``shape_error_mm``."""
    values = getattr(result, "shape_error_mm", None)
    return None if values is None else np.asarray(values, float) * UM_PER_MM


def best_method(run) -> tuple[object | None, str]:
    """The best successful method of ``run`` and the sentence saying why.

    Lowest RMS shape error against the truth when the truth is known, else lowest final
    gray-level residual; (None, reason) when no successful method can be ranked.
    """
    ok = succeeded(run.results)
    if run.truth_available:
        ranked = [(rms_error_um(r), r) for r in ok if rms_error_um(r) is not None]
        if ranked:
            err, best = min(ranked, key=lambda t: t[0])
            return best, (f"Best method: {best.spec.label}, by the lowest RMS shape error "
                          f"against the truth ({err:.3g} µm) among the successful methods.")
    ranked = [(float(r.measurement.residual_percent), r) for r in ok
              if _finite(r.measurement.residual_percent)]
    if not ranked:
        return None, "No best method: no method succeeded."
    res, best = min(ranked, key=lambda t: t[0])
    why = "the truth is unknown" if not run.truth_available else "no shape error is available"
    return best, (f"Best method: {best.spec.label}, by the lowest final gray-level residual "
                  f"({res:.3g}% of the dynamic range) among the successful methods ({why}).")


def georeg_pair(run) -> tuple[object | None, object | None]:
    """(multiscale, monoscale) georeg results of ``run`` with the same fixed levels (None when
    absent): the pair of the multiscale claim."""
    georeg = [r for r in run.results if r.spec.name == "georeg"]
    mono = [r for r in georeg if len(r.spec.scales) == 1]
    multi = [r for r in georeg if len(r.spec.scales) > 1
             and (not mono or getattr(r.spec, "levels", None) == getattr(mono[0].spec, "levels", None))]
    return (multi[0] if multi else None), (mono[0] if mono else None)


def georeg_main(run) -> object | None:
    """The run's first georeg result (the automatic levels when the run has them)."""
    georeg = [r for r in run.results if r.spec.name == "georeg"]
    return georeg[0] if georeg else None
