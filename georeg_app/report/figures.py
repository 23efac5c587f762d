"""Figures of a run, like the paper's (PNG bytes, matplotlib Agg, no display).

- maps (:mod:`georeg_app.report.maps`): :func:`shape_maps` (Figs. 8-10), :func:`residual_maps`
  (Fig. 12) and :func:`error_maps` (error against the truth, when known);
- :func:`convergence`: residual against iterations and against time normalised by one
  fine-scale iteration (Fig. 11);
- :func:`multiscale_vs_monoscale`: the georeg multiscale and monoscale runs (Fig. 11);
- :func:`shape_errors`: RMS error against the truth (um) and RMS distance to BFP (mm)
  per method.

Every function takes a ``RunResult`` (georeg_app.shape.pipeline) and returns PNG bytes (or None
when the run has nothing to draw). A failed method is drawn in grey and marked "failed";
it never sets a colour scale.
"""
from __future__ import annotations

import logging

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from georeg_app.report.maps import (FAILED_GREY, bfp_frame, cmap_colours, error_maps,  # noqa: F401 (re-exported)
                   nice_scale_factor, png, residual_maps, shape_maps, uncertainty_maps)
from georeg_app.report.run_view import best_method, georeg_pair, is_failed, rms_error_um, succeeded

logger = logging.getLogger(__name__)

__all__ = ["FE_ERROR_RATIO", "convergence", "multiscale_vs_monoscale", "shape_errors",
           "make_figures"]

FE_ERROR_RATIO = 0.3          # the shape claim: georeg error <= 0.3 x FE error


def _label(result) -> str:
    return str(result.spec.label) + (" (failed)" if is_failed(result) else "")


