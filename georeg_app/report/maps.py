"""Maps of a run, one panel per method, one colour scale per figure (PNG bytes).

- :func:`shape_maps`: measured shapes coloured by the distance to the best-fit plane (BFP),
  out-of-plane exaggerated by a deformation scale factor (Figs. 8-10);
- :func:`residual_maps`: gray-level residual per integration point in % of the dynamic
  range of the images, over the specimen (Fig. 12);
- :func:`error_maps`: signed error against the truth per node (um), when known.

A failed method is drawn with a grey "FAILED: <reason>" title (its best state, if it has
one) or as an empty panel saying why; it never sets a colour scale
(:func:`georeg_app.report.run_view.colour_range`).
"""
from __future__ import annotations

import io
import logging
import math
import textwrap

import matplotlib
import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.colors import Normalize, SymLogNorm
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers the 3-D projection)
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from georeg_app.report.run_view import (colour_range, failure, is_failed, measured, node_errors_um,
                                        succeeded)

logger = logging.getLogger(__name__)

__all__ = ["DPI", "FAILED_GREY", "png", "grid", "bfp_frame", "nice_scale_factor",
           "cmap_colours", "title", "plan_figure", "shape_maps", "residual_maps", "error_norm",
           "error_maps", "uncertainty_maps"]

DPI = 110
FAILED_GREY = "0.45"
_CORNERS = {"quad": 4, "triangle": 3}


def png(fig: Figure) -> bytes:
    """The figure as PNG bytes."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI, bbox_inches="tight")
    return buffer.getvalue()


def grid(n: int, ncols: int = 3) -> tuple[int, int]:
    """(rows, columns) of a grid of ``n`` panels, at most ``ncols`` wide."""
    ncols = max(1, min(ncols, n))
    return math.ceil(n / ncols), ncols


def bfp_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre (3,) and axes (3, 3) (rows e1, e2, n) of the best-fit plane of ``points`` (n, 3).

    ``e1`` is the direction of largest extent (sign: towards +x), ``n`` points towards +z.
    """
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    e1, n = vt[0], vt[2]
    e1 = -e1 if e1[0] < 0 else e1
    n = -n if n[2] < 0 else n
    return centre, np.array([e1, np.cross(n, e1), n])


def nice_scale_factor(extent_mm: float, max_distance_mm: float, fraction: float = 0.2) -> float:
    """Deformation scale factor (1, 2 or 5 x 10^k) making the largest distance to the BFP
    about ``fraction`` of the specimen extent."""
    if max_distance_mm <= 0 or not np.isfinite(max_distance_mm):
        return 1.0
    raw = fraction * extent_mm / max_distance_mm
    k = math.floor(math.log10(raw))
    return max(m * 10.0 ** k for m in (1, 2, 5) if m * 10.0 ** k <= raw)


def cmap_colours(cmap: str, norm: Normalize, values: np.ndarray) -> np.ndarray:
    """RGBA colours (n, 4) of ``values`` under a named colormap and a norm."""
    return matplotlib.colormaps[cmap](norm(values))


def title(ax, result, text: str) -> None:
    """Panel title: the label and ``text``; grey with the reason for a failed method."""
    if is_failed(result):
        reason = textwrap.fill(f"FAILED: {failure(result)}", 48)
        ax.set_title(f"{result.spec.label}\n{reason}", fontsize=8, color=FAILED_GREY)
    else:
        ax.set_title(f"{result.spec.label}\n{text}", fontsize=9)


def _empty_panel(ax, result) -> None:
    """A failed method without measurement: its label and reason, nothing drawn."""
    ax.set_axis_off()
    text = f"{result.spec.label}\n" + textwrap.fill(f"FAILED: {failure(result)}", 40)
    ax.text(0.5, 0.5, text,
            ha="center", va="center", fontsize=9, color=FAILED_GREY, transform=ax.transAxes)


