"""The gauge between shape and camera poses, and best-fit comparisons.

A rigid motion of the specimen changes the normal correction by
``n_I . (t + w x (X_I - c))`` and is undone exactly by moving the cameras the other way:
the residual cannot tell them apart (section 2.2). When the poses are calibrated, the
core keeps ``q`` orthogonal to these rigid normal modes (weighted by nodal areas) and
hands the rigid part to the camera extrinsics after each shape solve. On a flat
nominal surface these modes are the uniform offset and the two tilts. The rigid motions
that slide the surface in itself (in-plane translations and rotation of a plate) change
neither q nor the gray levels: the calibration keeps them fixed at their initial (landmark)
value, see :func:`tangential_motions` and :func:`pose_directions`. The shape is
reported also as "distance to best-fit plane", as the paper does.

The nodal weights of these least-squares problems must be non-negative (their square
roots weigh the rows): use :func:`fesdic_core.fe.mesh.nodal_areas`, positive for every
family. The consistent lumping ``L^T w`` of the pixel quadrature is not: the corner
shape functions of a T6 element integrate to zero, and its Riemann sum is slightly
negative at the corners. A negative weight is refused (:func:`checked_weights`).
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["TANGENTIAL_RTOL", "rigid_normal_modes", "checked_weights", "split_rigid_part",
           "normal_motions", "normal_gauge",
           "move_cameras_with_specimen", "transfer_rigid_part", "tangential_motions",
           "pose_directions", "best_fit_plane_distance", "rigid_align"]

#: relative singular value (rotations times the surface radius) below which a rigid motion
#: slides the surface in itself. An exact slide (rotation of a cylinder about its axis) is
#: seen through the FE node normals' error: 3e-4 (R 30 mm), 3e-5 / 7e-6 (R 100 mm, 8 / 16
#: Q9 elements) on a 40 mm wide panel; a genuine mode scales as width / R (0.33, 0.09,
#: 0.009 at R 1000 mm). Exact slides of a plane are ~1e-16.
TANGENTIAL_RTOL = 1e-3


def rigid_normal_modes(nodes: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normal components of the 6 rigid motions at the nodes, (n, 6), and the centre used."""
    centre = nodes.mean(axis=0)
    arm = nodes - centre
    translations = normals                                       # n . e_k
    rotations = np.cross(arm, normals)                           # n . (e_k x arm) = e_k . (arm x n)
    return np.concatenate([translations, rotations], axis=1), centre


def checked_weights(node_weights: np.ndarray, n_nodes: int) -> np.ndarray:
    """``node_weights`` as floats (n,), or ValueError naming the first negative or bad node.

    Zero weights are allowed (a node of no element); negative ones are not: their square
    root would be NaN.
    """
    w = np.asarray(node_weights, dtype=float)
    if w.shape != (n_nodes,):
        raise ValueError(f"node_weights must have shape ({n_nodes},) (one per node), got {w.shape}")
    bad = np.flatnonzero(~np.isfinite(w) | (w < 0.0))
    if bad.size:
        raise ValueError(
            f"node_weights: {bad.size} of {n_nodes} nodal weights are negative or not finite "
            f"(first: node {int(bad[0])}, {w[bad[0]]:.3g} mm^2); the gauge needs positive nodal "
            "areas, e.g. fesdic_core.fe.mesh.nodal_areas (L^T w of the pixel quadrature is <= 0 "
            "at the corners of T6 elements)")
    if not w.sum() > 0.0:
        raise ValueError(f"node_weights: all {n_nodes} nodal weights are zero")
    return w