def _history(result, unit_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(iteration count from 1, normalised time, residual %) of a result's history."""
    records = result.measurement.history
    residual = np.array([r.get("residual_percent", np.nan) for r in records], float)
    time = np.array([r.get("time_s", np.nan) for r in records], float) / unit_s
    return np.arange(1, len(records) + 1), time, residual


def _unit(run) -> float:
    unit = float(run.one_fine_iteration_s)
    return unit if unit > 0 else 1.0


def _log_residual_axis(ax) -> None:
    """Log y axis of residuals (%) with plain numbers (2, 3, 10 rather than 2 x 10^0)."""
    ax.set_yscale("log")
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    ax.yaxis.set_major_formatter(plain)
    ax.yaxis.set_minor_formatter(plain)
    ax.set_ylabel("residual std (% of dynamic range)")
    ax.grid(True, which="both", alpha=0.3)


def _not_drawn_note(fig: Figure, run) -> None:
    """Name the failed methods that have no measurement to draw."""
    missing = [r.spec.label for r in run.results if r.measurement is None]
    if missing:
        fig.text(0.01, 0.005, "not drawn (failed, no measurement): " + ", ".join(missing),
                 fontsize=8, color=FAILED_GREY)


def convergence(run) -> bytes | None:
    """Residual (%) against iterations and against time / one fine-scale iteration (Fig. 11);
    one colour per method (by its rank in the run), failed methods dashed grey; None if no
    method has a measurement."""
    if all(r.measurement is None for r in run.results):
        return None
    unit = _unit(run)
    fig = Figure(figsize=(11, 4.2))
    ax_it, ax_t = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for k, result in enumerate(run.results):
        if result.measurement is None:
            continue
        it, t, res = _history(result, unit)
        style = dict(color=FAILED_GREY, ls="--") if is_failed(result) else dict(color=f"C{k % 10}")
        ax_it.plot(it, res, marker=".", label=_label(result), **style)
        ax_t.plot(t, res, marker=".", label=_label(result), **style)
    for ax, xlabel in ((ax_it, "iteration (calibration and shape, all scales)"),
                       (ax_t, "time / one fine-scale iteration")):
        _log_residual_axis(ax)
        ax.set_xlabel(xlabel)
    ax_t.legend(fontsize=8)
    fig.suptitle("Convergence of the gray-level residual")
    _not_drawn_note(fig, run)
    return png(fig)


def multiscale_vs_monoscale(run) -> bytes | None:
    """Residual against normalised time of the georeg multiscale and monoscale runs
    (Fig. 11, right); None if the run lacks one of them or one has no measurement."""
    multi, mono = georeg_pair(run)
    if multi is None or mono is None or multi.measurement is None or mono.measurement is None:
        return None
    unit = _unit(run)
    fig = Figure(figsize=(7, 4.4))
    ax = fig.add_subplot(1, 1, 1)
    for result, style in ((multi, "o-"), (mono, "s-")):
        _, t, res = _history(result, unit)
        scales = np.array([r.get("scale", 0) for r in result.measurement.history])
        line, = ax.plot(t, res, style, markersize=3, label=_label(result))
        fine = scales == 0
        ax.plot(t[fine], res[fine], style[0], color=line.get_color(), markersize=6, alpha=0.5)
    mono_final = float(mono.measurement.residual_percent)
    ax.axhline(mono_final, color="gray", ls="--", lw=1, label=f"monoscale final {mono_final:.3f}%")
    half = 0.5 * float(mono.measurement.time_s) / unit
    ax.axvline(half, color="gray", ls=":", lw=1, label="half the monoscale time")
    _log_residual_axis(ax)
    ax.set_xlabel("time / one fine-scale iteration")
    ax.legend(fontsize=8)
    ax.set_title("georeg: multiscale vs monoscale (large markers: scale 0)")
    return png(fig)


def _bars(ax, x: np.ndarray, values: list, run, colour: str) -> None:
    """Bars of ``values`` with their value (None: no bar); failed methods hatched grey and
    marked, the best method edged in black."""
    best, _ = best_method(run)
    for xi, value, result in zip(x, values, run.results):
        failed = is_failed(result)
        if value is None:
            ax.text(xi, 0.02, "failed" if failed else "n/a", rotation=90, ha="center",
                    va="bottom", fontsize=8, color=FAILED_GREY, transform=ax.get_xaxis_transform())
            continue
        ax.bar(xi, value, 0.6, color=FAILED_GREY if failed else colour,
               hatch="//" if failed else None, alpha=0.6 if failed else 1.0,
               edgecolor="k" if result is best else "none", linewidth=2)
        ax.text(xi, value, ("failed\n" if failed else "") + f"{value:.3g}", ha="center",
                va="bottom", fontsize=8, color=FAILED_GREY if failed else "k")


def shape_errors(run) -> bytes:
    """Bars per method: RMS error against the truth (um, if known) and RMS distance to the
    BFP (mm); failed methods hatched grey, the best method edged in black."""
    labels = [r.spec.label for r in run.results]
    bfp = [None if r.distance_to_bfp_mm is None
           else float(np.sqrt(np.mean(np.square(r.distance_to_bfp_mm)))) for r in run.results]
    x = np.arange(len(labels))
    panels = 2 if run.truth_available else 1
    fig = Figure(figsize=(max(6.0, 1.1 * len(labels)) * panels, 4.2))
    axes = [fig.add_subplot(1, panels, k + 1) for k in range(panels)]
    if run.truth_available:
        ax = axes[0]
        _bars(ax, x, [rms_error_um(r) for r in run.results], run, "C0")
        fe = [r for r in succeeded(run.results) if r.spec.name == "fe" and rms_error_um(r)]
        if fe:
            ax.axhline(FE_ERROR_RATIO * rms_error_um(fe[0]), color="k", ls="--", lw=1,
                       label=f"{FE_ERROR_RATIO:g} x FE error")
            ax.legend(fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel("RMS shape error against the truth (µm)")
        ax.set_title("Error against the truth")
    _bars(axes[-1], x, bfp, run, "C1")
    axes[-1].set_ylabel("RMS distance to best-fit plane (mm)")
    axes[-1].set_title("Distance to the best-fit plane")
    for ax in axes:
        ax.set_xticks(x, labels, rotation=20, ha="right", fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
        lo, hi = ax.get_ylim()                                   # room for the value labels
        ax.set_ylim(lo, hi * (3.0 if ax.get_yscale() == "log" else 1.12))
    fig.suptitle("Shape per method (black edge: best method)")
    return png(fig)


def make_figures(run) -> dict[str, bytes]:
    """All figures of a run, name -> PNG bytes (names are the output file stems); a figure
    with nothing to draw (no error maps without the truth, ...) is left out."""
    candidates = {"shape_maps": shape_maps, "residual_maps": residual_maps,
                  "error_maps": error_maps, "convergence": convergence,
                  "multiscale_vs_monoscale": multiscale_vs_monoscale,
                  "shape_errors": shape_errors, "uncertainty_maps": uncertainty_maps}
    figures = {}
    for name, draw in candidates.items():
        data = draw(run)
        if data is not None:
            figures[name] = data
    return figures
