"""The comparison table, the radius investigation and the self-contained HTML report.

Reference figures (issue 5 and ``data/dic_challenge_stereo/README.md``): the laser scan of
the challenge's public analysis scripts, and pyvale 2026.10.2 (C++ subset stereo DIC,
ZNSSD, affine subsets of 27 px) run on this same pair.
"""
from __future__ import annotations

import base64
import html
import math

import numpy as np

from georeg_app.report import STYLESHEET

from .pipeline import FACES, ChallengeRun, Comparison

LASER = {"block_height_mm": 6.36, "radius_mm": {"cylinder_v": 6.38, "cylinder_h": 6.62},
         "axis_depth_mm": "0.13-0.37", "crest_mm": "about 6.2-6.4"}
PYVALE = {"base_plane_um": 7.9, "base_quadric_um": 3.6, "block_top_um": "4.2-4.4",
          "block_height_mm": 6.333, "radius_mm": {"cylinder_v": 6.157, "cylinder_h": 6.178},
          "crest_mm": "6.21-6.22", "cylinder_rms_um": 5.0,
          "time": "17.6 s (23,000 points), 166 s (555,000 points)", "failed": "about 4.5% (NaN)"}
#: done-means of issue 5
TARGETS = {"base_quadric_um": 3.6, "block_height_mm": (6.36, 0.03), "flat_vs_cylinder_um": 10.0,
           "time_s": 300.0}

_CSS = STYLESHEET + "code { background: #f4f4f4; }\n"


def _f(value, digits: int = 3, scale: float = 1.0) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value * scale:.{digits}f}"


def _status(ok: bool | None) -> str:
    name = "NOT CHECKED" if ok is None else ("PASS" if ok else "FAIL")
    return f'<span class="{name.replace(" ", "-")}">{name}</span>'


def targets(run: ChallengeRun, c: Comparison) -> list[tuple[str, bool | None, str]]:
    """The done-means of issue 5 checked on the run: (claim, passed or None, detail)."""
    out = [(f"base plate: RMS to the best-fit quadric < {TARGETS['base_quadric_um']} um (pyvale)",
            c.base_quadric_rms_mm * 1e3 < TARGETS["base_quadric_um"],
            f"{_f(c.base_quadric_rms_mm, 2, 1e3)} um over the README's base region")]
    if c.block is not None:
        ref, tol = TARGETS["block_height_mm"]
        out.append((f"block height within {tol} mm of {ref} mm", abs(c.block.height_mm - ref) <= tol,
                    f"{_f(c.block.height_mm, 4)} mm"))
    for name, cyl in c.cylinders.items():
        ok = None if cyl.flat_vs_cylinder_rms_mm is None else \
            cyl.flat_vs_cylinder_rms_mm * 1e3 <= TARGETS["flat_vs_cylinder_um"]
        out.append((f"{name}: flat and cylindrical nominals agree within "
                    f"{TARGETS['flat_vs_cylinder_um']:g} um RMS", ok,
                    f"{_f(cyl.flat_vs_cylinder_rms_mm, 2, 1e3)} um RMS (mean "
                    f"{_f(cyl.flat_vs_cylinder_mean_mm, 2, 1e3)} um)"))
    full = run.scales is None and run.crop is None and set(run.faces) == set(FACES)
    out.append((f"all four faces in < {TARGETS['time_s']:g} s", run.time_s < TARGETS["time_s"] if full else None,
                f"{run.time_s:.1f} s" + ("" if full else " (not the full run: faces, scales or crop overridden)")))
    return out


