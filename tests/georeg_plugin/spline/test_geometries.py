"""Nominal geometries: exact rectangle, plate with a hole (Fig. 7(a)), cylinder."""
import numpy as np
import pytest

from georeg_plugin.spline.geometries import (cylinder, plate_with_hole, quadrilateral, rectangle,
                                             transformed)
from georeg_plugin.spline.refine import insert_knots, refine_uniform

L, W, R = 180.0, 50.0, 14.0


def test_rectangle_is_flat_exact_and_oriented():
    s = rectangle(L, W, center=(3.0, -1.0), degrees=(2, 3))
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 1, (500, 2))
    X = s.evaluate(uv)
    # linear parametrization: x = x0 + u L, y = y0 + v W, z = 0
    np.testing.assert_allclose(X, np.c_[3 - L / 2 + L * uv[:, 0], -1 - W / 2 + W * uv[:, 1],
                                        np.zeros(len(uv))], atol=1e-12)
    np.testing.assert_allclose(s.normals(uv), np.tile([0, 0, 1.0], (len(uv), 1)), atol=0)
    assert s.n_elements == (1, 1) and not s.is_rational
    with pytest.raises(ValueError, match="width_mm"):
        rectangle(L, -1.0)


def test_plate_with_hole_structure():
    s = plate_with_hole(L, W, R)
    assert s.is_rational and s.degrees == (2, 2) and s.shape == (9, 3)
    np.testing.assert_array_equal(s.knots[0], [0, 0, 0, .25, .25, .5, .5, .75, .75, 1, 1, 1])
    np.testing.assert_array_equal(s.knots[1], [0, 0, 0, 1, 1, 1])
    np.testing.assert_allclose(s.weights[1::2], np.cos(np.pi / 4), atol=0)
    np.testing.assert_allclose(s.weights[0::2], 1.0, atol=0)
    # the C0 knots u = k/4 map to the plate corners; u = 0 and u = 1 coincide
    corners = s.evaluate(np.c_[np.arange(5) / 4, np.ones(5)])
    np.testing.assert_allclose(corners[:, :2], [[L / 2, W / 2], [L / 2, -W / 2],
                                                [-L / 2, -W / 2], [-L / 2, W / 2],
                                                [L / 2, W / 2]], atol=1e-12)
    with pytest.raises(ValueError, match="hole_radius_mm"):
        plate_with_hole(L, W, 30.0)


@pytest.mark.parametrize("refine", [0, 1, 2])
def test_hole_is_an_exact_circle_and_outer_boundary_the_rectangle(refine):
    s = plate_with_hole(L, W, R, center=(2.0, -3.0))
    if refine:
        s, _ = refine_uniform(s, refine)
        s, _ = insert_knots(s, [0.1, 0.33], [0.37])
    rng = np.random.default_rng(refine)
    u = rng.uniform(0, 1, 1000)
    hole = s.evaluate(np.c_[u, np.zeros_like(u)]) - [2.0, -3.0, 0.0]
    np.testing.assert_allclose(np.linalg.norm(hole, axis=1), R, atol=1e-12)
    outer = s.evaluate(np.c_[u, np.ones_like(u)]) - [2.0, -3.0, 0.0]
    on_side = np.minimum(np.abs(np.abs(outer[:, 0]) - L / 2), np.abs(np.abs(outer[:, 1]) - W / 2))
    assert on_side.max() < 1e-12
    assert np.all(np.abs(outer[:, 0]) <= L / 2 + 1e-12) and np.all(np.abs(outer[:, 1]) <= W / 2 + 1e-12)
    # each quarter of u: a 90-degree arc of the hole, clockwise from the +x+y diagonal,
    # and one side of the plate (right, bottom, left, top)
    angle = np.degrees(np.arctan2(hole[:, 1], hole[:, 0]))
    hole_quarter = np.floor(np.mod(45.0 - angle, 360.0) / 90.0)
    quarter = np.floor(4 * u).clip(0, 3)
    side = np.select([outer[:, 0] >= L / 2 - 1e-9, outer[:, 1] <= -W / 2 + 1e-9,
                      outer[:, 0] <= -L / 2 + 1e-9], [0, 1, 2], 3)
    assert np.all(side == quarter) and np.all(hole_quarter == quarter)


def test_plate_with_hole_is_planar_with_normal_plus_z():
    s = plate_with_hole(L, W, R)
    uv = np.random.default_rng(3).uniform(0, 1, (2000, 2))
    np.testing.assert_allclose(s.evaluate(uv)[:, 2], 0.0, atol=0)
    np.testing.assert_allclose(s.normals(uv), np.tile([0, 0, 1.0], (len(uv), 1)), atol=1e-14)
    # radial direction: linear interpolation between hole and boundary (v = 0.5 midway)
    u = uv[:, 0]
    mid = s.evaluate(np.c_[u, np.full_like(u, 0.5)])
    ends = 0.5 * (s.evaluate(np.c_[u, np.zeros_like(u)]) + s.evaluate(np.c_[u, np.ones_like(u)]))
    np.testing.assert_allclose(mid, ends, atol=1e-12)


