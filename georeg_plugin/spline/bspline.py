"""Univariate B-spline basis on open (clamped) knot vectors (section 3.1).

A degree ``p`` B-spline basis on the knot vector ``Xi = {xi_1, ..., xi_{n+p+1}}``
has ``n`` functions ``N_{i,p}``; a knot of multiplicity ``m`` leaves the functions
``C^{p-m}`` there. The values come from scipy's ``BSpline.design_matrix``; derivatives
follow from the lower-degree basis by the standard recurrence

    N'_{i,p} = p / (t_{i+p} - t_i) N_{i,p-1} - p / (t_{i+p+1} - t_{i+1}) N_{i+1,p-1}.

Knot insertion (Boehm's algorithm, one knot at a time) gives the matrix ``C`` with
``N_old(x) = C N_new(x)`` (Eq. 13) and ``x_new = C^T x_old`` (Eq. 15).

Internally the basis at ``m`` points is kept in *compact* form: the index of the first
non-zero function ``first (m,)`` and the ``p + 1`` values ``(m, p + 1)`` of functions
``first .. first + p``; this is what the tensor-product patch needs.
"""
from __future__ import annotations

import logging
import numbers

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import BSpline

logger = logging.getLogger(__name__)

__all__ = [
    "validate_knots",
    "n_functions",
    "basis_matrix",
    "compact_basis",
    "greville",
    "insertion_matrix",
    "span_breaks",
]


def _validate_degree(degree, name: str) -> int:
    if isinstance(degree, bool) or not isinstance(degree, numbers.Integral) or degree < 0:
        raise ValueError(f"{name}: degree must be an int >= 0, got {degree!r}")
    return int(degree)


