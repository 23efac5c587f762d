"""georeg_plugin's exception family: every exception class of the plugin derives from
GeoregPluginError (and keeps its built-in base); the spline file readers raise family members."""
import json

import numpy as np
import pytest

import georeg_plugin
from exception_family import exception_classes, outside_family
from georeg_plugin import GeoregPluginError, SingularProjectionError, SplineFileError
from georeg_plugin.io import read_iges, read_spline_json
from georeg_plugin.levels.multipatch import NonConformingFacesError
from georeg_plugin.levels.operators import NodesOutsidePatchError
from georeg_plugin.spline.fe_mesh import ElementDegreeError


def test_every_exception_class_of_the_plugin_derives_from_its_base():
    assert outside_family(georeg_plugin, GeoregPluginError) == []


@pytest.mark.parametrize("cls, builtin", [
    (SplineFileError, ValueError), (NonConformingFacesError, ValueError),
    (NodesOutsidePatchError, ValueError), (ElementDegreeError, ValueError),
    (SingularProjectionError, np.linalg.LinAlgError)])
def test_each_class_is_found_and_keeps_its_builtin_base(cls, builtin):
    assert cls in exception_classes(georeg_plugin).values()
    assert issubclass(cls, GeoregPluginError) and issubclass(cls, builtin)


def test_the_base_is_exported():
    assert {"GeoregPluginError", "SplineFileError"} <= set(georeg_plugin.__all__)
    assert georeg_plugin.GeoregPluginError is GeoregPluginError


def test_spline_json_reader_raises_spline_file_error(tmp_path):
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    with pytest.raises(SplineFileError, match="broken.json: not valid JSON"):
        read_spline_json(broken)
    foreign = tmp_path / "foreign.json"
    foreign.write_text(json.dumps({"format": "something else"}))
    with pytest.raises(SplineFileError, match="foreign.json: field 'format'"):
        read_spline_json(foreign)


def test_iges_reader_raises_spline_file_error(tmp_path):
    text = tmp_path / "notes.igs"
    text.write_text("these are not IGES records\n")
    with pytest.raises(SplineFileError, match="notes.igs"):
        read_iges(text)
