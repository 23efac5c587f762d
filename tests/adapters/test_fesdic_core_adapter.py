"""adapters.fesdic_core: nominal models refuse element families that cannot hold the spline;
legacy meshes of every family go through point inversion and the georeg solver."""
import numpy as np
import pytest
import scipy.sparse as sps
from numpy.testing import assert_allclose

from adapters.fesdic_core import georeg_solver, nominal_model
from fesdic_core.fe.mesh import boundary_nodes, nodal_areas, rectangle_mesh
from fesdic_core.fe.mesh_io import read_mesh, write_mesh
from fesdic_core.shape.driver import MeasurementSettings, measure
from fesdic_core.synthetic.accuracy import shape_error_to_surface
from georeg_plugin.levels.operators import multilevel_space, node_parameters
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.spline.fe_mesh import ElementDegreeError
from georeg_plugin.spline.geometries import plate_with_hole, quadrilateral, rectangle

L, W = 60.0, 40.0
CORNERS = [[-L / 2, -W / 2, 0.0], [L / 2, -W / 2, 0.0], [L / 2, W / 2, 0.0], [-L / 2, W / 2, 0.0]]


def test_q4_mesh_of_a_quadratic_spline_is_refused_naming_the_model():
    """One Q4 per knot span has fewer nodes than the degree-2 spline has dofs: refused at input."""
    with pytest.raises(ElementDegreeError,
                       match=r"nominal model 'plate' \(Q4 mesh\): degree \(2, 2\).*degree 1 of Q4"):
        nominal_model(rectangle(L, W), 2, "Q4", name="plate")


def test_cubic_spline_with_a_q9_mesh_is_refused():
    with pytest.raises(ElementDegreeError, match=r"'cubic' \(Q9 mesh\): degree \(3, 3\).*Q9"):
        nominal_model(quadrilateral(CORNERS, degrees=(3, 3)), 2, "Q9", name="cubic")


def test_mesh_that_does_not_refine_the_finest_level_is_refused():
    """6 x 6 Q9 elements under a finest level of 4 x 4 knot spans: elements straddle the
    knots 0.25 and 0.75, where the spline has a kink no Q9 element holds (Eq. 16 fails:
    the Q9 interpolant of a level-0 field is off by ~0.08 on a field of order 1)."""
    model = nominal_model(rectangle(L, W), (6, 6), "Q9", name="plate")
    with pytest.raises(ValueError, match=r"'plate': FE element \d+ spans u = .* across the knot "
                                         r"u = 0.25 of the finest of 3 spline levels"):
        georeg_solver(model, 3)
    georeg_solver(model, 2)                      # 2 x 2 knot spans: 6 x 6 refines them
    georeg_solver(nominal_model(rectangle(L, W), (8, 8), "Q9"), 3)


def test_welded_seam_of_the_plate_with_a_hole_is_no_false_alarm():
    model = nominal_model(plate_with_hole(L, W, 10.0), 2, "Q9")
    assert not np.any(model.uv[:, 0] == 1.0)     # the seam u = 1 is welded to u = 0
    space = georeg_solver(model, 3).space
    assert space.n_levels == 3


@pytest.mark.parametrize("family,degree", [("Q4", 1), ("Q9", 2), ("Q9", 1)])
def test_accepted_pairs_give_exact_nonsingular_levels(family, degree):
    """Degree <= element degree: every level's spline field is reproduced at the nodes, the
    Gram matrix of every level is invertible, and the mesh is the surface."""
    model = nominal_model(quadrilateral(CORNERS, degrees=(degree, degree)), (8, 4), family)
    solver = georeg_solver(model, 3)
    assert_allclose(nodal_areas(model.mesh).sum(), L * W, rtol=1e-12)
    rng = np.random.default_rng(0)
    for level in range(solver.n_levels):
        patch = solver.space.patch(level)
        q_s = rng.standard_normal(patch.n_dofs)
        q = solver.to_nodes(q_s, level)
        assert_allclose(q, patch.basis(model.uv) @ q_s, atol=1e-12)
        assert_allclose(solver.control_values(q, level), q_s, atol=1e-9)


# --- legacy meshes (a mesher's nodes, read with mesh_io) regularized by point inversion ----

@pytest.mark.slow
@pytest.mark.parametrize("family,nx,ny", [("T3", 12, 8), ("Q4", 12, 8), ("T6", 6, 4)])
def test_legacy_mesh_measures_through_point_inversion_and_the_georeg_solver(
        twisted_scene, tmp_path, family, nx, ny):
    """An irregular legacy mesh written and read back (gmsh), its nodes located on the
    nominal spline by point inversion, measured with the spline levels as step solver:
    shape RMS < 2% of the 0.5 mm deviation (measured: T3 0.5 um, Q4 0.7 um, T6 0.6 um)."""
    specimen, cameras, images = twisted_scene
    mesh = rectangle_mesh(L, W, nx, ny, family=family)
    inner = np.setdiff1d(np.arange(mesh.n_nodes), boundary_nodes(mesh))
    nodes = mesh.nodes.copy()
    nodes[inner, :2] += np.random.default_rng(0).uniform(-1.0, 1.0, (inner.size, 2))  # not a grid
    write_mesh(tmp_path / "legacy.msh", mesh.with_nodes(nodes))
    legacy = read_mesh(tmp_path / "legacy.msh")
    nominal = rectangle(L, W)
    uv, distance = node_parameters(nominal, legacy.nodes)
    assert distance.max() < 1e-9
    assert_allclose(uv, (legacy.nodes[:, :2] + [L / 2, W / 2]) / [L, W], atol=1e-9)  # flat: affine
    solver = GeometricRegularization(multilevel_space(nominal, 2, legacy.nodes))
    m = measure(legacy, images, cameras, solver, MeasurementSettings(scales=(1, 0)))
    rms = float(np.sqrt(np.mean(shape_error_to_surface(m.nodes, specimen) ** 2)))
    assert m.converged
    assert rms < 0.02 * 0.5, f"{family}: shape RMS {rms * 1e3:.2f} um"


