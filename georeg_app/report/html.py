"""The self-contained HTML report of a run (figures embedded, inline CSS, no external link).

It holds what produced the report (:mod:`georeg_app.report.provenance`), the table of the methods
(failed methods greyed out with their reason, the best method highlighted and the
criterion said), the figures and, where they apply, the two claims of the paper checked on
the run's own numbers (a FAIL is printed as such, never hidden):

- shape: the georeg RMS shape error (vs the truth) is below every Tikhonov run's and at
  most 0.3 times the unregularized FE run's (needs the truth, a georeg, an FE and a
  Tikhonov method: the demo);
- multiscale (Fig. 11): the georeg multiscale run reaches a final residual equal to or
  lower than the monoscale run's, in at most half the monoscale run's time (needs both).

A claim that does not apply to the run (``passed is None``) is left out of the report.
A failed georeg method fails its claim; a failed reference method (FE, Tikhonov,
monoscale) makes the claim not apply.
"""
from __future__ import annotations

import base64
import html
import logging
import math
from dataclasses import dataclass

import numpy as np

from georeg_app.report.figures import FE_ERROR_RATIO
from georeg_app.report.provenance import header_html
from georeg_app.report.run_view import (best_method, failure, georeg_main, georeg_pair, is_failed,
                                        rms_error_um)

logger = logging.getLogger(__name__)

__all__ = ["TIME_RATIO", "RESIDUAL_RTOL", "FIGURE_CAPTIONS", "STYLESHEET", "Claim",
           "shape_claim", "time_to_reach", "multiscale_claim", "check_claims",
           "level_search_html", "methods_table_html", "report_html"]

TIME_RATIO = 0.5              # multiscale in at most half the monoscale time (Fig. 11)
RESIDUAL_RTOL = 1e-3          # "equal" residuals: within 0.1 % (relative) of each other

