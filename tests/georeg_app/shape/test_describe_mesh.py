"""The nominal model's log line names the mesh's real element family (issue 22: a Q4 mesh was
logged as "892 Q9 nodes")."""
from fesdic_core.fe.mesh import rectangle_mesh
from georeg_app.shape.pipeline import describe_mesh


def test_a_q4_mesh_is_logged_as_q4_and_a_q9_mesh_as_q9():
    q4 = rectangle_mesh(60.0, 40.0, 6, 4, "Q4")
    assert describe_mesh("mesh", q4) == "mesh, 35 Q4 nodes, 24 elements"
    q9 = rectangle_mesh(60.0, 40.0, 6, 4, "Q9")
    assert describe_mesh("rectangle", q9) == "rectangle, 117 Q9 nodes, 24 elements"