def test_the_formulation_follows_the_nominal_flat_scalar_curved_vector():
    """A flat nominal keeps the scalar operators (bit for bit). A cylinder keeps the scalar
    space too: it holds the rigid normal motions (exact surface normals) and is nested. A
    doubly curved face, whose scalar space misses them, gets the vector formulation with the
    core's node normals: nested, rigid normal modes in range, and the measured NURBS
    (P_J + d_J) reproduces the nodal field at the nodes."""
    from adapters.fesdic_core import is_curved, measured_spline, multilevel_for_mesh
    from fesdic_core.fe.mesh import node_normals
    from georeg_plugin.spline.geometries import cylinder
    from georeg_plugin.spline.patch import SplinePatch

    def rigid_modes(n, X):
        return np.column_stack([n] + [np.einsum("kd,kd->k", n, np.cross(e, X)) for e in np.eye(3)])

    def nested_and_rigid(space, rigid):
        for s, C in enumerate(space.operators):
            C = C.toarray()
            coeffs, *_ = np.linalg.lstsq(C.T, rigid, rcond=None)
            assert np.abs(rigid - C.T @ coeffs).max() < 1e-12 * np.abs(rigid).max()
            if s + 1 < space.n_levels:
                Cc = space.operators[s + 1].toarray()
                coarse_in_fine, *_ = np.linalg.lstsq(C.T, Cc.T, rcond=None)
                assert np.abs(Cc.T - C.T @ coarse_in_fine).max() < 1e-10

    flat = nominal_model(plate_with_hole(L, W, 10.0), 2, "Q9")
    space = multilevel_for_mesh(flat, 2, curved=None)
    reference = multilevel_space(flat.patch, 2, flat.mesh.nodes, uv=flat.uv, family="Q9")
    assert not is_curved(flat) and not space.vector
    for C, R in zip(space.operators, reference.operators):
        assert (C != R).nnz == 0
    panel = nominal_model(cylinder(100.0, 40.0, 30.0), 3, "Q9")
    space = multilevel_for_mesh(panel, 3, curved=None)
    assert is_curved(panel) and not space.vector                # a cylinder: the scalar space
    nested_and_rigid(space, rigid_modes(panel.patch.normals(panel.uv), panel.mesh.nodes))
    U, V = np.meshgrid(np.linspace(-20, 20, 3), np.linspace(-15, 15, 3), indexing="ij")
    k = np.array([0, 0, 0, 1, 1, 1.0])                           # an elliptic paraboloid, twisted
    dome = nominal_model(SplinePatch((2, 2), (k, k), np.stack(
        [U, V, 0.004 * U ** 2 + 0.006 * V ** 2 + 0.002 * U * V], -1)), 3, "Q9")
    space = multilevel_for_mesh(dome, 3, curved=None)
    assert is_curved(dome) and space.vector                     # doubly curved: the vector one
    n = node_normals(dome.mesh)
    nested_and_rigid(space, rigid_modes(n, dome.mesh.nodes))
    solver = GeometricRegularization(space)
    q = space.operators[1].T @ np.random.default_rng(0).standard_normal(space.operators[1].shape[0])
    q *= 0.01 / np.abs(q).max()                                  # 10 um: linear regime
    spline, values = measured_spline(solver, q, 1)
    moved = spline.evaluate(dome.uv) - space.patch(1).evaluate(dome.uv)
    assert_allclose(np.einsum("kd,kd->k", moved, n), q, atol=1e-12)
    assert values.shape == (space.patch(1).n_dofs,)


def test_the_plugin_solver_is_recognised_by_the_core_hooks_it_implements():
    """The plugin imports nothing of the core: its solver meets the core's hook protocols by
    its methods alone (factorize, step_covariance, bias_step; no start_scale), and the core's
    uncertainty gets its step covariance through the protocol."""
    from fesdic_core.shape.uncertainty import shape_std
    from fesdic_core.solve import (BiasStepHook, FactorizeHook, StartScaleHook, StepCovarianceHook,
                                   StepSolver)
    model = nominal_model(rectangle(L, W), 4, "Q9")
    solver = georeg_solver(model, 2)
    assert isinstance(solver, GeometricRegularization)
    for hook, has in [(StepSolver, True), (FactorizeHook, True), (StepCovarianceHook, True),
                      (BiasStepHook, True), (StartScaleHook, False)]:
        assert isinstance(solver, hook) is has, hook.__name__
    H = sps.identity(model.mesh.n_nodes, format="csr")
    std = shape_std(H, 1.0, solver, scale=0)
    C = solver.operator(solver.level(0)).toarray()
    expected = np.sqrt(np.diag(C.T @ np.linalg.inv(C @ C.T) @ C))   # C^T (C H C^T)^-1 C, H = I
    assert_allclose(std, expected, rtol=1e-10)
