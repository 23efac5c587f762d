"""Output files of a run, written atomically.

Single files are written to a temporary file in the same folder and moved into place
with ``os.replace`` (on any exception the temporary file is removed): a reader never
sees a half-written file.

A whole run is written through :class:`OutputWriter`: every file goes first into a
hidden staging folder next to the output folder (``.<name>.staging-XXXX``) and the files
are moved into the output folder only when all of them were written. An error or an
interruption (exception, Ctrl-C) while the outputs are produced removes the staging
folder and leaves the output folder exactly as it was: no partial file, no partial set.
(A hard kill can only leave the hidden staging folder behind, never a file in the
output folder.) Files of an earlier run with the same names are replaced; other files
of the output folder are left alone.

Files of a run (:func:`write_all`): ``summary.json`` (schema of :func:`summary_dict`),
one ``<label>.vtu`` per method, ``<label>_spline.json`` and ``<label>_spline.igs`` for
each georeg method, ``convergence.csv``, the PNG figures and ``report.html``; the calibrated
rig of each method as ``<label>_cameras.json`` (the core's JSON) and ``<label>_cameras.yml``
(OpenCV FileStorage: K1 D1 K2 D2, the stereo R T, each camera's rvec tvec); a part's faces.
"""
from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from fesdic_core.atomic import temporary_folder, write_bytes_atomic, write_text_atomic

from georeg_app.config.measure import AUTO

logger = logging.getLogger(__name__)

__all__ = ["SUMMARY_FILE", "NOMINAL_FILE", "CONVERGENCE_FILE", "REPORT_FILE",
           "CONVERGENCE_COLUMNS", "write_json_atomic", "OutputWriter", "safe_stem", "method_stems",
           "summary_dict", "seen_fraction", "write_method_vtu", "convergence_rows",
           "write_convergence_csv", "write_spline_outputs", "write_all"]

SUMMARY_FILE = "summary.json"
NOMINAL_FILE = "nominal_spline.json"        # a CAD part's nominal faces (coarsest splines)
CONVERGENCE_FILE = "convergence.csv"
REPORT_FILE = "report.html"
CONVERGENCE_COLUMNS = ("method", "scale", "fixed_point", "stage", "iteration", "residual_percent",
                       "time_s", "time_per_fine_iteration")


# --------------------------------------------------------------------------- atomic writers