def plan_figure(results, span: np.ndarray) -> tuple[Figure, list]:
    """A figure with one plan-view panel per method (aspect ``span``); returns it and the
    ``(ax, result)`` pairs of the methods that have a measurement (the others get
    :func:`_empty_panel`)."""
    nrows, ncols = grid(len(results))
    fig = Figure(figsize=(4.6 * ncols, (4.6 * span[1] / span[0] + 0.9) * nrows))
    panels = []
    for k, result in enumerate(results):
        ax = fig.add_subplot(nrows, ncols, k + 1)
        if result.measurement is None:
            _empty_panel(ax, result)
        else:
            panels.append((ax, result))
    return fig, panels


def _reference_frame(results) -> tuple[np.ndarray, np.ndarray]:
    """BFP frame of the first successful measurement (else the first measurement)."""
    ranked = sorted(measured(results), key=is_failed)
    return bfp_frame(np.asarray(ranked[0].measurement.nodes, float))


def _colour_bar(fig: Figure, cmap: str, norm: Normalize, label: str,
                ticks: list[float] | None = None) -> None:
    """One colour bar for all the panels, with arrows (values beyond the scale saturate)."""
    mappable = matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap)
    bar = fig.colorbar(mappable, ax=fig.axes, shrink=0.7, label=label, extend="both", ticks=ticks)
    if ticks is not None:
        bar.ax.set_yticklabels([f"{t:g}" for t in ticks])


def shape_maps(run, scale_factor: float | None = None, cmap: str = "RdBu_r") -> bytes | None:
    """3-D views of the measured surfaces coloured by distance to the BFP (mm), out-of-plane
    coordinate multiplied by ``scale_factor`` (automatic if None), one colour scale set by
    the successful methods; None if no method has a measurement."""
    results = run.results
    if not measured(results):
        return None
    vmax = colour_range(results, lambda r: r.distance_to_bfp_mm)
    norm = Normalize(-vmax, vmax)
    centre, axes = _reference_frame(results)
    local = {id(r): (np.asarray(r.measurement.nodes, float) - centre) @ axes.T
             for r in measured(results)}
    extent = max(float(np.ptp(p[:, 0])) for p in local.values())
    factor = nice_scale_factor(extent, vmax) if scale_factor is None else scale_factor
    nrows, ncols = grid(len(results))
    fig = Figure(figsize=(4.6 * ncols, 3.6 * nrows + 0.4))
    for k, result in enumerate(results):
        if result.measurement is None:
            _empty_panel(fig.add_subplot(nrows, ncols, k + 1), result)
            continue
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        p, d = local[id(result)], np.asarray(result.distance_to_bfp_mm, float)
        shown = np.column_stack([p[:, 0], p[:, 1], factor * d])
        for block in result.mesh.blocks:
            conn = block.connectivity
            faces = shown[conn[:, :_CORNERS[block.family.reference]]]        # (ne, nc, 3)
            colours = cmap_colours(cmap, norm, d[conn].mean(axis=1))
            if is_failed(result):
                colours[:, 3] = 0.35                                           # faded
            ax.add_collection3d(Poly3DCollection(faces, facecolors=colours, edgecolors="none"))
        span = np.ptp(shown, axis=0)
        lo, hi = shown.min(axis=0), shown.max(axis=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2] - 1e-9, hi[2] + 1e-9)
        ax.set_box_aspect((span[0], span[1], max(span[2], 0.05 * span[0])))
        ax.view_init(elev=35, azim=-60)
        ax.set_axis_off()
        title(ax, result, f"RMS dist. to BFP {np.sqrt(np.mean(d ** 2)):.3f} mm")
    fig.suptitle(f"Distance to best-fit plane (mm), deformation scale factor x{factor:g}")
    _colour_bar(fig, cmap, norm, "distance to BFP (mm)")
    return png(fig)


def _binned_mean(uv: np.ndarray, values: np.ndarray, bins: tuple[int, int],
                 ranges: list) -> np.ndarray:
    """Mean of ``values`` over a regular grid of ``bins`` cells (NaN where empty)."""
    total, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], bins=bins, range=ranges, weights=values)
    count, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], bins=bins, range=ranges)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def _residual_field(result, centre, axes) -> tuple[np.ndarray, np.ndarray]:
    """(in-plane coordinates (n, 2), residual % (n,)) at the seen integration points."""
    m = result.measurement
    X = m.quadrature.points(np.asarray(m.nodes, float))
    percent = np.asarray(m.residual.percent, float)
    seen = np.isfinite(percent)
    return ((X - centre) @ axes.T)[seen, :2], percent[seen]


