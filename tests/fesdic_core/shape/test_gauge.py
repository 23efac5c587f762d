"""The gauge between shape and camera poses (section 2.2) and the best-fit comparisons."""
import cv2
import numpy as np
import pytest

from fesdic_core.fe.elements import FAMILIES as FAMILIES_BY_NAME
from fesdic_core.fe.mesh import (CellBlock, SurfaceMesh, element_areas, nodal_areas, node_normals,
                                 rectangle_mesh)
from fesdic_core.fe.quadrature import pixel_quadrature
from fesdic_core.shape.gauge import (best_fit_plane_distance, move_cameras_with_specimen,
                                     rigid_align, rigid_normal_modes, split_rigid_part,
                                     tangential_motions, transfer_rigid_part)
from fesdic_core.shape.operators import current_nodes
from fesdic_core.synthetic.render import demo_cameras


def _nodal_weights(mesh):
    """Nodal areas (n,): each element's area shared equally by its nodes."""
    w = np.zeros(mesh.n_nodes)
    for block, areas in zip(mesh.blocks, element_areas(mesh)):
        np.add.at(w, block.connectivity, (areas / block.connectivity.shape[1])[:, None])
    return w


def _plate():
    mesh = rectangle_mesh(60.0, 40.0, 12, 8, family="Q4")
    return mesh, node_normals(mesh), _nodal_weights(mesh)


def _cylinder(radius=30.0, sector_deg=90.0):
    """A rectangle mesh mapped onto a cylinder sector of axis x (the rectangle's y -> arc).

    Returns the exact (radial) normals: the node normals of a faceted mesh are off by half
    an element angle at the free edges, which is a discretisation matter, not the gauge's.
    """
    arc = np.deg2rad(sector_deg) * radius
    flat = rectangle_mesh(60.0, arc, 12, 8, family="Q4")
    theta = flat.nodes[:, 1] / radius
    nodes = np.column_stack([flat.nodes[:, 0], radius * np.sin(theta), radius * np.cos(theta)])
    mesh = SurfaceMesh(nodes, flat.blocks)
    radial = np.column_stack([np.zeros_like(theta), np.sin(theta), np.cos(theta)])
    return mesh, radial, _nodal_weights(mesh)


def _twist(nodes):
    """A non-rigid normal field, orthogonal to the rigid modes on the symmetric plate."""
    return 1e-3 * nodes[:, 0] * nodes[:, 1]


def test_split_rigid_part_recovers_a_known_rigid_normal_field():
    mesh, normals, weights = _plate()
    modes, centre = rigid_normal_modes(mesh.nodes, normals)
    coef = np.array([0.0, 0.0, 0.07, 2e-3, -3e-3, 0.0])   # offset and two tilts (seen on a plane)
    q_rigid = modes @ coef
    q_shape = _twist(mesh.nodes)
    got, got_coef, got_centre = split_rigid_part(q_shape + q_rigid, mesh.nodes, normals, weights)
    np.testing.assert_allclose(got, q_rigid, atol=1e-12)
    np.testing.assert_allclose(got_coef, coef, atol=1e-12)
    np.testing.assert_allclose(got_centre, centre)
    np.testing.assert_allclose(split_rigid_part(q_shape, mesh.nodes, normals, weights)[0], 0.0,
                               atol=1e-12)


def _transfer_mismatch(eps, mesh, normals, weights, cameras):
    """Largest pixel shift of the rigid part, and mismatch of the surface after transfer."""
    modes, _ = rigid_normal_modes(mesh.nodes, normals)
    q = eps * (_twist(mesh.nodes) + modes @ np.array([0.0, 0.0, 0.2, 4e-3, -5e-3, 0.0]))
    q_new, cams_new = transfer_rigid_part(q, mesh.nodes, normals, weights, cameras)
    np.testing.assert_allclose(split_rigid_part(q_new, mesh.nodes, normals, weights)[0], 0.0,
                               atol=1e-12)
    X_old = current_nodes(mesh.nodes, normals, q)
    X_new = current_nodes(mesh.nodes, normals, q_new)
    shift = max(np.abs(c.project(X_old) - c.project(X_new)).max() for c in cameras)
    mismatch = max(np.abs(old.project(X_old) - new.project(X_new)).max()
                   for old, new in zip(cameras, cams_new))
    return shift, mismatch


def test_transfer_rigid_part_keeps_the_corrected_surface_at_the_same_pixels():
    """Cameras moved with the rigid part see X0 + q' n where the old ones saw X0 + q n.

    To first order: the mismatch is quadratic in the size of q (halving q divides it by 4),
    while the image shift of the rigid part is linear.
    """
    mesh, normals, weights = _plate()
    cameras = demo_cameras(image_size=(640, 480), field_mm=72.0)
    shift, mismatch = _transfer_mismatch(1.0, mesh, normals, weights, cameras)
    half_shift, half_mismatch = _transfer_mismatch(0.5, mesh, normals, weights, cameras)
    assert shift > 1.0                                     # the rigid part is well seen (px)...
    assert mismatch < 0.05 * shift, (mismatch, shift)      # ...and undone by the cameras
    np.testing.assert_allclose(half_shift / shift, 0.5, rtol=0.01)     # perspective: ~linear
    np.testing.assert_allclose(half_mismatch / mismatch, 0.25, rtol=0.05)


