"""``georeg preview CONFIG``: the set-up of a measurement at a glance, without measuring.

In a few seconds: both reference images with the nominal FE mesh projected through both
cameras, each element coloured by the integration points of its pixel quadrature that both
cameras see (an element at 0 lies outside an image or behind the cameras: the mesh, the
units or the poses are wrong), the landmarks where they are given (the clicked pixel and the
landmark's point projected through the posed cameras: the two marks must coincide), and,
for a region of interest, its outline. Outputs (published together, like every command's):

- ``preview.png``: the two views;
- ``nominal.vtu``: the nominal mesh, cell data ``seen_points`` (points both cameras see)
  and ``points`` (all the element's points);
- ``preview.json``: the mesh (family, nodes, elements), the share of elements each camera
  sees, the points per element (min, median, max of those seen), the landmarks'
  reprojection errors (px) and their largest.
"""
from __future__ import annotations

import dataclasses
import logging
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from adapters.fesdic_core import NominalModel
from fesdic_core.fe.mesh_io import write_mesh
from fesdic_core.fe.quadrature import PixelQuadrature, pixel_quadrature
from fesdic_core.imaging.image import Image, read_image

from georeg_app.config.measure import Config
from georeg_app.inputs.cameras import load_cameras
from georeg_app.inputs.nominal import specimen_setup

logger = logging.getLogger(__name__)

__all__ = ["Preview", "preview", "preview_summary", "preview_figure", "write_preview",
           "PREVIEW_FILES"]

#: the files ``georeg preview`` writes
PREVIEW_FILES = ("preview.png", "nominal.vtu", "preview.json")


@dataclasses.dataclass(frozen=True, eq=False)
class Preview:
    """What a measurement would start from.

    ``seen_points`` (n_elements,): integration points of each element that both cameras
    see (in front of them and inside both images); ``points`` (n_elements,): all of them;
    ``landmark_errors_px`` (n_landmarks, 2): each landmark's reprojection error in camera 0
    and camera 1 (px; empty without landmarks).
    """

    config: Config
    model: NominalModel
    cameras: tuple
    images: tuple
    quadrature: PixelQuadrature
    seen_points: np.ndarray
    points: np.ndarray
    seen_by: np.ndarray                 # (2, n_elements) bool: some point of it in camera c
    landmark_errors_px: np.ndarray
    specimen: dict | None = None        # kind = "roi": the specimen frame and the surface fit


def _seen(quad: PixelQuadrature, nodes: np.ndarray, images: Sequence[Image],
          cameras: Sequence) -> tuple[np.ndarray, np.ndarray]:
    """Points seen by both cameras, per element, and whether each camera sees the element."""
    X = quad.points(nodes)
    inside = []
    for image, camera in zip(images, cameras):
        inside.append(camera.in_front(X) & image.inside(camera.project(X)))
    both = inside[0] & inside[1]
    by = np.array([quad.element_sum(m.astype(float)) > 0 for m in inside])
    return quad.element_sum(both.astype(float)), by


def _landmark_errors(config: Config, cameras: Sequence) -> np.ndarray:
    marks = config.cameras.landmarks
    if not marks:
        return np.zeros((0, 2))
    xyz = np.array([m.xyz_mm for m in marks], float)
    errors = [np.linalg.norm(cameras[c].project(xyz) - np.array([getattr(m, f"cam{c}_px") for m in marks]),
                             axis=1) for c in range(2)]
    return np.column_stack(errors)


def preview(config: Config, images: Sequence[Image] | None = None) -> Preview:
    """The nominal model, the posed cameras and the quadrature of ``config``, without measuring.

    Raises the errors the measurement would raise on these inputs (files, calibration,
    geometry), before any Gauss-Newton step.
    """
    if images is None:
        images = tuple(read_image(p, prefilter_px=config.method.prefilter_px,
                                  order=config.method.interpolation_order)
                       for p in (config.images.cam0, config.images.cam1))
    model, posed, roi = specimen_setup(config.geometry, config.method.fixed_levels,
                                       load_cameras(config.cameras, images), images)
    cameras = tuple(posed)
    quad = pixel_quadrature(model.mesh, cameras)
    seen, by = _seen(quad, model.mesh.nodes, images, cameras)
    points = quad.element_sum(np.ones(quad.n_points))
    return Preview(config=config, model=model, cameras=cameras, images=tuple(images),
                   quadrature=quad, seen_points=seen, points=points, seen_by=by,
                   landmark_errors_px=_landmark_errors(config, cameras),
                   specimen=None if roi is None else roi.summary())


