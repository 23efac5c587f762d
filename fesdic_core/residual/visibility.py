"""Visibility of the integration points: self-occlusion and the grazing-angle cut-off.

Gray-level conservation (Eq. 3) holds only where both cameras see the material point: a
point hidden behind another part of the surface (or behind a fixture) from one camera, or
seen so obliquely that a pixel spreads over several speckles, would pull the shape toward
whatever that camera images there. Such points are masked, not fitted. Both tests run on
the *current* surface (nodes moved by ``q``, Remark 1), once per image scale, so that they
follow the shape as it is measured.

Self-occlusion: the point ``X`` is hidden from the camera of centre ``C`` when the segment
``[X, C]`` crosses a triangle of the occluder soup: the current mesh's surface (each element
split into flat triangles through its nodes, :func:`surface_triangles`) plus optional extra
triangles (e.g. the CAD faces that are not measured). The triangles of the point's own
element are left out, and a hit closer to ``X`` than the tolerance (measured along the ray)
is ignored, so that a point is not hidden by its neighbourhood: the triangles through the
nodes deviate from the curved elements by their chord error, and a ray leaving a point at an
angle ``theta`` from the normal meets them within ``chord / cos(theta)``. The default tolerance is a quarter of the median
edge of the mesh's triangles (:data:`TOLERANCE_FRACTION`), far above that chord error for
any element that resolves its surface, and scaled with the mesh; its cost is a band of
``tolerance * sin(angle)`` at the foot of a wall (a concave corner) where points are called
seen although the wall hides them.

The test is exact for the flat triangles (no rasterisation): in the camera frame the ray
through ``X`` has the pinhole coordinates ``u = (x / z, y / z)``; a triangle covers the ray
when ``u`` lies inside its projected triangle (barycentric coordinates), and its depth there
is ``1 / w(u)`` with ``w = 1 / z`` affine in ``u`` over a plane. Candidate (point, triangle)
pairs come from a coarse grid on ``u`` (each triangle binned into the cells of its bounding
box; each point tested against its cell's triangles). With ``trimesh`` and ``embreex``
installed, ``engine="embree"`` casts the same rays with Intel's Embree instead (single
precision; the numpy path is always available and tested equal away from triangle edges).

Grazing angle: a point whose unit normal (from the current mesh's shape functions at the
point) makes more than ``max_view_angle_deg`` with the direction to a camera is dropped.
The normal's sign is not used (an open surface has no outside); a back face of a closed
part is hidden by the self-occlusion test.
"""
from __future__ import annotations

import logging
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from fesdic_core.fe.mesh import SurfaceMesh
from fesdic_core.fe.quadrature import PixelQuadrature, _reference_rule

logger = logging.getLogger(__name__)

__all__ = ["VisibilitySettings", "DEFAULT_MAX_VIEW_ANGLE_DEG", "TOLERANCE_FRACTION",
           "DEFAULT_MARGIN_PX", "surface_triangles", "point_normals", "occluded", "grazing", "visibility_mask",
           "embree_available", "median_edge_mm"]

#: default grazing-angle cut-off (deg), measured (``benchmarks/bench_visibility.py
#: --view-angles``: a plate tilted toward one camera, FE): RMS shape error 13, 22, 49 um with
#: the larger view angle in 50-55, 60-65, 65-70 deg, then 143, 266, 5653 um in 70-75, 75-80,
#: 80-85 deg (a 4 px speckle shrinks to 4 cos(angle) px); the cut-off drops the latter
DEFAULT_MAX_VIEW_ANGLE_DEG = 70.0
#: default tolerance of the self-occlusion test, as a fraction of the median edge of the
#: mesh's triangles (see the module docstring)
TOLERANCE_FRACTION = 0.25
#: default margin (px of the current scale) around an occluder's image: the measured choice
#: of docs/validation/visibility.md (a bar in front of a plate: 1 px brings FE back to its error
#: without the bar; 0 px leaves 2.4 times that error, 2 px takes data from the nodes)
DEFAULT_MARGIN_PX = 1.0
#: barycentric slack: a ray through the shared edge of two occluders is caught by both
_INSIDE_EPS = 1e-9
#: points per block of the candidate pairs (bounds the temporaries to ~100 MB)
_BLOCK = 1 << 16