def residual_maps(run, cells_along_length: int = 300, cmap: str = "RdBu_r") -> bytes | None:
    """Gray-level residual at the integration points in % of the dynamic range (Fig. 12),
    averaged over cells of the specimen's best-fit plane (at most ``cells_along_length``
    along its length, about 2 points per cell), one panel per method; the colour scale is
    the median over the successful methods of the 99th percentile of ``|r|`` (a poor method
    saturates: arrows of the colour bar). None if no method has a measurement."""
    results = run.results
    if not measured(results):
        return None
    centre, axes = _reference_frame(results)
    fields = {id(r): _residual_field(r, centre, axes) for r in measured(results)}
    all_uv = np.concatenate([uv for uv, _ in fields.values()])
    lo, hi = all_uv.min(axis=0), all_uv.max(axis=0)
    span = np.maximum(hi - lo, 1e-9)
    n_points = min(len(p) for _, p in fields.values()) or 1      # about 2 points per cell
    nx = int(min(cells_along_length, max(2, np.sqrt(0.5 * n_points * span[0] / span[1]))))
    bins = (nx, max(1, int(round(nx * span[1] / span[0]))))
    ranges = [[lo[0], hi[0]], [lo[1], hi[1]]]
    vmax = colour_range(results, lambda r: fields[id(r)][1])
    fig, panels = plan_figure(results, span)
    for ax, result in panels:
        uv, p = fields[id(result)]
        ax.imshow(_binned_mean(uv, p, bins, ranges).T, origin="lower",
                  extent=(lo[0], hi[0], lo[1], hi[1]), cmap=cmap, vmin=-vmax, vmax=vmax,
                  interpolation="nearest", alpha=0.5 if is_failed(result) else 1.0)
        m = result.measurement
        noise = getattr(m, "noise_percent", None)
        noise_text = "" if noise is None else f" (noise {noise:.2f}%)"
        title(ax, result, f"std {m.residual_percent:.2f}%{noise_text}")
        ax.set_xlabel("mm")
        ax.set_aspect("equal")
    fig.suptitle("Gray-level residual (% of the image dynamic range)")
    _colour_bar(fig, cmap, Normalize(-vmax, vmax), "residual (%)")
    return png(fig)


def error_norm(results) -> SymLogNorm:
    """Colour scale of the error maps (um): symmetric, up to :func:`colour_range` of the
    successful methods, logarithmic beyond the smallest RMS error of a successful method
    (errors of the methods often span decades: the best one stays visible)."""
    vmax = colour_range(results, node_errors_um)
    rms = [float(np.sqrt(np.mean(e ** 2))) for e in map(node_errors_um, succeeded(results))
           if e is not None and e.size]
    linthresh = min([vmax, *(v for v in rms if v > 0)])
    return SymLogNorm(max(linthresh, 1e-3 * vmax), vmin=-vmax, vmax=vmax, base=10)


