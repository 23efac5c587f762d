"""Checks of spline levels shared by the plugin's tests: ranges, nesting (Eq. 13), rigid modes."""
import numpy as np


def assert_in_range(C: np.ndarray, fields: np.ndarray, rtol: float) -> None:
    """The columns of ``fields`` (nodal fields) lie in the range of ``C^T`` (least squares)."""
    coeffs, *_ = np.linalg.lstsq(C.T, fields, rcond=None)
    assert np.abs(fields - C.T @ coeffs).max() < rtol * max(np.abs(fields).max(), 1.0)


def assert_nested(space, rtol: float = 1e-10) -> None:
    """Eq. 13 between consecutive levels: each coarser level in the range of the finer one."""
    for s in range(space.n_levels - 1):
        assert_in_range(space.operators[s].toarray(), space.operators[s + 1].toarray().T, rtol)


def assert_nested_with_rigid_modes(space, normals, X, rtol=1e-12):
    """:func:`assert_nested`, and the rigid normal motions ``n . (t + w x X)`` in every
    level's range."""
    rigid = np.column_stack([normals] + [np.einsum("kd,kd->k", normals, np.cross(e, X))
                                         for e in np.eye(3)])
    for s in range(space.n_levels):
        assert_in_range(space.operators[s].toarray(), rigid, rtol)
    assert_nested(space)