def test_tangential_motions_three_on_a_plane():
    mesh, normals, weights = _plate()
    motions, centre = tangential_motions(mesh.nodes, normals, weights)
    assert motions.shape == (6, 3)
    np.testing.assert_allclose(motions[[2, 3, 4]], 0.0, atol=1e-9)   # tz, wx, wy: not slides
    assert np.linalg.matrix_rank(motions[[0, 1, 5]]) == 3            # tx, ty, wz
    modes, _ = rigid_normal_modes(mesh.nodes, normals)
    np.testing.assert_allclose(modes @ motions, 0.0, atol=1e-9)


def test_tangential_motions_two_on_a_cylinder():
    mesh, normals, weights = _cylinder()
    motions, centre = tangential_motions(mesh.nodes, normals, weights)
    assert motions.shape == (6, 2)
    modes, _ = rigid_normal_modes(mesh.nodes, normals)
    # no node moves along its normal: slide along the axis and rotation about it
    velocity = motions[:3].T[:, None, :] + np.cross(motions[3:].T[:, None, :],
                                                    (mesh.nodes - centre)[None])
    np.testing.assert_allclose(np.einsum("knd,nd->kn", velocity, normals), 0.0, atol=1e-6)
    # the span of: slide along x, rotation about the axis (w = e_x, t = e_x x (centre - 0))
    expected = np.array([[1.0, 0, 0, 0, 0, 0], [0, -centre[2], 0, 1.0, 0, 0]]).T
    residue = expected - motions @ np.linalg.lstsq(motions, expected, rcond=None)[0]
    np.testing.assert_allclose(residue, 0.0, atol=1e-9)


def test_best_fit_plane_distance():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-30.0, 30.0, (200, 2))
    tilted = np.column_stack([xy, 3.0 + 0.1 * xy[:, 0] - 0.2 * xy[:, 1]])
    np.testing.assert_allclose(best_fit_plane_distance(tilted), 0.0, atol=1e-12)
    g = np.linspace(-30.0, 30.0, 13)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    twisted = np.column_stack([x, y, 1e-3 * x * y])        # symmetric grid: best plane z = 0
    np.testing.assert_allclose(best_fit_plane_distance(twisted),
                               1e-3 * x * y, atol=1e-12)


def test_rigid_align_recovers_a_known_motion():
    rng = np.random.default_rng(1)
    source = rng.normal(size=(50, 3)) * [30.0, 20.0, 1.0]
    R = cv2.Rodrigues(np.array([0.1, -0.2, 0.3]))[0]
    t = np.array([1.0, -2.0, 0.5])
    R_got, t_got = rigid_align(source, source @ R.T + t)
    np.testing.assert_allclose(R_got, R, atol=1e-12)
    np.testing.assert_allclose(t_got, t, atol=1e-12)
    assert np.isclose(np.linalg.det(R_got), 1.0)


# --- element families: positive nodal weights, and the gauge on T3, T6, Q4, Q9 -------------

# linear sub-elements of the quadratic elements, local node indices (gmsh order)
_SUBELEMENTS = {"T6": ("T3", [[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]]),
                "Q9": ("Q4", [[0, 4, 8, 7], [4, 1, 5, 8], [8, 5, 2, 6], [7, 8, 6, 3]])}
FAMILIES = ("T3", "T6", "Q4", "Q9")


def _curved(family, radius=30.0):
    """A 60 x 40 mm rectangle mesh of ``family`` bent onto a cylinder of axis x."""
    flat = rectangle_mesh(60.0, 40.0, 6, 4, family=family)
    theta = flat.nodes[:, 1] / radius
    nodes = np.column_stack([flat.nodes[:, 0], radius * np.sin(theta), radius * np.cos(theta)])
    return SurfaceMesh(nodes, flat.blocks, name=f"cylinder_{family}")


@pytest.mark.parametrize("family", FAMILIES)
def test_nodal_areas_are_positive_and_share_the_element_areas(family):
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, family=family)
    w = nodal_areas(mesh)
    assert w.min() > 0.0
    np.testing.assert_allclose(w.sum(), 60.0 * 40.0, rtol=1e-12)
    if family in _SUBELEMENTS:
        # independent: the same nodes cut into linear sub-elements, each area in equal thirds/quarters
        linear, local = _SUBELEMENTS[family]
        conn = mesh.blocks[0].connectivity[:, local].reshape(-1, len(local[0]))
        sub = SurfaceMesh(mesh.nodes, (CellBlock(FAMILIES_BY_NAME[linear], conn),))
        np.testing.assert_allclose(w, _nodal_weights(sub), rtol=1e-12)