# each element family split into flat triangles through its nodes (gmsh local numbering)
_SPLITS = {
    "T3": [[0, 1, 2]],
    "Q4": [[0, 1, 2], [0, 2, 3]],
    "T6": [[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]],
    "Q9": [[0, 4, 8], [0, 8, 7], [4, 1, 5], [4, 5, 8], [8, 5, 2], [8, 2, 6], [7, 8, 6], [7, 6, 3]],
}


@dataclass(frozen=True, eq=False)
class VisibilitySettings:
    """Which points the cameras see (see the module docstring).

    self_occlusion : mask the points hidden by the surface itself (and ``extra_occluders``).
    max_view_angle_deg : mask the points seen at more than this angle from their normal by
        either camera; None: no cut-off.
    extra_occluders : (m, 3, 3) triangles (mm, world frame) that hide points too but are not
        measured (fixtures, the CAD faces left out); used when ``self_occlusion`` is on.
    tolerance_fraction : hits closer to the point than this fraction of the median edge of
        the mesh's triangles are ignored (the point's own element).
    margin_px : a point whose ray passes within this many pixels (of the camera given, i.e.
        of the current image scale) of an occluder in front of it is hidden too: the image
        model spreads an occluding edge over about a pixel (docs/validation/visibility.md).
    engine : "numpy", "embree" (needs ``trimesh`` and ``embreex``; exact triangles, so only
        with ``margin_px = 0``) or "auto" (embree when installed and the margin is 0).
    """

    self_occlusion: bool = True
    max_view_angle_deg: float | None = DEFAULT_MAX_VIEW_ANGLE_DEG
    extra_occluders: np.ndarray | None = None
    tolerance_fraction: float = TOLERANCE_FRACTION
    margin_px: float = DEFAULT_MARGIN_PX
    engine: str = "numpy"

    def __post_init__(self):
        a = self.max_view_angle_deg
        if a is not None and not (isinstance(a, (int, float)) and 0.0 < a <= 90.0):
            raise ValueError(f"max_view_angle_deg must be in (0, 90] or None, got {a!r}")
        if not (self.tolerance_fraction >= 0.0):
            raise ValueError(f"tolerance_fraction must be >= 0, got {self.tolerance_fraction!r}")
        if self.engine not in ("numpy", "embree", "auto"):
            raise ValueError(f"engine must be 'numpy', 'embree' or 'auto', got {self.engine!r}")
        if not (self.margin_px >= 0.0):
            raise ValueError(f"margin_px must be >= 0, got {self.margin_px!r}")
        if self.engine == "embree" and not embree_available():
            raise ValueError("engine 'embree' needs the packages trimesh and embreex")
        if self.engine == "embree" and self.margin_px > 0:
            raise ValueError("engine 'embree' tests the exact triangles: it needs margin_px = 0, "
                             f"got {self.margin_px!r}")
        if self.extra_occluders is not None:
            T = np.array(self.extra_occluders, dtype=np.float64)
            if T.ndim != 3 or T.shape[1:] != (3, 3) or not np.all(np.isfinite(T)):
                raise ValueError(f"extra_occluders must be finite triangles (m, 3, 3) in mm, got "
                                 f"shape {T.shape}")
            T.setflags(write=False)
            object.__setattr__(self, "extra_occluders", T)

    @property
    def active(self) -> bool:
        return self.self_occlusion or self.max_view_angle_deg is not None


def embree_available() -> bool:
    """True when ``trimesh`` with its Embree ray engine (``embreex``) is importable."""
    try:
        from trimesh.ray import ray_pyembree  # noqa: F401
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


