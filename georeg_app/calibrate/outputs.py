"""The outputs of ``georeg calibrate``, written all together or not at all.

- ``cameras.json``: the core's camera format (camera 0 at the world origin, camera 1 by the
  stereo relation), for ``[cameras] file``;
- ``cameras.yml``: OpenCV FileStorage (``K1 D1 K2 D2 R T``), for ``[cameras] opencv``;
- ``summary.json``: every parameter with its standard deviation, the reprojection and
  epipolar errors, each view's status (and why a view was left out), the comparison and the
  speckle check when asked for;
- ``view_NN_cam0.png``, ``view_NN_cam1.png``: each image with its detected points (green:
  used, orange: found but not used) and the reprojection error vectors magnified;
- ``report.html``: the same, readable, with the residual vectors over the image.
"""
from __future__ import annotations

import base64
import html
import io
import os
from pathlib import Path

import cv2
import matplotlib
import numpy as np

from fesdic_core.cameras.io.formats import write_opencv_stereo
from fesdic_core.cameras.rig import write_cameras_json

from georeg_app.calibrate.run import CalibrationRun, read_gray
from georeg_app.report.html import STYLESHEET
from georeg_app.report.provenance import package_version
from georeg_app.shape.outputs import OutputWriter

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

__all__ = ["calibration_summary", "write_calibration", "REPORT_FILE", "VECTOR_GAIN"]

REPORT_FILE = "report.html"
VECTOR_GAIN = 100.0       # residual vectors drawn this many times their length
_OVERLAY_MAX_PX = 1200    # overlays are shrunk to at most this width


def _f(value) -> float | None:
    return None if value is None or not np.isfinite(value) else float(value)


def calibration_summary(run: CalibrationRun) -> dict:
    """summary.json's content."""
    cal, cfg = run.calibration, run.config
    epi = cal.epipolar_px.ravel()
    cameras = []
    for c, cam in enumerate(cal.cameras):
        cameras.append(dict(name=cam.name, K=cam.K.tolist(), dist=cam.dist.tolist(),
                            rvec=cam.rvec.tolist(), tvec=cam.tvec.tolist(),
                            image_size=list(cam.image_size),
                            std={k.split(".", 1)[1]: v for k, v in cal.std.items()
                                 if k.startswith(f"cam{c}.")}))
    views = [dict(index=v.index, cam0=v.sources[0], cam1=v.sources[1], found=list(v.found),
                  used=v.used, rms_px=[_f(r) for r in v.rms_px], status=v.status)
             for v in cal.views]
    used = sum(v.status == "used" for v in cal.views)
    return {"tool": "georeg calibrate", "version": package_version(run),
            "config": str(cfg.source), "target": dict(kind=cfg.target.kind, rows=cfg.target.rows,
                                                      columns=cfg.target.columns,
                                                      pitch_mm=cfg.target.pitch_mm,
                                                      dot_diameter_mm=cfg.target.dot_diameter_mm),
            "model": dict(distortion=cfg.model.distortion,
                          fix_principal_point=cfg.model.fix_principal_point,
                          fix_aspect=cfg.model.fix_aspect, refine_target=cfg.model.refine_target),
            "views": views, "views_used": used, "views_total": len(cal.views),
            "reprojection_rms_px": cal.rms_px,
            "reprojection_rms_per_coordinate_px": cal.rms_px / np.sqrt(2.0),   # OpenCV's figure
            "residual_sigma_px": cal.sigma_px,
            "epipolar_px": dict(median=float(np.median(epi)), rms=float(np.sqrt(np.mean(epi ** 2))),
                                max=float(np.max(epi))),
            "circle_centre_bias_corrected": cal.bias_corrected,
            "target_refined": cal.target_deviation_mm is not None,
            "target_deviation_um": None if cal.target_deviation_mm is None else dict(
                rms=(np.sqrt(np.mean(cal.target_deviation_mm ** 2, axis=0)) * 1e3).tolist(),
                max=(np.max(np.abs(cal.target_deviation_mm), axis=0) * 1e3).tolist()),
            "cameras": cameras,
            "stereo": dict(rvec=cal.cameras[1].rvec.tolist(), T=cal.cameras[1].tvec.tolist(),
                           rvec_std=cal.std["rvec"], T_std=cal.std["T"],
                           baseline_mm=cal.baseline_mm, baseline_std_mm=cal.std["baseline_mm"],
                           stereo_angle_deg=cal.stereo_angle_deg,
                           stereo_angle_std_deg=cal.std["stereo_angle_deg"]),
            "comparison": run.comparison, "speckle_check": run.check, "time_s": run.time_s}


def _overlay(path: str, detection, used_px: np.ndarray | None, residual: np.ndarray | None,
             status: str) -> bytes:
    image = cv2.cvtColor(cv2.normalize(read_gray(Path(path)), None, 0, 255, cv2.NORM_MINMAX)
                         .astype(np.uint8), cv2.COLOR_GRAY2BGR)
    scale = min(1.0, _OVERLAY_MAX_PX / image.shape[1])
    radius = max(3, int(round(6 / scale)))
    for p in detection.px:
        cv2.circle(image, tuple(int(round(v)) for v in p), radius, (0, 140, 255), 2)
    if used_px is not None and residual is not None:
        for p, r in zip(used_px, residual):
            a = tuple(int(round(v)) for v in p)
            cv2.circle(image, a, radius, (0, 200, 0), 2)
            b = tuple(int(round(v)) for v in p + VECTOR_GAIN * r)
            cv2.line(image, a, b, (255, 0, 0), 2)
    colour = (0, 160, 0) if status == "used" else (0, 0, 220)
    cv2.putText(image, status[:90], (20, 50), cv2.FONT_HERSHEY_SIMPLEX, 1.2 / max(scale, 0.3) * 0.5,
                colour, 2)
    if scale < 1.0:
        image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    ok, png = cv2.imencode(".png", image)
    return png.tobytes()


