"""Spline levels on any outline: a level restricted to the dofs that the data sees.

A spline level's bounding patch is usually larger than the specimen (a D- or L-shaped
outline, a cut-out, a hole that is not in the nominal patch, a region the images mask).
Its dofs then fall in three groups, per level ``s`` and Gauss-Newton operator ``H``:

* **unseen on the mesh**: row ``J`` of ``C_s`` is zero, i.e. ``R_J`` vanishes at every FE
  node. For a mesh made from the spline (Eq. 16, Q9 of degree-2 splines) this is exactly
  "the support of ``R_J`` meets no element"; it is unseen whatever the images are.
* **unseen in the images**: row ``J`` is not zero, but the diagonal term
  ``(C_s H C_s^T)_JJ`` is (relative to the largest one, :data:`ZERO_PIVOT`): no integration
  point with a nonzero weight sees ``R_J`` (masked, hidden, beyond the grazing cut-off).
  ``H`` is positive semi-definite, so a zero diagonal means ``H C_s^T e_J = 0``.
* **seen**: the others.

Both unseen groups are removed from the level (by default, ``hold_unseen``): the step is solved in the span of the seen
rows and the removed dofs keep their value. Removing zero rows of ``C_s`` leaves the range of
``C_s^T`` unchanged, so the restricted levels stay nested exactly (Eq. 13):
``C_{s+1}[kept] = C_r[kept, kept'] C_s[kept']``, the dropped fine rows being zero. Removing
the dofs unseen in the images keeps the levels nested on the data (on every integration
point that sees anything, the dropped functions vanish).

**Slivers.** A dof whose support holds only a sliver of the integration points (the outline
clips the corner of its support) is seen but weakly: its diagonal term is a tiny fraction
of its neighbours' (below :data:`SLIVER_RATIO` times the median: a sliver). Measured on the
twisted 60 x 40 mm plate of ``tests/conftest.py`` (0.5 mm twist, 640 x 480 px, here with a
noise of 2 gray levels), a 24 x 16 Q9 mesh of the rectangle's spline with the elements
outside an L (the corner x > 7, y > 4 mm removed: 330 elements) or a D (x < 5 mm, or within
19 mm of (5, 0): 314 elements) removed, three dyadic levels, the finest level (6 x 6 = 36 dofs)
solved at image scale 0: the condition number of ``C_s H C_s^T`` restricted to the seen dofs,
and the RMS shape error against the true surface (FE on the same mesh: 3.58 um on the L,
3.80 um on the D):

==========================  ===============  ================  ================
remedy                      L: cond, error   D: cond, error    slivers (L / D)
==========================  ===============  ================  ================
none                        1.2e4, 0.37 um   6.6e6, 0.51 um    3 / 4
diagonal (Jacobi) scaling   86, 0.37 um      130, 0.51 um      3 / 4
merge into neighbour        118, 2.45 um     1070, 1.76 um     3 / 4
==========================  ===============  ================  ================

(smallest diagonal over the median: 2.6e-3 on the L, 1.8e-6 on the D). The remedy chosen is
the symmetric diagonal scaling of the restricted system, ``J (E H_s E^T) J`` with
``J = diag(E H_s E^T)^-1/2``: it does not change the step (the same space, the same error),
brings the condition number down to that of the rectangle's levels, and makes the pivot
test of a SEEN dof's singularity scale-free. This is the first remedy of de Prenter et al.
(Comput. Methods Appl. Mech. Engrg. 316, 2017) for the finite cell method; it fails only
when sliver functions become nearly linearly dependent, which the pivot test then reports.
Merging a sliver into its most strongly coupled neighbour (the lowest-order form of the
extended B-splines of Hoellig, Reif and Wipper, SIAM J. Numer. Anal. 39, 2001) is kept as an
option (``merge_slivers``): it conditions as well but keeps only the partition of unity, not
the linear fields, and measured 5-7 times less accurate above; full extended B-splines would
need each level's tensor-product structure, which the glued, vector and multi-face levels do
not expose.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sps

if TYPE_CHECKING:  # pragma: no cover - typing only
    from georeg_plugin.levels.operators import MultilevelSpace

logger = logging.getLogger(__name__)

__all__ = ["LevelSupport", "level_restriction", "mesh_seen", "dof_location",
           "ZERO_PIVOT", "SLIVER_RATIO"]

#: relative size below which a diagonal term of a projected matrix counts as zero
ZERO_PIVOT = 1e-12
#: a seen dof whose diagonal of ``C_s H C_s^T`` is below this fraction of the median of the
#: seen dofs' diagonals is a sliver
SLIVER_RATIO = 1e-2


@dataclasses.dataclass(frozen=True)
class LevelSupport:
    """What a level kept of its dofs in the last step solved at it.

    Attributes
    ----------
    level : the spline level (0 = finest).
    n_dofs : the level's dofs (rows of ``C_s``).
    unseen_mesh : dofs removed because their row of ``C_s`` is zero on the mesh's nodes.
    unseen_images : dofs removed because ``(C_s H C_s^T)_JJ`` is zero (no point sees them).
    slivers : seen dofs whose diagonal is below :data:`SLIVER_RATIO` times the median
        (treated by the diagonal scaling, or merged into a neighbour on request).
    """

    level: int
    n_dofs: int
    unseen_mesh: int = 0
    unseen_images: int = 0
    slivers: int = 0

    @property
    def dropped(self) -> int:
        """Dofs the level lost: unseen on the mesh or in the images."""
        return self.unseen_mesh + self.unseen_images

    def as_dict(self) -> dict:
        """The counts as plain ints (for JSON)."""
        return {"n_dofs": self.n_dofs, "dropped": self.dropped, "unseen_mesh": self.unseen_mesh,
                "unseen_images": self.unseen_images, "slivers": self.slivers}


def mesh_seen(C: sps.spmatrix) -> np.ndarray:
    """(n_spline,) bool: the rows of ``C`` (n_spline, n_fe) that are not zero on the nodes."""
    C = sps.csr_matrix(C)
    return np.diff(C.indptr) > 0 if C.nnz else np.zeros(C.shape[0], dtype=bool)


def level_restriction(H_s: sps.spmatrix, seen_rows: np.ndarray, level: int,
                      sliver_ratio: float = SLIVER_RATIO, merge: bool = False
                      ) -> tuple[sps.csr_matrix, LevelSupport]:
    """The restriction ``E`` (m_kept, m) of a level to its seen dofs.

    Parameters
    ----------
    H_s : (m, m) ``C_s H C_s^T``, symmetric positive semi-definite.
    seen_rows : (m,) bool, :func:`mesh_seen` of ``C_s``.
    level : the level (for the report).
    sliver_ratio : :data:`SLIVER_RATIO`: the seen dofs below it are counted as slivers.
    merge : merge each sliver into its most strongly coupled non-sliver neighbour (off by
        default: measured less accurate, see the module docstring).

    Returns
    -------
    E : csr (m_kept, m) with 0/1 entries: the restricted level's functions are ``E R``, its
        operator ``E C_s``, its step ``E^T (E H_s E^T)^-1 E C_s b``. Each column has at
        most one 1 (a dof belongs to at most one kept function); a dropped dof's column is zero.
    support : the counts.
    """
    H_s = sps.csr_matrix(H_s)
    m = H_s.shape[0]
    diag = np.abs(H_s.diagonal())
    scale = float(diag[seen_rows].max()) if seen_rows.any() else 0.0
    alive = seen_rows & (diag > ZERO_PIVOT * scale) if scale > 0 else np.zeros(m, dtype=bool)
    owner = np.where(alive, np.arange(m), -1)
    slivers = np.zeros(m, dtype=bool)
    if sliver_ratio > 0 and alive.sum() > 1:
        slivers = alive & (diag < sliver_ratio * float(np.median(diag[alive])))
    strong = alive & ~slivers
    merged = np.zeros(m, dtype=bool)
    if merge and strong.any():
        for i in np.flatnonzero(slivers):
            row = H_s.getrow(i)
            cols, vals = row.indices, np.abs(row.data)
            ok = strong[cols]
            if ok.any():                            # else: no strong neighbour, kept on its own
                owner[i] = int(cols[ok][np.argmax(vals[ok])])
                merged[i] = True
    kept = np.flatnonzero(alive & ~merged)
    index = np.full(m, -1)
    index[kept] = np.arange(kept.size)
    cols = np.flatnonzero(owner >= 0)
    E = sps.csr_matrix((np.ones(cols.size), (index[owner[cols]], cols)), shape=(kept.size, m))
    support = LevelSupport(level=level, n_dofs=m, unseen_mesh=int(np.count_nonzero(~seen_rows)),
                           unseen_images=int(np.count_nonzero(seen_rows & ~alive)),
                           slivers=int(np.count_nonzero(slivers)))
    return E, support


def dof_location(space: "MultilevelSpace", level: int, dof: int) -> str:
    """Where spline dof ``dof`` of ``level`` lies: its control point (mm) and, for a scalar
    level, its Greville point ``(u, v)``; a component of a displacement (``kron(C_s, I_k)``)
    is named too. Empty when the level does not say (the vector formulation)."""
    if space.vector:
        return ""
    patches = space.level_patches(level)
    if not patches or any(not hasattr(p, "control_points") for p in patches):
        return ""
    points = np.vstack([np.asarray(p.control_points, dtype=float).reshape(-1, 3)
                        for p in patches])
    n_rows = space.operators[level].shape[0]
    n_dofs = space.gluing[level].shape[0] if space.gluing else points.shape[0]
    k = max(1, n_rows // max(n_dofs, 1))
    base, component = divmod(int(dof), k)
    point = base
    if space.gluing:
        G = sps.csr_matrix(space.gluing[level])
        point = int(G.indices[G.indptr[base * k]]) // k if G.nnz else base
    if point >= points.shape[0]:
        return ""
    text = f"control point {point} at {np.round(points[point], 3).tolist()} mm"
    if len(patches) == 1:
        greville = np.asarray(patches[0].greville_points(), dtype=float).reshape(-1, 2)
        text += f", Greville point (u, v) = {np.round(greville[point], 4).tolist()}"
    if k > 1:
        text += f", component {component}"
    return text
