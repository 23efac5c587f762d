"""The pose of a known surface from triangulated points: point-to-plane ICP on a triangle soup.

What places a CAD part in the rig's frame when no landmark is given: the stereo matches of
the reference pair, triangulated (:func:`fesdic_core.cameras.triangulation.stereo_points`),
are moved rigidly onto the part's triangles (any soup of triangles: a CAD triangulation,
a mesh; no connectivity is needed).

- **Closest points.** The triangles are sampled about every ``spacing_mm`` (a k-d tree of the
  samples, :class:`scipy.spatial.cKDTree`); the triangles of a point's :data:`CANDIDATES`
  nearest samples are the candidates, and the exact closest point on each (Ericson,
  *Real-Time Collision Detection*, 5.1.5, vectorised) gives the nearest one.
- **Residuals.** A point whose closest point lies inside its triangle contributes its
  signed distance along the triangle's normal (point-to-plane: the point slides freely along
  the surface, so the part's features, not its outline, set the pose); a point whose closest
  point lies on an edge of the soup (beyond the part's outline, past a ridge) contributes the
  whole vector to it (point-to-point).
- **Robust weights.** Tukey's biweight on the residuals, cut at :data:`TUKEY` times a scale
  that starts wide (the 90th percentile of the first residuals) and shrinks by
  :data:`ANNEAL` a step down to the residuals' robust scale (1.4826 times their median
  absolute value): the points near the features, far off while the pose is rough, set it
  first; the points off the part (background, faces not in the soup, the real part
  departing from its CAD) fall out as the pose improves.
- **Step.** Gauss-Newton on a small rotation about the points' centroid and a translation
  (6 unknowns, the rotation scaled by the points' radius of gyration), with a small
  Levenberg damping: a direction the surface leaves free (a flat plate sliding in its
  plane) stays where it started, and :attr:`IcpResult.conditioning` says so.

:mod:`fesdic_core.cameras.icp_start` gives the rough poses of a part without any (its
principal axes).
"""
from __future__ import annotations

import dataclasses
import logging
import numpy as np
from scipy.spatial import cKDTree

logger = logging.getLogger(__name__)

__all__ = ["TriangleSurface", "IcpResult", "closest_points_on_triangles",
           "point_to_plane_icp", "rotation_vector", "rotation_matrix", "CANDIDATES", "TUKEY",
           "MAX_SAMPLES", "ANNEAL"]

CANDIDATES = 8          # nearest samples whose triangles are searched for the closest point
TUKEY = 4.685           # Tukey's biweight constant (95 % efficiency for Gaussian residuals)
MAX_SAMPLES = 30000     # the default sample spacing keeps about this many samples
ANNEAL = 0.8            # the robust scale of ICP shrinks by this factor a step
_MAD = 1.4826           # median absolute residual -> standard deviation (Gaussian)
_DAMPING = 1e-6         # Levenberg damping, relative to the largest diagonal term


def rotation_matrix(rvec: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) of the rotation vector ``rvec`` (3,) (axis times angle, rad)."""
    w = np.asarray(rvec, dtype=float).reshape(3)
    angle = float(np.linalg.norm(w))
    if angle < 1e-15:
        return np.eye(3)
    k = w / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """The rotation vector (3,) (rad) of the rotation ``R`` (3, 3)."""
    R = np.asarray(R, dtype=float)
    cos = np.clip(0.5 * (np.trace(R) - 1.0), -1.0, 1.0)
    angle = float(np.arccos(cos))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-8:
        return 0.5 * axis
    if np.pi - angle < 1e-6:                         # near a half turn: from R + I
        B = 0.5 * (R + np.eye(3))
        k = B[:, int(np.argmax(np.diag(B)))]
        return angle * k / np.linalg.norm(k)
    return angle * axis / (2.0 * np.sin(angle))


def closest_points_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
                                ) -> tuple[np.ndarray, np.ndarray]:
    """The closest point (n, 3) of each triangle ``(a, b, c)`` (n, 3 each) to the point ``p``
    (n, 3), and whether it lies strictly inside the triangle (n,) bool (not on an edge or a
    vertex). Ericson's region tests (*Real-Time Collision Detection*, 5.1.5), vectorised."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        v_ab = d1 / (d1 - d3)
        w_ac = d2 / (d2 - d6)
        w_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        total = va + vb + vc
        v_in, w_in = vb / total, vc / total
    regions = [(d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3),
               (vc <= 0) & (d1 >= 0) & (d3 <= 0), (d6 >= 0) & (d5 <= d6),
               (vb <= 0) & (d2 >= 0) & (d6 <= 0), (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)]
    choices = [a, b, a + v_ab[:, None] * ab, c, a + w_ac[:, None] * ac,
               b + w_bc[:, None] * (c - b)]
    inside = ~np.logical_or.reduce(regions)
    q = a + v_in[:, None] * ab + w_in[:, None] * ac
    for region, choice in zip(regions[::-1], choices[::-1]):     # the first region wins
        q = np.where(region[:, None], choice, q)
    return q, inside


