"""The stereo bundle with the target's points released: a target as printed, not as drawn.

A printed or machined target is not exactly its drawing: its points are off by a few
micrometres and its plate is not quite flat. Seen in many views, these errors repeat from
view to view and read as a model error (the same residual at the same target point in every
view). Here every target point is an unknown too (Strobl and Hirzinger's "object-releasing"
calibration, extended to the stereo bundle): the reprojection error of both cameras over
every view is minimised over both cameras' intrinsics, the stereo relation, the target's pose
in each view and the points' positions: a damped Gauss-Newton on the normal equations, the
Jacobian analytic (:func:`cv2.projectPoints` chained through :func:`cv2.composeRT`).

The points' gauge is a similarity (the target's own position, orientation and size, which
the poses and the focal lengths would otherwise trade with the points), fixed on three points
that every view sees (:func:`gauge_mask`: a dot grid's ring markers, a board's corners): the
first two as drawn (their distance is the drawing's scale), the third's ``z``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np
import scipy.sparse as sp

__all__ = ["BundleResult", "released_bundle", "gauge_mask"]


@dataclass(frozen=True, eq=False)
class BundleResult:
    """The optimum: cameras' ``K`` and ``dist``, ``R, T``, per view ``rvecs, tvecs``, the
    target points (N, 3), the residual vectors per view and camera, the covariance of every
    unknown (intrinsics, stereo, poses, free point coordinates) and the residual's sigma."""

    K: list
    dist: list
    R: np.ndarray
    T: np.ndarray
    rvecs: list
    tvecs: list
    points: np.ndarray
    residuals: tuple
    cov: np.ndarray
    sigma_px: float
    n_intrinsic: int


def _levenberg_marquardt(evaluate, x: np.ndarray, max_iter: int = 50, rtol: float = 1e-10
                         ) -> np.ndarray:
    """Damped Gauss-Newton on the normal equations (a few hundred unknowns: dense solve)."""
    r, J = evaluate(x, True)
    cost, mu = float(r @ r), 1e-3
    for _ in range(max_iter):
        N = (J.T @ J).toarray()
        g = J.T @ r
        d = np.diag(N).copy()
        d[d <= 0] = 1.0
        while True:
            step = np.linalg.solve(N + mu * np.diag(d), -g)
            r_new, _ = evaluate(x + step, False)
            new = float(r_new @ r_new)
            if new < cost:
                break
            mu *= 10.0
            if mu > 1e8:
                return x
        x, gain = x + step, (cost - new) / cost
        mu = max(mu / 10.0, 1e-9)
        r, J = evaluate(x, True)
        cost = float(r @ r)
        if gain < rtol:
            break
    return x


def gauge_mask(n_points: int, anchors: Sequence[int]) -> np.ndarray:
    """(N, 3) bool: the point coordinates that are free, the similarity gauge fixed on the
    three ``anchors`` (points seen in every view: a dot grid's ring markers): the first and
    the second fixed (their distance is the drawing's scale), the third keeps its ``z``."""
    if len(anchors) < 3 or len(set(int(a) for a in anchors[:3])) < 3:
        raise ValueError(f"the target's gauge needs three distinct anchor points, got {anchors!r}")
    free = np.ones((n_points, 3), bool)
    a, b, c = (int(i) for i in anchors[:3])
    free[a] = False
    free[b] = False
    free[c, 2] = False
    return free