def surface_triangles(mesh: SurfaceMesh, nodes: np.ndarray | None = None) -> np.ndarray:
    """(m, 3, 3) flat triangles through the nodes of every element (Q9: 8, Q4: 2, T6: 4)."""
    X = mesh.nodes if nodes is None else np.asarray(nodes, float)
    tris = [X[block.connectivity[:, _SPLITS[block.family.name]]].reshape(-1, 3, 3)
            for block in mesh.blocks]
    return np.concatenate(tris)


def _triangle_elements(mesh: SurfaceMesh) -> np.ndarray:
    """(m,) the element (global index, blocks concatenated) of each of
    :func:`surface_triangles`."""
    offsets = np.cumsum([0] + [b.n_elements for b in mesh.blocks])
    return np.concatenate([np.repeat(np.arange(b.n_elements) + o, len(_SPLITS[b.family.name]))
                           for b, o in zip(mesh.blocks, offsets)])


def point_normals(mesh: SurfaceMesh, quad: PixelQuadrature, nodes: np.ndarray) -> np.ndarray:
    """(g, 3) unit normals ``X,xi x X,eta / |.|`` of the current surface (nodes (n, 3)) at the
    integration points."""
    nodes = np.asarray(nodes, float)
    offsets = np.cumsum([0] + [b.n_elements for b in mesh.blocks])
    out = np.empty((quad.n_points, 3))
    for group in quad.groups:
        block = mesh.blocks[int(np.searchsorted(offsets, group.elements[0], "right")) - 1]
        m = group.points_per_element
        xi = quad.xi[group.start:group.start + m]
        if block.family.reference == "quad":                     # the sub-cell grid (n0, n1)
            n0 = len(np.unique(xi[:, 0]))
            n1 = m // n0
        else:
            n0 = n1 = int(round(np.sqrt(m)))
        dN = _reference_rule(block.family, n0, n1)[3]            # (m, nn, 2), cached
        if dN.shape[0] != m or not np.array_equal(_reference_rule(block.family, n0, n1)[0], xi):
            dN = block.family.shape_derivatives(xi)
        E, nn = group.connectivity.shape
        Xe = nodes[group.connectivity].transpose(1, 0, 2).reshape(nn, 3 * E)   # (nn, E * 3)
        a = (dN[..., 0] @ Xe).reshape(m, E, 3)                  # X,xi (m, E, 3): one product
        b = (dN[..., 1] @ Xe).reshape(m, E, 3)                  # X,eta
        n = out[group.span].reshape(E, m, 3)                   # a view: written into out
        n[..., 0] = (a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]).T
        n[..., 1] = (a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]).T
        n[..., 2] = (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]).T
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)


def grazing(X: np.ndarray, normals: np.ndarray, camera, max_view_angle_deg: float) -> np.ndarray:
    """(g,) bool: the points seen by ``camera`` at more than ``max_view_angle_deg`` from their
    (unsigned) normal."""
    d = np.asarray(camera.center, float) - X
    cos = np.abs(np.einsum("ij,ij->i", normals, d)) / np.linalg.norm(d, axis=1)
    return cos < np.cos(np.radians(max_view_angle_deg)) - 1e-12


