"""Tests of the 3-D surface mesh (fesdic_core.fe.mesh)."""
import numpy as np
import pytest

from fesdic_core.fe.elements import FAMILIES, centroid
from fesdic_core.fe.mesh import (CellBlock, MeshError, SurfaceMesh, boundary_nodes, edges,
                                 element_areas, map_points, node_normals, rectangle_mesh,
                                 surface_jacobian, tangents, validate_mesh)

ALL = ["T3", "T6", "Q4", "Q9"]


def _total_area(mesh):
    return sum(a.sum() for a in element_areas(mesh))


def _cylinder(family, n, radius=20.0, angle=np.pi / 2, width=10.0):
    """Rectangle mesh wrapped onto the cylinder (R sin(s/R), y, R cos(s/R)) (axis y)."""
    flat = rectangle_mesh(angle * radius, width, n, 2, family)
    s, y = flat.nodes[:, 0], flat.nodes[:, 1]
    nodes = np.column_stack([radius * np.sin(s / radius), y, radius * np.cos(s / radius)])
    exact_normals = np.column_stack([np.sin(s / radius), np.zeros_like(s), np.cos(s / radius)])
    return flat.with_nodes(nodes), exact_normals, angle * radius * width


def _sphere_cap(family, n, radius=15.0):
    """Square (side R) mesh projected radially onto the sphere of centre 0; normals = X / R."""
    flat = rectangle_mesh(radius, radius, n, n, family)
    d = flat.nodes + [0.0, 0.0, radius]
    nodes = radius * d / np.linalg.norm(d, axis=1, keepdims=True)
    return flat.with_nodes(nodes), nodes / radius


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


@pytest.mark.parametrize("family", ALL)
def test_rectangle_area_and_normals(family):
    mesh = rectangle_mesh(30.0, 12.0, 5, 3, family, center=(2.0, -1.0))
    assert mesh.n_elements == (15 if family[0] == "Q" else 30)
    np.testing.assert_allclose(_total_area(mesh), 30.0 * 12.0, rtol=1e-13)
    np.testing.assert_allclose(node_normals(mesh), np.tile([0.0, 0.0, 1.0], (mesh.n_nodes, 1)),
                               atol=1e-14)
    np.testing.assert_allclose(mesh.nodes.min(axis=0), [2.0 - 15.0, -1.0 - 6.0, 0.0])
    np.testing.assert_allclose(mesh.nodes.max(axis=0), [2.0 + 15.0, -1.0 + 6.0, 0.0])
    validate_mesh(mesh, "rectangle")
    # every node belongs to an element
    assert np.unique(mesh.blocks[0].connectivity).size == mesh.n_nodes


