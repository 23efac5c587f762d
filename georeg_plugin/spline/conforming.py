"""Faces that meet along an edge made to share their knots there (knot insertion, Eq. 13).

Two CAD faces that meet along an edge rarely split it alike: a box's side face runs the
whole length of the box while the face beside it stops where a fillet begins; a CAD writer
gives each face its own knot spans. Meshed one element per knot span (Eq. 17) and refined
alike, their edge nodes then do not coincide (:class:`~georeg_plugin.levels.multipatch.NonConformingFacesError`)
and their control points are not glued.

The coupling used here is the common refinement: every knot of one face's edge (and every
end of that edge) that lies inside the other face's edge, with a span of the edge next to it
running along the other's edge too (a shared stretch; a point where two edges merely touch,
such as a rim circle tangent to a square plate's edge, adds nothing), is inserted into the
other face, in the direction along that edge, with the continuity the source has there, in
the target's degree: C0 at an end (multiplicity ``p``: the edge curve splits there into
separate pieces, one per neighbour), ``C^(p_s - m)`` at a knot of multiplicity ``m``. Knot
insertion leaves each surface exactly as it was (Eq. 15); afterwards the
shared stretch of edge has the same knots on both faces, so a common dyadic refinement keeps
it so, the FE nodes along it coincide and so do the control points wherever the two faces
parameterize the edge alike (affinely: the straight edges of planes, cylinders, cones, and
arcs written with the same weights), which :func:`~georeg_plugin.levels.curved.vector_gluing` then
glues into one vector. Where the two parameterizations differ more than affinely the edge's
knots still match but its mid-span nodes do not, and the part's mesh refuses the pair, naming
it, as before.

Only a face's own boundary (the edges of its parameter box) is matched: a face whose edge
lies inside another face (a feature standing on a trimmed plate) meets that face along its
trimming loop, where the mesh of the trimmed face ends in a staircase and is not welded
(:mod:`georeg_plugin.spline.trimmed`).
"""
from __future__ import annotations

import logging
from typing import Sequence

import numpy as np

from georeg_plugin.spline.patch import SplinePatch, invert_points
from georeg_plugin.spline.refine import insert_knots

logger = logging.getLogger(__name__)

__all__ = ["conforming_faces"]

#: passes of the common refinement at most (a knot inserted into one face can reach a third
#: face through that face's opposite edge)
MAX_PASSES = 20