def occluded(X: np.ndarray, camera, triangles: np.ndarray, tolerance_mm: float,
             engine: str = "numpy", margin_px: float = 0.0,
             owners: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(g,) bool: the segment from ``X`` (g, 3) to the centre of ``camera`` crosses one of
    ``triangles`` (m, 3, 3) farther than ``tolerance_mm`` from ``X`` (along the segment), or
    passes within ``margin_px`` pixels (in the camera's image) of such a triangle.

    Triangles with a vertex at or behind the camera's plane are left out. ``engine``:
    "numpy" (exact for the flat triangles, double precision), "embree" (margin 0 only), or
    "auto" (embree when installed, the margin is 0 and no ``owners``). ``owners``: the
    element of each point (g,) and of each triangle (m,) (-1: none); a point is not hidden
    by the triangles of its own element (numpy engine only).
    """
    X = np.asarray(X, float)
    T = np.asarray(triangles, float).reshape(-1, 3, 3)
    if len(X) == 0 or len(T) == 0:
        return np.zeros(len(X), bool)
    if engine == "embree" and margin_px > 0:
        raise ValueError(f"engine 'embree' needs margin_px = 0, got {margin_px!r}")
    if engine == "embree" or (engine == "auto" and margin_px == 0 and owners is None
                              and embree_available()):
        return _occluded_embree(X, np.asarray(camera.center, float), T, tolerance_mm)
    P = _to_camera(camera, X)
    Tc = _to_camera(camera, T.reshape(-1, 3)).reshape(-1, 3, 3)
    K = np.asarray(camera.K, float)
    return _occluded_numpy(P, Tc, tolerance_mm, margin_px / min(K[0, 0], K[1, 1]), owners)


def _to_camera(camera, X: np.ndarray) -> np.ndarray:
    """``camera.to_camera(X)`` (``R X + t``) by einsum: the (n, 3) @ (3, 3) matmul took 7 times
    longer on the shared 2-core machine (0.45 s against 0.06 s for 0.8 M points)."""
    return np.einsum("ij,kj->ik", X, camera.R) + np.asarray(camera.tvec, float)


def _occluded_embree(X, centre, T, tolerance_mm) -> np.ndarray:
    """The first hit from the camera centre toward each point, by Embree (trimesh)."""
    import trimesh
    from trimesh.ray.ray_pyembree import RayMeshIntersector
    soup = trimesh.Trimesh(vertices=T.reshape(-1, 3), faces=np.arange(3 * len(T)).reshape(-1, 3),
                           process=False, validate=False)
    d = X - centre
    dist = np.linalg.norm(d, axis=1)
    loc, rays, _ = RayMeshIntersector(soup).intersects_location(
        np.broadcast_to(centre, X.shape), d / dist[:, None], multiple_hits=False)
    out = np.zeros(len(X), bool)
    first = np.linalg.norm(loc - centre, axis=1)
    out[rays] = first < dist[rays] - tolerance_mm
    return out


def _triangle_planes(Tc: np.ndarray, z_eps: float, margin: float):
    """Affine coefficients (m, 9) in ``(u, v, 1)`` of the barycentric coordinates l1, l2 and
    of ``w = 1/z`` of the triangles Tc (camera frame), then the slacks (m, 3) of l1 >= 0,
    l2 >= 0 and l1 + l2 <= 1 that move each edge out by ``margin`` (in u), their bounding
    boxes in u grown by the margin (m, 2, 2), their nearest depth, and which triangles are
    usable (in front of the camera, not seen edge-on)."""
    z = Tc[..., 2]
    usable = np.all(z > z_eps, axis=1)
    Tc, z = Tc[usable], z[usable]
    u = Tc[..., :2] / z[..., None]                                    # (m, 3, 2)
    e1, e2, u0 = u[:, 1] - u[:, 0], u[:, 2] - u[:, 0], u[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    scale = np.maximum(np.abs(e1).max(1), np.abs(e2).max(1)) ** 2
    flat = np.abs(det) > 1e-12 * scale                               # not edge-on
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = np.stack([e2[:, 1], -e2[:, 0], e2[:, 0] * u0[:, 1] - e2[:, 1] * u0[:, 0]], 1) / det[:, None]
        l2 = np.stack([-e1[:, 1], e1[:, 0], e1[:, 1] * u0[:, 0] - e1[:, 0] * u0[:, 1]], 1) / det[:, None]
    w = 1.0 / z
    coef = np.concatenate([l1, l2, w[:, :1] * np.array([0.0, 0.0, 1.0])
                           + (w[:, 1:2] - w[:, :1]) * l1 + (w[:, 2:3] - w[:, :1]) * l2], 1)
    with np.errstate(divide="ignore", invalid="ignore"):     # edge lengths over twice the area
        slack = margin * np.stack([np.linalg.norm(e2, axis=1), np.linalg.norm(e1, axis=1),
                                   np.linalg.norm(e2 - e1, axis=1)], 1) / np.abs(det)[:, None]
    coef = np.concatenate([coef, slack + _INSIDE_EPS], 1)
    box = np.stack([u.min(1) - margin, u.max(1) + margin], 1)
    keep = np.flatnonzero(usable)[flat]
    return coef[flat], box[flat], z[flat].min(1), keep


def _occluded_numpy(P: np.ndarray, Tc: np.ndarray, tolerance_mm: float,
                    margin: float = 0.0,
                    owners: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Exact segment-triangle test in the camera frame (triangles grown by ``margin`` in u;
    a grown corner is cut at the grown bounding box), candidates from a grid on u."""
    depth = P[:, 2]
    out = np.zeros(len(P), bool)
    front = depth > 0
    if not np.any(front):
        return out
    z_eps = 1e-9 * float(np.max(depth))
    coef, box, zmin, usable = _triangle_planes(Tc, z_eps, margin)
    point_owner, tri_owner = (None, None) if owners is None else owners
    if tri_owner is not None:
        tri_owner = np.asarray(tri_owner)[usable]
    u = P[:, :2] / np.where(front, depth, 1.0)[:, None]
    reach = depth - tolerance_mm / np.sqrt(1.0 + np.einsum("ij,ij->i", u, u))  # depth of the hits
    lo, hi = u[front].min(0), u[front].max(0)                                   # that count
    inside = np.all((box[:, 1] >= lo) & (box[:, 0] <= hi), axis=1) & (zmin < reach[front].max())
    coef, box, zmin = coef[inside], box[inside], zmin[inside]
    if tri_owner is not None:
        tri_owner = tri_owner[inside]
    if len(coef) == 0:
        return out
    # the grid: cells of half the median triangle's size, at most ~4 cells per point
    extent = np.median(np.max(box[:, 1] - box[:, 0], axis=1))
    span = np.maximum(hi - lo, 1e-12)
    cell = max(0.5 * float(extent), float(np.sqrt(span[0] * span[1] / (4.0 * len(P) + 16))), 1e-15)
    n = np.minimum(np.floor(span / cell).astype(np.int64) + 1, 1 << 12)
    size = span / n
    c0 = np.clip(np.floor((box[:, 0] - lo) / size), 0, n - 1).astype(np.int64)   # (m, 2)
    c1 = np.clip(np.floor((box[:, 1] - lo) / size), 0, n - 1).astype(np.int64)
    nx = c1[:, 0] - c0[:, 0] + 1
    count = nx * (c1[:, 1] - c0[:, 1] + 1)
    tri = np.repeat(np.arange(len(coef)), count)
    k = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    cells = (c0[tri, 1] + k // nx[tri]) * n[0] + c0[tri, 0] + k % nx[tri]
    # the nearest depth of each (triangle, cell) pair: the triangle's plane over the cell's
    # rectangle (w = 1/z is affine: largest at a corner), and not nearer than its vertices
    ix, iy = cells % n[0], cells // n[0]
    ux = lo[0] + size[0] * np.stack([ix, ix + 1], 1)
    vy = lo[1] + size[1] * np.stack([iy, iy + 1], 1)
    c = coef[tri]
    w_max = (c[:, 8] + np.max(c[:, 6:7] * ux, axis=1) + np.max(c[:, 7:8] * vy, axis=1))
    with np.errstate(divide="ignore"):
        near = np.maximum(zmin[tri], np.where(w_max > 0, 1.0 / w_max, 0.0))
    # pairs sorted by cell, then by nearest depth: a point tests the first pairs of its cell,
    # those nearer than its reach (key: cell + depth / z_scale, depth / z_scale in [0, 1))
    z_scale = 2.0 * float(max(near.max(), reach.max()))
    key = cells + near / z_scale
    order = np.argsort(key)
    tri, key = tri[order], key[order]
    per_cell = np.bincount(cells, minlength=int(n[0] * n[1]))
    first = np.cumsum(per_cell) - per_cell
    ip = np.clip(np.floor((u - lo) / size), 0, n - 1).astype(np.int64)
    pcell = ip[:, 1] * n[0] + ip[:, 0]
    n_near = np.searchsorted(key, pcell + np.clip(reach, 0.0, None) / z_scale) - first[pcell]
    todo = np.flatnonzero(front & (n_near > 0))
    if todo.size == 0:
        return out

    def block(rows: np.ndarray) -> None:
        cnt = n_near[rows]
        pid = np.repeat(rows, cnt)
        k = np.arange(len(pid)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        t = tri[first[pcell[pid]] + k]
        c = coef[t]                                                             # (p, 12)
        uu, vv = u[pid, 0], u[pid, 1]
        l1 = c[:, 0] * uu + c[:, 1] * vv + c[:, 2]
        l2 = c[:, 3] * uu + c[:, 4] * vv + c[:, 5]
        w = c[:, 6] * uu + c[:, 7] * vv + c[:, 8]
        hit = ((l1 >= -c[:, 9]) & (l2 >= -c[:, 10]) & (l1 + l2 <= 1.0 + c[:, 11])
               & (w * reach[pid] > 1.0))                          # 1/w < reach: nearer than X
        if tri_owner is not None and point_owner is not None:     # not by its own element
            hit &= tri_owner[t] != point_owner[pid]
        if margin > 0:                                            # the grown corners: cut
            b = box[t]
            hit &= ((uu >= b[:, 0, 0]) & (uu <= b[:, 1, 0]) & (vv >= b[:, 0, 1])
                    & (vv <= b[:, 1, 1]))
        out[pid[hit]] = True

    blocks = [todo[i:i + _BLOCK] for i in range(0, len(todo), _BLOCK)]
    workers = min(len(blocks), os.cpu_count() or 1)
    if workers > 1:
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(block, blocks))
    else:
        for rows in blocks:
            block(rows)
    return out


def median_edge_mm(triangles: np.ndarray) -> float:
    """Median edge length (mm) of triangles (m, 3, 3)."""
    e = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2)
    return float(np.median(e))


def visibility_mask(mesh: SurfaceMesh, quad: PixelQuadrature, nodes: np.ndarray,
                    cameras: Sequence, settings: VisibilitySettings = VisibilitySettings(),
                    X: np.ndarray | None = None) -> np.ndarray:
    """(g,) bool: the integration points of ``quad`` that every camera sees on the current
    surface (``nodes`` (n, 3), mm; ``X``: the points, default ``quad.points(nodes)``).

    A point is kept when, for each camera, it is not hidden (self-occlusion by the current
    mesh and ``settings.extra_occluders``) and not seen beyond the grazing angle.
    """
    nodes = np.asarray(nodes, float)
    X = quad.points(nodes) if X is None else X
    keep = np.ones(len(X), bool)
    if settings.max_view_angle_deg is not None:
        normals = point_normals(mesh, quad, nodes)
        for cam in cameras:
            steep = grazing(X, normals, cam, settings.max_view_angle_deg)
            logger.debug("%d of %d points beyond %g deg from %s", steep.sum(), len(X),
                         settings.max_view_angle_deg, getattr(cam, "name", "a camera"))
            keep &= ~steep
    if settings.self_occlusion:
        own = surface_triangles(mesh, nodes)
        tol = settings.tolerance_fraction * median_edge_mm(own)
        soup = own if settings.extra_occluders is None else np.concatenate(
            [own, settings.extra_occluders])
        tri_owner = np.concatenate([_triangle_elements(mesh), np.full(len(soup) - len(own), -1)])
        for cam in cameras:
            hidden = np.zeros(len(X), bool)
            owners = None if settings.engine == "embree" else (quad.element[keep], tri_owner)
            hidden[keep] = occluded(X[keep], cam, soup, tol, settings.engine, settings.margin_px,
                                    owners)
            logger.debug("%d of %d points hidden from %s", hidden.sum(), len(X),
                         getattr(cam, "name", "a camera"))
            keep &= ~hidden
    return keep
