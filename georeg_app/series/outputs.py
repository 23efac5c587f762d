"""Output files of ``georeg track``, all published together (:class:`OutputWriter`).

- ``frame_NNNN_<image>.vtu`` per frame (NNNN = frame index, the reference being frame 0;
  ``<image>`` the stem of the frame's camera-0 image, so that a file says which pair it
  measures: ``frame_0006_GT4-0110_0.vtu``): the reference surface (mm, world frame) with point data ``displacement_mm`` (3),
  ``residual`` (percent of the reference images' dynamic range, root mean square of the two
  cameras at the nodes), ``strain_xx``, ``strain_yy``, ``strain_xy`` (surface Green-Lagrange
  in the local tangent frame, :mod:`fesdic_core.displacement.strain`), ``valid`` (1 for a node
  that passed its local checks, 0 for one the images do not determine or that diverged:
  :mod:`fesdic_core.displacement.validity`) and ``residual_to_noise`` (the residual over the
  node's support against the local noise floor there); for a trusted frame measured by a
  solver that gives its step's covariance, ``displacement_uncertainty_mm`` (3) with its parts
  ``displacement_std_mm`` (the image noise) and ``displacement_bias_mm`` (the estimated
  bias: the change with the next finer level less its noise), per component
  (:mod:`fesdic_core.displacement.uncertainty`). A frame that failed
  its checks is written as ``frame_NNNN_<image>_failed.vtu`` (its untrusted field) and left
  out of the time series. The outputs are written even when every frame failed (there is
  then something to inspect; the command still exits with status 1).
- ``displacement.pvd``: the ParaView time series of the frames that succeeded (time = frame
  index).
- ``summary.json``: :func:`track_summary`.
- ``report.html``: :mod:`georeg_app.report.track`.
"""
from __future__ import annotations

import os
import re
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from fesdic_core.fe.mesh_io import write_mesh

from georeg_app.report.track import REPORT_FILE, track_report_html
from georeg_app.shape.outputs import OutputWriter, _json_ready

__all__ = ["SUMMARY_FILE", "PVD_FILE", "REPORT_FILE", "image_stem", "frame_file", "valid_field",
           "track_summary", "pvd_text", "write_track"]

SUMMARY_FILE = "summary.json"
PVD_FILE = "displacement.pvd"


def image_stem(path: str) -> str:
    """A file-name stem from an image's path, case kept: ``"frames/GT4-0110_0.tif" ->
    "GT4-0110_0"`` (characters other than letters, digits, ``.+-`` become ``_``)."""
    stem = re.sub(r"[^A-Za-z0-9.+-]+", "_", Path(path).stem).strip("_.")
    return stem or "image"


def frame_file(frame) -> str | None:
    """The VTU of a frame, named after its index and its camera-0 image (None for a frame
    that raised before giving a field)."""
    if frame.U is None:
        return None
    return (f"frame_{frame.index:04d}_{image_stem(frame.cam0)}" + ("" if frame.ok else "_failed")
            + ".vtu")


def valid_field(frame) -> np.ndarray | None:
    """The displacements (m, 3) of a frame's valid nodes (every node without the local
    checks; None with no field or no valid node)."""
    if frame.U is None:
        return None
    U = np.asarray(frame.U) if frame.valid is None else np.asarray(frame.U)[frame.valid]
    return U if len(U) else None


def _finite(value) -> float | None:
    return float(value) if value is not None and np.isfinite(value) else None


