"""Eq. 18 for a general H: ``project`` computes ``C_s H C_s^T``, not ``C_s H^T C_s^T``.

Added after a mutation check of georeg_plugin/levels/solver.py: transposing H in the projection
survived every other test, because every H they build is symmetric (Gauss-Newton H, SPD
random matrices). ``project`` is public and documented as ``C_s H C_s^T`` for any (n_fe, n_fe)
H; a non-symmetric H tells the two apart.
"""
import numpy as np
import scipy.sparse as sps
from numpy.testing import assert_allclose

from georeg_plugin.levels.operators import MultilevelSpace
from georeg_plugin.levels.solver import GeometricRegularization


def test_project_is_c_h_ct_for_a_non_symmetric_h():
    rng = np.random.default_rng(4)
    n, m = 12, 5
    C = sps.csr_matrix(rng.standard_normal((m, n)))
    reg = GeometricRegularization(MultilevelSpace(patches=(None,), operators=(C,)))
    H = rng.standard_normal((n, n))                  # not symmetric
    b = rng.standard_normal(n)
    H_s, b_s = reg.project(sps.csr_matrix(H), b, 0)
    Cd = C.toarray()
    assert_allclose(H_s.toarray(), Cd @ H @ Cd.T, rtol=1e-12, atol=1e-12)
    assert not np.allclose(Cd @ H @ Cd.T, Cd @ H.T @ Cd.T)   # the case tells them apart
    assert_allclose(b_s, Cd @ b, rtol=1e-12)
    # and the step solves the projected system: C H C^T d_s = C b with d = C^T d_s
    d = reg.solve(sps.csr_matrix(H), b, np.zeros(n), 0)
    d_s = np.linalg.solve(Cd @ H @ Cd.T, Cd @ b)
    assert_allclose(d, Cd.T @ d_s, rtol=1e-9, atol=1e-12)