@dataclasses.dataclass(frozen=True, eq=False)
class TriangleSurface:
    """A triangle soup ready for closest-point queries.

    Attributes
    ----------
    triangles : (m, 3, 3) vertices (mm), degenerate triangles removed.
    normals : (m, 3) unit normals (``(b - a) x (c - a)``).
    samples : (k, 3) points on the triangles, about ``spacing_mm`` apart.
    sample_triangle : (k,) the triangle of each sample.
    spacing_mm : the sample spacing.
    """

    triangles: np.ndarray
    normals: np.ndarray
    samples: np.ndarray
    sample_triangle: np.ndarray
    spacing_mm: float
    tree: cKDTree

    @classmethod
    def of(cls, triangles: np.ndarray, spacing_mm: float | None = None) -> TriangleSurface:
        """Sample ``triangles`` (m, 3, 3) mm every ``spacing_mm`` (default: about
        :data:`MAX_SAMPLES` samples over the area) on a grid of each triangle: along its
        longest edge, and from it to the opposite vertex (a thin sliver gets few samples).

        Raises ValueError when no triangle has an area."""
        T = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
        cross = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        double_area = np.linalg.norm(cross, axis=1)
        keep = double_area > 1e-12 * max(float(double_area.max(initial=0.0)), 1e-300)
        if not keep.any():
            raise ValueError(f"TriangleSurface: none of the {len(T)} triangles has an area")
        T, cross, double_area = T[keep], cross[keep], double_area[keep]
        if spacing_mm is None:
            spacing_mm = float(np.sqrt(double_area.sum() / MAX_SAMPLES))
        edges = np.linalg.norm(T[:, [1, 2, 0]] - T, axis=2)       # |ab|, |bc|, |ca|
        first = np.argmax(edges, axis=1)                           # the longest edge first
        order = (first[:, None] + np.arange(3)) % 3
        tri = np.take_along_axis(T, order[:, :, None], axis=1)     # a b: the longest edge
        along = np.maximum(1, np.ceil(edges.max(axis=1) / spacing_mm)).astype(int)
        across = np.maximum(1, np.ceil(double_area / edges.max(axis=1) / spacing_mm)).astype(int)
        samples, owner = [], []
        for n, m in np.unique(np.column_stack([along, across]), axis=0):   # one grid a size
            i, j = np.meshgrid(np.arange(n + 1) / n, np.arange(m + 1) / m, indexing="ij")
            u, v = (i * (1.0 - j)).ravel(), j.ravel()             # j = 1: the apex c
            rows = np.flatnonzero((along == n) & (across == m))
            t = tri[rows]
            pts = (t[:, None, 0] + u[None, :, None] * (t[:, None, 1] - t[:, None, 0])
                   + v[None, :, None] * (t[:, None, 2] - t[:, None, 0]))
            samples.append(pts.reshape(-1, 3))
            owner.append(np.repeat(rows, len(u)))
        points, owners = np.concatenate(samples), np.concatenate(owner)
        logger.debug("triangle surface: %d triangles, %d samples every %.3g mm", len(T),
                     len(points), spacing_mm)
        return cls(triangles=T, normals=cross / double_area[:, None], samples=points,
                   sample_triangle=owners, spacing_mm=float(spacing_mm), tree=cKDTree(points))

    @property
    def area_mm2(self) -> float:
        """The soup's area (mm^2)."""
        T = self.triangles
        return 0.5 * float(np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]),
                                          axis=1).sum())

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """The area centroid (3,) and the covariance (3, 3) of the surface (exact: a
        uniform density on each triangle, ``E[x x^T] = (sum v v^T + s s^T) / 12``, s the
        sum of its vertices)."""
        T = self.triangles
        w = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
        w = w / w.sum()
        centroid = np.einsum("t,tij->j", w, T) / 3.0
        s = T.sum(axis=1)
        second = (np.einsum("t,tvi,tvj->ij", w, T, T) + np.einsum("t,ti,tj->ij", w, s, s)) / 12.0
        return centroid, second - np.outer(centroid, centroid)

    def closest(self, points: np.ndarray, bound: float = np.inf
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For ``points`` (n, 3): the closest point on the soup (n, 3), its triangle (n,),
        and whether it lies inside that triangle (n,) bool (else on an edge or a vertex).
        A point with no sample within ``bound`` mm gets triangle -1 (its point: itself)."""
        x = np.asarray(points, dtype=float).reshape(-1, 3)
        k = min(CANDIDATES, len(self.samples))
        _, idx = self.tree.query(x, k=k, distance_upper_bound=bound + self.spacing_mm)
        idx = np.asarray(idx).reshape(len(x), k)
        far = idx[:, 0] >= len(self.samples)
        idx = np.where(idx >= len(self.samples), idx[:, :1], idx)   # missing: the nearest
        tri = self.sample_triangle[np.where(far[:, None], 0, idx)]
        T = self.triangles[tri.ravel()]
        q, inside = closest_points_on_triangles(np.repeat(x, k, axis=0), T[:, 0], T[:, 1], T[:, 2])
        d = np.linalg.norm(q - np.repeat(x, k, axis=0), axis=1).reshape(len(x), k)
        rows = np.arange(len(x)) * k + np.argmin(d, axis=1)
        q, tri, inside = q[rows], tri.ravel()[rows], inside[rows]
        return np.where(far[:, None], x, q), np.where(far, -1, tri), inside & ~far


@dataclasses.dataclass(frozen=True, eq=False)
class IcpResult:
    """The rigid motion ``x_surface = rotation @ x_point + translation`` of the points onto
    the surface.

    Attributes
    ----------
    rotation : (3, 3); translation : (3,) mm.
    residual_mm : (n,) each point's residual at the end (signed normal distance, or the
        distance to an edge of the soup).
    inliers : (n,) bool, the points of nonzero weight at the end.
    rms_mm : RMS of the inliers' residuals.
    iterations : Gauss-Newton steps taken; converged : the last step was below the tolerances.
    conditioning : smallest over largest eigenvalue of the (scaled) 6 x 6 normal matrix:
        near 0 when the surface leaves a motion free (a plane: sliding in it).
    """

    rotation: np.ndarray
    translation: np.ndarray
    residual_mm: np.ndarray
    inliers: np.ndarray
    rms_mm: float
    iterations: int
    converged: bool
    conditioning: float

    def apply(self, points: np.ndarray) -> np.ndarray:
        """``points`` (n, 3) moved by the result (onto the surface)."""
        return np.asarray(points, dtype=float) @ self.rotation.T + self.translation


def _residuals(x: np.ndarray, surface: TriangleSurface, bound: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per point: signed residual (n,) (inf beyond ``bound`` mm), the closest point (n, 3),
    normal (n, 3), inside (n,)."""
    q, tri, inside = surface.closest(x, bound)
    n = surface.normals[np.maximum(tri, 0)]
    gap = x - q
    r = np.where(inside, np.einsum("ij,ij->i", gap, n), np.linalg.norm(gap, axis=1))
    return np.where(tri >= 0, r, np.inf), q, n, inside


