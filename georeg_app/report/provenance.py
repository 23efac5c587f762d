"""What produced a report: package version, dates, inputs with checksums, the configuration
(as TOML) and the calibrated stereo rig of each method (HTML fragments).

Reads the optional fields of ``georeg_app.shape.pipeline.RunResult`` (``version``, ``started``,
``inputs`` as ``(label, path, sha256 hex)`` tuples, ``config``) with defaults, so a run
without them still gets a header saying what is not recorded.
"""
from __future__ import annotations

import dataclasses
import datetime
import html
import json
import math
from typing import Any

import numpy as np

from georeg_app.report.run_view import failure, is_failed
from georeg_app.version import installed_version

__all__ = ["package_version", "config_toml", "inputs_html", "rig_html", "header_html"]


def package_version(run) -> str:
    """The run's ``version``, else the installed georeg's, else "unknown"."""
    return str(getattr(run, "version", None) or installed_version())


def _toml_value(value: Any) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else
                                                  ("inf" if v > 0 else "-inf"))
    if dataclasses.is_dataclass(value):          # an inline table (a CAD part's rough pose)
        return "{" + ", ".join(f"{f.name} = {_toml_value(getattr(value, f.name))}"
                               for f in dataclasses.fields(value)) + "}"
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return json.dumps(str(value))            # strings and paths: a TOML basic string


def _table_lines(obj: Any) -> tuple[list[str], list[tuple[str, Any]]]:
    """``key = value`` lines of a dataclass (None omitted) and its arrays of tables."""
    lines, arrays = [], []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if value is None:
            continue
        if isinstance(value, tuple) and value and dataclasses.is_dataclass(value[0]):
            arrays.append((f.name, value))
        elif isinstance(value, tuple) and not value:
            continue
        else:
            lines.append(f"{f.name} = {_toml_value(value)}")
    return lines, arrays


def config_toml(config) -> str:
    """A ``Config`` (georeg_app.config.measure) as TOML text: one table per section, arrays of
    tables (landmarks) at the top level as the configuration file accepts them."""
    out = []
    if getattr(config, "source", None) is not None:
        out.append(f"# configuration read from {config.source} (paths resolved)")
    arrays = []
    for f in dataclasses.fields(config):
        section = getattr(config, f.name)
        if not dataclasses.is_dataclass(section):
            continue
        lines, more = _table_lines(section)
        out += [f"[{f.name}]", *lines, ""]
        arrays += more
    for name, tables in arrays:
        for table in tables:
            lines, _ = _table_lines(table)
            out += [f"[[{name}]]", *lines, ""]
    return "\n".join(out).rstrip() + "\n"


def _table(head: list[str], rows: list[list[str]], css: str = "") -> str:
    cls = f' class="{css}"' if css else ""
    h = "<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in head) + "</tr>"
    body = ["<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows]
    return f"<table{cls}>\n{h}\n" + "\n".join(body) + "\n</table>"


def inputs_html(run) -> str:
    """Table of the input files (label, path, SHA-256), or a line saying none is recorded."""
    inputs = tuple(getattr(run, "inputs", ()) or ())
    if not inputs:
        return "<p>Input files: not recorded by this run.</p>"
    rows = [[str(label), str(path), str(sha)] for label, path, sha in inputs]
    return _table(["input", "file", "SHA-256"], rows, css="inputs")


def _vector(v) -> str:
    return ", ".join(f"{x:.6g}" for x in np.asarray(v, float).ravel())


def rig_html(run) -> str:
    """Table of the final (calibrated) camera poses of each method: rvec (rad), rotation
    angle (deg), tvec (mm), focal lengths (px)."""
    rows = []
    for r in run.results:
        if r.measurement is None:
            rows.append([r.spec.label, "-", f"failed: {failure(r)}", "", "", ""])
            continue
        label = r.spec.label + (" (failed)" if is_failed(r) else "")
        for cam in getattr(r.measurement, "cameras", ()) or ():
            rvec = np.asarray(cam.rvec, float)
            K = np.asarray(cam.K, float)
            rows.append([label, str(getattr(cam, "name", "cam")), _vector(rvec),
                         f"{np.degrees(np.linalg.norm(rvec)):.4f}", _vector(cam.tvec),
                         f"{K[0, 0]:.6g}, {K[1, 1]:.6g}"])
    if not rows:
        return "<p>Calibrated cameras: not recorded by this run.</p>"
    return _table(["method", "camera", "rvec (rad, world to camera)", "|rvec| (deg)",
                   "tvec (mm)", "fx, fy (px)"], rows, css="rig")


def header_html(run) -> str:
    """The report's header: version, dates, inputs with checksums, configuration, rig."""
    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    started = getattr(run, "started", None) or "not recorded"
    config = getattr(run, "config", None)
    config_part = ("<p>Configuration: not recorded by this run.</p>" if config is None else
                   f"<details><summary>Configuration (TOML)</summary>"
                   f"<pre>{html.escape(config_toml(config))}</pre></details>")
    return "\n".join([
        '<section id="provenance"><h2>What produced this report</h2>',
        f"<p>georeg {html.escape(package_version(run))}; run started {html.escape(str(started))}; "
        f"report written {now}.</p>",
        "<h3>Inputs</h3>", inputs_html(run),
        "<h3>Configuration</h3>", config_part,
        "<h3>Calibrated stereo rig per method</h3>",
        "<details><summary>Final camera poses (x_cam = R(rvec) X + tvec)</summary>",
        rig_html(run), "</details>", "</section>"])
