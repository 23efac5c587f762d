"""The self-contained HTML report of a run (figures embedded, inline CSS, no external link).

It holds the table of the methods, the figures and the two claims of the paper checked on
the run's own numbers (a FAIL is printed as such, never hidden):

- shape: the georeg RMS shape error (vs the truth) is below every Tikhonov run's and at
  most 0.3 times the unregularized FE run's (needs the truth: demo);
- multiscale (Fig. 11): the georeg multiscale run reaches a final residual equal to or
  lower than the monoscale run's, in at most half the monoscale run's time.
"""
from __future__ import annotations

import base64
import html
import logging
import math
from dataclasses import dataclass

import numpy as np

from .figures import georeg_pair

logger = logging.getLogger(__name__)

FE_ERROR_RATIO = 0.3          # georeg error <= 0.3 x FE error (issue 4)
TIME_RATIO = 0.5              # multiscale in at most half the monoscale time (Fig. 11)
RESIDUAL_RTOL = 1e-3          # "equal" residuals: within 0.1 % (relative) of each other

FIGURE_CAPTIONS = {
    "shape_maps": "Measured shapes coloured by the distance to the best-fit plane (Figs. 8-10).",
    "residual_maps": "Gray-level residual at the integration points, % of the image dynamic range "
                     "(Fig. 12).",
    "convergence": "Residual against iterations and against time normalised by one fine-scale "
                   "iteration (Fig. 11).",
    "multiscale_vs_monoscale": "Geometric regularization: multiscale against monoscale (Fig. 11).",
    "shape_errors": "Shape error against the truth and distance to the best-fit plane per method.",
}

