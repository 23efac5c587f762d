"""NURBS / B-spline surface patch (section 3.1, Eqs. 11-12).

A patch ``S(xi) = sum_I R_I(xi) x_I`` (Eq. 11) with ``xi = (u, v)`` in the parameter box
``[u_0, u_end] x [v_0, v_end]``. The bivariate B-spline functions are tensor products
``N_I(u, v) = N_i(u) N_j(v)`` of the univariate bases of :mod:`georeg_plugin.spline.bspline`;
the NURBS functions are ``R_I = w_I N_I / W`` with ``W = sum_k w_k N_k`` (Eq. 12).

Degree-of-freedom numbering: control point ``(i, j)`` is dof ``I = i * nv + j``, i.e.
the C order of ``control_points[:, :, k]``.
"""
from __future__ import annotations

import dataclasses
import logging
import numbers

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from georeg_plugin.spline.bspline import (compact_basis, greville, n_functions, span_breaks,
                                          validate_knots)

logger = logging.getLogger(__name__)

__all__ = ["SplinePatch", "invert_points"]

_DERIVATIVES = {None: (0, 0), "u": (1, 0), "v": (0, 1)}


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)  # copy
    a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class SplinePatch:
    """Tensor-product NURBS (or B-spline if ``weights is None``) surface patch.

    Attributes
    ----------
    degrees : (p_u, p_v) ints
    knots : (Xi_u, Xi_v), open knot vectors of ``nu + p_u + 1`` and ``nv + p_v + 1`` knots
    control_points : (nu, nv, 3) control point coordinates x_I, in mm
    weights : (nu, nv) positive weights w_I, or None for a B-spline patch
    """

    degrees: tuple[int, int]
    knots: tuple[np.ndarray, np.ndarray]
    control_points: np.ndarray
    weights: np.ndarray | None = None

    def __post_init__(self) -> None:
        degrees = tuple(self.degrees) if np.ndim(self.degrees) == 1 else None
        if degrees is None or len(degrees) != 2 or not all(
                isinstance(p, numbers.Integral) and not isinstance(p, bool) and p >= 0
                for p in degrees):
            raise ValueError(f"degrees: expected two ints >= 0, got {self.degrees!r}")
        degrees = (int(degrees[0]), int(degrees[1]))
        if not isinstance(self.knots, (tuple, list)) or len(self.knots) != 2:
            raise ValueError("knots: expected a tuple of two knot vectors (u, v)")
        knots = tuple(_readonly(validate_knots(self.knots[d], degrees[d], f"knots[{d}]"))
                      for d in range(2))
        shape = tuple(n_functions(knots[d], degrees[d]) for d in range(2))
        cp = np.asarray(self.control_points, dtype=float)
        if cp.shape != shape + (3,):
            raise ValueError(f"control_points: shape {cp.shape} does not match the "
                             f"{shape[0]} x {shape[1]} basis functions of knots/degrees "
                             f"{degrees} (expected {shape + (3,)})")
        if not np.all(np.isfinite(cp)):
            raise ValueError("control_points: non-finite coordinates")
        weights = None
        if self.weights is not None:
            weights = np.asarray(self.weights, dtype=float)
            if weights.shape != shape:
                raise ValueError(f"weights: shape {weights.shape}, expected {shape}")
            if not np.all(np.isfinite(weights) & (weights > 0)):
                raise ValueError("weights: must be finite and > 0")
            weights = _readonly(weights)
        object.__setattr__(self, "degrees", degrees)
        object.__setattr__(self, "knots", knots)
        object.__setattr__(self, "control_points", _readonly(cp))
        object.__setattr__(self, "weights", weights)

    # ------------------------------------------------------------------ sizes
    @property
    def is_rational(self) -> bool:
        """True for a NURBS patch (weights given)."""
        return self.weights is not None

    @property
    def shape(self) -> tuple[int, int]:
        """Number of control points ``(nu, nv)``."""
        return self.control_points.shape[:2]

    @property
    def n_dofs(self) -> int:
        """Number of control points ``nu * nv``."""
        return self.shape[0] * self.shape[1]

    @property
    def breaks(self) -> tuple[np.ndarray, np.ndarray]:
        """Distinct knots (element boundaries) in u and v."""
        return span_breaks(self.knots[0]), span_breaks(self.knots[1])

    @property
    def n_elements(self) -> tuple[int, int]:
        """Number of non-empty knot spans in u and v."""
        bu, bv = self.breaks
        return len(bu) - 1, len(bv) - 1

    @property
    def bounds(self) -> np.ndarray:
        """Parameter box ``[[u0, v0], [u_end, v_end]]``, (2, 2)."""
        return np.array([[self.knots[0][0], self.knots[1][0]],
                         [self.knots[0][-1], self.knots[1][-1]]])

    @property
    def homogeneous_weights(self) -> np.ndarray:
        """Weights per dof, ones for a B-spline patch, (n_dofs,)."""
        if self.weights is None:
            return np.ones(self.n_dofs)
        return self.weights.ravel()

    # ------------------------------------------------------------------ basis
    def _check_uv(self, uv) -> np.ndarray:
        uv = np.asarray(uv, dtype=float)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise ValueError(f"uv: expected shape (m, 2), got {uv.shape}")
        lo, hi = self.bounds
        tol = 1e-12 * (hi - lo)
        bad = np.flatnonzero(~np.all((uv >= lo - tol) & (uv <= hi + tol), axis=1))
        if bad.size:
            raise ValueError(f"uv: point {uv[bad[0]]} (index {bad[0]}) outside the "
                             f"parameter box {lo} - {hi}")
        return np.clip(uv, lo, hi)

    def _compact(self, uv: np.ndarray, du: int, dv: int) -> tuple[np.ndarray, np.ndarray]:
        """Tensor-product B-spline values in compact form: cols, vals (m, K).

        Row-wise Kronecker (Khatri-Rao) product of the two univariate bases; the
        columns do not depend on the derivative order.
        """
        (pu, pv), (tu, tv) = self.degrees, self.knots
        fu, Nu = compact_basis(uv[:, 0], tu, pu, du)
        fv, Nv = compact_basis(uv[:, 1], tv, pv, dv)
        nv = self.shape[1]
        iu = fu[:, None] + np.arange(pu + 1)[None, :]
        jv = fv[:, None] + np.arange(pv + 1)[None, :]
        m = uv.shape[0]
        cols = (iu[:, :, None] * nv + jv[:, None, :]).reshape(m, -1)
        vals = (Nu[:, :, None] * Nv[:, None, :]).reshape(m, -1)
        return cols, vals

    def _compact_rational(self, uv: np.ndarray,
                          derivative) -> tuple[np.ndarray, np.ndarray]:
        du, dv = _DERIVATIVES[derivative]
        cols, N = self._compact(uv, 0, 0)
        if self.weights is None:                        # a B-spline
            return (cols, N) if derivative is None else (cols, self._compact(uv, du, dv)[1])
        w = self.weights.ravel()[cols]
        W = np.sum(w * N, axis=1, keepdims=True)       # W = sum_k w_k N_k (Eq. 12)
        R = w * N / W                                   # R_I = w_I N_I / W (Eq. 12)
        if derivative is None:
            return cols, R
        Nd = self._compact(uv, du, dv)[1]
        Wd = np.sum(w * Nd, axis=1, keepdims=True)
        return cols, (w * Nd - R * Wd) / W              # quotient rule on Eq. 12

    def basis(self, uv, derivative: str | None = None) -> sp.csr_matrix:
        """Basis functions R_I (Eq. 12) or their first derivatives at points.

        Parameters
        ----------
        uv : (m, 2) parameters in the parameter box
        derivative : None, "u" or "v"

        Returns
        -------
        csr_matrix (m, nu * nv), column ``i * nv + j`` for control point ``(i, j)``.
        """
        if derivative not in _DERIVATIVES:
            raise ValueError(f"derivative: expected None, 'u' or 'v', got {derivative!r}")
        uv = self._check_uv(uv)
        cols, vals = self._compact_rational(uv, derivative)
        m, k = vals.shape
        return sp.csr_matrix((vals.ravel(), cols.ravel(), np.arange(m + 1) * k),
                             shape=(m, self.n_dofs))

    def _combine(self, uv: np.ndarray, derivative) -> np.ndarray:
        cols, vals = self._compact_rational(uv, derivative)
        return np.einsum("mk,mkc->mc", vals, self.control_points.reshape(-1, 3)[cols])

    # ------------------------------------------------------------------ geometry
    def evaluate(self, uv) -> np.ndarray:
        """Surface points ``S(uv) = R^T x`` (Eq. 11), (m, 3)."""
        return self._combine(self._check_uv(uv), None)

    def derivatives(self, uv) -> tuple[np.ndarray, np.ndarray]:
        """Tangent vectors ``(S_u, S_v)``, each (m, 3)."""
        uv = self._check_uv(uv)
        return self._combine(uv, "u"), self._combine(uv, "v")

    def normals(self, uv) -> np.ndarray:
        """Unit normals ``S_u x S_v / |S_u x S_v|``, (m, 3)."""
        su, sv = self.derivatives(uv)
        n = np.cross(su, sv)
        norm = np.linalg.norm(n, axis=1)
        bad = np.flatnonzero(~(norm > 0))
        if bad.size:
            raise ValueError(f"uv: degenerate surface (S_u x S_v = 0) at point index "
                             f"{bad[0]}, uv = {np.asarray(uv)[bad[0]]}")
        return n / norm[:, None]

    def greville_points(self) -> np.ndarray:
        """Greville abscissae of the control points, (nu * nv, 2), dof order."""
        gu = greville(self.knots[0], self.degrees[0])
        gv = greville(self.knots[1], self.degrees[1])
        U, V = np.meshgrid(gu, gv, indexing="ij")
        return np.column_stack([U.ravel(), V.ravel()])

    def control_normals(self) -> np.ndarray:
        """Surface normal at the Greville abscissae of each control point, (n_dofs, 3)."""
        return self.normals(self.greville_points())

    def sample_parameters(self, per_span: int = 20,
                          max_per_direction: int = 400) -> tuple[np.ndarray, np.ndarray]:
        """Parameters at the centres of ``per_span`` equal cells of every knot span.

        All samples are strictly inside a span (never on a knot), u and v.
        """
        out = []
        for b in self.breaks:
            k = max(2, min(per_span, max_per_direction // (len(b) - 1)))
            s = b[:-1, None] + (b[1:] - b[:-1])[:, None] * (np.arange(k) + 0.5) / k
            out.append(s.ravel())
        return out[0], out[1]


def _gauss_newton(S, Su, Sv, X) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gradient g (m, 2), Gauss-Newton matrix H (m, 2, 2) and f = 1/2 |S - X|^2 (m,)."""
    r = S - X
    g = np.column_stack([np.sum(Su * r, 1), np.sum(Sv * r, 1)])
    H = np.empty((len(S), 2, 2))
    H[:, 0, 0] = np.sum(Su * Su, 1)
    H[:, 0, 1] = H[:, 1, 0] = np.sum(Su * Sv, 1)
    H[:, 1, 1] = np.sum(Sv * Sv, 1)
    return g, H, 0.5 * np.sum(r * r, 1)


def _active(uv, g, lo, hi) -> np.ndarray:
    """Box constraints active at uv (on a bound, gradient pushing outwards), (m, 2)."""
    return ((uv <= lo) & (g > 0)) | ((uv >= hi) & (g < 0))


def _projected_step(uv, g, H, lo, hi) -> np.ndarray:
    """Gauss-Newton step, restricted to the free coordinates of the box."""
    det = H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] ** 2
    det = np.where(np.abs(det) > 0, det, np.finfo(float).tiny)
    step = -np.column_stack([H[:, 1, 1] * g[:, 0] - H[:, 0, 1] * g[:, 1],
                             H[:, 0, 0] * g[:, 1] - H[:, 0, 1] * g[:, 0]]) / det[:, None]
    active = _active(uv, g, lo, hi)
    diag = np.maximum(np.stack([H[:, 0, 0], H[:, 1, 1]], 1), np.finfo(float).tiny)
    one = active[:, 0] ^ active[:, 1]
    step[one] = np.where(active[one], 0.0, (-g / diag)[one])
    step[active[:, 0] & active[:, 1]] = 0.0
    return step


def _newton_in_boxes(patch, X, uv, lo, hi, step_tol, f_tol, max_iter) -> np.ndarray:
    """Projected Gauss-Newton with backtracking, each point in its own box (m, 2)."""
    uv = uv.copy()
    todo = np.arange(len(X))
    for _ in range(max_iter):
        if todo.size == 0:
            break
        u, x, a, b = uv[todo], X[todo], lo[todo], hi[todo]
        Su, Sv = patch.derivatives(u)
        g, H, f = _gauss_newton(patch.evaluate(u), Su, Sv, x)
        step = _projected_step(u, g, H, a, b)
        t = np.ones(len(u))
        new = u.copy()
        pending = np.arange(len(u))
        for _ in range(30):  # backtracking; f is known to round-off only
            trial = np.clip(u[pending] + t[pending, None] * step[pending],
                            a[pending], b[pending])
            r = patch.evaluate(trial) - x[pending]
            ok = 0.5 * np.sum(r * r, 1) <= f[pending] + f_tol * np.sqrt(2 * f[pending])
            new[pending[ok]] = trial[ok]
            pending = pending[~ok]
            if pending.size == 0:
                break
            t[pending] *= 0.5
        uv[todo] = new
        todo = todo[np.any(np.abs(new - u) > step_tol, axis=1)]
    return uv


def _descend(patch, X, uv, tol, max_iter) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Span-by-span projected Gauss-Newton from ``uv``.

    Returns the best parameters (m, 2), their f (m,), and whether the point ended on
    the patch boundary with the gradient pushing outwards (m,) bool.
    """
    box_lo, box_hi = patch.bounds
    breaks = patch.breaks
    span = np.column_stack([np.clip(np.searchsorted(b, uv[:, d], side="right") - 1,
                                    0, len(b) - 2) for d, b in enumerate(breaks)])
    n_spans = np.array([len(b) - 1 for b in breaks])
    step_tol = tol * (box_hi - box_lo)
    # stay a hair below an interior upper knot: derivatives are then one-sided
    inset = 16 * np.finfo(float).eps * np.max(np.abs(patch.bounds))
    scale = np.max(np.abs(patch.control_points)) + np.max(np.abs(X))
    f_tol = 64 * np.finfo(float).eps * scale
    uv = uv.copy()
    best = uv.copy()
    best_f = np.full(len(X), np.inf)
    outside = np.zeros(len(X), bool)
    rows = np.arange(len(X))
    for _ in range(4):  # passes over neighbouring spans
        lo = np.column_stack([breaks[d][span[rows, d]] for d in range(2)])
        top = np.column_stack([breaks[d][span[rows, d] + 1] for d in range(2)])
        hi = np.where(span[rows] < n_spans - 1, top - inset, top)
        res = _newton_in_boxes(patch, X[rows], np.clip(uv[rows], lo, hi), lo, hi,
                               step_tol, f_tol, max_iter)
        Su, Sv = patch.derivatives(res)
        g, H, f = _gauss_newton(patch.evaluate(res), Su, Sv, X[rows])
        better = f < best_f[rows]
        best[rows[better]], best_f[rows[better]] = res[better], f[better]
        # leave the span through an interior knot if that still decreases f noticeably
        diag = np.maximum(np.stack([H[:, 0, 0], H[:, 1, 1]], 1), np.finfo(float).tiny)
        push = np.abs(g) / np.sqrt(diag) > 1e-10 * scale
        active = _active(res, g, lo, hi) & push
        first, last = span[rows] == 0, span[rows] == n_spans - 1
        down = active & (res <= lo) & ~first
        up = active & (res >= hi) & ~last
        outside[rows[better]] = np.any(active & ((res <= lo) & first | (res >= hi) & last),
                                       axis=1)[better]
        move = np.any(down | up, axis=1)
        if not np.any(move):
            break
        span[rows] += up.astype(int) - down.astype(int)
        uv[rows] = res
        rows = rows[move]
    return best, best_f, outside


def invert_points(patch: SplinePatch, X, uv0=None, tol: float = 1e-12,
                  max_iter: int = 60, per_span: int = 20,
                  n_starts: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Closest parametric points of a patch to points in space.

    Start from the nearest of a grid of surface points sampled inside the knot spans
    (``per_span`` per span and direction, nearest by a k-d tree) unless ``uv0`` is
    given. Then projected Gauss-Newton on ``1/2 |S(uv) - X|^2`` with backtracking,
    one knot span at a time (so that derivatives are never taken across a C0 knot);
    a point whose minimum lies on an interior knot with the gradient pushing outwards
    moves on to the neighbouring span. Points that end on the patch boundary with the
    gradient pushing outwards (a closed patch's seam, or a point beyond the boundary)
    are restarted from the next ``n_starts - 1`` nearest samples; the best is kept.

    Parameters
    ----------
    patch : SplinePatch
    X : (m, 3) points in space
    uv0 : (m, 2) optional starting parameters
    tol : float, convergence tolerance on the parameter step (relative to the box size)

    Returns
    -------
    uv : (m, 2) closest parameters
    distance : (m,) Euclidean distances ``|S(uv) - X|``
    """
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] != 3 or not np.all(np.isfinite(X)):
        raise ValueError(f"X: expected finite points of shape (m, 3), got {X.shape}")
    box_lo, box_hi = patch.bounds
    if uv0 is not None:
        uv0 = np.asarray(uv0, dtype=float)
        if uv0.shape != (len(X), 2):
            raise ValueError(f"uv0: expected shape {(len(X), 2)}, got {uv0.shape}")
        starts = np.clip(uv0, box_lo, box_hi)[:, None, :]
    else:
        su, sv = patch.sample_parameters(per_span)
        U, V = np.meshgrid(su, sv, indexing="ij")
        grid = np.column_stack([U.ravel(), V.ravel()])
        k = max(1, min(int(n_starts), len(grid)))
        _, nearest = cKDTree(patch.evaluate(grid)).query(X, k=k)
        starts = grid[nearest.reshape(len(X), k)]
    uv, f, outside = _descend(patch, X, starts[:, 0], tol, max_iter)
    for s in range(1, starts.shape[1]):  # restarts, for the few suspicious points
        rows = np.flatnonzero(outside)
        if rows.size == 0:
            break
        res, f_s, out_s = _descend(patch, X[rows], starts[rows, s], tol, max_iter)
        better = f_s < f[rows]
        uv[rows[better]], f[rows[better]] = res[better], f_s[better]
        outside[rows] = np.where(better, out_s, True)  # not better: try the next start
    distance = np.linalg.norm(patch.evaluate(uv) - X, axis=1)
    return uv, distance