def validate_knots(knots, degree: int, name: str = "knots") -> np.ndarray:
    """Check an open (clamped) knot vector and return it as a float array.

    Parameters
    ----------
    knots : array_like (n + p + 1,)
    degree : int >= 0
    name : str, used in error messages

    Raises
    ------
    ValueError
        Naming ``name`` and the offending degree, index or value: not 1-D, not finite,
        decreasing, end knots not repeated ``degree + 1`` times, interior multiplicity
        above ``degree`` (above 1 for degree 0), or fewer than ``degree + 1`` basis functions.
    """
    p = _validate_degree(degree, name)
    try:
        t = np.array(knots, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: knots are not numbers ({exc})") from exc
    if t.ndim != 1:
        raise ValueError(f"{name}: knots must be 1-D, got shape {t.shape}")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ValueError(f"{name}: knot at index {bad[0]} is not finite ({t[bad[0]]})")
    if t.size < 2 * (p + 1):
        raise ValueError(f"{name}: {t.size} knots give fewer than degree+1 = {p + 1} "
                         f"basis functions for degree {p} (need >= {2 * (p + 1)} knots)")
    dec = np.flatnonzero(np.diff(t) < 0)
    if dec.size:
        i = dec[0] + 1
        raise ValueError(f"{name}: knots must be non-decreasing, knot at index {i} "
                         f"({t[i]}) < knot at index {i - 1} ({t[i - 1]})")
    if not t[-1] > t[0]:
        raise ValueError(f"{name}: empty parameter range [{t[0]}, {t[-1]}]")
    values, first, counts = np.unique(t, return_index=True, return_counts=True)
    if counts[0] != p + 1 or counts[-1] != p + 1:
        end, idx = (0, 0) if counts[0] != p + 1 else (-1, first[-1])
        raise ValueError(f"{name}: not an open knot vector for degree {p}: end knot "
                         f"{values[end]} (index {idx}) has multiplicity {counts[end]}, "
                         f"expected degree+1 = {p + 1}")
    limit = max(p, 1)  # C^{p-m} >= C^0 (degree 0: piecewise constants, m = 1)
    over = np.flatnonzero(counts[1:-1] > limit)
    if over.size:
        k = over[0] + 1
        raise ValueError(f"{name}: interior knot {values[k]} at index {first[k]} has "
                         f"multiplicity {counts[k]} > {limit} (degree {p})")
    return t


def n_functions(knots: np.ndarray, degree: int) -> int:
    """Number of basis functions ``n = len(knots) - degree - 1``."""
    return len(knots) - degree - 1


def span_breaks(knots: np.ndarray) -> np.ndarray:
    """Distinct knot values (element boundaries), (n_elements + 1,)."""
    return np.unique(knots)


def _check_x(x, t: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float).reshape(-1)
    out = np.flatnonzero(~((x >= t[0]) & (x <= t[-1])))
    if out.size:
        raise ValueError(f"x: parameter value {x[out[0]]} (index {out[0]}) outside the "
                         f"knot range [{t[0]}, {t[-1]}]")
    return x


def _safe_ratio(num: float, den: np.ndarray) -> np.ndarray:
    """``num / den`` with 0 where ``den == 0`` (the 0/0 := 0 convention of Cox-de Boor)."""
    out = np.zeros_like(den, dtype=float)
    np.divide(num, den, out=out, where=den > 0)
    return out


def compact_basis(x: np.ndarray, knots: np.ndarray, degree: int,
                  derivative: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Non-zero basis values (or derivatives) at points, in compact form.

    Parameters
    ----------
    x : (m,) parameter values inside ``[knots[0], knots[-1]]`` (not re-checked)
    knots : open knot vector (validated)
    degree : int
    derivative : int >= 0

    Returns
    -------
    first : (m,) int, index of the first function that may be non-zero at each point
    values : (m, degree + 1), values of functions ``first .. first + degree``
    """
    p = degree
    m = x.size
    if derivative == 0:
        D = BSpline.design_matrix(x, knots, p)
        if D.nnz != m * (p + 1):  # scipy stores exactly p+1 entries per row
            D = D.tocsr()
            D.sort_indices()
        return D.indices[:: p + 1].astype(np.int64), D.data.reshape(m, p + 1).copy()
    if derivative > p:
        first, _ = compact_basis(x, knots, p, 0)
        return first, np.zeros((m, p + 1))
    # The trimmed vector t[1:-1] is open for degree p-1; its function j is N_{j+1,p-1}
    # of the full vector, and it picks the same knot span as t at every x (also at the
    # right end, where it takes the last non-empty span).
    first, lower = compact_basis(x, knots[1:-1], p - 1, derivative - 1)
    t = knots
    n = n_functions(t, p)
    i = np.arange(n)
    a = _safe_ratio(p, t[i + p] - t[i])          # p / (t_{i+p} - t_i)
    b = _safe_ratio(p, t[i + p + 1] - t[i + 1])  # p / (t_{i+p+1} - t_{i+1})
    padded = np.zeros((m, p + 2))                # N_{i,p-1}, i = first .. first + p + 1
    padded[:, 1:-1] = lower
    idx = first[:, None] + np.arange(p + 1)[None, :]
    values = a[idx] * padded[:, :-1] - b[idx] * padded[:, 1:]  # recurrence above
    return first, values


def compact_to_csr(first: np.ndarray, values: np.ndarray, n: int) -> sp.csr_matrix:
    """CSR matrix (m, n) from the compact form of :func:`compact_basis`."""
    m, k = values.shape
    cols = first[:, None] + np.arange(k)[None, :]
    indptr = np.arange(m + 1) * k
    return sp.csr_matrix((values.ravel(), cols.ravel(), indptr), shape=(m, n))


def basis_matrix(x, knots, degree: int, derivative: int = 0) -> sp.csr_matrix:
    """B-spline basis functions (or their derivatives) at points.

    Parameters
    ----------
    x : (m,) parameter values in ``[knots[0], knots[-1]]`` (the right end is included:
        the last function is 1 there)
    knots : (n + degree + 1,) open knot vector
    degree : int >= 0
    derivative : int >= 0, order of the derivative

    Returns
    -------
    csr_matrix (m, n) with ``[k, i] = N_i^{(derivative)}(x_k)``.
    """
    t = validate_knots(knots, degree)
    if isinstance(derivative, bool) or not isinstance(derivative, numbers.Integral) \
            or derivative < 0:
        raise ValueError(f"derivative: must be an int >= 0, got {derivative!r}")
    x = _check_x(x, t)
    first, values = compact_basis(x, t, int(degree), int(derivative))
    return compact_to_csr(first, values, n_functions(t, degree))


def greville(knots, degree: int) -> np.ndarray:
    """Greville abscissae ``(t_{i+1} + ... + t_{i+p}) / p``, (n,).

    For degree 0, the midpoints of the knot spans of the functions.
    """
    t = validate_knots(knots, degree)
    p = int(degree)
    n = n_functions(t, p)
    if p == 0:
        return 0.5 * (t[:-1] + t[1:])
    c = np.concatenate([[0.0], np.cumsum(t)])
    i = np.arange(n)
    return (c[i + p + 1] - c[i + 1]) / p


def _boehm_step(t: np.ndarray, p: int, x: float) -> tuple[sp.csr_matrix, np.ndarray]:
    """Insert one knot ``x``: returns ``A (n + 1, n)`` with ``P_new = A P_old``."""
    n = n_functions(t, p)
    k = int(np.searchsorted(t, x, side="right")) - 1  # t_k <= x < t_{k+1}
    i = np.arange(n + 1)
    alpha = np.ones(n + 1)
    alpha[i >= k + 1] = 0.0
    mid = (i >= k - p + 1) & (i <= k)
    im = i[mid]
    alpha[mid] = (x - t[im]) / (t[im + p] - t[im])
    # Q_i = alpha_i P_i + (1 - alpha_i) P_{i-1}
    rows = np.concatenate([i[i < n], i[i >= 1]])
    cols = np.concatenate([i[i < n], i[i >= 1] - 1])
    vals = np.concatenate([alpha[i < n], 1.0 - alpha[i >= 1]])
    keep = vals != 0.0
    A = sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(n + 1, n))
    return A, np.insert(t, k + 1, x)


def insertion_matrix(knots, degree: int, new_knots) -> tuple[sp.csr_matrix, np.ndarray]:
    """Knot insertion operator (Eq. 13).

    Parameters
    ----------
    knots : (n_old + degree + 1,) open knot vector
    degree : int
    new_knots : (k,) knots to insert, strictly inside the parameter range (an existing
        knot may be repeated up to multiplicity ``degree``)

    Returns
    -------
    C : csr_matrix (n_old, n_new) with ``N_old(x) = C N_new(x)`` (Eq. 13) and
        ``x_new = C^T x_old`` (Eq. 15)
    refined_knots : (n_new + degree + 1,)
    """
    t = validate_knots(knots, degree)
    p = int(degree)
    new = np.sort(np.asarray(new_knots, dtype=float).reshape(-1))
    bad = np.flatnonzero(~((new > t[0]) & (new < t[-1])))
    if bad.size:
        raise ValueError(f"new_knots: value {new[bad[0]]} is not strictly inside "
                         f"({t[0]}, {t[-1]})")
    CT = sp.identity(n_functions(t, p), format="csr")
    for x in new:  # one knot at a time (a loop over knots, not over points)
        A, t = _boehm_step(t, p, float(x))
        CT = A @ CT
    validate_knots(t, p, name="refined knots")
    return CT.T.tocsr(), t
