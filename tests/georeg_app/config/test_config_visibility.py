"""georeg_app.config.measure: ``[method] self_occlusion`` and ``max_view_angle_deg`` (issue 11 item 4),
their checks, and the core settings the pipeline makes of them."""
import pytest

from fesdic_core.residual.visibility import DEFAULT_MAX_VIEW_ANGLE_DEG, VisibilitySettings
from georeg_app.config.measure import ConfigError, MethodConfig
from georeg_app.shape.visibility import visibility_settings
from test_config_prefilter import _load      # a minimal config with the [method] lines given


def test_defaults_are_the_cores(tmp_path):
    m = _load(tmp_path, "").method
    assert m.self_occlusion is True and m.max_view_angle_deg == DEFAULT_MAX_VIEW_ANGLE_DEG
    v = visibility_settings(m)
    assert isinstance(v, VisibilitySettings) and v.self_occlusion
    assert v.max_view_angle_deg == DEFAULT_MAX_VIEW_ANGLE_DEG


@pytest.mark.parametrize("text, occlusion, angle", [
    ("self_occlusion = false", False, DEFAULT_MAX_VIEW_ANGLE_DEG),
    ("max_view_angle_deg = 60", True, 60.0),
    ("max_view_angle_deg = 90", True, None),                    # 90: no cut-off
])
def test_settings_are_read(tmp_path, text, occlusion, angle):
    v = visibility_settings(_load(tmp_path, text).method)
    assert v.self_occlusion is occlusion and v.max_view_angle_deg == angle


def test_both_off_is_no_visibility():
    assert visibility_settings(MethodConfig(self_occlusion=False, max_view_angle_deg=90.0)) is None


@pytest.mark.parametrize("text, expected", [
    ("max_view_angle_deg = 0", "[method] max_view_angle_deg: must be in (0, 90] (deg; 90 = no "
                               "cut-off), got 0"),
    ("max_view_angle_deg = 95.5", "[method] max_view_angle_deg: must be in (0, 90]"),
    ("max_view_angle_deg = nan", "[method] max_view_angle_deg: expected a number (deg), got nan"),
    ('max_view_angle_deg = "75"', '[method] max_view_angle_deg: expected a number (deg), got "75"'),
    ('self_occlusion = "yes"', '[method] self_occlusion: expected true or false, got "yes"'),
    ("self_occlusion = 1", "[method] self_occlusion: expected true or false, got 1"),
])
def test_bad_values_name_the_key_and_value(tmp_path, text, expected):
    with pytest.raises(ConfigError) as info:
        _load(tmp_path, text)
    assert expected in str(info.value), str(info.value)


def test_self_occlusion_is_cast_only_where_something_can_hide_the_surface():
    """A single flat face cannot hide itself: no ray casting (the grazing test stays); a
    curved face, a part of several faces, or extra occluders (CAD faces not measured) do."""
    import numpy as np
    from adapters.fesdic_core import nominal_model, part_model
    from georeg_plugin.spline.geometries import cylinder, quadrilateral, rectangle
    method = MethodConfig()
    flat = nominal_model(rectangle(40.0, 30.0), 2, "Q9")
    v = visibility_settings(method, flat)
    assert not v.self_occlusion and v.max_view_angle_deg == DEFAULT_MAX_VIEW_ANGLE_DEG
    wall = np.zeros((2, 3, 3))
    v = visibility_settings(method, flat, wall)
    assert v.self_occlusion and np.array_equal(v.extra_occluders, wall)
    assert visibility_settings(method, nominal_model(cylinder(100.0, 40.0, 30.0), 2, "Q9")
                               ).self_occlusion
    halves = [quadrilateral([[-20, -15, 0], [0, -15, 0], [0, 15, 0], [-20, 15, 0]], (2, 2)),
              quadrilateral([[0, -15, 0], [20, -15, 0], [20, 15, 0], [0, 15, 0]], (2, 2))]
    assert visibility_settings(method, part_model(halves, 1)).self_occlusion