def released_bundle(points: np.ndarray, ids: Sequence[np.ndarray], px0: Sequence[np.ndarray],
                    px1: Sequence[np.ndarray], K: Sequence[np.ndarray], dist: Sequence[np.ndarray],
                    R: np.ndarray, T: np.ndarray, rvecs: Sequence[np.ndarray],
                    tvecs: Sequence[np.ndarray], free_intrinsics: np.ndarray, free_points: np.ndarray,
                    tie_aspect: bool = False, refine: bool = True) -> BundleResult:
    """Minimise both cameras' reprojection error over intrinsics, stereo, poses and points.

    Parameters
    ----------
    points : (N, 3) the target's points as drawn (the start).
    ids : per view, (m,) the indices of the points both cameras saw.
    px0, px1 : per view, (m, 2) their pixels in camera 0 and camera 1.
    K, dist, R, T, rvecs, tvecs : the start (OpenCV's stereo calibration).
    free_intrinsics : (9,) bool over fx fy cx cy k1 k2 p1 p2 k3.
    free_points : (N, 3) bool, :func:`gauge_mask`.
    tie_aspect : ``fy / fx`` kept.
    refine : minimise (True), or only linearise at the start (False: the covariance of an
        optimum found elsewhere, e.g. by OpenCV's stereo calibration).
    """
    n_views, fi = len(ids), np.asarray(free_intrinsics, bool)
    ni = int(fi.sum())
    point_index = -np.ones(free_points.shape, int)
    point_index[free_points] = np.arange(int(free_points.sum()))
    n_par = 2 * ni + 6 + 6 * n_views + int(free_points.sum())
    o_stereo, o_views, o_points = 2 * ni, 2 * ni + 6, 2 * ni + 6 + 6 * n_views
    aspect = [K[c][1, 1] / K[c][0, 0] for c in range(2)]

    def intrinsic_vector(c):
        k = K[c]
        return np.r_[k[0, 0], k[1, 1], k[0, 2], k[1, 2], np.asarray(dist[c], float).ravel()[:5]]

    x0 = np.concatenate([intrinsic_vector(0)[fi], intrinsic_vector(1)[fi],
                         cv2.Rodrigues(np.asarray(R, float))[0].ravel(), np.ravel(T),
                         np.concatenate([np.r_[np.ravel(r), np.ravel(t)] for r, t in zip(rvecs, tvecs)]),
                         np.zeros(int(free_points.sum()))])
    base = [intrinsic_vector(c) for c in range(2)]

    def unpack(x):
        cams = []
        for c in range(2):
            v = base[c].copy()
            v[fi] = x[c * ni:(c + 1) * ni]
            if tie_aspect:
                v[1] = aspect[c] * v[0]
            Kc = np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]])
            cams.append((Kc, v[4:9]))
        P = np.asarray(points, float).copy()
        P[free_points] += x[o_points:]
        return cams, x[o_stereo:o_stereo + 3], x[o_stereo + 3:o_stereo + 6], P

    def evaluate(x, jacobian: bool):
        cams, rs, ts, P = unpack(x)
        res, rows, cols, vals, offset = [], [], [], [], 0
        for v in range(n_views):
            rv = x[o_views + 6 * v:o_views + 6 * v + 3].reshape(3, 1)
            tv = x[o_views + 6 * v + 3:o_views + 6 * v + 6].reshape(3, 1)
            X = P[ids[v]]
            composed = cv2.composeRT(rv, tv, rs.reshape(3, 1), ts.reshape(3, 1))
            for c, seen in enumerate((px0[v], px1[v])):
                r_c, t_c = (rv, tv) if c == 0 else composed[:2]
                proj, J = cv2.projectPoints(X.reshape(-1, 1, 3), r_c, t_c, cams[c][0], cams[c][1])
                res.append((proj.reshape(-1, 2) - np.asarray(seen, float).reshape(-1, 2)).ravel())
                if not jacobian:
                    offset += 2 * len(X)
                    continue
                m = 2 * len(X)
                row = offset + np.arange(m)
                Jr, Jt, Jint = J[:, 0:3], J[:, 3:6], J[:, 6:15].copy()
                if tie_aspect:
                    Jint[:, 0] += Jint[:, 1] * aspect[c]
                blocks = [(Jint[:, fi], c * ni)]
                if c == 0:
                    blocks.append((np.hstack([Jr, Jt]), o_views + 6 * v))
                else:
                    _, _, dr3dr1, dr3dt1, dr3dr2, dr3dt2, dt3dr1, dt3dt1, dt3dr2, dt3dt2 = composed
                    blocks.append((np.hstack([Jr @ dr3dr1 + Jt @ dt3dr1, Jr @ dr3dt1 + Jt @ dt3dt1]),
                                   o_views + 6 * v))
                    blocks.append((np.hstack([Jr @ dr3dr2 + Jt @ dt3dr2, Jr @ dr3dt2 + Jt @ dt3dt2]),
                                   o_stereo))
                for block, start in blocks:
                    rr, cc = np.meshgrid(row, start + np.arange(block.shape[1]), indexing="ij")
                    rows.append(rr.ravel())
                    cols.append(cc.ravel())
                    vals.append(block.ravel())
                # d proj / d X = d proj / d t  R   (x_cam = R X + t)
                Rc = cv2.Rodrigues(r_c)[0]
                dX = (Jt.reshape(len(X), 2, 3) @ Rc)                  # (m/2, 2, 3)
                pi = point_index[ids[v]]                              # (m/2, 3)
                ok = pi >= 0
                pt, ax = np.nonzero(ok)
                for comp in range(2):
                    rows.append(offset + 2 * pt + comp)
                    cols.append(o_points + pi[pt, ax])
                    vals.append(dX[pt, comp, ax])
                offset += m
        r = np.concatenate(res)
        if not jacobian:
            return r, None
        Jm = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(len(r), n_par))
        return r, Jm

    x = _levenberg_marquardt(evaluate, x0) if refine else x0
    r, Jm = evaluate(x, True)
    dof = len(r) - n_par
    sigma2 = float(r @ r) / dof
    N = (Jm.T @ Jm).toarray()
    cov = sigma2 * np.linalg.pinv(N)
    cams, rs, ts, P = unpack(x)
    residuals, offset = [], 0
    for v in range(n_views):
        m = 2 * len(ids[v])
        residuals.append((-r[offset:offset + m].reshape(-1, 2), -r[offset + m:offset + 2 * m].reshape(-1, 2)))
        offset += 2 * m
    rvecs_out = [x[o_views + 6 * v:o_views + 6 * v + 3] for v in range(n_views)]
    tvecs_out = [x[o_views + 6 * v + 3:o_views + 6 * v + 6] for v in range(n_views)]
    return BundleResult(K=[c[0] for c in cams], dist=[c[1] for c in cams],
                        R=cv2.Rodrigues(rs.reshape(3, 1))[0], T=ts.copy(), rvecs=rvecs_out,
                        tvecs=tvecs_out, points=P, residuals=tuple(residuals), cov=cov,
                        sigma_px=float(np.sqrt(sigma2)), n_intrinsic=ni)