def _json_ready(value: Any) -> Any:
    """numpy scalars/arrays to Python; non-finite floats to None (JSON has no NaN)."""
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_ready(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def write_json_atomic(path: str | os.PathLike, obj: Any, indent: int = 2) -> Path:
    """Write ``obj`` as JSON atomically (numpy values converted, NaN/inf written as null)."""
    return write_text_atomic(path, json.dumps(_json_ready(obj), indent=indent, allow_nan=False) + "\n")


class OutputWriter:
    """Stage all files of a run and publish them in ``out_dir`` only if the run succeeds.

    >>> with OutputWriter("out") as w:            # doctest: +SKIP
    ...     w.write_text("report.html", html)
    ...     write_mesh(w.path("fe.vtu"), mesh)    # any writer that takes a path

    After the ``with`` block, ``w.published`` lists the final paths. If the block raises,
    nothing is written to ``out_dir`` (see the module docstring).
    """

    def __init__(self, out_dir: str | os.PathLike, replace: bool = False):
        self.out_dir = Path(out_dir)
        self.replace = replace
        self.staging: Path | None = None
        self.names: list[str] = []
        self.published: list[Path] = []

    def __enter__(self) -> OutputWriter:
        self.out_dir.parent.mkdir(parents=True, exist_ok=True)
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise NotADirectoryError(f"output folder {self.out_dir} exists and is not a folder")
        self.staging = temporary_folder(self.out_dir.parent, f".{self.out_dir.name}.staging-")
        return self

    def path(self, name: str) -> Path:
        """Staged path of the output file ``name`` (a plain file name, no folder)."""
        if self.staging is None:
            raise RuntimeError("OutputWriter.path() called outside its `with` block")
        if not name or Path(name).name != name or name.startswith("."):
            raise ValueError(f"output file name {name!r} must be a plain, non-hidden file name")
        if name not in self.names:
            self.names.append(name)
        return self.staging / name

    def write_bytes(self, name: str, data: bytes) -> Path:
        return write_bytes_atomic(self.path(name), data)

    def write_text(self, name: str, text: str) -> Path:
        return write_text_atomic(self.path(name), text)

    def write_json(self, name: str, obj: Any) -> Path:
        return write_json_atomic(self.path(name), obj)

    def __exit__(self, exc_type, exc, tb) -> None:
        staging, self.staging = self.staging, None
        try:
            if exc_type is None:
                self._publish(staging)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
        if exc_type is not None:
            logger.debug("run failed: staged outputs discarded, %s untouched", self.out_dir)

    def _move_in(self, staging: Path) -> None:
        os.replace(staging, self.out_dir)                    # the whole folder at once
        staging.mkdir()                                      # (rmtree target of __exit__)

    def _publish(self, staging: Path) -> None:
        missing = [n for n in self.names if not (staging / n).is_file()]
        if missing:
            raise RuntimeError(f"outputs announced but not written: {', '.join(missing)}")
        if self.replace and self.out_dir.is_dir():           # the old folder goes as a whole
            old = temporary_folder(self.out_dir.parent, f".{self.out_dir.name}.old-")
            os.replace(self.out_dir, old / "previous")
            try:
                self._move_in(staging)
            except BaseException:
                os.replace(old / "previous", self.out_dir)   # put the old run back
                raise
            finally:
                shutil.rmtree(old, ignore_errors=True)
        elif not self.out_dir.exists():
            self._move_in(staging)
        else:
            for name in self.names:
                os.replace(staging / name, self.out_dir / name)
        self.published = [self.out_dir / n for n in self.names]
        logger.info("wrote %d files to %s", len(self.published), self.out_dir)


# --------------------------------------------------------------------------- run contents

def safe_stem(label: str) -> str:
    """A file-name stem from a method label: ``"Tikhonov 10 mm" -> "tikhonov_10_mm"``."""
    stem = re.sub(r"[^a-z0-9.+-]+", "_", label.lower()).strip("_.")
    return stem or "method"


def method_stems(run) -> list[str]:
    """Unique file-name stems of the methods of ``run``, from their labels."""
    stems: list[str] = []
    for result in run.results:
        stem = base = safe_stem(result.spec.label)
        k = 2
        while stem in stems or stem in ("summary", "convergence", "report"):
            stem, k = f"{base}_{k}", k + 1
        stems.append(stem)
    return stems


def _rms(values: np.ndarray) -> float:
    values = np.asarray(values, float)
    return float(np.sqrt(np.mean(values ** 2))) if values.size else float("nan")


def _number(value) -> float | None:
    return None if value is None or not np.isfinite(value) else float(value)


def _stat(values, how) -> float | None:
    if values is None:
        return None
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    return float(how(values)) if values.size else None


def _uncertainty_entry(m) -> dict:
    """The shape's standard deviation, bias indicator and uncertainty in summary.json (mm)."""
    entry = {f"shape_{name}_{how.__name__}_mm": _stat(values, how)
             for name in ("std", "bias", "uncertainty")
             for values in [getattr(m, f"shape_{name}_mm", None)] for how in (np.median, np.max)}
    noise = getattr(m, "noise", None)
    return {**entry, "noise_variance": None if noise is None else _number(noise.variance)}


def _levels_chosen(result) -> dict | None:
    """georeg's level: the search's record (automatic levels) or the fixed level used."""
    search = getattr(result, "level_search", None)
    if search is not None:
        return search.as_dict()
    levels = getattr(result.spec, "levels", None)
    if levels is None:
        return None
    if levels == AUTO:                    # the search did not finish (the method failed first)
        return {"levels": AUTO, "chosen_level": None}
    return {"fixed_levels": int(levels), "chosen_level": 0}


def summary_dict(run) -> dict:
    """The ``summary.json`` document (extend it, do not change it: readers depend on its keys).

    ``{"truth_available": bool, "failed_methods": [label], "methods": [{"name", "param",
    "shape_rms_error_mm", "distance_to_bfp_rms_mm", "residual_percent", "iterations",
    "time_s", "mesh_file", "label", "converged", "scales", "status", "failure",
    "noise_percent", "residual_to_noise", "scale_reports", "shape_std_median_mm",
    "shape_std_max_mm", "shape_bias_median_mm", "shape_bias_max_mm",
    "shape_uncertainty_median_mm", "shape_uncertainty_max_mm", "noise_variance",
    "levels_chosen", "regularization", "dropped_dofs", "n_valid", "valid_share"}]}``, plus
    ``"specimen"`` (the frame and surface fit) for ``[geometry] kind = "roi"``. ``dropped_dofs``
    (georeg): per spline level solved at, ``{"n_dofs", "dropped", "unseen_mesh", "unseen_images",
    "slivers"}`` (the dofs outside the mesh's outline or seen by no point), else null. ``status`` is "ok" or
    "failed" (``failure`` says why); a method that failed without any state has null
    measurement fields and no mesh file. ``n_valid``, ``valid_share``: the nodes valid locally.
    """
    methods = []
    for result, stem in zip(run.results, method_stems(run)):
        m, spec = result.measurement, result.spec
        entry = {
            "name": str(spec.name),
            "param": None if spec.param is None else (spec.param if isinstance(spec.param, str)
                                                      else float(spec.param)),
            "label": str(spec.label),
            "scales": [int(s) for s in spec.scales],
            "status": str(getattr(result, "status", "ok")),
            "failure": getattr(result, "failure", None),
            "shape_rms_error_mm": _number(result.shape_rms_error_mm),
            "distance_to_bfp_rms_mm": None, "residual_percent": None, "noise_percent": None,
            "residual_to_noise": None, "iterations": None, "time_s": None, "mesh_file": None,
            "converged": False, "scale_reports": [],
            **_uncertainty_entry(None),                       # null without a measurement
            "levels_chosen": _levels_chosen(result),
            "regularization": getattr(result, "regularization", None),
            "dropped_dofs": getattr(result, "dropped_dofs", None), "n_valid": None, "valid_share": None,
        }
        if m is not None:
            noise = getattr(m, "noise_percent", float("nan"))
            entry.update({
                "distance_to_bfp_rms_mm": _rms(result.distance_to_bfp_mm),
                "residual_percent": float(m.residual_percent),
                "noise_percent": _number(noise),
                "residual_to_noise": _number(m.residual_percent / noise) if noise else None,
                "iterations": int(m.iterations),
                "time_s": float(m.time_s),
                "mesh_file": f"{stem}.vtu",
                "converged": bool(m.converged),
                "scale_reports": [{"scale": r.scale, "residual_percent": _number(r.residual_percent),
                                   "noise_percent": _number(r.noise_percent),
                                   "fixed_point_iterations": r.fixed_point_iterations,
                                   "shape_converged": r.shape_converged,
                                   "fixed_point_converged": r.fixed_point_converged}
                                  for r in getattr(m, "scales", ())],
                **_uncertainty_entry(m), **(getattr(m, "validity", None) and m.validity.counts() or {}),
            })
        methods.append(entry)
    failed = [e["label"] for e in methods if e["status"] != "ok"]
    doc = {"truth_available": bool(run.truth_available), "failed_methods": failed,
           "methods": methods}
    if getattr(run, "specimen", None) is not None:        # kind = "roi" only
        doc["specimen"] = run.specimen
    return doc


def seen_fraction(measurement, n_elements: int) -> np.ndarray:
    """(n_elements,) share of each element's integration points (finest scale) inside the
    residual's mask; 0 for an element without points."""
    element = np.asarray(measurement.quadrature.element)
    mask = np.asarray(measurement.residual.mask, bool)
    total = np.bincount(element, minlength=n_elements)
    seen = np.bincount(element, weights=mask.astype(float), minlength=n_elements)
    return np.divide(seen, total, out=np.zeros(n_elements), where=total > 0)


def write_method_vtu(path: str | os.PathLike, result) -> Path:
    """VTU of the measured surface (world frame, mm) with point data
    ``shape_correction_mm`` (q, along the nominal normals), ``distance_to_bfp_mm``, and when
    known ``shape_error_mm``, ``shape_std_mm`` (std from the image noise), ``shape_bias_mm``
    (the bias indicator), ``shape_uncertainty_mm`` (their root sum of squares), ``valid``,
    ``residual_to_noise``; the cell data ``seen_fraction`` (the share of each element's
    integration points at the finest scale that entered the residual: seen
    by both cameras, not hidden, not grazing, not in the edge margin; 0 where the shape is
    only carried by the regularization) and, for a part of several faces, ``face`` (each
    element's face index), the point data ``node_face``, ``face_uv`` (each node's face and
    parameters: with :data:`NOMINAL_FILE`, the part)."""
    from fesdic_core.fe.mesh_io import write_mesh
    m = result.measurement
    mesh = result.mesh.with_nodes(np.asarray(m.nodes, float))
    point_data = {"shape_correction_mm": np.asarray(m.q, float), **(getattr(m, "validity", None) and m.validity.point_data() or {}),
                  "distance_to_bfp_mm": np.asarray(result.distance_to_bfp_mm, float)}
    for source, name in ((result, "shape_error_mm"), (m, "shape_std_mm"), (m, "shape_bias_mm"),
                         (m, "shape_uncertainty_mm")):
        if getattr(source, name, None) is not None:
            point_data[name] = np.asarray(getattr(source, name), float)
    cell_data = {"seen_fraction": seen_fraction(m, mesh.n_elements)}
    face = getattr(result, "element_face", None)               # a part of several faces
    if face is not None:
        cell_data["face"] = np.asarray(face, dtype=np.int32)
    nominal = getattr(result, "nominal", None)
    if nominal is not None and nominal.is_part:
        point_data["node_face"] = np.asarray(nominal.node_face, dtype=np.int32)
        point_data["face_uv"] = np.asarray(nominal.uv, dtype=float)
    write_mesh(path, mesh, point_data=point_data, cell_data=cell_data)
    return Path(path)


def convergence_rows(run) -> list[dict]:
    """One row per history record of every method (columns :data:`CONVERGENCE_COLUMNS`)."""
    unit = float(run.one_fine_iteration_s)
    rows = []
    for result in run.results:
        if result.measurement is None:
            continue
        for record in result.measurement.history:
            t = float(record.get("time_s", float("nan")))
            rows.append({"method": result.spec.label, "scale": record.get("scale", ""),
                         "fixed_point": record.get("fixed_point", ""), "stage": record.get("stage", ""),
                         "iteration": record.get("iteration", ""),
                         "residual_percent": record.get("residual_percent", ""), "time_s": t,
                         "time_per_fine_iteration": t / unit if unit > 0 else float("nan")})
    return rows


def write_convergence_csv(path: str | os.PathLike, run) -> Path:
    """``convergence.csv``: the iteration history of every method (one row per record)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CONVERGENCE_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(convergence_rows(run))
    return write_text_atomic(path, buffer.getvalue())


def write_spline_outputs(json_path: str | os.PathLike, iges_path: str | os.PathLike, result) -> None:
    """The measured spline of a georeg result as JSON (with the control values q_s) and IGES;
    a part's faces as one JSON of faces and one IGES entity 128 per face."""
    from georeg_plugin.io.spline_io import write_iges, write_part_json, write_spline_json
    patch, values = result.spline, result.spline_values
    if isinstance(patch, tuple):
        sizes = np.cumsum([p.n_dofs for p in patch])[:-1]
        std = getattr(result, "spline_std", None)
        fields = None if values is None else np.split(np.asarray(values), sizes)
        stds = None if std is None or values is None else np.split(np.asarray(std), sizes)
        names = getattr(result, "face_names", None) or [f"face{k}" for k in range(len(patch))]
        write_part_json(json_path, patch, names, fields, stds)
        write_iges(iges_path, list(patch), names=list(names))
        return
    n_ctrl = int(np.prod(patch.control_points.shape[:2]))
    if values is not None and np.size(values) != n_ctrl:
        logger.warning("%s: %d control values for %d control points; not written",
                       result.spec.label, np.size(values), n_ctrl)
        values = None
    std = getattr(result, "spline_std", None)
    if values is None or std is None or np.size(std) != n_ctrl:
        std = None
    write_spline_json(json_path, patch, scalar_field=values, scalar_field_std=std)
    write_iges(iges_path, patch)


def write_all(out_dir: str | os.PathLike, run, figures: dict[str, bytes] | None = None,
              overwrite: bool = False) -> list[Path]:
    """Write every output of ``run`` into ``out_dir`` (all or nothing, see OutputWriter).

    ``overwrite``: an existing ``out_dir`` is replaced as a whole (no file of an earlier
    run stays mixed with the new ones); else the new files are added to it.

    ``figures`` (name -> PNG bytes) defaults to :func:`georeg_app.report.figures.make_figures`.
    Returns the final paths.
    """
    from fesdic_core.cameras.io.formats import write_opencv_stereo
    from fesdic_core.cameras.rig import write_cameras_json
    from georeg_plugin.io.spline_io import write_part_json

    from georeg_app.report.figures import make_figures
    from georeg_app.report.html import report_html

    figures = make_figures(run) if figures is None else figures
    with OutputWriter(out_dir, replace=overwrite) as w:
        w.write_json(SUMMARY_FILE, summary_dict(run))
        for result, stem in zip(run.results, method_stems(run)):
            if result.measurement is None:                     # failed without a state
                continue
            write_method_vtu(w.path(f"{stem}.vtu"), result)
            if result.spline is not None:
                write_spline_outputs(w.path(f"{stem}_spline.json"), w.path(f"{stem}_spline.igs"),
                                     result)
            rig = getattr(getattr(result, "measurement", None), "cameras", ())   # calibrated rig
            if len(rig) == 2:                                  # (none for a failed method)
                write_cameras_json(w.path(f"{stem}_cameras.json"), rig)
                write_opencv_stereo(w.path(f"{stem}_cameras.yml"), rig)
        part = [r.nominal for r in run.results if getattr(r, "nominal", None) is not None]
        if part and part[0].is_part:                           # the part's coarsest faces
            write_part_json(w.path(NOMINAL_FILE), part[0].faces, part[0].face_names)
        write_convergence_csv(w.path(CONVERGENCE_FILE), run)
        for name, png in figures.items():
            w.write_bytes(f"{name}.png", png)
        w.write_text(REPORT_FILE, report_html(run, figures))
    return w.published