def error_maps(run, cmap: str = "RdBu_r") -> bytes | None:
    """Signed error against the truth per node (um) over the best-fit plane, one panel per
    method, one colour scale set by the successful methods (:func:`error_norm`). None when
    the truth is unknown or no method carries per-node errors (``shape_error_mm``)."""
    results = run.results
    with_errors = [r for r in measured(results) if node_errors_um(r) is not None]
    if not run.truth_available or not with_errors:
        if run.truth_available:
            logger.debug("truth known but no per-node error (shape_error_mm): no error maps")
        return None
    norm = error_norm(results)
    centre, axes = _reference_frame(results)
    first = (np.asarray(with_errors[0].measurement.nodes, float) - centre) @ axes.T
    span = np.maximum(np.ptp(first[:, :2], axis=0), 1e-9)
    fig, panels = plan_figure(results, span)
    for ax, result in panels:
        errors = node_errors_um(result)
        if errors is None:
            ax.set_axis_off()
            title(ax, result, "no error against the truth")
            continue
        uv = ((np.asarray(result.measurement.nodes, float) - centre) @ axes.T)[:, :2]
        for block in result.mesh.blocks:
            conn = block.connectivity
            colours = cmap_colours(cmap, norm, errors[conn].mean(axis=1))
            if is_failed(result):
                colours[:, 3] = 0.5
            ax.add_collection(PolyCollection(uv[conn[:, :_CORNERS[block.family.reference]]],
                                             facecolors=colours, edgecolors="none"))
        ax.autoscale_view()
        ax.set_aspect("equal")
        ax.set_xlabel("mm")
        title(ax, result, f"RMS error {np.sqrt(np.mean(errors ** 2)):.3g} µm")
    fig.suptitle(f"Shape error against the truth (µm, after best rigid alignment; "
                 f"logarithmic beyond ±{norm.linthresh:.3g} µm)")
    decades = 10.0 ** np.arange(np.ceil(np.log10(norm.linthresh)), np.log10(norm.vmax) + 1e-9)
    _colour_bar(fig, cmap, norm, "error (µm)", ticks=[*(-decades[::-1]), 0.0, *decades])
    return png(fig)


def _node_field_um(result, name: str) -> np.ndarray | None:
    values = getattr(result.measurement, name, None) if result.measurement is not None else None
    return None if values is None else 1e3 * np.asarray(values, float)


def uncertainty_maps(run, cmap: str = "viridis") -> bytes | None:
    """Two rows of plan views per method: the shape's standard deviation from the image
    noise (µm) and the bias indicator (µm: how far one notch less regularization would move
    the shape, :mod:`fesdic_core.shape.uncertainty`), one logarithmic colour scale for both. The
    std alone understates the error where the regularization misses part of the shape; the
    bias indicator shows where. None if no method carries them."""
    rows = [("shape_std_mm", "std"), ("shape_bias_mm", "bias indicator")]
    results = [r for r in measured(run.results)
               if any(_node_field_um(r, name) is not None for name, _ in rows)]
    if not results:
        return None
    values = np.concatenate([v[np.isfinite(v) & (v > 0)] for r in results for name, _ in rows
                             for v in [_node_field_um(r, name)] if v is not None])
    if not values.size:
        return None
    norm = matplotlib.colors.LogNorm(*np.percentile(values, [1.0, 99.5]))
    centre, axes = _reference_frame(results)
    first = (np.asarray(results[0].measurement.nodes, float) - centre) @ axes.T
    span = np.maximum(np.ptp(first[:, :2], axis=0), 1e-9)
    ncols = len(results)
    fig = Figure(figsize=(3.6 * ncols, 2 * (3.6 * span[1] / span[0] + 0.9)))
    for row, (name, what) in enumerate(rows):
        for col, result in enumerate(results):
            ax = fig.add_subplot(2, ncols, row * ncols + col + 1)
            field = _node_field_um(result, name)
            if field is None:
                ax.set_axis_off()
                title(ax, result, f"no {what}")
                continue
            uv = ((np.asarray(result.measurement.nodes, float) - centre) @ axes.T)[:, :2]
            for block in result.mesh.blocks:
                conn = block.connectivity
                colours = cmap_colours(cmap, norm, np.clip(field[conn].mean(axis=1), norm.vmin, None))
                ax.add_collection(PolyCollection(uv[conn[:, :_CORNERS[block.family.reference]]],
                                                 facecolors=colours, edgecolors="none"))
            ax.autoscale_view()
            ax.set_aspect("equal")
            title(ax, result, f"{what}: median {np.nanmedian(field):.3g} µm, "
                              f"max {np.nanmax(field):.3g} µm")
    fig.suptitle("Shape uncertainty (µm): top, standard deviation from the image noise; "
                 "bottom, bias indicator")
    _colour_bar(fig, cmap, norm, "µm")
    return png(fig)