def _residual_figure(run: CalibrationRun) -> bytes:
    cal = run.calibration
    fig = Figure(figsize=(12, 4.5))
    for c in range(2):
        ax = fig.add_subplot(1, 2, c + 1)
        px = np.vstack([r[2 * c] for r in cal.residuals])
        res = np.vstack([r[2 * c + 1] for r in cal.residuals])
        w, h = cal.cameras[c].image_size
        q = ax.quiver(px[:, 0], px[:, 1], res[:, 0], -res[:, 1], np.linalg.norm(res, axis=1),
                      angles="xy", scale_units="xy", scale=1.0 / VECTOR_GAIN, cmap="viridis")
        fig.colorbar(q, ax=ax, label="reprojection error (px)")
        ax.set_xlim(0, w), ax.set_ylim(h, 0), ax.set_aspect("equal")
        ax.set_title(f"camera {c}: residual vectors x {VECTOR_GAIN:g}, all used views")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90, bbox_inches="tight")
    return buffer.getvalue()


def _table(head, rows) -> str:
    th = "".join(f"<th>{html.escape(str(h))}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in row) + "</tr>"
                   for row in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _g(value, digits=6) -> str:
    return "—" if value is None or (isinstance(value, float) and not np.isfinite(value)) \
        else f"{value:.{digits}g}"


def report_html(run: CalibrationRun, summary: dict, figure: bytes) -> str:
    """The self-contained report (figure embedded) of ``run`` and its ``summary``."""
    s = summary
    parts = [f"<h1>Stereo calibration</h1><p>{html.escape(str(run.config.source))}: "
             f"{s['views_used']} of {s['views_total']} views used, reprojection RMS "
             f"{s['reprojection_rms_px']:.4f} px, median epipolar distance of the target points "
             f"{s['epipolar_px']['median']:.4f} px, baseline {s['stereo']['baseline_mm']:.4f} "
             f"&plusmn; {s['stereo']['baseline_std_mm']:.4f} mm, stereo angle "
             f"{s['stereo']['stereo_angle_deg']:.4f} &plusmn; "
             f"{s['stereo']['stereo_angle_std_deg']:.4f} deg. The standard deviations come from "
             "the Jacobian at the optimum and the residual's variance; they assume independent "
             "detection errors and say nothing of a model error (see the residual vectors).</p>"]
    rows = []
    for c, cam in enumerate(s["cameras"]):
        K, d = cam["K"], cam["dist"]
        for name, value in zip(("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"),
                               (K[0][0], K[1][1], K[0][2], K[1][2], *d)):
            rows.append([f"camera {c} {name}", _g(value, 8), _g(cam["std"].get(name), 3)])
    parts.append("<h2>Parameters</h2>" + _table(["parameter", "value", "std"], rows))
    if run.comparison:
        parts.append("<h2>Against the compared calibration</h2>" + _table(
            ["parameter", "ours", "std", "theirs", "difference", "in std"],
            [[r["name"], _g(r["ours"], 8), _g(r["std"], 3), _g(r["theirs"], 8),
              _g(r["difference"], 4), _g(r["sigmas"], 3)] for r in run.comparison]))
    if run.check:
        parts.append("<h2>Speckle check</h2>" + _table(
            ["calibration", "SIFT matches kept", "median epipolar (px)", "RMS (px)"],
            [[k, v["kept"], _g(v["median_px"], 4), _g(v["rms_px"], 4)]
             for k, v in run.check.items() if isinstance(v, dict)]))
    parts.append("<h2>Views</h2>" + _table(
        ["view", "camera 0", "camera 1", "found", "used", "RMS cam0 (px)", "RMS cam1 (px)", "status"],
        [[v["index"], Path(v["cam0"]).name, Path(v["cam1"]).name, f"{v['found'][0]} / {v['found'][1]}",
          v["used"], _g(v["rms_px"][0], 4), _g(v["rms_px"][1], 4), v["status"]] for v in s["views"]]))
    data = base64.b64encode(figure).decode("ascii")
    parts.append(f'<figure><img src="data:image/png;base64,{data}" alt="residual vectors">'
                 "<figcaption>Reprojection error vectors of every used point over the image "
                 "(a pattern means a model error; noise means the detection).</figcaption></figure>")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>georeg calibrate</title>"
            f"<style>{STYLESHEET}</style></head><body>{''.join(parts)}</body></html>")


def write_calibration(out_dir: str | os.PathLike, run: CalibrationRun,
                      overwrite: bool = False) -> list[Path]:
    """Write every output of ``run`` into ``out_dir`` (all or nothing)."""
    summary = calibration_summary(run)
    cal = run.calibration
    used = {v.index: i for i, v in enumerate(v for v in cal.views if v.status == "used")}
    with OutputWriter(out_dir, replace=overwrite) as w:
        write_cameras_json(w.path("cameras.json"), cal.cameras)
        write_opencv_stereo(w.path("cameras.yml"), cal.cameras)
        w.write_json("summary.json", summary)
        for v in cal.views:
            for c in range(2):
                detection = run.detections[c][v.index]
                px = res = None
                if v.index in used:
                    px, res = cal.residuals[used[v.index]][2 * c:2 * c + 2]
                w.write_bytes(f"view_{v.index:02d}_cam{c}.png",
                              _overlay(v.sources[c], detection, px, res, v.status))
        w.write_text(REPORT_FILE, report_html(run, summary, _residual_figure(run)))
    return w.published
