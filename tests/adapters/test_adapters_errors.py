"""adapters' exception family: every exception class of the adapters derives from
AdapterError (and keeps its built-in base); the level checks of a nominal model raise it."""
import pytest

import adapters
from adapters import AdapterError, LevelMeshError
from adapters.fesdic_core import georeg_solver, multilevel_for_mesh, nominal_model, part_model
from exception_family import exception_classes, outside_family
from georeg_plugin.spline.geometries import quadrilateral, rectangle


def test_every_exception_class_of_the_adapters_derives_from_its_base():
    assert outside_family(adapters, AdapterError) == []


def test_the_level_mesh_error_is_found_and_keeps_its_builtin_base():
    assert LevelMeshError in exception_classes(adapters).values()
    assert issubclass(LevelMeshError, AdapterError) and issubclass(LevelMeshError, ValueError)


def test_the_base_is_exported():
    assert {"AdapterError", "LevelMeshError"} <= set(adapters.__all__)


def test_a_mesh_across_the_knots_of_the_finest_level_raises_level_mesh_error():
    model = nominal_model(rectangle(60.0, 40.0), (6, 6), "Q9", name="plate")
    with pytest.raises(LevelMeshError, match=r"'plate': FE element \d+ spans u"):
        georeg_solver(model, 3)


def test_a_part_with_too_few_elements_per_span_raises_level_mesh_error():
    halves = [quadrilateral([[-20, -15, 0], [0, -15, 0], [0, 15, 0], [-20, 15, 0]], (2, 2)),
              quadrilateral([[0, -15, 0], [20, -15, 0], [20, 15, 0], [0, 15, 0]], (2, 2))]
    model = part_model(halves, 1)                # one refinement: 4 elements in each face's span
    multilevel_for_mesh(model, 2)
    with pytest.raises(LevelMeshError, match=r"face 0 has 4 FE elements per knot span, fewer "
                                             r"than the 16"):
        multilevel_for_mesh(model, 3)
