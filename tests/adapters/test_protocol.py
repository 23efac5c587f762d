"""adapters.protocol: C^T placed in a host dof layout, one block per component."""
import numpy as np
import pytest
import scipy.sparse as sps

from adapters.protocol import Adapter, reduced_basis


def test_reduced_basis_places_c_transpose_per_component():
    rng = np.random.default_rng(0)
    C = sps.csr_matrix(rng.random((3, 4)))  # (n_spline, n_nodes)
    layout = np.array([[4, 0], [-1, -1], [1, 5], [2, 3]])  # node 1 carries no dof
    B = reduced_basis(C, layout, 6).toarray()
    assert B.shape == (6, 6)
    for c in range(2):
        for node in (0, 2, 3):
            np.testing.assert_array_equal(B[layout[node, c], 3 * c:3 * c + 3], C.toarray()[:, node])
    # a block-component field: B [a; b] gives C^T a on the x dofs, C^T b on the y dofs
    a, b = rng.random(3), rng.random(3)
    U = B @ np.r_[a, b]
    np.testing.assert_allclose(U[layout[[0, 2, 3], 0]], (C.T @ a)[[0, 2, 3]])
    np.testing.assert_allclose(U[layout[[0, 2, 3], 1]], (C.T @ b)[[0, 2, 3]])


def test_reduced_basis_rejects_bad_layouts():
    C = sps.eye(2, 3, format="csr")
    with pytest.raises(ValueError, match="integer"):
        reduced_basis(C, np.zeros((3, 2)), 6)
    with pytest.raises(ValueError, match="rows"):
        reduced_basis(C, np.zeros((2, 2), dtype=int), 6)
    with pytest.raises(ValueError, match="n_dof"):
        reduced_basis(C, np.arange(6).reshape(3, 2), 5)


def test_adapter_protocol_is_structural():
    class Host:
        nodes = np.zeros((1, 2))
        connectivity = {}
        dof_layout = np.zeros((1, 2), dtype=int)
        n_dof = 2

        def correlate(self, basis, U0, image_scale):
            return np.zeros(2), 0.0, 0

    assert isinstance(Host(), Adapter)
    assert not isinstance(object(), Adapter)
