"""The self-contained HTML report of ``georeg track`` (figures embedded, no external link).

It holds the frames' table (a failed frame greyed out with its reason: nothing is shown as
a success that is not), the residual and the mean displacement against the frame (failed
frames marked, never joined to the curve), and maps of the last frame that succeeded:
the three displacement components, the surface strain and the residual at the nodes,
drawn in the best-fit plane of the reference surface, and which nodes are valid.

The statistics (the table's mean displacement, the mean displacement against the frame)
count only the nodes valid locally (:mod:`fesdic_core.displacement.validity`): a node the
images do not determine, or that diverged, is never counted as measured. The table says how
many nodes are valid in each frame; the maps grey the invalid nodes' triangles.
"""
from __future__ import annotations

import base64
from pathlib import Path
import html

import numpy as np
from matplotlib.figure import Figure
from matplotlib.tri import Triangulation

from georeg_app.report.html import STYLESHEET
from georeg_app.report.maps import bfp_frame, png


def _valid_U(frame) -> np.ndarray:
    """The displacements (m, 3) of a frame's valid nodes (every node without the checks)."""
    U = np.asarray(frame.U, float)
    return U if frame.valid is None else U[np.asarray(frame.valid, bool)]


def _mean_valid(frame) -> np.ndarray:
    """(3,) mean displacement of the valid nodes (NaN if none is valid)."""
    U = _valid_U(frame)
    return np.mean(U, axis=0) if len(U) else np.full(3, np.nan)

__all__ = ["series_figure", "maps_figure", "track_report_html"]

REPORT_FILE = "report.html"


def series_figure(run) -> bytes:
    """Residual (%) and mean displacement (um) of each frame against the frame index."""
    fig = Figure(figsize=(10, 3.6))
    ax_r, ax_u = fig.subplots(1, 2)
    index = np.array([f.index for f in run.frames])
    ok = np.array([f.ok for f in run.frames])
    residual = np.array([f.residual_percent for f in run.frames], float)
    ax_r.plot(index[ok], residual[ok], "o-", color="C0", label="residual")
    ax_r.plot(index[ok], [f.noise_percent for f in run.frames if f.ok], "--", color="0.5",
              label="noise floor")
    for ax in (ax_r, ax_u):
        for k in index[~ok]:
            ax.axvline(k, color="#b22", lw=1, ls=":")
        ax.set_xlabel("frame")
    ax_r.set_ylabel("residual (% of the dynamic range)")
    ax_r.legend(fontsize=8)
    if ok.any():
        mean = 1e3 * np.array([_mean_valid(f) for f in run.frames if f.ok])
        for k, name in enumerate("xyz"):
            ax_u.plot(index[ok], mean[:, k], "o-", label=f"mean u_{name}")
        ax_u.legend(fontsize=8)
    ax_u.set_ylabel("mean displacement of the valid nodes (µm)")
    if (~ok).any():
        fig.suptitle("dotted red lines: frames that failed (left out)", fontsize=9, color="#b22")
    fig.tight_layout()
    return png(fig)


def _triangulation(mesh) -> Triangulation:
    """Corner triangles of every element in the best-fit plane of the reference surface."""
    centre, axes = bfp_frame(mesh.nodes)
    uv = (mesh.nodes - centre) @ axes[:2].T
    triangles = []
    for block in mesh.blocks:
        c = block.connectivity
        if block.family.reference == "quad":
            triangles += [c[:, [0, 1, 2]], c[:, [0, 2, 3]]]
        else:
            triangles.append(c[:, :3])
    return Triangulation(uv[:, 0], uv[:, 1], np.concatenate(triangles))


def maps_figure(run) -> bytes | None:
    """Maps of the last frame that succeeded (None if none did)."""
    good = [f for f in run.frames if f.ok]
    if not good:
        return None
    frame = good[-1]
    tri = _triangulation(run.mesh)
    fields = [(f"u_{n} (µm)", 1e3 * frame.U[:, k], "RdBu_r", True) for k, n in enumerate("xyz")]
    fields += [(f"strain_{n} (µε)", 1e6 * frame.strain[:, k], "RdBu_r", False)
               for k, n in enumerate(("xx", "yy", "xy"))]
    fields.append(("residual (%)", frame.residual_node, "viridis", False))
    valid = (np.ones(run.mesh.n_nodes, bool) if frame.valid is None
             else np.asarray(frame.valid, bool))
    fields.append(("valid (1) / invalid (0) nodes", valid.astype(float), "RdYlGn", False))
    # the invalid nodes are not measured: their triangles are masked in the field maps
    mask = ~np.all(valid[tri.triangles], axis=1)
    fig = Figure(figsize=(13, 8))
    axes = fig.subplots(3, 3).ravel()
    for k, (ax, (title, values, cmap, _)) in enumerate(zip(axes, fields)):
        values = np.asarray(values, float)
        finite = np.isfinite(values) & (valid if k < len(fields) - 1 else True)
        shown = np.where(finite, values, np.nanmean(values[finite]) if finite.any() else 0.0)
        shown_tri = tri
        if k < len(fields) - 1 and mask.any() and not mask.all():
            shown_tri = Triangulation(tri.x, tri.y, tri.triangles, mask=mask)
        artist = ax.tripcolor(shown_tri, shown, shading="gouraud", cmap=cmap)
        fig.colorbar(artist, ax=ax, shrink=0.8)
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes[len(fields):]:
        ax.set_visible(False)
    fig.suptitle(f"frame {frame.index}, {Path(frame.cam0).name} (the last that succeeded), in the "
                 "best-fit plane of the reference surface", fontsize=10)
    return png(fig)