def comparison_rows(run: ChallengeRun, c: Comparison) -> list[list[str]]:
    """Rows: quantity, this measurement, laser, pyvale."""
    rows = [["base plate: RMS to the best-fit plane (um), README region",
             _f(c.base_plane_rms_mm, 2, 1e3), "", _f(PYVALE["base_plane_um"], 1)],
            ["base plate: RMS to the best-fit quadric (um), README region",
             _f(c.base_quadric_rms_mm, 2, 1e3), "", _f(PYVALE["base_quadric_um"], 1)],
            ["base plate: RMS to plane / quadric (um), whole measured plate",
             f"{_f(c.base_all_plane_rms_mm, 2, 1e3)} / {_f(c.base_all_quadric_rms_mm, 2, 1e3)}", "", ""]]
    if c.block is not None:
        rows += [["block top: RMS to its best-fit plane (um)", _f(c.block.top_rms_plane_mm, 2, 1e3), "",
                  PYVALE["block_top_um"]],
                 ["block height above the plate ring around it (mm)", _f(c.block.height_mm, 4),
                  _f(LASER["block_height_mm"], 2), _f(PYVALE["block_height_mm"], 3)]]
    for name, cyl in c.cylinders.items():
        flat = "" if cyl.fit_flat is None else f" / {_f(cyl.fit_flat.radius_mm, 4)}"
        rows += [[f"{name}: fitted radius (mm), cylindrical / flat nominal",
                  _f(cyl.fit.radius_mm, 4) + flat, _f(LASER["radius_mm"][name], 2),
                  _f(PYVALE["radius_mm"][name], 3)],
                 [f"{name}: crest height above the plate ring around the bar (mm)",
                  _f(cyl.crest_above_ring_mm, 4), LASER["crest_mm"], PYVALE["crest_mm"]],
                 [f"{name}: axis below the plate ring (mm)", _f(cyl.axis_below_ring_mm, 3),
                  LASER["axis_depth_mm"], ""],
                 [f"{name}: RMS residual of the cylinder fit (um)", _f(cyl.fit.rms_mm, 2, 1e3), "",
                  _f(PYVALE["cylinder_rms_um"], 1)],
                 [f"{name}: flat vs cylindrical nominal, RMS distance (um)",
                  _f(cyl.flat_vs_cylinder_rms_mm, 2, 1e3), "", ""]]
    rows += [["gray-level residual std (% of the dynamic range)",
              ", ".join(f"{k} {v:.2f}" for k, v in c.residual_percent.items()), "", ""],
             ["integration points (seen) / masked",
              ", ".join(f"{k} {c.n_points[k]:,} / {100 * c.masked_fraction[k]:.1f}%" for k in c.n_points),
              "", PYVALE["failed"] + " failed"],
             ["wall time (all faces, 2 cores)", f"{run.time_s:.1f} s", "", PYVALE["time"]]]
    return rows


def _pattern(fit) -> str:
    """Mean radial residual near the crest and on the flanks of a fit (um)."""
    crest = fit.residuals_mm[np.abs(fit.angle_deg) <= 10.0]
    flanks = fit.residuals_mm[np.abs(fit.angle_deg) >= 30.0]
    return f"mean residual {_f(float(np.mean(crest)), 1, 1e3)} um at the crest (+-10 deg), " \
           f"{_f(float(np.mean(flanks)), 1, 1e3)} um on the flanks (beyond 30 deg)"


def radius_discussion(c: Comparison) -> str:
    """What the measurement says about the laser's and pyvale's radii (numbers of this run)."""
    if not c.cylinders:
        return "<p>No cylinder measured in this run.</p>"
    items, verdicts = [], []
    for name, cyl in c.cylinders.items():
        best = cyl.fit.rms_mm
        radii = [r for _, r, _ in cyl.by_arc]
        spread = max(radii) - min(radii) if radii else float("nan")
        fixed = "".join(f"<li>{lab} imposed: fit RMS {_f(f.rms_mm, 1, 1e3)} um ({_f(f.rms_mm / best, 1)} x "
                        f"the best fit), {_pattern(f)}</li>" for lab, f in cyl.fixed.items())
        arcs = ", ".join(f"+-{a:g} deg: {r:.3f} mm" for a, r, _ in cyl.by_arc)
        flat = "" if cyl.fit_flat is None else (
            f"; from the flat nominal (the method is given no radius): {cyl.fit_flat.radius_mm:.3f} mm")
        dist = {lab.split()[0]: abs(float(lab.split()[1]) - cyl.fit.radius_mm) for lab in cyl.fixed}
        verdicts.append(min(dist, key=dist.get))
        items.append(
            f"<li><b>{name}</b>: best-fit radius {cyl.fit.radius_mm:.3f} mm (fit RMS {_f(best, 2, 1e3)} um, "
            f"{_pattern(cyl.fit)}){flat}. Over sub-arcs about the crest: {arcs} (spread "
            f"{_f(spread, 3)} mm).<ul>{fixed}</ul></li>")
    verdict = verdicts[0] if len(set(verdicts)) == 1 else "neither for both bars"
    ratios = {who: [f.rms_mm / cyl.fit.rms_mm for cyl in c.cylinders.values()
                    for lab, f in cyl.fixed.items() if lab.startswith(who)] for who in ("laser", "pyvale")}
    span = {who: f"{min(v):.1f}-{max(v):.1f} x" for who, v in ratios.items() if v}
    return (
        "<p>Each bar is measured over the 80 degrees of arc about its crest that both cameras see, "
        "twice: from an exact NURBS cylinder with the laser's radius as nominal, and from a flat "
        "patch at crest height where the method is given no radius at all and the shape "
        "correction carries the whole arc. The two measured surfaces agree to the RMS distance of "
        "the table, so the radius below is the images', not the nominal's. On rendered images of "
        "bars seen by this rig (examples/dic_challenge/synthetic_cylinder.py) the same measurement "
        "recovers the true radius, 6.38 or 6.23 mm, from either nominal.</p><ul>"
        + "".join(items) + "</ul>"
        f"<p>Radius closer to this measurement: <b>{verdict}</b>. Neither reference radius fits the "
        "measured cross-sections: imposed, each leaves a systematic residual (opposite signs at the "
        "crest and on the flanks), the laser's "
        f"{span.get('laser', 'n/a')} and pyvale's {span.get('pyvale', 'n/a')} the best fit's RMS, "
        "while the radius fitted over 40, 60 or 80 degrees of arc varies by the spread above "
        "only. What the pair sees (80 degrees about the crest) does not reach the flanks near the "
        "plate, so a fit over a wider profile that departs from a circle there can differ.</p>")


