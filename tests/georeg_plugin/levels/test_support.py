"""Spline levels restricted to an outline (georeg_plugin.levels.support, issue 22 item 2).

The mesh: a 12 x 8 Q9 mesh of the spline of a 60 x 40 mm rectangle with the elements of the
quadrant x > 0, y > 0 removed (an L; the rectangle is centred on 0). Three dyadic levels of the rectangle's spline; the
finest (6 x 6 dofs) has functions whose support misses the L.
"""
import numpy as np
import pytest
import scipy.sparse as sps
from numpy.testing import assert_allclose

from georeg_plugin.levels.components import component_levels
from georeg_plugin.levels.operators import multilevel_space
from georeg_plugin.levels.solver import GeometricRegularization, SingularProjectionError
from georeg_plugin.levels.support import dof_location, level_restriction, mesh_seen
from georeg_plugin.spline.fe_mesh import fe_mesh_from_spline
from georeg_plugin.spline.geometries import rectangle
from georeg_plugin.spline.refine import refine_to_elements


@pytest.fixture(scope="module")
def l_space():
    coarse = rectangle(60.0, 40.0)
    fe = fe_mesh_from_spline(refine_to_elements(coarse, 12, 8)[0], "Q9")
    centres = fe.nodes[fe.connectivity[:, 8]]
    keep = ~((centres[:, 0] > 0.0) & (centres[:, 1] > 0.0))
    used = np.unique(fe.connectivity[keep])
    space = multilevel_space(coarse, 3, fe.nodes[used], uv=fe.uv[used])
    return space, fe.nodes[used]


def _spd(n, rng):
    A = rng.standard_normal((n, n))
    return sps.csr_matrix(A @ A.T + n * np.eye(n))


def test_zero_rows_are_the_functions_outside_the_outline_and_the_levels_stay_nested(l_space):
    """A zero row of C_s (no node of the L in the function's support) is unseen; removing the
    zero rows keeps Eq. 13: C_{s+1}[kept] = C_r[kept, kept'] C_s[kept'] exactly."""
    space, nodes = l_space
    seen = [mesh_seen(C) for C in space.operators]
    assert [int(np.count_nonzero(~k)) for k in seen] == [4, 1, 0]   # finest loses a 2 x 2 corner
    # the unseen functions of the finest level are the ones whose Greville point is in the corner
    greville = space.patch(0).greville_points()
    corner = (greville[:, 0] > 0.5) & (greville[:, 1] > 0.5)
    assert np.all(corner[~seen[0]])
    for s, C_r in enumerate(space.refinement):
        fine, coarse = space.operators[s], space.operators[s + 1]
        kf, kc = seen[s], seen[s + 1]
        restricted = sps.csr_matrix(C_r)[kc][:, kf] @ fine[kf]
        assert_allclose(restricted.toarray(), coarse[kc].toarray(), atol=1e-12)
        # and the range of the restricted coarse level lies in the restricted fine one
        coeffs, *_ = np.linalg.lstsq(fine[kf].toarray().T, coarse[kc].toarray().T, rcond=None)
        assert np.abs(fine[kf].toarray().T @ coeffs - coarse[kc].toarray().T).max() < 1e-10


def test_the_default_solver_drops_the_unseen_dofs_and_counts_them(l_space):
    space, _ = l_space
    rng = np.random.default_rng(4)
    H, b = _spd(space.n_fe, rng), rng.standard_normal(space.n_fe)
    reg = GeometricRegularization(space)
    d = reg.solve(H, b, np.zeros(space.n_fe), 0)
    C = space.operators[0].toarray()
    Ck = C[mesh_seen(space.operators[0])]
    expected = Ck.T @ np.linalg.solve(Ck @ H.toarray() @ Ck.T, Ck @ b)
    assert_allclose(d, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())
    assert dict(reg.dropped_dofs) == {0: 4}
    assert reg.supports[0].unseen_mesh == 4 and reg.supports[0].unseen_images == 0
    # the strict mode refuses the same level, naming the dof that no point sees
    with pytest.raises(SingularProjectionError, match="level 0"):
        GeometricRegularization(space, hold_unseen=False).solve(H, b, np.zeros(space.n_fe), 0)
    # the least-squares control values exist too (0 on the dropped dofs)
    q_s = reg.control_values(d, 0)
    assert_allclose(reg.to_nodes(q_s, 0), d, atol=1e-10 * np.abs(d).max())
    assert np.all(q_s[~mesh_seen(space.operators[0])] == 0)


