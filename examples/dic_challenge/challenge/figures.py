"""Figures of the Stereo DIC Challenge part (PNG bytes, matplotlib Agg, no display).

The gray-level residual maps are ``georeg measure``'s own (``residual_maps.png`` in its
output folder): its VTU holds no per-point residual to redraw them from.

- :func:`overview`: height of every measured face above the base plane (mm);
- :func:`shape_maps`: deviation of each face from its best-fit plane (base plate, block
  top) or cylinder (bars), micrometres;
- :func:`cylinder_profiles`: radial residual against the angle from the crest for the
  best-fit radius and for the laser's and pyvale's radii imposed.
"""
from __future__ import annotations

import io

import numpy as np
from matplotlib.figure import Figure

from . import analysis

DPI = 100


def _png(fig: Figure) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI, bbox_inches="tight")
    return buffer.getvalue()


def _dots(ax, xy: np.ndarray, values: np.ndarray, size: float, **kwargs):
    """The sampled points (4 x 4 per element) as square dots of ``size`` (points^2) coloured
    by ``values``, rasterized."""
    return ax.scatter(xy[:, 0], xy[:, 1], c=values, s=size, marker="s", linewidths=0, rasterized=True,
                      **kwargs)


def overview(points: dict) -> bytes:
    """All measured faces (points by face name) coloured by their height above the base plane (mm)."""
    fig = Figure(figsize=(8.5, 7.5))
    ax = fig.add_subplot(1, 1, 1)
    image = None
    for name, P in points.items():
        image = _dots(ax, P[:, :2], P[:, 2], 6.0, cmap="viridis", vmin=-0.05, vmax=6.5)
        ax.text(P[:, 0].mean(), P[:, 1].mean(), name, ha="center", va="center", fontsize=8,
                color="w" if name == "base" else "k")
    ax.set_xlim(-52, 52)
    ax.set_ylim(-52, 52)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("Measured faces: height above the base plane (mm), world frame")
    if image is not None:
        fig.colorbar(image, ax=ax, shrink=0.8, label="z (mm)")
    return _png(fig)


def _deviation(name, P, comparison) -> tuple[np.ndarray, np.ndarray, str]:
    """(x, y) of the points, their deviation (um) from the face's fit, and a label."""
    cyl = comparison.cylinders.get(name)
    if cyl is not None:
        fit = cyl.fit
        arm = P - fit.axis_point_mm
        radial = arm - np.outer(arm @ fit.axis_direction, fit.axis_direction)
        dev = np.linalg.norm(radial, axis=1) - fit.radius_mm
        return P[:, :2], 1e3 * dev, f"radial distance to the best-fit cylinder (r = {fit.radius_mm:.3f} mm)"
    if name == "base":
        return P[:, :2], 1e3 * analysis.plane_residuals(P), "distance to the best-fit plane (whole plate)"
    return P[:, :2], 1e3 * analysis.plane_residuals(P), "distance to the best-fit plane"


def shape_maps(points: dict, comparison, polygon=None) -> bytes:
    """Deviation (um) of each face from its best-fit plane or cylinder."""
    names = [n for n in points]
    ncols = 3
    nrows = int(np.ceil(len(names) / ncols))
    fig = Figure(figsize=(5.2 * ncols, 4.6 * nrows))
    for k, name in enumerate(names):
        ax = fig.add_subplot(nrows, ncols, k + 1)
        xy, dev, label = _deviation(name, points[name], comparison)
        vmax = float(np.nanpercentile(np.abs(dev), 99)) or 1.0
        image = _dots(ax, xy, dev, 4.0, cmap="RdBu_r", vmin=-vmax, vmax=vmax)
        if name == "base" and polygon is not None:
            ring = np.vstack([polygon, polygon[:1]])
            ax.plot(ring[:, 0], ring[:, 1], "k--", lw=1)
        ax.set_aspect("equal")
        ax.set_title(f"{name}: RMS {analysis.rms(dev):.2f} um\n{label}", fontsize=8)
        ax.set_xlabel("x (mm)", fontsize=8)
        fig.colorbar(image, ax=ax, shrink=0.8, label="um")
    fig.suptitle("Shape: deviation from the best-fit plane or cylinder (um)")
    return _png(fig)


def _profile(fit: analysis.CylinderFit, step_deg: float = 2.5):
    edges = np.arange(-45.0, 45.0 + step_deg, step_deg)
    i = np.digitize(fit.angle_deg, edges)
    centres, means = [], []
    for k in range(1, len(edges)):
        sel = i == k
        if sel.sum() > 50:
            centres.append(0.5 * (edges[k - 1] + edges[k]))
            means.append(1e3 * float(np.mean(fit.residuals_mm[sel])))
    return np.array(centres), np.array(means)


def cylinder_profiles(comparison) -> bytes | None:
    """Radial residual (um) against the angle from the crest: best fit and imposed radii."""
    cyl = comparison.cylinders
    if not cyl:
        return None
    fig = Figure(figsize=(6.0 * len(cyl), 4.4))
    for k, (name, c) in enumerate(cyl.items()):
        ax = fig.add_subplot(1, len(cyl), k + 1)
        fits = {f"best fit r = {c.fit.radius_mm:.3f} mm": c.fit, **{f"r = {lab}": f for lab, f in c.fixed.items()}}
        for label, fit in fits.items():
            x, y = _profile(fit)
            ax.plot(x, y, ".-", label=f"{label} (RMS {1e3 * fit.rms_mm:.1f} um)")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("angle from the crest (degrees)")
        ax.set_ylabel("radial residual, mean per 2.5 degrees (um)")
        ax.set_title(name)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Measured cross-sections against cylinders of the laser's and pyvale's radii")
    return _png(fig)