#: the reports' style sheet (also used by the examples' reports)
STYLESHEET = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
table { border-collapse: collapse; margin: 1em 0; }
th, td { border: 1px solid #bbb; padding: 0.3em 0.7em; text-align: right; }
th { background: #eee; } td:first-child, th:first-child { text-align: left; }
.PASS { color: #fff; background: #2a7d2a; padding: 0 0.4em; font-weight: bold; }
.FAIL { color: #fff; background: #b22; padding: 0 0.4em; font-weight: bold; }
.NOT-CHECKED { color: #fff; background: #777; padding: 0 0.4em; font-weight: bold; }
figure { margin: 1.5em 0; } img { max-width: 100%; } figcaption { color: #555; }
"""


@dataclass(frozen=True)
class Claim:
    """One claim checked on a run: ``passed`` is None when it cannot be checked."""

    name: str
    passed: bool | None
    detail: str

    @property
    def status(self) -> str:
        return "NOT CHECKED" if self.passed is None else ("PASS" if self.passed else "FAIL")


def _f(value: float | None, digits: int = 4) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}g}"


def shape_claim(run) -> Claim:
    """georeg error < every Tikhonov error and <= 0.3 x the FE error (needs the truth)."""
    name = (f"georeg shape error below every Tikhonov run's and <= {FE_ERROR_RATIO:g} x "
            f"the unregularized FE run's")
    if not run.truth_available:
        return Claim(name, None, "no truth available (only the demo knows the true shape)")
    multi, _ = georeg_pair(run)
    fe = [r for r in run.results if r.spec.name == "fe"]
    tik = [r for r in run.results if r.spec.name == "tikhonov"]
    if multi is None or not fe or not tik:
        return Claim(name, None, "the run needs a georeg, an FE and at least one Tikhonov method")
    geo, fe_err = multi.shape_rms_error_mm, fe[0].shape_rms_error_mm
    tik_err = [r.shape_rms_error_mm for r in tik]
    if geo is None or fe_err is None or any(e is None for e in tik_err) or fe_err <= 0:
        return Claim(name, None, "a method of the run has no shape error against the truth")
    below_tik = all(geo < e for e in tik_err)
    below_fe = geo <= FE_ERROR_RATIO * fe_err
    tik_text = ", ".join(f"{r.spec.label}: {_f(e)} mm" for r, e in zip(tik, tik_err))
    detail = (f"georeg {_f(geo)} mm; {tik_text} ({'all above' if below_tik else 'NOT all above'}); "
              f"FE {_f(fe_err)} mm, ratio georeg/FE = {_f(geo / fe_err, 3)} "
              f"({'<=' if below_fe else '>'} {FE_ERROR_RATIO:g})")
    return Claim(name, bool(below_tik and below_fe), detail)


def time_to_reach(result, target_percent: float) -> float:
    """Time (s) at which ``result`` first reaches a residual <= ``target_percent`` at the
    full-resolution scale 0 (coarse-scale residuals are on coarse images, Remark 10);
    its total time if only its final state does; inf if it never does."""
    for record in result.measurement.history:
        if record.get("scale", 0) == 0 and record.get("residual_percent", np.inf) <= target_percent:
            return float(record["time_s"])
    if result.measurement.residual_percent <= target_percent:
        return float(result.measurement.time_s)
    return math.inf


def multiscale_claim(run) -> Claim:
    """Multiscale georeg reaches a residual <= the monoscale final one in <= half its time."""
    name = (f"georeg multiscale reaches an equal or lower residual than monoscale in at most "
            f"{TIME_RATIO:g} x its time")
    multi, mono = georeg_pair(run)
    if multi is None or mono is None:
        return Claim(name, None, "the run needs a georeg multiscale and a georeg monoscale method")
    r_multi, r_mono = multi.measurement.residual_percent, mono.measurement.residual_percent
    t_mono = float(mono.measurement.time_s)
    target = r_mono * (1.0 + RESIDUAL_RTOL)
    t_reach = time_to_reach(multi, target)
    unit = float(run.one_fine_iteration_s) if run.one_fine_iteration_s > 0 else math.nan
    ok = t_reach <= TIME_RATIO * t_mono
    reach = (f"multiscale never reaches <= {_f(target)}%" if math.isinf(t_reach) else
             f"multiscale reaches <= {_f(target)}% at {_f(t_reach, 3)} s = "
             f"{_f(t_reach / unit, 3)} fine iterations")
    detail = (f"final residual: multiscale {_f(r_multi)}%, monoscale {_f(r_mono)}% "
              f"(equal within {RESIDUAL_RTOL:g} relative); {reach} "
              f"(total {_f(multi.measurement.time_s, 3)} s); monoscale time {_f(t_mono, 3)} s = "
              f"{_f(t_mono / unit, 3)} fine iterations; ratio {_f(t_reach / t_mono, 3)} "
              f"({'<=' if ok else '>'} {TIME_RATIO:g})")
    return Claim(name, bool(ok), detail)


def check_claims(run) -> tuple[Claim, ...]:
    """The two claims of issue 4 on ``run``."""
    claims = (shape_claim(run), multiscale_claim(run))
    for c in claims:
        logger.log(logging.DEBUG if c.passed is None else logging.INFO,
                   "claim %s: %s (%s)", c.status, c.name, c.detail)
    return claims


def methods_table_html(run) -> str:
    """HTML table: method, param, RMS error vs truth, RMS distance to BFP, residual, iterations, time."""
    head = ("<tr><th>method</th><th>name</th><th>param</th><th>RMS shape error vs truth (mm)</th>"
            "<th>RMS distance to BFP (mm)</th><th>residual (% dyn.)</th><th>iterations</th>"
            "<th>time (s)</th><th>converged</th></tr>")
    rows = []
    for r in run.results:
        m = r.measurement
        bfp = float(np.sqrt(np.mean(np.square(r.distance_to_bfp_mm))))
        cells = [r.spec.label, r.spec.name, "" if r.spec.param is None else f"{r.spec.param:g}",
                 _f(r.shape_rms_error_mm), _f(bfp), _f(m.residual_percent), str(int(m.iterations)),
                 _f(m.time_s, 3), "yes" if m.converged else "no"]
        rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    return f"<table>\n{head}\n" + "\n".join(rows) + "\n</table>"


def _claims_html(claims) -> str:
    items = [f'<li><span class="{c.status.replace(" ", "-")}">{c.status}</span> '
             f"{html.escape(c.name)}<br><small>{html.escape(c.detail)}</small></li>" for c in claims]
    return "<ul>\n" + "\n".join(items) + "\n</ul>"


def _figure_html(name: str, png: bytes) -> str:
    data = base64.b64encode(png).decode("ascii")
    caption = html.escape(FIGURE_CAPTIONS.get(name, name))
    return (f'<figure id="{html.escape(name)}"><img alt="{html.escape(name)}" '
            f'src="data:image/png;base64,{data}"><figcaption>{caption}</figcaption></figure>')


def report_html(run, figures: dict[str, bytes]) -> str:
    """One self-contained HTML page: methods table, claims (PASS/FAIL with numbers), figures."""
    claims = check_claims(run)
    truth = ("the true shape is known (synthetic images): errors are after best rigid alignment"
             if run.truth_available else "no true shape: the RMS shape error is not available")
    body = [
        "<h1>georeg: FE stereo-DIC shape measurement</h1>",
        f"<p>{len(run.results)} method(s) on the same images; {html.escape(truth)}. "
        f"One fine-scale iteration: {_f(run.one_fine_iteration_s, 3)} s.</p>",
        "<h2>Methods</h2>", methods_table_html(run),
        "<h2>Claims checked on this run</h2>", _claims_html(claims),
        "<h2>Figures</h2>", *(_figure_html(n, png) for n, png in figures.items()),
    ]
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<title>georeg report</title>\n<style>" + STYLESHEET + "</style>\n</head>\n<body>\n"
            + "\n".join(body) + "\n</body>\n</html>\n")
