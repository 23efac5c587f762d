"""Local validity of a shape measurement's nodes (fesdic_core.shape.validity).

The session's noise-free twisted plate (tests/conftest.py ``twisted_scene``: 60 x 40 mm,
0.5 mm twist, 640 x 480 px). The plate fills the mesh: without the edge margin the band
along its edges, where the image model mixes the speckle with the background, drags the
boundary nodes; the local checks see them.
"""
import numpy as np
import pytest

from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.shape.driver import MeasurementSettings, measure
from fesdic_core.synthetic.accuracy import shape_error_to_surface


@pytest.mark.slow
def test_a_good_shape_keeps_its_nodes_valid(twisted_scene):
    specimen, cameras, images = twisted_scene
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, family="Q4")
    m = measure(mesh, images, cameras, None, MeasurementSettings(scales=(0,), uncertainty=False))
    assert m.ok, m.failure
    assert m.valid.shape == (mesh.n_nodes,) and m.valid.mean() >= 0.95
    assert np.all(np.isfinite(m.residual_to_noise)) and np.all(m.residual_to_noise < 1.0)
    assert m.validity.seen.all()


@pytest.mark.slow
def test_without_the_edge_margin_the_dragged_boundary_nodes_are_invalid(twisted_scene):
    """The invalid nodes lie on the boundary and are farther off than the valid ones; with
    a max_invalid_share the measurement fails naming them, by default (1: never) it passes
    its verdict and keeps them flagged."""
    specimen, cameras, images = twisted_scene
    mesh = rectangle_mesh(60.0, 40.0, 12, 8, family="Q4")
    settings = MeasurementSettings(scales=(0,), uncertainty=False, edge_margin_px=0.0,
                                   max_invalid_share=0.03)
    m = measure(mesh, images, cameras, None, settings)
    assert not m.ok and "not valid locally" in m.failure
    x, y = np.abs(mesh.nodes[:, 0]), np.abs(mesh.nodes[:, 1])
    boundary = (x > 29.9) | (y > 19.9)
    assert np.all(boundary[~m.valid])
    error = np.abs(shape_error_to_surface(m.nodes, specimen))
    assert np.median(error[~m.valid]) > 3 * np.median(error[m.valid])
    loose = measure(mesh, images, cameras, None,
                    MeasurementSettings(scales=(0,), uncertainty=False, edge_margin_px=0.0))
    assert loose.ok and np.array_equal(loose.valid, m.valid)


def test_the_invalid_share_of_a_shape_is_a_checked_setting():
    with pytest.raises(ValueError, match="max_invalid_share must be a share in"):
        MeasurementSettings(max_invalid_share=-0.1)