def test_map_points_and_tangents_on_affine_element():
    """On a flat Q9 mesh under an affine map the tangents are the map's columns."""
    mesh = rectangle_mesh(4.0, 2.0, 2, 1, "Q9")
    A = np.array([[1.0, 0.3, 0.0], [0.2, 2.0, 0.0], [0.5, -0.4, 0.0]])  # X -> A X
    b = np.array([1.0, 2.0, 3.0])
    moved = mesh.with_nodes(mesh.nodes @ A.T + b)
    block = moved.blocks[0]
    xi = np.array([[0.0, 0.0], [0.3, -0.7], [-1.0, 1.0]])
    X = map_points(moved.nodes, block, xi)
    X0 = map_points(mesh.nodes, mesh.blocks[0], xi)
    np.testing.assert_allclose(X, X0 @ A.T + b, atol=1e-12)
    t = tangents(moved.nodes, block, xi)
    assert t.shape == (2, 3, 3, 2)
    # element half-sizes along x and y are 1 mm each: dX/dxi = A e_x, dX/deta = A e_y
    np.testing.assert_allclose(t[..., 0], np.broadcast_to(A[:, 0], (2, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(t[..., 1], np.broadcast_to(A[:, 1], (2, 3, 3)), atol=1e-12)
    dA, n = surface_jacobian(moved.nodes, block, xi)
    c = np.cross(A[:, 0], A[:, 1])
    np.testing.assert_allclose(dA, np.linalg.norm(c), rtol=1e-12)
    np.testing.assert_allclose(n, np.broadcast_to(c / np.linalg.norm(c), (2, 3, 3)), atol=1e-12)


def test_tangents_match_finite_differences_on_curved_mesh():
    mesh, _, _ = _cylinder("Q9", 3)
    block = mesh.blocks[0]
    xi = np.array([[0.1, -0.3], [0.7, 0.2]])
    h = 1e-6
    t = tangents(mesh.nodes, block, xi)
    for a in range(2):
        step = np.zeros(2)
        step[a] = h
        fd = (map_points(mesh.nodes, block, xi + step)
              - map_points(mesh.nodes, block, xi - step)) / (2 * h)
        np.testing.assert_allclose(t[..., a], fd, atol=1e-7)


@pytest.mark.parametrize("family", ["Q9", "T6"])
def test_curved_area_converges_at_fourth_order(family):
    errors = []
    for n in (2, 4, 8):
        mesh, _, exact = _cylinder(family, n)
        errors.append(abs(_total_area(mesh) - exact) / exact)
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert errors[-1] < 2e-6
    assert np.all(rates > 3.8), rates   # quadratic geometry: area error O(h^4)


@pytest.mark.parametrize("family", ["Q9", "T6"])
def test_cylinder_node_normals_match_analytic(family):
    mesh, exact, _ = _cylinder(family, 8)   # 11.25 deg elements
    err = _angle_deg(node_normals(mesh), exact)
    assert err.max() < 0.02, err.max()      # measured 0.0135 deg


@pytest.mark.parametrize("family, n, bound_deg", [("Q9", 8, 0.2), ("T6", 8, 0.35),
                                                   ("Q4", 16, 0.15), ("T3", 16, 0.15)])
def test_sphere_node_normals_match_analytic(family, n, bound_deg):
    """Quadratic meshes: all nodes, O(h^2). Linear meshes: interior nodes (where the
    averaging recovers second order; boundary nodes see the chord normal only)."""
    errors = []
    for k in (n // 2, n):
        mesh, exact = _sphere_cap(family, k)
        validate_mesh(mesh, "sphere")
        err = _angle_deg(node_normals(mesh), exact)
        if FAMILIES[family].degree == 1:
            err = err[np.setdiff1d(np.arange(mesh.n_nodes), boundary_nodes(mesh))]
        errors.append(err.max())
    assert errors[1] < bound_deg, errors          # measured Q9 0.17, T6 0.30, Q4 0.11, T3 0.13
    assert errors[0] / errors[1] > 3.5, errors     # second order


def test_node_normal_is_area_weighted_mean_at_the_node():
    """Two flat T3 at a fold: the shared nodes' normal is the area-weighted mean."""
    nodes = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, -2.0]])
    # element 0 in plane z=0 (normal +z, area 1/2); element 1 in plane x=0
    conn = np.array([[0, 1, 2], [0, 2, 3]])
    mesh = SurfaceMesh(nodes, (CellBlock(FAMILIES["T3"], conn),))
    n1 = np.cross(nodes[2] - nodes[0], nodes[3] - nodes[0])   # area 1 -> |n1| = 2
    expected = 0.5 * np.array([0, 0, 1.0]) + 1.0 * n1 / np.linalg.norm(n1)
    got = node_normals(mesh)
    np.testing.assert_allclose(got[0], expected / np.linalg.norm(expected), atol=1e-14)
    np.testing.assert_allclose(got[1], [0, 0, 1.0], atol=1e-14)
    np.testing.assert_allclose(got[3], n1 / np.linalg.norm(n1), atol=1e-14)


def _with_connectivity(mesh, conn):
    return SurfaceMesh(mesh.nodes, (CellBlock(mesh.blocks[0].family, conn),), mesh.name)


@pytest.mark.parametrize("family", ALL)
def test_validate_catches_inverted_element(family):
    mesh = rectangle_mesh(20.0, 20.0, 4, 4, family)
    conn = mesh.blocks[0].connectivity.copy()
    bad = 6
    # reverse the orientation: swap corners 1 and (last corner), with their mid-edges
    swap = {"T3": [0, 2, 1], "T6": [0, 2, 1, 5, 4, 3], "Q4": [0, 3, 2, 1],
            "Q9": [0, 3, 2, 1, 7, 6, 5, 4, 8]}[family]
    conn[bad] = conn[bad, swap]
    flipped = _with_connectivity(mesh, conn)
    block = flipped.blocks[0]
    _, n = surface_jacobian(flipped.nodes, block, centroid(block.family)[None])
    assert n[bad, 0, 2] == pytest.approx(-1.0)      # the swap does invert it
    with pytest.raises(MeshError, match=rf"block 0 \({family}\) element {bad} .*is inverted"):
        validate_mesh(flipped, "plate")
    # the neighbours are not blamed
    with pytest.raises(MeshError) as info:
        validate_mesh(flipped, "plate")
    assert f"element {bad} is inverted" in str(info.value)


def test_inverted_element_on_a_curved_mesh():
    mesh, _ = _sphere_cap("Q9", 4)
    conn = mesh.blocks[0].connectivity.copy()
    conn[9] = conn[9, [0, 3, 2, 1, 7, 6, 5, 4, 8]]
    with pytest.raises(MeshError, match="element 9 .*is inverted"):
        validate_mesh(_with_connectivity(mesh, conn), "cap")


def test_single_element_is_never_inverted():
    mesh = rectangle_mesh(2.0, 1.0, 1, 1, "Q9")
    conn = mesh.blocks[0].connectivity[:, [0, 3, 2, 1, 7, 6, 5, 4, 8]]
    validate_mesh(_with_connectivity(mesh, conn), "single")


@pytest.mark.parametrize("family", ["Q4", "Q9"])
def test_validate_catches_degenerate_element(family):
    mesh = rectangle_mesh(6.0, 6.0, 3, 3, family)
    nodes = mesh.nodes.copy()
    conn = mesh.blocks[0].connectivity
    bad = 4
    # move corner 2 of element 4 onto the line through corners 1 and 3: zero area element
    nodes[conn[bad, 2]] = 0.5 * (nodes[conn[bad, 1]] + nodes[conn[bad, 3]])
    if family == "Q9":   # keep the mid-edge nodes at mid-edges
        for e in FAMILIES["Q9"].edges:
            nodes[conn[:, e[2]]] = 0.5 * (nodes[conn[:, e[0]]] + nodes[conn[:, e[1]]])
    with pytest.raises(MeshError, match=rf"element {bad} .*is degenerate"):
        validate_mesh(mesh.with_nodes(nodes), "plate")


def test_validate_catches_repeated_node_index_and_names_block():
    mesh = rectangle_mesh(4.0, 2.0, 2, 1, "T3")
    conn = mesh.blocks[0].connectivity.copy()
    conn[3, 2] = conn[3, 0]
    other = rectangle_mesh(4.0, 2.0, 2, 1, "T3").blocks[0]
    broken = SurfaceMesh(mesh.nodes, (other, CellBlock(FAMILIES["T3"], conn)), "twin")
    with pytest.raises(MeshError, match=r"'twin'.*block 1 \(T3\) element 3 repeats"):
        validate_mesh(broken)


def test_validate_catches_folded_element():
    """A bow-tie Q4: corners 2 and 3 exchanged."""
    nodes = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    mesh = SurfaceMesh(nodes, (CellBlock(FAMILIES["Q4"], np.array([[0, 1, 3, 2]])),))
    with pytest.raises(MeshError, match="element 0 "):
        validate_mesh(mesh)


def test_dataclass_validation_names_the_field():
    q4 = FAMILIES["Q4"]
    with pytest.raises(ValueError, match="connectivity"):
        CellBlock(q4, np.zeros((2, 3), dtype=int))
    with pytest.raises(ValueError, match="connectivity"):
        CellBlock(q4, np.zeros((2, 4)))
    with pytest.raises(ValueError, match="negative"):
        CellBlock(q4, -np.ones((1, 4), dtype=int))
    block = CellBlock(q4, np.array([[0, 1, 2, 3]], dtype=np.int32))
    assert block.connectivity.dtype == np.int64
    with pytest.raises(ValueError, match="nodes"):
        SurfaceMesh(np.zeros((4, 2)), (block,))
    with pytest.raises(ValueError, match="nodes"):
        SurfaceMesh(np.full((4, 3), np.nan), (block,))
    with pytest.raises(ValueError, match=r"blocks\[0\].connectivity.*node 3"):
        SurfaceMesh(np.zeros((3, 3)), (block,))
    with pytest.raises(ValueError, match="family"):
        rectangle_mesh(1.0, 1.0, 1, 1, "Q8")


def test_edges_and_boundary_nodes():
    mesh = rectangle_mesh(3.0, 2.0, 3, 2, "Q9")
    corners, count = edges(mesh)
    assert len(corners) == 3 * 3 + 4 * 2                # horizontal + vertical edges
    assert np.sum(count == 1) == 2 * (3 + 2)             # boundary edges
    b = boundary_nodes(mesh)
    x, y = mesh.nodes[:, 0], mesh.nodes[:, 1]
    on_border = np.flatnonzero(np.isclose(np.abs(x), 1.5) | np.isclose(np.abs(y), 1.0))
    np.testing.assert_array_equal(b, on_border)
