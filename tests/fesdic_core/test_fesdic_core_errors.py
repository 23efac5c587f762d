"""fesdic_core's exception family: every exception class of the core derives from
FesdicCoreError (and keeps its built-in base); the file readers raise family members."""
import sys

import meshio
import numpy as np
import pytest

import fesdic_core
from exception_family import exception_classes, outside_family
from fesdic_core import (CalibrationError, FesdicCoreError, ImageError, MeasurementInputError,
                         MeshError, ShapeDivergedError, SingularSystemError)
from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.rig import initial_pose, read_cameras_json
from fesdic_core.fe.mesh_io import read_mesh


def test_every_exception_class_of_the_core_derives_from_its_base():
    assert outside_family(fesdic_core, FesdicCoreError) == []


@pytest.mark.parametrize("cls, builtin", [
    (CalibrationError, ValueError), (ImageError, ValueError), (MeshError, ValueError),
    (MeasurementInputError, ValueError), (ShapeDivergedError, RuntimeError),
    (SingularSystemError, RuntimeError)])
def test_each_class_is_found_and_keeps_its_builtin_base(cls, builtin):
    assert cls in exception_classes(fesdic_core).values()
    assert issubclass(cls, FesdicCoreError) and issubclass(cls, builtin)


def test_the_base_is_exported():
    assert "FesdicCoreError" in fesdic_core.__all__
    assert fesdic_core.FesdicCoreError is FesdicCoreError


def test_the_check_finds_a_class_outside_the_family(tmp_path, monkeypatch):
    """The walk sees every module of a package, nested ones included."""
    pkg = tmp_path / "stray_pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("class Base(Exception):\n    pass\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "mod.py").write_text("from stray_pkg import Base\n\n"
                                        "class Good(Base, ValueError):\n    pass\n\n"
                                        "class Stray(ValueError):\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import stray_pkg
    try:
        assert outside_family(stray_pkg, stray_pkg.Base) == ["stray_pkg.sub.mod.Stray"]
        assert "stray_pkg.sub.mod.Good" in exception_classes(stray_pkg)
    finally:
        for name in [m for m in sys.modules if m.split(".")[0] == "stray_pkg"]:
            del sys.modules[name]


def test_unreadable_mesh_files_raise_mesh_error(tmp_path):
    garbage = tmp_path / "mesh.vtu"
    garbage.write_text("not a mesh")
    with pytest.raises(MeshError, match="mesh.vtu"):
        read_mesh(garbage)
    dangling = tmp_path / "dangling.vtu"                 # a cell refers to node 7 of 3
    meshio.write(dangling, meshio.Mesh(np.eye(3), [("triangle", np.array([[0, 1, 7]]))]))
    with pytest.raises(MeshError, match="dangling.vtu"):
        read_mesh(dangling)


def test_calibration_readers_raise_calibration_error(tmp_path):
    bad_json = tmp_path / "cameras.json"
    bad_json.write_text("{")
    with pytest.raises(CalibrationError, match="cameras.json: not valid JSON"):
        read_cameras_json(bad_json)
    camera = Camera(np.array([[1000.0, 0, 320], [0, 1000, 240], [0, 0, 1]]), np.zeros(5),
                    np.zeros(3), np.array([0, 0, 500.0]), (640, 480), "cam0")
    with pytest.raises(CalibrationError, match=r"cam0.*at least 4 landmarks, got 3"):
        initial_pose(camera, np.eye(3), np.full((3, 2), 100.0))