FIGURE_CAPTIONS = {
    "shape_maps": "Measured shapes coloured by the distance to the best-fit plane (Figs. 8-10).",
    "residual_maps": "Gray-level residual at the integration points, % of the image dynamic range "
                     "(Fig. 12); colour scale set by the successful methods (a poor method "
                     "saturates).",
    "error_maps": "Signed shape error against the truth per node (µm), after best rigid "
                  "alignment; colour scale set by the successful methods.",
    "convergence": "Residual against iterations and against time normalised by one fine-scale "
                   "iteration (Fig. 11).",
    "multiscale_vs_monoscale": "Geometric regularization: multiscale against monoscale (Fig. 11).",
    "shape_errors": "RMS shape error against the truth (µm, when known) and RMS distance to the "
                    "best-fit plane (mm) per method.",
    "uncertainty_maps": "Shape uncertainty per method: the standard deviation from the image "
                        "noise and the bias indicator (the move of one notch less "
                        "regularization; the std alone understates the error where the "
                        "regularization misses part of the shape).",
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
td.status { text-align: left; }
tr.failed td { color: #888; background: #f3f3f3; }
tr.failed td.status { color: #b22; }
tr.best td { background: #e3f4e3; font-weight: bold; }
table.inputs td, table.rig td { font-family: monospace; font-size: 0.85em; text-align: left; }
table.inputs th, table.rig th { text-align: left; }
pre { background: #f6f6f6; padding: 0.7em; overflow-x: auto; }
figure { margin: 1.5em 0; } img { max-width: 100%; } figcaption { color: #555; }
"""


@dataclass(frozen=True)
class Claim:
    """One claim checked on a run: ``passed`` is None when it does not apply to the run."""

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
    multi = georeg_main(run)
    fe = [r for r in run.results if r.spec.name == "fe"]
    tik = [r for r in run.results if r.spec.name == "tikhonov"]
    if multi is None or not fe or not tik:
        return Claim(name, None, "the run needs a georeg, an FE and at least one Tikhonov method")
    if any(is_failed(r) for r in [fe[0], *tik]):
        return Claim(name, None, "a reference method (FE or Tikhonov) failed")
    if is_failed(multi):
        return Claim(name, False, f"{multi.spec.label} failed: {failure(multi)}")
    geo, fe_err = rms_error_um(multi), rms_error_um(fe[0])
    tik_err = [rms_error_um(r) for r in tik]
    if geo is None or fe_err is None or any(e is None for e in tik_err) or fe_err <= 0:
        return Claim(name, None, "a method of the run has no shape error against the truth")
    below_tik = all(geo < e for e in tik_err)
    below_fe = geo <= FE_ERROR_RATIO * fe_err
    tik_text = ", ".join(f"{r.spec.label}: {_f(e)} µm" for r, e in zip(tik, tik_err))
    detail = (f"georeg {_f(geo)} µm; {tik_text} ({'all above' if below_tik else 'NOT all above'}); "
              f"FE {_f(fe_err)} µm, ratio georeg/FE = {_f(geo / fe_err, 3)} "
              f"({'<=' if below_fe else '>'} {FE_ERROR_RATIO:g})")
    return Claim(name, bool(below_tik and below_fe), detail)


def time_to_reach(result, target_percent: float) -> float:
    """Time (s) at which ``result`` first reaches a residual <= ``target_percent`` at the
    full-resolution scale 0 (coarse-scale residuals are on coarse images, Remark 10);
    its total time if only its final state does; inf if it never does (or has no measurement)."""
    if result.measurement is None:
        return math.inf
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
    if is_failed(mono):
        return Claim(name, None, f"the reference {mono.spec.label} failed: {failure(mono)}")
    if is_failed(multi):
        return Claim(name, False, f"{multi.spec.label} failed: {failure(multi)}")
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
    """The two claims of the demo (README, "Headline results") on ``run`` (``passed`` None
    where a claim does not apply)."""
    claims = (shape_claim(run), multiscale_claim(run))
    for c in claims:
        logger.log(logging.DEBUG if c.passed is None else logging.INFO,
                   "claim %s: %s (%s)", c.status, c.name, c.detail)
    return claims


def _rms(values) -> float | None:
    return None if values is None else float(np.sqrt(np.mean(np.square(values))))


def _median_max_um(values) -> str:
    if values is None:
        return "n/a"
    values = 1e3 * np.asarray(values, float)
    return f"{_f(float(np.nanmedian(values)), 3)} / {_f(float(np.nanmax(values)), 3)}"


def _chosen(result) -> str:
    """What a method chose from the data: georeg's level, Tikhonov's lengths per scale."""
    search = getattr(result, "level_search", None)
    if search is not None:
        dofs = [t.dofs for t in search.trials if t.chosen]
        return (f"level {search.chosen} of {search.n_levels}"
                + (f" ({dofs[0]} dofs)" if dofs else ""))
    chosen = (getattr(result, "regularization", None) or {}).get("tikhonov_length_mm")
    if chosen:
        return ", ".join(f"scale {k}: {v:.3g} mm" for k, v in sorted(chosen.items()))
    return ""


def level_search_html(run) -> str:
    """Per georeg method with automatic levels: the levels looked at, their dofs, residual,
    agreement with the finer levels (standard deviations of the change), estimated RMS shape
    error and its noise part (:mod:`georeg_plugin.levels.risk`)."""
    parts = []
    for r in run.results:
        search = getattr(r, "level_search", None)
        if search is None or not search.trials:
            continue
        rows = "".join(
            f"<tr><td>{t.level}</td><td>{t.dofs}</td><td>{'measured' if t.measured else 'predicted'}"
            f"</td><td>{_f(t.residual_percent)}</td><td>{_f(t.agreement, 3)}</td>"
            f"<td>{_f(1e3 * t.error_mm, 3)}</td><td>{_f(1e3 * t.std_mm, 3)}</td>"
            f"<td>{'chosen' if t.chosen else ''}</td></tr>" for t in search.trials)
        parts.append(
            f"<h3>{html.escape(r.spec.label)}: level search</h3><p>Levels of the ladder "
            f"{search.n_levels} (0 = the spline of the FE mesh), start {search.start}, chosen "
            f"{search.chosen}; noise variance kappa {_f(search.variance)}; added time "
            f"{_f(search.time_s, 3)} s. The coarsest level is taken whose shape agrees with every "
            "finer level's to within 2 standard deviations of their change (RMS over the nodes, "
            "modulo the rigid normal motions). The estimated error (bias and noise) is measured "
            "against the next finer level.</p>"
            "<table><tr><th>level</th><th>dofs</th><th></th><th>residual (%)</th>"
            "<th>agreement (std)</th><th>estimated error (µm)</th><th>of which noise (µm)</th>"
            f"<th></th></tr>{rows}</table>")
    return "".join(parts)


def methods_table_html(run) -> str:
    """HTML table of the methods: status (failed: reason), RMS error vs truth (um), RMS
    distance to BFP (mm), residual and noise floor (%; the column only when the run gives
    ``noise_percent``), iterations, time, convergence, the shape's std, bias indicator and
    uncertainty (their root sum of squares), the level chosen. Failed rows have class "failed",
    the best method's row class "best"."""
    noise = any(getattr(r.measurement, "noise_percent", None) is not None for r in run.results)
    head = ("<tr><th>method</th><th>name</th><th>param</th><th>status</th>"
            "<th>RMS shape error vs truth (µm)</th><th>RMS distance to BFP (mm)</th>"
            "<th>residual (% dyn.)</th>" + ("<th>noise floor (% dyn.)</th>" if noise else "")
            + "<th>iterations</th><th>time (s)</th><th>converged</th>"
            "<th>shape std median / max (µm)</th><th>bias indicator median / max (µm)</th>"
            "<th>uncertainty median / max (µm)</th><th>chosen</th></tr>")
    best, _ = best_method(run)
    rows = []
    for r in run.results:
        m = r.measurement
        status = f"failed: {failure(r)}" if is_failed(r) else ("best" if r is best else "ok")
        param = r.spec.param
        cells = [r.spec.label, r.spec.name, "" if param is None else
                 (param if isinstance(param, str) else f"{param:g}"),
                 status, _f(rms_error_um(r)), _f(_rms(r.distance_to_bfp_mm))]
        if m is None:
            cells += ["n/a"] * (9 if noise else 8)
        else:
            cells += [_f(m.residual_percent), *([_f(getattr(m, "noise_percent", None))] * noise),
                      str(int(m.iterations)), _f(m.time_s, 3), "yes" if m.converged else "no",
                      _median_max_um(getattr(m, "shape_std_mm", None)),
                      _median_max_um(getattr(m, "shape_bias_mm", None)),
                      _median_max_um(getattr(m, "shape_uncertainty_mm", None)), _chosen(r)]
        css = "failed" if is_failed(r) else ("best" if r is best else "")
        tds = "".join(f'<td class="status">{html.escape(c)}</td>' if k == 3 else
                      f"<td>{html.escape(c)}</td>" for k, c in enumerate(cells))
        rows.append((f'<tr class="{css}">' if css else "<tr>") + tds + "</tr>")
    return f"<table class=\"methods\">\n{head}\n" + "\n".join(rows) + "\n</table>"


def _claims_html(claims) -> str:
    items = [f'<li><span class="{c.status.replace(" ", "-")}">{c.status}</span> '
             f"{html.escape(c.name)}<br><small>{html.escape(c.detail)}</small></li>" for c in claims]
    return "<ul>\n" + "\n".join(items) + "\n</ul>"


def _figure_html(name: str, png: bytes) -> str:
    data = base64.b64encode(png).decode("ascii")
    caption = html.escape(FIGURE_CAPTIONS.get(name, name))
    return (f'<figure id="{html.escape(name)}"><img alt="{html.escape(name)}" '
            f'src="data:image/png;base64,{data}"><figcaption>{caption}</figcaption></figure>')


def _summary_line(run) -> str:
    failed = [r for r in run.results if is_failed(r)]
    truth = ("the true shape is known (synthetic images): errors are after best rigid alignment"
             if run.truth_available else "no true shape: the RMS shape error is not available")
    text = (f"{len(run.results)} method(s) on the same images; {truth}. "
            f"One fine-scale iteration: {_f(run.one_fine_iteration_s, 3)} s.")
    if failed:
        text += (f" {len(failed)} method(s) failed ({', '.join(r.spec.label for r in failed)}): "
                 "greyed out, drawn faded or not at all, and never setting a colour scale.")
    return f"<p>{html.escape(text)}</p>"


def report_html(run, figures: dict[str, bytes]) -> str:
    """One self-contained HTML page: what produced it, methods table with the best method,
    the claims that apply (PASS/FAIL with numbers), figures."""
    claims = [c for c in check_claims(run) if c.passed is not None]
    _, why_best = best_method(run)
    body = ["<h1>georeg: FE stereo-DIC shape measurement</h1>", _summary_line(run),
            header_html(run), "<h2>Methods</h2>", methods_table_html(run),
            f'<p class="best-method">{html.escape(why_best)}</p>', level_search_html(run)]
    if claims:
        body += ['<h2 id="claims">Claims of the paper checked on this run</h2>', _claims_html(claims)]
    body += ["<h2>Figures</h2>", *(_figure_html(n, png) for n, png in figures.items())]
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<title>georeg report</title>\n<style>" + STYLESHEET + "</style>\n</head>\n<body>\n"
            + "\n".join(body) + "\n</body>\n</html>\n")