def track_summary(run) -> dict:
    """``summary.json``: ``{"reference", "displacement", "scheduler", "time_s",
    "failed_frames": [index], "frames": [{"index", "cam0", "cam1", "residual_percent",
    "iterations", "converged", "time_s", "mesh_file", "status", "failure", "noise_percent",
    "start_frame", "start", "mean_displacement_mm", "max_displacement_mm", "n_valid",
    "valid_share", "displacement_uncertainty_mm"}]}``; ``status`` is "ok" or "failed"
    (``failure`` says why); ``start_frame``:
    the frame whose field started this one (0: from rest); ``start``: where the starting
    field came from (``[displacement] start``: features, the previous field, zero); ``n_valid``: the nodes valid
    locally (of ``n_nodes``), ``valid_share`` their share (None with no field); the mean and
    largest displacements are those of the valid nodes; ``displacement_uncertainty_mm``: the
    median and the largest uncertainty of each component over the valid nodes (None without
    one)."""
    frames = []
    for f in run.frames:
        U = valid_field(f)
        frames.append({
            "index": f.index, "cam0": f.cam0, "cam1": f.cam1,
            "residual_percent": _finite(f.residual_percent), "iterations": int(f.iterations),
            "converged": bool(f.converged), "time_s": float(f.time_s), "mesh_file": frame_file(f),
            "status": "ok" if f.ok else "failed", "failure": f.failure,
            "noise_percent": _finite(f.noise_percent), "start_frame": int(f.start_frame),
            "start": f.start,
            "mean_displacement_mm": None if U is None else np.mean(U, axis=0),
            "max_displacement_mm": None if U is None else float(np.max(np.linalg.norm(U, axis=1))),
            "n_valid": f.n_valid,
            "valid_share": None if f.valid is None else _finite(np.mean(f.valid)),
            "displacement_uncertainty_mm": f.uncertainty_summary(),
        })
    d = run.config.displacement
    chosen = getattr(run, "levels", None)
    length = getattr(run, "tikhonov_length", None)
    return _json_ready({
        "reference": run.reference_label,
        "displacement": {"method": d.method, "scales": list(d.scale_sequence),
                         "incremental": d.incremental,
                         "tikhonov_length_mm": (d.tikhonov_length_mm if length is None
                                                else length.length_mm)
                         if d.method == "tikhonov" else None,
                         "tikhonov_length_chosen": None if length is None else length.as_dict(),
                         "levels": (d.levels if chosen is None else chosen.levels)
                         if d.method == "georeg" else None,
                         "levels_chosen": None if chosen is None else chosen.as_dict(),
                         "jacobian": d.jacobian, "max_invalid_share": d.max_invalid_share},
        "n_nodes": int(run.mesh.n_nodes), "scheduler": run.scheduler, "time_s": float(run.time_s),
        "failed_frames": [f.index for f in run.frames if not f.ok],
        "frames": frames,
    })


def pvd_text(run) -> str:
    """The ParaView collection of the frames that succeeded."""
    rows = "".join(f'    <DataSet timestep="{f.index}" part="0" file={quoteattr(frame_file(f))}/>\n'
                   for f in run.frames if f.ok)
    return ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
            f"{rows}  </Collection>\n</VTKFile>\n")


def write_frame_vtu(path: str | os.PathLike, mesh, frame, element_face=None) -> None:
    """One frame's VTU: displacement, residual and strain per node; for a CAD part of
    several faces the cell data ``face`` (as ``georeg measure``'s VTU)."""
    write_mesh(path, mesh, point_data={
        "displacement_mm": np.asarray(frame.U, float),
        "residual": np.asarray(frame.residual_node, float),
        "strain_xx": frame.strain[:, 0], "strain_yy": frame.strain[:, 1],
        "strain_xy": frame.strain[:, 2], **_validity_data(frame), **_uncertainty_data(frame)},
        cell_data=None if element_face is None else {"face": np.asarray(element_face, np.int32)})


def _validity_data(frame) -> dict:
    """The point data ``valid`` (0/1) and ``residual_to_noise`` of a frame, if it has them."""
    if frame.valid is None:
        return {}
    return {"valid": np.asarray(frame.valid, np.uint8),
            "residual_to_noise": np.asarray(frame.residual_to_noise, float)}


def _uncertainty_data(frame) -> dict:
    """The point data of a frame's uncertainty and its parts (those it has)."""
    u = frame.uncertainty
    if u is None or u.std_mm is None:
        return {}
    data = {"displacement_uncertainty_mm": np.asarray(u.uncertainty_mm, float),
            "displacement_std_mm": np.asarray(u.std_mm, float)}
    if u.bias_mm is not None:             # the estimated bias: the indicator less its noise
        data["displacement_bias_mm"] = np.sqrt(np.asarray(u.squared_bias_mm2, float))
    return data


def write_track(out_dir: str | os.PathLike, run, overwrite: bool = False) -> list[Path]:
    """Write every output of ``run`` into ``out_dir`` (all or nothing)."""
    with OutputWriter(out_dir, replace=overwrite) as w:
        for frame in run.frames:
            name = frame_file(frame)
            if name is not None:
                write_frame_vtu(w.path(name), run.mesh, frame, run.element_face)
        w.write_text(PVD_FILE, pvd_text(run))
        w.write_json(SUMMARY_FILE, track_summary(run))
        w.write_text(REPORT_FILE, track_report_html(run))
    return w.published