def _figure(name: str, png: bytes, caption: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return (f'<figure id="{html.escape(name)}"><img alt="{html.escape(name)}" '
            f'src="data:image/png;base64,{data}"><figcaption>{html.escape(caption)}</figcaption></figure>')


def report_html(run: ChallengeRun, c: Comparison, figures: dict[str, tuple[bytes, str]],
                command: str) -> str:
    """One self-contained HTML page: targets, comparison table, radius investigation, figures."""
    head = "<tr><th>quantity</th><th>this measurement (georeg FE-SDIC)</th><th>laser scan</th>" \
           "<th>pyvale 2026.10.2 (subset DIC)</th></tr>"
    rows = "\n".join("<tr>" + "".join(f"<td>{html.escape(x)}</td>" for x in r) + "</tr>"
                     for r in comparison_rows(run, c))
    claims = "\n".join(f"<li>{_status(ok)} {html.escape(name)}: {html.escape(detail)}</li>"
                       for name, ok, detail in targets(run, c))
    scales = "per face configuration" if run.scales is None else ", ".join(map(str, run.scales))
    body = [
        "<h1>Stereo DIC Challenge 1.0: shape of the specimen by FE stereo-DIC with geometric "
        "regularization</h1>",
        f"<p>Command: <code>{html.escape(command)}</code>. Image scales: {html.escape(scales)}"
        f"{'' if run.crop is None else f'; crop {run.crop}'}. Wall time {run.time_s:.1f} s. "
        "Fixed point of calibration (6 pose unknowns, pyvale's stereo relation kept) and shape, "
        "initialised by the landmarks of specimen.toml; world frame: mm, measured base plane "
        "z = 0.</p>",
        "<p>Images and calibration: SEM/iDICs Stereo-DIC Challenge 1.0 (Experimental Mechanics "
        "2024, doi 10.1007/s11340-024-01077-7), redistributed by pyvale 2026.10.2 (MIT licence, "
        "Computer Aided Validation Laboratory).</p>",
        "<h2>Done-means of issue 5</h2>", f"<ul>\n{claims}\n</ul>",
        "<h2>Comparison</h2>", f"<table>\n{head}\n{rows}\n</table>",
        "<h2>The cylinder radii: laser or pyvale?</h2>", radius_discussion(c),
        "<h2>Figures</h2>", *(_figure(n, png, cap) for n, (png, cap) in figures.items())]
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<title>Stereo DIC Challenge: georeg report</title>\n<style>" + _CSS +
            "</style>\n</head>\n<body>\n" + "\n".join(body) + "\n</body>\n</html>\n")


def summary(run: ChallengeRun, c: Comparison) -> dict:
    """The figures of the run as plain numbers (summary.json)."""
    out = {"time_s": run.time_s, "scales": run.scales, "crop": run.crop,
           "base": {"plane_rms_um": 1e3 * c.base_plane_rms_mm, "quadric_rms_um": 1e3 * c.base_quadric_rms_mm,
                    "whole_plane_rms_um": 1e3 * c.base_all_plane_rms_mm,
                    "whole_quadric_rms_um": 1e3 * c.base_all_quadric_rms_mm},
           "residual_percent": c.residual_percent, "masked_fraction": c.masked_fraction,
           "n_points": c.n_points,
           "targets": [{"claim": n, "passed": ok, "detail": d} for n, ok, d in targets(run, c)]}
    if c.block is not None:
        out["block"] = {"height_mm": c.block.height_mm, "top_rms_plane_um": 1e3 * c.block.top_rms_plane_mm}
    for name, cyl in c.cylinders.items():
        out[name] = {"radius_mm": cyl.fit.radius_mm,
                     "radius_flat_nominal_mm": None if cyl.fit_flat is None else cyl.fit_flat.radius_mm,
                     "crest_above_ring_mm": cyl.crest_above_ring_mm,
                     "axis_below_ring_mm": cyl.axis_below_ring_mm, "fit_rms_um": 1e3 * cyl.fit.rms_mm,
                     "flat_vs_cylinder_rms_um": None if cyl.flat_vs_cylinder_rms_mm is None
                     else 1e3 * cyl.flat_vs_cylinder_rms_mm,
                     "radius_by_half_arc_deg": {f"{a:g}": r for a, r, _ in cyl.by_arc},
                     "fit_rms_um_with_radius": {lab: 1e3 * f.rms_mm for lab, f in cyl.fixed.items()}}
    return out