def test_lumped_quadrature_weights_are_not_positive_on_t6():
    """Why the gauge does not use L^T w: a T6 corner shape function integrates to 0."""
    mesh = rectangle_mesh(60.0, 40.0, 12, 8, family="T6")
    quad = pixel_quadrature(mesh, demo_cameras(image_size=(640, 480), field_mm=72.0))
    lumped = quad.to_nodes(quad.weight_mm2)
    corners = np.unique(mesh.blocks[0].connectivity[:, :3])
    assert np.abs(lumped[corners]).max() < 1e-3 * lumped.max()      # ~0, of either sign
    assert lumped.min() < 0.0
    normals = node_normals(mesh)
    with pytest.raises(ValueError, match=r"node_weights: \d+ of 425 .*negative.*nodal_areas"):
        tangential_motions(mesh.nodes, normals, lumped)
    with pytest.raises(ValueError, match="node_weights: .*negative"):
        split_rigid_part(np.zeros(mesh.n_nodes), mesh.nodes, normals, lumped)


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("shape", ["plate", "cylinder"])
def test_transfer_rigid_part_removes_the_rigid_normal_part_exactly(family, shape):
    """q = rigid + shape: the rigid part goes to the cameras exactly, to round-off.

    A purely rigid q leaves nothing and moves the cameras by exactly that motion; for any q
    the remainder has no weighted rigid part (modes^T W q' = 0) and the cameras moved by the
    removed motion.
    """
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, family=family) if shape == "plate" else _curved(family)
    normals, weights = node_normals(mesh), nodal_areas(mesh)
    cameras = demo_cameras(image_size=(640, 480), field_mm=72.0)
    modes, centre = rigid_normal_modes(mesh.nodes, normals)
    # motions off the slides (plate: tx, ty, wz; cylinder of axis x: tx and wx with ty)
    seen = [2, 3, 4] if shape == "plate" else [2, 4, 5]
    coef = np.zeros(6)
    coef[seen] = [0.07, 2e-3, -3e-3]
    # off the mesh's own slides exactly (a coarse T6/Q9 cylinder's FE normals make the
    # rotation about its axis a near-slide, 3e-4 of the largest mode): the gauge moves
    # only what the normals see
    slides, _ = tangential_motions(mesh.nodes, normals, weights)
    radius = np.sqrt(np.average(np.sum((mesh.nodes - centre) ** 2, axis=1), weights=weights))
    scale = np.r_[np.ones(3), np.full(3, radius)]
    basis, _ = np.linalg.qr(slides * scale[:, None])
    coef = (coef * scale - basis @ (basis.T @ (coef * scale))) / scale
    q_rigid = modes @ coef
    q_new, cams = transfer_rigid_part(q_rigid, mesh.nodes, normals, weights, cameras)
    np.testing.assert_allclose(q_new, 0.0, atol=1e-12)
    expected = move_cameras_with_specimen(cameras, coef[:3], coef[3:], centre)
    for got, want in zip(cams, expected):
        np.testing.assert_allclose(got.extrinsics, want.extrinsics, atol=1e-12)
    q = q_rigid + 1e-3 * mesh.nodes[:, 0] * mesh.nodes[:, 1] + 1e-4 * mesh.nodes[:, 0] ** 2
    q_new, _ = transfer_rigid_part(q, mesh.nodes, normals, weights, cameras)
    np.testing.assert_allclose(modes.T @ (weights * q_new), 0.0,
                               atol=1e-10 * np.abs(modes).max() * weights.sum() * np.abs(q).max())
    np.testing.assert_allclose(split_rigid_part(q_new, mesh.nodes, normals, weights)[0], 0.0,
                               atol=1e-12)


def test_a_curvature_change_of_a_cylinder_panel_moves_no_camera_along_its_slide():
    """A shallow cylinder panel's FE normals see the rotation about its axis only through
    their error (~1e-5): the rigid part of a change of radius must not put tens of mm into
    that near-slide (it moved the cameras by 78 px before the gauge's tolerance matched
    ``tangential_motions``)."""
    mesh = _curved("Q9", radius=100.0)
    normals, weights = node_normals(mesh), nodal_areas(mesh)
    x, y = mesh.nodes[:, 0], mesh.nodes[:, 1]
    q = 0.1 * (y / 20.0) ** 2 + 0.01 * (y / 20.0) ** 3 + 0.003 * x * y / 400.0  # R 100 -> ~95
    _, coef, _ = split_rigid_part(q, mesh.nodes, normals, weights)
    assert abs(coef[1]) < 0.01 and abs(coef[3]) < 1e-3    # mm, rad (were 174 mm, 1.76 rad)