def _robust_scale(r: np.ndarray, floor_mm: float) -> float:
    return max(_MAD * float(np.median(np.abs(r[np.isfinite(r)]))), floor_mm)


def _weights(r: np.ndarray, scale: float) -> np.ndarray:
    u = r / (TUKEY * scale)
    return np.where(np.abs(u) < 1.0, (1.0 - u ** 2) ** 2, 0.0)


def point_to_plane_icp(points: np.ndarray, surface: TriangleSurface,
                       rotation: np.ndarray | None = None,
                       translation: np.ndarray | None = None, max_iterations: int = 100,
                       step_tol_mm: float = 1e-5, floor_mm: float = 1e-6) -> IcpResult:
    """Point-to-plane ICP of ``points`` (n, 3) mm onto ``surface``, robust (see the module).

    The robust scale starts wide (the 90th percentile of the residuals at the start: a pose
    off by a few degrees leaves the points near the part's features far off, and they are
    what sets it) and shrinks by :data:`ANNEAL` a step down to the residuals' own robust
    scale; the iteration stops once it has and no point moves more than ``step_tol_mm``.

    Parameters
    ----------
    points : (n, 3) the measured points (any frame).
    surface : the triangles to fit them to.
    rotation, translation : (3, 3), (3,) the start, ``x_surface = R x + t`` (default: none).
    max_iterations : Gauss-Newton steps at most.
    step_tol_mm : converged when no point moves more than this in a step.
    floor_mm : the smallest robust scale of the residuals (exact synthetic points).

    Returns
    -------
    IcpResult

    Raises
    ------
    ValueError
        Fewer than 6 points, or every point rejected.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(p) < 6:
        raise ValueError(f"point_to_plane_icp: {len(p)} points, at least 6 needed for a "
                         "rigid motion")
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    t = np.zeros(3) if translation is None else np.asarray(translation, dtype=float)
    converged, conditioning, k, wide = False, 0.0, 0, None
    for k in range(1, max_iterations + 1):
        x = p @ R.T + t
        bound = np.inf if wide is None else 3.0 * TUKEY * wide   # farther: weight 0 anyway
        r, q, n, inside = _residuals(x, surface, bound)
        scale = _robust_scale(r, floor_mm)
        if wide is None:
            finite = np.abs(r[np.isfinite(r)])
            wide = float(np.quantile(finite, 0.9)) / TUKEY if finite.size else scale
        wide = max(scale, wide * ANNEAL) if k > 1 else max(scale, wide)
        w = _weights(np.where(np.isfinite(r), r, np.inf), wide)
        if not np.any(w > 0):
            raise ValueError(f"point_to_plane_icp: every one of the {len(p)} points is rejected "
                             "as an outlier")
        use = w > 0
        x, r, q, n, inside, w = x[use], r[use], q[use], n[use], inside[use], w[use]
        centre = np.average(x, axis=0, weights=w)
        y = x - centre
        radius = max(float(np.sqrt(np.average(np.sum(y ** 2, axis=1), weights=w))), 1e-9)
        # rows: inside -> n . (x + w x y + dt - q); on an edge -> the vector (x + w x y + dt - q)
        plane = np.column_stack([np.cross(y, n) / radius, n])[inside]
        ys = y[~inside] / radius
        skew = np.zeros((len(ys), 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = ys[:, 2], -ys[:, 1], ys[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = -ys[:, 2], ys[:, 1], -ys[:, 0]
        edge = np.concatenate([skew, np.broadcast_to(np.eye(3), skew.shape)], axis=2)
        A = np.concatenate([plane, edge.reshape(-1, 6)])
        b = np.concatenate([r[inside], (x - q)[~inside].ravel()])
        wt = np.concatenate([w[inside], np.repeat(w[~inside], 3)])
        M = A.T @ (wt[:, None] * A)
        eig = np.linalg.eigvalsh(M)
        conditioning = float(eig[0] / eig[-1]) if eig[-1] > 0 else 0.0
        step = np.linalg.solve(M + _DAMPING * float(np.max(np.diag(M))) * np.eye(6),
                               -A.T @ (wt * b))
        E = rotation_matrix(step[:3] / radius)
        R, t = E @ R, E @ t + centre - E @ centre + step[3:]
        moved = float(np.max(np.linalg.norm(y @ (E - np.eye(3)).T + step[3:], axis=1)))
        if moved < step_tol_mm and wide <= scale:
            converged = True
            break
    x = p @ R.T + t
    r, *_ = _residuals(x, surface, np.inf)
    inliers = _weights(r, _robust_scale(r, floor_mm)) > 0
    rms = float(np.sqrt(np.mean(r[inliers] ** 2))) if inliers.any() else float("inf")
    return IcpResult(rotation=R, translation=t, residual_mm=r, inliers=inliers, rms_mm=rms,
                     iterations=k, converged=converged, conditioning=conditioning)