def test_dofs_unseen_in_the_images_are_dropped_and_counted_apart(l_space):
    """H zero on the nodes of one seen function's support: that dof (and any other living only
    there) is unseen in the images, counted apart from the dofs outside the mesh."""
    space, _ = l_space
    rng = np.random.default_rng(5)
    C = space.operators[1]
    dof = 5
    mask = (C[dof].toarray().ravel() == 0).astype(float)
    H = sps.csr_matrix(sps.diags(mask) @ _spd(space.n_fe, rng) @ sps.diags(mask))
    reg = GeometricRegularization(space)
    d = reg.solve(H, mask * rng.standard_normal(space.n_fe), np.zeros(space.n_fe), 1)
    dense = C.toarray()
    blind = (np.abs(dense[:, mask == 1]).sum(axis=1) == 0) & mesh_seen(C)   # only on masked nodes
    assert blind[dof]
    support = reg.supports[1]
    assert (support.unseen_mesh, support.unseen_images) == (1, int(blind.sum()))
    assert reg.dropped_dofs[1] == 1 + int(blind.sum())
    assert np.all(np.isfinite(d))


def test_levels_restricted_to_what_the_images_see_stay_nested_on_the_seen_nodes(l_space):
    """H zero on a band of nodes (a region masked in the images): the dofs living only there
    are dropped at each level; on the nodes the images see, every kept coarse function is a
    combination of the kept fine ones (Eq. 13 on the data)."""
    space, nodes = l_space
    rng = np.random.default_rng(10)
    band = (nodes[:, 0] < -12.0).astype(float)                     # the left 18 mm masked
    mask = 1.0 - band
    H = sps.csr_matrix(sps.diags(mask) @ _spd(space.n_fe, rng) @ sps.diags(mask))
    reg = GeometricRegularization(space)
    kept = []
    for s in range(space.n_levels):
        H_s, _ = reg.project(H, np.zeros(space.n_fe), s)
        E, support = level_restriction(H_s, mesh_seen(space.operators[s]), s)
        kept.append((E @ space.operators[s]).toarray()[:, mask == 1])
        if s == 0:
            assert support.unseen_images > 0
    for s in range(space.n_levels - 1):
        coeffs, *_ = np.linalg.lstsq(kept[s].T, kept[s + 1].T, rcond=None)
        assert np.abs(kept[s].T @ coeffs - kept[s + 1].T).max() < 1e-10, s


def test_a_seen_singular_dof_still_raises_naming_the_level_the_dof_and_where(l_space):
    """Two seen dofs the data cannot tell apart (H of rank one): an error, not a silent drop;
    the message names the level, the dof, its control point in mm and its Greville point."""
    space, _ = l_space
    rng = np.random.default_rng(6)
    v = rng.standard_normal(space.n_fe)
    H = sps.csr_matrix(np.outer(v, v))
    with pytest.raises(SingularProjectionError,
                       match=r"level 2.*spline dof \d+ \(control point \d+ at \[.*\] mm, "
                             r"Greville point"):
        GeometricRegularization(space).solve(H, v, np.zeros(space.n_fe), 2)


