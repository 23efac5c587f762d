"""examples/tutorial_operator_projection.py runs and its stated identities hold.

The tutorial checks every identity it prints (Eqs. 15-21 and 28 on a real H_FE, b_FE
of the core); here its numbers are asserted again, plus the comparisons it tells the
reader about (the spline step and shape are closer to the truth than the FE ones).
"""
import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "examples" / "tutorial_operator_projection.py"


@pytest.fixture(scope="module")
def tutorial():
    spec = importlib.util.spec_from_file_location("tutorial_operator_projection", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def run(tutorial, tmp_path_factory):
    figure = tmp_path_factory.mktemp("tutorial") / "figure.png"
    return tutorial.main(["--plot", str(figure)]), figure


IDENTITIES = {  # name -> bound, as stated in the tutorial (<= unless said otherwise)
    "eq17_nodes": 1e-10, "eq15_geometry": 1e-10, "eq28_product_form": 1e-12,
    "eq16_inside_elements": 1e-12, "partition_of_unity": 1e-12, "H_symmetric": 1e-12,
    "hook_equals_by_hand": 1e-12, "range_of_C_T": 1e-10, "reduced_residual": 1e-10,
    "fe_step_solves": 1e-10, "h_orthogonal_projection": 1e-10, "fe_model_lower": 0.0,
    "spline_field_exact": 1e-9, "gn_spline_in_range": 1e-10,
}
LOWER_BOUNDS = {"H_s_positive": 0.0, "minimum_over_splines": 0.0}


@pytest.mark.slow
def test_every_identity_of_the_tutorial_holds(run):
    result, _ = run
    assert result["failed"] == []
    assert set(result["checks"]) == set(IDENTITIES) | set(LOWER_BOUNDS)
    for name, bound in IDENTITIES.items():
        value, _, sense = result["checks"][name]
        assert sense == "<=" and value <= bound, (name, value)
    for name, bound in LOWER_BOUNDS.items():
        value, _, sense = result["checks"][name]
        assert sense == ">=" and value > bound, (name, value)


def test_smallest_example_sizes(run):
    result, _ = run
    assert (result["n_spline"], result["n_fe"]) == (16, 117)  # 4 x 4 control points; 13 x 9 Q9 nodes
    assert result["n_points"] > 20_000                         # ~1 point per pixel


def test_spline_projection_is_closer_to_the_truth_than_fe(run):
    result, _ = run
    assert result["step_error_spline_mm"] < 0.5 * result["step_error_fe_mm"]
    assert result["gn_error_spline_mm"] < 0.5 * result["gn_error_fe_mm"]
    assert result["gn_error_spline_mm"] < 0.05 * result["true_rms_mm"]
    # the FE solution minimises over a larger space: it fits the images (and noise) better
    assert result["gn_residual_fe_percent"] <= result["gn_residual_spline_percent"]


def test_plot_option_writes_a_png(run):
    _, figure = run
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(figure.parent.glob(".*.tmp")) and not list(figure.parent.glob(".figure*"))