def split_rigid_part(q: np.ndarray, nodes: np.ndarray, normals: np.ndarray,
                     node_weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted least-squares rigid part of ``q``: returns ``(q_rigid, [t, w], centre)``.

    ``node_weights`` (n,) >= 0, e.g. :func:`fesdic_core.fe.mesh.nodal_areas`.

    The rigid motions that slide the surface in itself (:func:`tangential_motions`, same
    scaling and tolerance) get no part: on a cylinder panel the rotation about its own axis
    is nearly invisible in the normal modes of a Q9 mesh (its FE normals are not exactly
    radial), and a least-squares coefficient along it would move the cameras by tens of
    pixels for nothing.
    """
    modes, centre = rigid_normal_modes(nodes, normals)
    w = checked_weights(node_weights, len(nodes))
    sw = np.sqrt(w)
    radius = float(np.sqrt(np.average(np.sum((nodes - centre) ** 2, axis=1), weights=w)))
    scale = np.r_[np.ones(3), np.full(3, radius)]                # mm and radians * radius
    coef, *_ = np.linalg.lstsq(modes / scale * sw[:, None], q * sw, rcond=TANGENTIAL_RTOL)
    coef = coef / scale
    return modes @ coef, coef, centre


def move_cameras_with_specimen(cameras, translation: np.ndarray, rotation: np.ndarray,
                               centre: np.ndarray) -> list:
    """Cameras that see the specimen moved by ``X -> R(w)(X - c) + c + t`` as before.

    ``x_cam = R_c X' + t_c`` with ``X' = R (X - c) + c + t`` gives the new extrinsics
    ``R_c' = R_c R`` and ``t_c' = R_c (c + t - R c) + t_c``.
    """
    R, _ = cv2.Rodrigues(np.asarray(rotation, dtype=float).reshape(3, 1))
    out = []
    for cam in cameras:
        Rc = cam.R
        new_R = Rc @ R
        new_t = Rc @ (centre + translation - R @ centre) + cam.tvec
        rvec, _ = cv2.Rodrigues(new_R)
        out.append(cam.with_extrinsics(np.concatenate([rvec.ravel(), new_t])))
    return out


def transfer_rigid_part(q: np.ndarray, nodes: np.ndarray, normals: np.ndarray,
                        node_weights: np.ndarray, cameras) -> tuple[np.ndarray, list]:
    """Remove the rigid normal part from ``q`` and give it to the camera poses."""
    q_rigid, coef, centre = split_rigid_part(q, nodes, normals, node_weights)
    return q - q_rigid, move_cameras_with_specimen(cameras, coef[:3], coef[3:], centre)


def tangential_motions(nodes: np.ndarray, normals: np.ndarray, node_weights: np.ndarray,
                       rtol: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rigid motions ``[t, w]`` (6, k) that slide the surface in itself, and the centre.

    They are the (near) null space of the rigid normal modes: no node moves along its
    normal, so the gray levels cannot see them (k = 3 on a plane, 2 on a cylinder).
    """
    rtol = TANGENTIAL_RTOL if rtol is None else rtol
    sv, vt, scale, centre = _rigid_svd(nodes, normals, node_weights)
    return (vt[sv <= rtol * sv.max()] / scale).T, centre


def _rigid_svd(nodes: np.ndarray, normals: np.ndarray, node_weights: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """SVD ``(sv (6,), vt (6, 6))`` of the weighted rigid normal modes, with the scaling of the
    motions (metres and radians on a comparable footing: rotations times the surface radius)
    and the centre they turn about."""
    node_weights = checked_weights(node_weights, len(nodes))
    modes, centre = rigid_normal_modes(nodes, normals)
    radius = float(np.sqrt(np.average(np.sum((nodes - centre) ** 2, axis=1), weights=node_weights)))
    scale = np.r_[np.ones(3), np.full(3, radius)]
    A = modes / scale * np.sqrt(node_weights)[:, None]
    A = np.vstack([A, np.zeros((max(0, 6 - len(A)), 6))])        # at least 6 rows: vt is 6 x 6
    _, sv, vt = np.linalg.svd(A, full_matrices=False)
    return sv, vt, scale, centre


def pose_directions(cameras, motions: np.ndarray, centre: np.ndarray, keep_stereo: bool,
                    step: float = 1e-6) -> np.ndarray:
    """Extrinsic parameter directions (6 or 12, k) produced by rigid specimen motions."""
    columns = []
    for m in motions.T:
        plus = move_cameras_with_specimen(cameras, step * m[:3], step * m[3:], centre)
        minus = move_cameras_with_specimen(cameras, -step * m[:3], -step * m[3:], centre)
        d = np.concatenate([(a.extrinsics - b.extrinsics) / (2 * step) for a, b in zip(plus, minus)])
        columns.append(d[:6] if keep_stereo else d)
    return np.array(columns).T.reshape(6 if keep_stereo else 12, -1)


def normal_motions(nodes: np.ndarray, normals: np.ndarray, node_weights: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motions ``[t, w]`` (6, k_n) that move the nodes along their normals, and the
    centre they turn about: the complement of :func:`tangential_motions` (same scaling and
    tolerance), orthonormal in the ``node_weights`` metric of their normal parts. On a plane
    k_n = 3 (offset, two tilts), on a cylinder 4, on a part of several faces 6.
    """
    sv, vt, scale, centre = _rigid_svd(nodes, normals, node_weights)
    keep = sv > TANGENTIAL_RTOL * sv.max()
    return (vt[keep] / sv[keep, None] / scale).T, centre


def normal_gauge(nodes: np.ndarray, normals: np.ndarray, node_weights: np.ndarray) -> np.ndarray:
    """``N`` (n, k_n): the gauge conditions ``N^T q = 0``: ``q`` keeps no rigid normal part
    (the ``node_weights``-weighted normal parts of :func:`normal_motions`, columns of unit
    norm; the joint Gauss-Newton weighs by the seen area, :func:`fesdic_core.shape.joint.seen_areas`)."""
    motions, _ = normal_motions(nodes, normals, node_weights)
    modes, _ = rigid_normal_modes(nodes, normals)
    N = checked_weights(node_weights, len(nodes))[:, None] * (modes @ motions)
    return N / np.linalg.norm(N, axis=0)


def best_fit_plane_distance(points: np.ndarray) -> np.ndarray:
    """Signed distance of each point to the least-squares plane of all points (mm)."""
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    normal = vt[2]
    if normal[2] < 0:
        normal = -normal
    return centred @ normal


def rigid_align(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best rigid motion (R, t) with ``R source + t ~ target`` in least squares (Kabsch)."""
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    U, _, Vt = np.linalg.svd((source - cs).T @ (target - ct))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, ct - R @ cs