@pytest.mark.parametrize("axis", ["x", "y"])
@pytest.mark.parametrize("angle", [60.0, 180.0, 270.0])
def test_cylinder_is_exact_with_outward_normal(axis, angle):
    radius, length = 12.0, 40.0
    s = cylinder(radius, length, angle, axis=axis, center=(1.0, 2.0))
    assert s.n_elements[0] == int(np.ceil(angle / 90))
    uv = np.random.default_rng(4).uniform(0, 1, (1000, 2))
    X = s.evaluate(uv)
    a, b = (0, 1) if axis == "x" else (1, 0)
    radial = np.c_[X[:, b] - (1.0, 2.0)[b], X[:, 2]]
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), radius, atol=1e-12)
    opening = np.degrees(np.abs(np.arctan2(radial[:, 0], radial[:, 1])))
    assert opening.max() <= angle / 2 + 1e-9
    np.testing.assert_allclose(X[:, a], (1.0, 2.0)[a] + length * (uv[:, 1] - 0.5), atol=1e-12)
    n = s.normals(uv)
    expected = np.zeros_like(X)
    expected[:, b], expected[:, 2] = radial[:, 0] / radius, radial[:, 1] / radius
    np.testing.assert_allclose(n, expected, atol=1e-12)
    crest = s.evaluate([[0.5, 0.5]])[0]
    assert crest[2] == pytest.approx(radius, abs=1e-12)


def _rotation(axis, angle_rad):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1 - np.cos(angle_rad)) * K @ K


@pytest.mark.parametrize("degrees", [(1, 1), (2, 2), (3, 2)])
def test_quadrilateral_is_the_flat_bilinear_map_of_its_corners(degrees):
    R = _rotation([1.0, -2.0, 0.5], 0.7)
    flat = np.array([[0, 0, 0], [30, 2, 0], [27, 21, 0], [-1, 18, 0]], float)  # not a rectangle
    corners = flat @ R.T + [5.0, -3.0, 6.36]
    s = quadrilateral(corners, degrees=degrees)
    assert s.degrees == degrees and s.n_elements == (1, 1) and not s.is_rational
    np.testing.assert_allclose(s.evaluate([[0, 0], [1, 0], [1, 1], [0, 1]]), corners, atol=1e-12)
    uv = np.random.default_rng(5).uniform(0, 1, (500, 2))
    u, v = uv[:, :1], uv[:, 1:]
    bilinear = (1 - u) * (1 - v) * corners[0] + u * (1 - v) * corners[1] + u * v * corners[2] \
        + (1 - u) * v * corners[3]
    np.testing.assert_allclose(s.evaluate(uv), bilinear, atol=1e-11)
    # flat, normal = R e_z (the corners turn counter-clockwise seen from +z before rotation)
    np.testing.assert_allclose(s.normals(uv), np.tile(R[:, 2], (len(uv), 1)), atol=1e-12)
    refined, _ = refine_uniform(s, 2)
    np.testing.assert_allclose(refined.evaluate(uv), s.evaluate(uv), atol=1e-11)


def test_quadrilateral_rejects_bad_corners():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    with pytest.raises(ValueError, match="not coplanar"):
        quadrilateral(square + [[0, 0, 0], [0, 0, 0], [0, 0, 1e-3], [0, 0, 0]])
    with pytest.raises(ValueError, match="degenerate"):
        quadrilateral([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    with pytest.raises(ValueError, match=r"\(4, 3\)"):
        quadrilateral(square[:3])


def test_transformed_cylinder_stays_exact():
    radius, length = 6.38, 40.0
    R = _rotation([0.1, 0.2, 1.0], 0.4)
    t = np.array([40.9, 24.7, -0.23])
    s = transformed(cylinder(radius, length, 80.0, axis="y"), R, t)
    uv = np.random.default_rng(6).uniform(0, 1, (1000, 2))
    X = s.evaluate(uv)
    axis = R @ [0.0, 1.0, 0.0]
    arm = X - t
    radial = arm - np.outer(arm @ axis, axis)
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), radius, atol=1e-12)
    np.testing.assert_allclose(s.normals(uv), radial / radius, atol=1e-12)
    with pytest.raises(ValueError, match="rotation"):
        transformed(s, np.diag([1.0, 1.0, -1.0]))
