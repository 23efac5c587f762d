"""Figures of a run, like the paper's (PNG bytes, matplotlib Agg, no display).

- :func:`shape_maps`: measured shapes coloured by the distance to the best-fit plane (BFP),
  out-of-plane exaggerated by a deformation scale factor, one panel per method, one
  colour scale (Figs. 8-10);
- :func:`residual_maps`: gray-level residual per integration point in % of the dynamic
  range of the images, over the specimen (Fig. 12);
- :func:`convergence`: residual against iterations and against time normalised by one
  fine-scale iteration (Fig. 11);
- :func:`multiscale_vs_monoscale`: the georeg multiscale and monoscale runs (Fig. 11);
- :func:`shape_errors`: RMS error against the truth and RMS distance to BFP per method.

Every function takes a ``RunResult`` (georeg_app.pipeline) and returns PNG bytes.
"""
from __future__ import annotations

import io
import logging
import math

import matplotlib
import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers the 3-D projection)
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

logger = logging.getLogger(__name__)

DPI = 110
_CORNERS = {"quad": 4, "triangle": 3}


def _png(fig: Figure) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI, bbox_inches="tight")
    return buffer.getvalue()


def _grid(n: int, ncols: int = 3) -> tuple[int, int]:
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


def _label(result) -> str:
    return str(result.spec.label)


def shape_maps(run, scale_factor: float | None = None, cmap: str = "RdBu_r") -> bytes:
    """3-D views of the measured surfaces coloured by distance to the BFP (mm), out-of-plane
    coordinate multiplied by ``scale_factor`` (automatic if None), common colour scale."""
    results = run.results
    vmax = max(float(np.max(np.abs(r.distance_to_bfp_mm))) for r in results) or 1.0
    norm = Normalize(-vmax, vmax)
    centre, axes = bfp_frame(np.asarray(results[0].measurement.nodes, float))
    local = [(np.asarray(r.measurement.nodes, float) - centre) @ axes.T for r in results]
    extent = max(float(np.ptp(p[:, 0])) for p in local)
    factor = nice_scale_factor(extent, vmax) if scale_factor is None else scale_factor
    nrows, ncols = _grid(len(results))
    fig = Figure(figsize=(4.6 * ncols, 3.6 * nrows + 0.4))
    for k, (result, p) in enumerate(zip(results, local)):
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        d = np.asarray(result.distance_to_bfp_mm, float)
        shown = np.column_stack([p[:, 0], p[:, 1], factor * d])
        for block in result.mesh.blocks:
            conn = block.connectivity
            faces = shown[conn[:, :_CORNERS[block.family.reference]]]        # (ne, nc, 3)
            colours = cmap_colours(cmap, norm, d[conn].mean(axis=1))
            ax.add_collection3d(Poly3DCollection(faces, facecolors=colours, edgecolors="none"))
        span = np.ptp(shown, axis=0)
        lo, hi = shown.min(axis=0), shown.max(axis=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2] - 1e-9, hi[2] + 1e-9)
        ax.set_box_aspect((span[0], span[1], max(span[2], 0.05 * span[0])))
        ax.view_init(elev=35, azim=-60)
        ax.set_axis_off()
        ax.set_title(f"{_label(result)}\nRMS dist. to BFP {np.sqrt(np.mean(d ** 2)):.3f} mm",
                     fontsize=9)
    fig.suptitle(f"Distance to best-fit plane (mm), deformation scale factor x{factor:g}")
    mappable = _mappable(cmap, norm)
    fig.colorbar(mappable, ax=fig.axes, shrink=0.6, label="distance to BFP (mm)")
    return _png(fig)


def cmap_colours(cmap: str, norm: Normalize, values: np.ndarray) -> np.ndarray:
    """RGBA colours (n, 4) of ``values`` under a named colormap and a norm."""
    return matplotlib.colormaps[cmap](norm(values))


def _mappable(cmap: str, norm: Normalize) -> ScalarMappable:
    return ScalarMappable(norm=norm, cmap=cmap)


def _binned_mean(uv: np.ndarray, values: np.ndarray, bins: tuple[int, int],
                 ranges: list) -> np.ndarray:
    """Mean of ``values`` over a regular grid of ``bins`` cells (NaN where empty)."""
    total, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], bins=bins, range=ranges, weights=values)
    count, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], bins=bins, range=ranges)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def residual_maps(run, cells_along_length: int = 300, cmap: str = "RdBu_r") -> bytes:
    """Gray-level residual at the integration points in % of the dynamic range (Fig. 12),
    averaged over cells of the specimen's best-fit plane (at most ``cells_along_length``
    along its length, about 2 points per cell), one panel per method, common colour scale."""
    results = run.results
    centre, axes = bfp_frame(np.asarray(results[0].measurement.nodes, float))
    fields = []
    for r in results:
        m = r.measurement
        X = m.quadrature.points(np.asarray(m.nodes, float))
        percent = np.asarray(m.residual.percent, float)
        seen = np.isfinite(percent)
        fields.append((((X - centre) @ axes.T)[seen, :2], percent[seen]))
    all_uv = np.concatenate([uv for uv, _ in fields]
                            + [((np.asarray(results[0].measurement.nodes, float) - centre) @ axes.T)[:, :2]])
    lo, hi = all_uv.min(axis=0), all_uv.max(axis=0)
    span = np.maximum(hi - lo, 1e-9)
    n_points = min(len(p) for _, p in fields) or 1      # about 2 points per cell at most
    nx = int(min(cells_along_length, max(2, np.sqrt(0.5 * n_points * span[0] / span[1]))))
    bins = (nx, max(1, int(round(nx * span[1] / span[0]))))
    ranges = [[lo[0], hi[0]], [lo[1], hi[1]]]
    # colour range: the median over methods of the 99th percentile of |r|, so that the noise
    # floor of the good methods shows and a poor method saturates (arrows of the colour bar)
    tops = [float(np.percentile(np.abs(p), 99)) for _, p in fields if p.size]
    vmax = float(np.median(tops)) if tops else 1.0
    vmax = vmax if vmax > 0 else 1.0
    nrows, ncols = _grid(len(results))
    fig = Figure(figsize=(4.6 * ncols, (4.6 * span[1] / span[0] + 0.9) * nrows))
    image = None
    for k, (result, (uv, p)) in enumerate(zip(results, fields)):
        ax = fig.add_subplot(nrows, ncols, k + 1)
        grid = _binned_mean(uv, p, bins, ranges)
        image = ax.imshow(grid.T, origin="lower", extent=(lo[0], hi[0], lo[1], hi[1]),
                          cmap=cmap, vmin=-vmax, vmax=vmax, interpolation="nearest")
        ax.set_title(f"{_label(result)}\nstd {result.measurement.residual_percent:.2f}% "
                     f"of the dynamic range", fontsize=9)
        ax.set_xlabel("mm")
        ax.set_aspect("equal")
    fig.suptitle("Gray-level residual (% of the image dynamic range)")
    if image is not None:
        fig.colorbar(image, ax=fig.axes, shrink=0.8, label="residual (%)", extend="both")
    return _png(fig)


