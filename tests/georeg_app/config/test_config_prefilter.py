"""georeg_app.config.measure: the image model's ``[method] prefilter_px``, ``interpolation_order`` and
``edge_margin_px`` (issue 13) and their checks."""
import textwrap
from pathlib import Path

import pytest

from fesdic_core.shape.driver import MeasurementSettings
from fesdic_core.residual.edges import DEFAULT_EDGE_MARGIN_PX
from fesdic_core.imaging.image import DEFAULT_ORDER, DEFAULT_PREFILTER_PX
from georeg_app.config.measure import ConfigError, MethodConfig, load_config

BASE = """
[images]
cam0 = "left.tif"
cam1 = "right.tif"

[cameras]
file = "cameras.json"

[geometry]
kind = "rectangle"
length_mm = 60.0
width_mm = 40.0

[method]
"""


def _load(folder: Path, method: str):
    for name in ("left.tif", "right.tif", "cameras.json"):
        (folder / name).write_bytes(b"x")
    path = folder / "config.toml"
    path.write_text(textwrap.dedent(BASE) + method + "\n")
    return load_config(path)


def test_prefilter_default_is_the_core_default(tmp_path):
    assert _load(tmp_path, "").method.prefilter_px == DEFAULT_PREFILTER_PX
    assert MethodConfig().prefilter_px == DEFAULT_PREFILTER_PX


@pytest.mark.parametrize("text, value", [("prefilter_px = 0.7", 0.7), ("prefilter_px = 0", 0.0),
                                         ("prefilter_px = 1", 1.0), ("edge_margin_px = 3", 3.0),
                                         ("edge_margin_px = 0", 0.0)])
def test_image_model_settings_are_read(tmp_path, text, value):
    key = text.split(" =")[0]
    m = _load(tmp_path, text).method
    assert getattr(m, key) == value and isinstance(getattr(m, key), float)


@pytest.mark.parametrize("text, expected", [
    ("prefilter_px = -0.5", "[method] prefilter_px: must be >= 0 (px; 0 = no prefilter), got -0.5"),
    ("prefilter_px = nan", "[method] prefilter_px: expected a number (px), got nan"),
    ("prefilter_px = inf", "[method] prefilter_px: expected a number (px), got inf"),
    ('prefilter_px = "0.7"', '[method] prefilter_px: expected a number (px), got "0.7"'),
    ("prefilter_px = true", "[method] prefilter_px: expected a number (px), got true"),
    ("prefilter = 0.7", "[method] prefilter: unknown key (did you mean prefilter_px?)"),
    ("edge_margin_px = -1", "[method] edge_margin_px: must be >= 0 (px; 0 = no margin), got -1"),
    ("edge_margin_px = nan", "[method] edge_margin_px: expected a number (px), got nan"),
    ('edge_margin_px = "2"', '[method] edge_margin_px: expected a number (px), got "2"'),
    ("interpolation_order = 4", "[method] interpolation_order: must be 3 or 5 (3 = cubic, 5 = quintic "
                                "B-spline), got 4"),
    ("interpolation_order = 1", "[method] interpolation_order: must be 3 or 5"),
    ("interpolation_order = 5.0", "[method] interpolation_order: expected an integer (3 or 5), got 5.0"),
    ('interpolation_order = "quintic"', '[method] interpolation_order: expected an integer (3 or 5), '
                                        'got "quintic"'),
    ("interpolation_order = true", "[method] interpolation_order: expected an integer (3 or 5), got true"),
    ("order = 5", "[method] order: unknown key"),
])
def test_bad_image_model_settings_are_refused_naming_the_key(tmp_path, text, expected):
    with pytest.raises(ConfigError) as info:
        _load(tmp_path, text)
    message = str(info.value)
    assert expected in message and "config.toml" in message and "\n" not in message


def test_the_pipeline_reads_the_images_with_the_configured_prefilter(tmp_path, monkeypatch):
    from georeg_app.shape import pipeline

    seen = []

    class Stop(Exception):
        pass

    def fake_read_image(path, prefilter_px, order):
        seen.append((Path(path).name, prefilter_px, order))
        if len(seen) % 2 == 0:
            raise Stop
        return None

    monkeypatch.setattr(pipeline, "read_image", fake_read_image)
    for text in ("prefilter_px = 0.7", "prefilter_px = 0.7\ninterpolation_order = 5"):
        with pytest.raises(Stop):
            pipeline.run_methods(_load(tmp_path, text), [])
    assert seen == [("left.tif", 0.7, 3), ("right.tif", 0.7, 3), ("left.tif", 0.7, 5), ("right.tif", 0.7, 5)]


@pytest.mark.parametrize("text, order", [("", DEFAULT_ORDER), ("interpolation_order = 3", 3),
                                         ("interpolation_order = 5", 5)])
def test_interpolation_order_is_read(tmp_path, text, order):
    m = _load(tmp_path, text).method
    assert m.interpolation_order == order and isinstance(m.interpolation_order, int)
    assert MethodConfig().interpolation_order == DEFAULT_ORDER == 3


def test_edge_margin_default_is_the_core_default(tmp_path):
    assert _load(tmp_path, "").method.edge_margin_px == DEFAULT_EDGE_MARGIN_PX
    assert MeasurementSettings().edge_margin_px == DEFAULT_EDGE_MARGIN_PX == MethodConfig().edge_margin_px


def test_core_settings_refuse_a_negative_margin():
    with pytest.raises(ValueError, match="edge_margin_px"):
        MeasurementSettings(edge_margin_px=-1.0)


@pytest.mark.parametrize("method", ["fe", "georeg"])
def test_the_pipeline_measures_with_the_configured_edge_margin(tmp_path, monkeypatch, method):
    """``[method] edge_margin_px`` reaches the core's settings, for the plain measurement and
    for the level search alike."""
    from adapters.fesdic_core import nominal_model
    from fesdic_core.shape.driver import MeasurementInputError
    from georeg_app.shape import pipeline
    from georeg_app.shape.methods import default_specs
    from georeg_plugin.spline.geometries import rectangle

    seen = []

    def record(*args, **kwargs):
        seen.append(next(a for a in args if isinstance(a, MeasurementSettings)).edge_margin_px)
        raise MeasurementInputError("stop here")

    monkeypatch.setattr(pipeline, "measure", record)
    monkeypatch.setattr(pipeline, "measure_auto_levels", record)
    config = _load(tmp_path, f'name = "{method}"\nedge_margin_px = 3.5')
    spec = default_specs(config)[0]
    with pytest.raises(MeasurementInputError):
        pipeline._measure_one(spec, nominal_model(rectangle(60.0, 40.0), 2, "Q9"), None, None,
                              config, None, None)
    assert seen == [3.5]