def preview_summary(p: Preview) -> dict:
    """``preview.json``: the mesh, what each camera sees of it, the landmarks' errors."""
    mesh = p.model.mesh
    seen = p.seen_points[p.seen_points > 0]
    errors = p.landmark_errors_px
    return {
        "geometry": p.config.geometry.kind,
        "mesh": {"family": "+".join(b.family.name for b in mesh.blocks),
                 "n_nodes": int(mesh.n_nodes), "n_elements": int(mesh.n_elements)},
        "elements_seen_fraction": {"cam0": float(np.mean(p.seen_by[0])),
                                   "cam1": float(np.mean(p.seen_by[1])),
                                   "both": float(np.mean(p.seen_points > 0))},
        "points_per_element_seen": None if seen.size == 0 else {
            "min": float(seen.min()), "median": float(np.median(seen)), "max": float(seen.max())},
        "landmark_errors_px": errors.tolist(),
        "landmark_error_max_px": float(errors.max()) if errors.size else None,
        **({} if p.specimen is None else {"specimen": p.specimen}),
    }


def preview_figure(p: Preview) -> bytes:
    """The two reference images with the projected mesh and the landmarks (PNG bytes)."""
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    from georeg_app.report.maps import png

    fig = Figure(figsize=(14, 5.8))
    axes = fig.subplots(1, 2)
    mesh = p.model.mesh
    corners = [b.connectivity[:, :4 if b.family.reference == "quad" else 3]   # gmsh: corners first
               for b in mesh.blocks]
    vmax = max(float(p.seen_points.max()), 1.0)
    for c, ax in enumerate(axes):
        image, camera = p.images[c], p.cameras[c]
        ax.imshow(image.values, cmap="gray", interpolation="nearest")
        xy = camera.project(mesh.nodes)
        polygons = [xy[conn] for block in corners for conn in block]
        shade = PolyCollection(polygons, array=p.seen_points, cmap="viridis", clim=(0.0, vmax),
                               edgecolors="w", linewidths=0.2, alpha=0.55)
        ax.add_collection(shade)
        marks = p.config.cameras.landmarks
        if marks:
            clicked = np.array([getattr(m, f"cam{c}_px") for m in marks], float)
            projected = camera.project(np.array([m.xyz_mm for m in marks], float))
            ax.plot(clicked[:, 0], clicked[:, 1], "r+", ms=12, label="landmark (clicked)")
            ax.plot(projected[:, 0], projected[:, 1], "yo", mfc="none", ms=10,
                    label="landmark (projected)")
            ax.legend(loc="lower right", fontsize=8)
        h, w = image.values.shape
        ax.set_xlim(-0.5, w - 0.5)
        ax.set_ylim(h - 0.5, -0.5)
        ax.set_title(f"camera {c}: {Path(str(image.source)).name}", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(shade, ax=axes, shrink=0.8, label="integration points seen by both cameras")
    return png(fig)


def write_preview(out_dir: str | os.PathLike, p: Preview, overwrite: bool = False) -> list[Path]:
    """Write :data:`PREVIEW_FILES` into ``out_dir`` (all or nothing)."""
    from georeg_app.shape.outputs import OutputWriter

    with OutputWriter(out_dir, replace=overwrite) as w:
        w.write_bytes("preview.png", preview_figure(p))
        write_mesh(w.path("nominal.vtu"), p.model.mesh,
                   cell_data={"seen_points": p.seen_points, "points": p.points})
        w.write_json("preview.json", preview_summary(p))
    return w.published