def _edges(patch: SplinePatch) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per edge of the parameter box: ``(uv, continuity, mid)``: its breakpoints, ends
    included, with the order ``k`` of the basis's continuity there (``C^k``: ``p - m`` for a
    knot of multiplicity ``m``; 0 at the ends: where the edge stops, a neighbour's must split
    into separate pieces), and the midpoints of its spans."""
    out = []
    for d in (0, 1):                                   # the direction along the edge
        knots, p = patch.knots[d], patch.degrees[d]
        values, counts = np.unique(knots, return_counts=True)
        counts = p - np.minimum(counts, p)             # the continuity C^k at each breakpoint
        mids = 0.5 * (values[:-1] + values[1:])
        lo, hi = patch.knots[1 - d][0], patch.knots[1 - d][-1]
        for fixed in (lo, hi):
            uv, mid = np.empty((values.size, 2)), np.empty((mids.size, 2))
            uv[:, d], uv[:, 1 - d] = values, fixed
            mid[:, d], mid[:, 1 - d] = mids, fixed
            out.append((uv, counts, mid))
    return out


def _missing(knots: np.ndarray, value: float, multiplicity: int, tol: float) -> int:
    """How many times ``value`` must be inserted to reach ``multiplicity`` (0 at the ends)."""
    if value <= knots[0] + tol or value >= knots[-1] - tol:
        return 0
    have = int(np.count_nonzero(np.abs(knots - value) <= tol))
    return max(0, multiplicity - have)


def _snap(knots: np.ndarray, value: float, tol: float) -> float:
    """``value``, or the knot it lies within ``tol`` of (so that repeated knots are equal)."""
    near = np.abs(knots - value) <= tol
    return float(knots[near][0]) if near.any() else float(value)


def _on_box_edge(target: SplinePatch, points: np.ndarray, distance_tol: float,
                 param_rtol: float) -> tuple[np.ndarray, np.ndarray]:
    """``(edge, uv)``: for each point, which edge of ``target``'s parameter box it lies on
    (0, 1: u = lo, hi; 2, 3: v = lo, hi; -1: off the surface, inside it, or at a corner)."""
    uv, distance = invert_points(target, points)
    lo = np.array([target.knots[0][0], target.knots[1][0]])
    hi = np.array([target.knots[0][-1], target.knots[1][-1]])
    tol = param_rtol * (hi - lo)
    at = np.stack([np.abs(uv[:, 0] - lo[0]) <= tol[0], np.abs(uv[:, 0] - hi[0]) <= tol[0],
                   np.abs(uv[:, 1] - lo[1]) <= tol[1], np.abs(uv[:, 1] - hi[1]) <= tol[1]], axis=1)
    edge = np.where(at.sum(axis=1) == 1, np.argmax(at, axis=1), -1)
    edge[distance > distance_tol] = -1
    return edge, uv


def _insertions(target: SplinePatch, edges: list, source: SplinePatch, distance_tol: float,
                param_rtol: float) -> tuple[list, list]:
    """Knots to insert into ``target`` (per direction) where a stretch of one of ``source``'s
    ``edges`` runs along an edge of ``target``'s parameter box: a breakpoint of the source's
    edge on the target's edge, with a span next to it on the same edge (its midpoint there).
    A point where the two merely touch (a circle tangent to a square) adds nothing."""
    new: tuple[list[float], list[float]] = ([], [])       # knots to insert in u, in v
    lo = np.array([target.knots[0][0], target.knots[1][0]])
    hi = np.array([target.knots[0][-1], target.knots[1][-1]])
    tol = param_rtol * (hi - lo)
    for uv, counts, mid in edges:
        at, t_uv = _on_box_edge(target, source.evaluate(uv), distance_tol, param_rtol)
        mid_at, _ = _on_box_edge(target, source.evaluate(mid), distance_tol, param_rtol)
        for i, (e, k) in enumerate(zip(at, counts)):
            shared = [mid_at[j] == e for j in (i - 1, i) if 0 <= j < mid.shape[0]]
            if e < 0 or not any(shared):
                continue
            d = 1 if e < 2 else 0                      # on a u-edge the edge runs along v
            x = _snap(target.knots[d], t_uv[i, d], tol[d])
            m = max(1, target.degrees[d] - int(k))     # the same continuity in the target
            count = _missing(target.knots[d], x, m, tol[d]) - new[d].count(x)
            new[d].extend([x] * max(count, 0))
    return new


def conforming_faces(faces: Sequence[SplinePatch], names: Sequence[str] | None = None,
                     rtol: float = 1e-7, param_rtol: float = 1e-6) -> list[SplinePatch]:
    """The faces with knots inserted so that faces meeting along an edge split it alike.

    Parameters
    ----------
    faces : the part's faces (each surface stays the same, Eq. 15). The edges of a trimmed
        face's parameter box count as any face's (it can meet its neighbours along them);
        its trimming loops, in (u, v), stay valid.
    names : for the log.
    rtol : a point lies on a face when closer than ``rtol`` times the part's size.
    param_rtol : a parameter is on the box's boundary (or on a knot) within this fraction
        of the parameter range.

    Returns
    -------
    list of SplinePatch : the same surfaces; every stretch of edge two faces share has the
    same breakpoints on both.
    """
    faces = list(faces)
    names = list(names) if names is not None else [f"face {k}" for k in range(len(faces))]
    size = float(np.ptp(np.vstack([f.control_points.reshape(-1, 3) for f in faces]), axis=0).max())
    distance_tol = rtol * (size or 1.0)
    for _ in range(MAX_PASSES):
        changed = False
        for b, source in enumerate(faces):
            edges = _edges(source)
            points = np.vstack([source.evaluate(uv) for uv, _, _ in edges])
            for a, target in enumerate(faces):
                if a == b:
                    continue
                box = target.control_points.reshape(-1, 3)      # convex hull: quick rejection
                if not np.any(np.all((points >= box.min(0) - distance_tol)
                                     & (points <= box.max(0) + distance_tol), axis=1)):
                    continue
                new_u, new_v = _insertions(target, edges, source, distance_tol, param_rtol)
                if new_u or new_v:
                    faces[a] = insert_knots(target, sorted(new_u), sorted(new_v))[0]
                    logger.info("%s: knots %s (u), %s (v) inserted where %s's edge meets it",
                                names[a], np.round(sorted(new_u), 6).tolist(),
                                np.round(sorted(new_v), 6).tolist(), names[b])
                    changed = True
        if not changed:
            return faces
    raise RuntimeError(f"conforming_faces: the common refinement did not settle in "
                       f"{MAX_PASSES} passes")