def _frames_table(run) -> str:
    rows = []
    for f in run.frames:
        mean = "" if f.U is None else ", ".join(f"{1e3 * v:.2f}" for v in _mean_valid(f))
        valid = "" if f.valid is None else f"{f.n_valid} of {len(f.valid)}"
        u = f.uncertainty_summary()
        spread = "" if u is None else " / ".join(
            ", ".join(f"{1e3 * v:.2f}" for v in u[key]) for key in ("median", "max"))
        status = "ok" if f.ok else f"FAILED: {f.failure}"
        rows.append(f'<tr class="{"" if f.ok else "failed"}"><td>{f.index}</td>'
                    f"<td>{html.escape(f.cam0)}<br>{html.escape(f.cam1)}</td>"
                    f"<td>{f.residual_percent:.3f}</td><td>{f.noise_percent:.3f}</td>"
                    f"<td>{valid}</td><td>{mean}</td><td>{spread}</td><td>{f.iterations}</td><td>{f.start_frame}</td>"
                    f"<td>{f.time_s:.1f}</td><td class=\"status\">{html.escape(status)}</td></tr>")
    head = ("<tr><th>frame</th><th>images</th><th>residual (%)</th><th>noise floor (%)</th>"
            "<th>valid nodes</th><th>mean u of the valid nodes (µm)</th>"
            "<th>uncertainty x, y, z: median / max (µm)</th><th>iterations</th><th>started from</th><th>time (s)</th>"
            "<th>status</th></tr>")
    note = ("<p>Statistics count only the nodes valid locally (residual within the local noise, "
            "texture, conditioning, consistent with their neighbours); the others are not "
            "measured. The uncertainty of a component is the root sum of squares of its "
            "standard deviation under the images' noise and its bias indicator (the change "
            "with the next finer spline level).</p>")
    return "<table>\n" + head + "\n" + "\n".join(rows) + "\n</table>\n" + note


def _figure(png_bytes: bytes, caption: str) -> str:
    data = base64.b64encode(png_bytes).decode("ascii")
    return (f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def track_report_html(run) -> str:
    """One self-contained page: the run, the frames' table and the figures."""
    d = run.config.displacement
    failed = [f"{f.index} ({Path(f.cam0).name})" for f in run.frames if not f.ok]
    summary = (f"{len(run.frames)} frame(s) against the reference ({run.reference_label}); "
               f"{run.mesh.n_nodes} nodes; displacement method {d.method}, image scales "
               f"{list(d.scale_sequence)}, {'incremental' if d.incremental else 'each from rest'}; "
               f"scheduler {run.scheduler}; {run.time_s:.1f} s.")
    chosen = getattr(run, "levels", None)
    if d.method == "georeg":
        summary += (f" Spline levels per component: {d.levels}." if chosen is None else
                    f" Spline levels per component: {chosen.levels}, chosen on "
                    f"{Path(chosen.frame).name} (the coarsest level whose field agrees with "
                    "every finer level's within 2 standard deviations of their change).")
    if failed:
        summary += f" {len(failed)} frame(s) FAILED ({', '.join(failed)}): greyed out."
    body = ["<h1>georeg track: displacement over a series of stereo pairs</h1>",
            f"<p>{html.escape(summary)}</p>", "<h2>Frames</h2>", _frames_table(run),
            "<h2>Figures</h2>",
            _figure(series_figure(run), "Residual and mean displacement against the frame.")]
    maps = maps_figure(run)
    if maps is not None:
        body.append(_figure(maps, "Displacement, surface Green-Lagrange strain (local tangent "
                                  "frame) and residual of the last frame that succeeded."))
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<title>georeg track report</title>\n<style>" + STYLESHEET + "</style>\n</head>\n"
            "<body>\n" + "\n".join(body) + "\n</body>\n</html>\n")
