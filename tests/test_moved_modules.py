"""The flat import paths of release 0.1 still import, for one release, as the new modules."""
import importlib
import importlib.util
import pathlib
import sys
import warnings

import pytest

import _georeg_moved


@pytest.mark.parametrize("old, new", sorted(_georeg_moved.MOVED.items()))
def test_an_old_path_is_the_new_module_and_warns(old, new):
    if new.endswith("cad_kernel"):
        pytest.importorskip("OCP")                       # the cad extra
    module = importlib.import_module(new)
    sys.modules.pop(old, None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        aliased = importlib.import_module(old)
    assert aliased is module and sys.modules[old] is module
    assert any(issubclass(w.category, DeprecationWarning) and new in str(w.message) for w in caught)


def test_every_new_path_exists_and_no_old_path_is_still_a_file():
    for old, new in _georeg_moved.MOVED.items():
        assert importlib.util.find_spec(new) is not None, new
        parent, _, name = old.rpartition(".")
        package = importlib.import_module(parent)
        assert not any((pathlib.Path(p) / f"{name}.py").exists() for p in package.__path__), old


def test_the_names_of_the_old_flat_modules_now_packages_are_exported():
    """``fesdic_core.residual``, ``.shape``, ``.displacement``, ``georeg_app.config`` and
    ``georeg_app.report`` were modules; their public names are the packages' exports."""
    from fesdic_core.displacement import measure_displacement
    from fesdic_core.residual import GrayLevelResidual, gray_level_residual
    from fesdic_core.shape import ShapeResult, shape_gauss_newton
    from georeg_app.config import load_config
    from georeg_app.report import report_html
    assert callable(gray_level_residual) and callable(shape_gauss_newton)
    assert callable(measure_displacement) and GrayLevelResidual and ShapeResult
    assert callable(load_config) and callable(report_html)
