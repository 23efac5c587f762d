"""Figures and the self-contained HTML reports of a run and of a series."""

from georeg_app.report.figures import (FE_ERROR_RATIO, convergence, multiscale_vs_monoscale,
                                       shape_errors, make_figures)
from georeg_app.report.html import (TIME_RATIO, RESIDUAL_RTOL, FIGURE_CAPTIONS, STYLESHEET, Claim,
                                    shape_claim, time_to_reach, multiscale_claim, check_claims,
                                    level_search_html, methods_table_html, report_html)
from georeg_app.report.maps import (DPI, FAILED_GREY, png, grid, bfp_frame, nice_scale_factor,
                                    cmap_colours, title, plan_figure, shape_maps, residual_maps,
                                    error_norm, error_maps, uncertainty_maps)
from georeg_app.report.provenance import (package_version, config_toml, inputs_html, rig_html,
                                          header_html)
from georeg_app.report.run_view import (UM_PER_MM, is_failed, failure, succeeded, measured,
                                        colour_range, rms_error_um, node_errors_um, best_method,
                                        georeg_pair, georeg_main)
from georeg_app.report.track import series_figure, maps_figure, track_report_html

__all__ = ["FE_ERROR_RATIO", "convergence", "multiscale_vs_monoscale", "shape_errors",
           "make_figures", "TIME_RATIO", "RESIDUAL_RTOL", "FIGURE_CAPTIONS", "STYLESHEET", "Claim",
           "shape_claim", "time_to_reach", "multiscale_claim", "check_claims", "level_search_html",
           "methods_table_html", "report_html", "DPI", "FAILED_GREY", "png", "grid", "bfp_frame",
           "nice_scale_factor", "cmap_colours", "title", "plan_figure", "shape_maps",
           "residual_maps", "error_norm", "error_maps", "uncertainty_maps", "package_version",
           "config_toml", "inputs_html", "rig_html", "header_html", "UM_PER_MM", "is_failed",
           "failure", "succeeded", "measured", "colour_range", "rms_error_um", "node_errors_um",
           "best_method", "georeg_pair", "georeg_main", "series_figure", "maps_figure",
           "track_report_html"]
