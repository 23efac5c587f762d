"""The gray-level residual of Eq. 3 and its brightness/contrast normalisation (Remark 2)."""
import numpy as np
import pytest

from fesdic_core.fe.elements import FAMILIES
from fesdic_core.fe.mesh import CellBlock, SurfaceMesh, node_normals, rectangle_mesh
from fesdic_core.fe.quadrature import pixel_quadrature
from fesdic_core.imaging.image import Image
from fesdic_core.residual.graylevel import gray_level_residual
from fesdic_core.shape.operators import current_nodes
from fesdic_core.synthetic.render import true_normal_offset


def _two_separate_elements():
    """Two Q4 elements 16 mm apart (left: x in [-28, -8], right: x in [8, 28])."""
    nodes = np.array([[-28, -15, 0], [-8, -15, 0], [-8, 15, 0], [-28, 15, 0],
                      [8, -15, 0], [28, -15, 0], [28, 15, 0], [8, 15, 0]], float)
    return SurfaceMesh(nodes, (CellBlock(FAMILIES["Q4"], np.arange(8).reshape(2, 4)),))


def _surface_points(specimen, mesh, quad):
    normals = node_normals(mesh)
    q = true_normal_offset(specimen, mesh.nodes, normals)
    return quad.points(current_nodes(mesh.nodes, normals, q))


def test_element_normalisation_is_invariant_to_a_per_element_affine_change(twisted_scene):
    """Remark 2: f1 -> a f1 + b, with (a, b) different under each element, leaves r unchanged."""
    specimen, cameras, images = twisted_scene
    mesh = _two_separate_elements()
    quad = pixel_quadrature(mesh, cameras)
    X = _surface_points(specimen, mesh, quad)
    seam = cameras[1].project(np.array([[0.0, y, 0.0] for y in (-15.0, 15.0)]))[:, 0].mean()
    columns = np.arange(images[1].shape[1])[None, :]
    a = np.where(columns < seam, 0.6, 1.3)                  # contrast, left / right element
    b = np.where(columns < seam, 25.0, -40.0)               # brightness
    changed = Image.from_array(a * images[1].values + b, source="cam1 affine")
    assert np.all(np.abs(cameras[1].project(X)[:, 0] - seam) > 40.0)   # far from the seam (px)
    for mode, invariant in (("element", True), ("global", False), ("none", False)):
        before = gray_level_residual(X, quad, images, cameras, mode, "point")
        after = gray_level_residual(X, quad, (images[0], changed), cameras, mode, "point")
        np.testing.assert_array_equal(before.mask, after.mask)
        gap = np.abs(after.r - before.r).max()
        if invariant:
            assert gap < 1e-6 * np.abs(before.r).max(), gap
            np.testing.assert_allclose(after.dr_dX, before.dr_dX,
                                       atol=1e-6 * np.abs(before.dr_dX).max())
        else:
            assert gap > 0.1 * np.abs(before.r).max(), (mode, gap)


def test_percent_conventions(twisted_scene):
    """percent = 100 r sigma0 / dynamic range of image 0; std_percent its std over the mask."""
    _, cameras, images = twisted_scene
    mesh = rectangle_mesh(40.0, 30.0, 4, 3, family="Q4")
    quad = pixel_quadrature(mesh, cameras[:1])
    X = quad.points(mesh.nodes)
    a, b = 0.8, 12.0
    pair = (images[0], Image.from_array(a * images[0].values + b, source="affine copy"))
    same = (cameras[0], cameras[0])
    raw = gray_level_residual(X, quad, pair, same, "none", None)
    f0 = images[0].evaluate(cameras[0].project(X))
    expected = 100.0 * ((1.0 - a) * f0 - b) / images[0].dynamic_range
    assert raw.mask.all()
    np.testing.assert_allclose(raw.percent, expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(raw.std_percent, np.std(expected), rtol=1e-9)
    normalised = gray_level_residual(X, quad, pair, same, "element", None)
    np.testing.assert_allclose(normalised.r, 0.0, atol=1e-9)    # contrast and brightness removed
    assert normalised.std_percent < 1e-7
    # in element mode sigma0 is the gray-level std of image 0 over each element
    for e in range(mesh.n_elements):
        np.testing.assert_allclose(normalised.sigma0[quad.element == e], np.std(f0[quad.element == e]),
                                   rtol=1e-9)


def test_points_outside_an_image_are_masked_and_counted(twisted_scene):
    _, cameras, images = twisted_scene
    mesh = rectangle_mesh(100.0, 40.0, 10, 4, family="Q4")     # wider than the 72 mm field
    quad = pixel_quadrature(mesh, cameras)
    X = quad.points(mesh.nodes)
    hidden = np.zeros(quad.n_points, bool)
    hidden[::7] = True
    res = gray_level_residual(X, quad, images, cameras, "element", "point", extra_mask=~hidden)
    seen = ~hidden
    for image, cam in zip(images, cameras):
        seen &= image.inside(cam.project(X))
    np.testing.assert_array_equal(res.mask, seen)
    assert 0 < res.n_dropped == np.count_nonzero(~seen) < quad.n_points
    assert np.all(res.r[~seen] == 0.0) and np.all(np.isnan(res.percent[~seen]))
    assert np.all(np.isfinite(res.percent[seen]))
    assert np.all(res.dr_dX[~seen] == 0.0)


def test_unknown_normalisation_is_named():
    with pytest.raises(ValueError, match="'median'"):
        gray_level_residual(np.zeros((1, 3)), None, (), (), "median")
