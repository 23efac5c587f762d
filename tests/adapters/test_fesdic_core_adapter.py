"""adapters.fesdic_core: nominal models refuse element families that cannot hold the spline."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from adapters.fesdic_core import georeg_solver, nominal_model
from fesdic_core.mesh import nodal_areas
from georeg_plugin.fe_mesh import ElementDegreeError
from georeg_plugin.geometries import quadrilateral, rectangle

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


@pytest.mark.parametrize("family,degree", [("Q4", 1), ("Q9", 2), ("Q9", 1)])
def test_accepted_pairs_give_exact_nonsingular_levels(family, degree):
    """Degree <= element degree: every level's spline field is reproduced at the nodes, the
    Gram matrix of every level is invertible, and the mesh is the surface."""
    model = nominal_model(quadrilateral(CORNERS, degrees=(degree, degree)), (8, 6), family)
    solver = georeg_solver(model, 3)
    assert_allclose(nodal_areas(model.mesh).sum(), L * W, rtol=1e-12)
    rng = np.random.default_rng(0)
    for level in range(solver.n_levels):
        patch = solver.space.patch(level)
        q_s = rng.standard_normal(patch.n_dofs)
        q = solver.to_nodes(q_s, level)
        assert_allclose(q, patch.basis(model.uv) @ q_s, atol=1e-12)
        assert_allclose(solver.control_values(q, level), q_s, atol=1e-9)