def test_slivers_are_counted_and_the_diagonal_scaling_leaves_the_step_unchanged(l_space):
    """A function seeing only a sliver (its nodes weighted 1e-7): counted as a sliver; the
    step is the dense formula's (the scaling changes the conditioning, not the solution)."""
    space, _ = l_space
    rng = np.random.default_rng(7)
    C = space.operators[0]
    kept = mesh_seen(C)
    sliver = int(np.flatnonzero(kept)[0])
    w = np.where(C[sliver].toarray().ravel() != 0, 1e-7, 1.0)
    W = sps.diags(np.sqrt(w))
    H = sps.csr_matrix(W @ _spd(space.n_fe, rng) @ W)
    b = W @ rng.standard_normal(space.n_fe)
    reg = GeometricRegularization(space)
    d = reg.solve(H, b, np.zeros(space.n_fe), 0)
    assert reg.supports[0].slivers >= 1
    Ck = C.toarray()[kept]
    expected = Ck.T @ np.linalg.solve(Ck @ H.toarray() @ Ck.T, Ck @ b)
    assert_allclose(d, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())
    # merging (optional) keeps the partition of unity: the rows of E C_s still sum to 1
    H_s, _ = reg.project(H, b, 0)
    E, support = level_restriction(H_s, kept, 0, merge=True)
    assert E.shape[0] == np.count_nonzero(kept) - support.slivers
    assert_allclose(np.asarray((E @ C).sum(axis=0)).ravel(), 1.0, atol=1e-12)


def test_a_displacement_level_names_the_component_of_its_dof(l_space):
    space, _ = l_space
    vector = component_levels(space, 3)
    assert [int(np.count_nonzero(~mesh_seen(C))) for C in vector.operators] == [12, 3, 0]
    text = dof_location(vector, 0, 3 * 7 + 2)
    assert text.startswith("control point 7 at ") and text.endswith("component 2")
    point = space.patch(0).control_points.reshape(-1, 3)[7]
    assert str(np.round(point, 3).tolist()) in text


@pytest.mark.slow
def test_a_curved_vector_space_on_an_outline_keeps_only_the_seen_directions():
    """The vector formulation (a doubly curved 40 x 30 mm patch) on an L of its Q9 mesh: each
    level's operator is a basis of the range on the L's nodes, so the directions outside the
    outline are not dofs at all (rank below 3 x the control points), the levels stay nested
    and the default solve needs no drop."""
    from georeg_plugin.spline.patch import SplinePatch
    from georeg_plugin.spline.refine import refine_uniform
    U, V = np.meshgrid(np.linspace(-20, 20, 3), np.linspace(-15, 15, 3), indexing="ij")
    k = np.array([0, 0, 0, 1, 1, 1.0])
    coarse = SplinePatch((2, 2), (k, k), np.stack([U, V, 0.004 * U ** 2 + 0.006 * V ** 2], -1))
    fine = refine_uniform(coarse, 3)[0]
    fe = fe_mesh_from_spline(fine, "Q9")
    centres = fe.uv[fe.connectivity[:, 8]]
    used = np.unique(fe.connectivity[~((centres[:, 0] > 0.5) & (centres[:, 1] > 0.5))])
    uv = fe.uv[used]
    space = multilevel_space(coarse, 3, fe.nodes[used], node_normals=fine.normals(uv), uv=uv)
    full = multilevel_space(coarse, 3, fe.nodes, node_normals=fine.normals(fe.uv), uv=fe.uv)
    assert space.operators[0].shape[0] < full.operators[0].shape[0]
    for s in range(2):
        fine_op, coarse_op = space.operators[s].toarray(), space.operators[s + 1].toarray()
        coeffs, *_ = np.linalg.lstsq(fine_op.T, coarse_op.T, rcond=None)
        assert np.abs(fine_op.T @ coeffs - coarse_op.T).max() < 1e-8
    rng = np.random.default_rng(9)
    H, b = _spd(space.n_fe, rng), rng.standard_normal(space.n_fe)
    reg = GeometricRegularization(space)
    d = reg.solve(H, b, np.zeros(space.n_fe), 0)
    C = space.operators[0].toarray()
    assert_allclose(d, C.T @ np.linalg.solve(C @ H.toarray() @ C.T, C @ b), rtol=1e-8,
                    atol=1e-10 * np.abs(d).max())
    assert reg.dropped_dofs[0] == 0