def _history(result, unit_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(iteration count from 1, normalised time, residual %) of a result's history."""
    records = result.measurement.history
    residual = np.array([r.get("residual_percent", np.nan) for r in records], float)
    time = np.array([r.get("time_s", np.nan) for r in records], float) / unit_s
    return np.arange(1, len(records) + 1), time, residual


def convergence(run) -> bytes:
    """Residual (%) against iterations and against time / one fine-scale iteration (Fig. 11)."""
    unit = float(run.one_fine_iteration_s) if run.one_fine_iteration_s > 0 else 1.0
    fig = Figure(figsize=(11, 4.2))
    ax_it, ax_t = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for result in run.results:
        it, t, res = _history(result, unit)
        ax_it.plot(it, res, marker=".", label=_label(result))
        ax_t.plot(t, res, marker=".", label=_label(result))
    for ax, xlabel in ((ax_it, "iteration (calibration and shape, all scales)"),
                       (ax_t, "time / one fine-scale iteration")):
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("residual std (% of dynamic range)")
        ax.grid(True, which="both", alpha=0.3)
    ax_t.legend(fontsize=8)
    fig.suptitle("Convergence of the gray-level residual")
    return _png(fig)


def georeg_pair(run) -> tuple[object | None, object | None]:
    """(multiscale, monoscale) georeg results of ``run`` (None when absent)."""
    georeg = [r for r in run.results if r.spec.name == "georeg"]
    mono = [r for r in georeg if "monoscale" in r.spec.label.lower()]
    multi = [r for r in georeg if "monoscale" not in r.spec.label.lower()]
    return (multi[0] if multi else None), (mono[0] if mono else None)


def multiscale_vs_monoscale(run) -> bytes | None:
    """Residual against normalised time of the georeg multiscale and monoscale runs
    (Fig. 11, right); None if the run lacks one of them."""
    multi, mono = georeg_pair(run)
    if multi is None or mono is None:
        return None
    unit = float(run.one_fine_iteration_s) if run.one_fine_iteration_s > 0 else 1.0
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
    ax.set_yscale("log")
    ax.set_xlabel("time / one fine-scale iteration")
    ax.set_ylabel("residual std (% of dynamic range)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("georeg: multiscale vs monoscale (large markers: scale 0)")
    return _png(fig)


def shape_errors(run) -> bytes:
    """Bars per method: RMS error vs truth (if known) and RMS distance to BFP (mm)."""
    labels = [_label(r) for r in run.results]
    bfp = [float(np.sqrt(np.mean(np.square(r.distance_to_bfp_mm)))) for r in run.results]
    x = np.arange(len(labels))
    fig = Figure(figsize=(max(6.0, 1.3 * len(labels)), 4.2))
    ax = fig.add_subplot(1, 1, 1)
    if run.truth_available:
        err = [np.nan if r.shape_rms_error_mm is None else float(r.shape_rms_error_mm)
               for r in run.results]
        ax.bar(x - 0.2, err, 0.4, label="RMS error vs truth (mm)")
        fe = [e for r, e in zip(run.results, err) if r.spec.name == "fe"]
        if fe:
            ax.axhline(0.3 * fe[0], color="k", ls="--", lw=1, label="0.3 x FE error")
        ax.bar(x + 0.2, bfp, 0.4, label="RMS distance to BFP (mm)")
        ax.set_yscale("log")
    else:
        ax.bar(x, bfp, 0.6, label="RMS distance to BFP (mm)")
    ax.set_xticks(x, labels, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("mm")
    ax.legend(fontsize=8)
    ax.grid(True, axis="y", alpha=0.3)
    ax.set_title("Shape per method")
    return _png(fig)


def make_figures(run) -> dict[str, bytes]:
    """All figures of a run, name -> PNG bytes (names are the output file stems)."""
    figures = {"shape_maps": shape_maps(run), "residual_maps": residual_maps(run),
               "convergence": convergence(run)}
    pair = multiscale_vs_monoscale(run)
    if pair is not None:
        figures["multiscale_vs_monoscale"] = pair
    figures["shape_errors"] = shape_errors(run)
    return figures
