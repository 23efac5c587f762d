"""The solve hook of the geometric regularization, Eqs. 18-21.

At each Gauss-Newton step the host FE-DIC code assembles ``H_FE`` and ``b_FE`` in the
normal-projected nodal unknown ``q`` (Eq. 8 + Remark 1) and asks for a step ``d``.
Instead of the ill-posed ``H_FE d = b_FE`` the plugin solves the same problem in the
spline space of level ``s``:

    H_IG = C_s H_FE C_s^T,   b_IG = C_s b_FE          (Eqs. 18-20)
    d_IG = H_IG^-1 b_IG,     d = C_s^T d_IG           (Eq. 21)

At the finest level of its schedule the step lands in the level's span from any ``q``:
``q + d = C_s^T H_IG^-1 C_s (b_FE + H_FE q)``, the optimum of the Gauss-Newton model (Eq. 8)
over the level's dofs. For ``q`` in the span (the nominal, a coarser level's result: the
levels are nested, Eq. 13) this is the step of Eq. 21; a start outside it (a displacement
interpolated from matched features, an FE field) is drawn into it at once, instead of
keeping for ever the part that no step in the span can change. Coarser levels (coarser image
scales) take the step of Eq. 21 alone: they leave a start's finer detail to the finer scales.

``GeometricRegularization`` duck-types the core's ``StepSolver`` protocol
(``solve(H, b, q, scale) -> d``); it holds only the (immutable) multilevel space and
the schedule image scale -> spline level, so it is stateless: the spline control
values of the current shape are recovered from ``q`` by ``control_values``.

A spline dof that no integration point sees (its support lies outside the mesh's
outline, in a cut-out or a hole, or in a region masked in the images) would make
``C_s H C_s^T`` singular: by default (``hold_unseen=True``) such dofs are removed from the
level and keep their value, and the dofs that see only a sliver of points are merged into a
neighbour (:mod:`georeg_plugin.levels.support` says precisely what "unseen" and "sliver"
mean, and why the levels stay nested). A level is then singular only when a SEEN dof is:
the error names the level, the dof and where it lies. ``hold_unseen=False`` keeps the strict
behaviour (any unseen dof is an error). What each level lost is logged and kept in
:attr:`GeometricRegularization.supports` (:attr:`~GeometricRegularization.dropped_dofs`).
"""
from __future__ import annotations

import dataclasses
import logging
from types import MappingProxyType
from typing import TYPE_CHECKING, Callable, Mapping

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from georeg_plugin.errors import GeoregPluginError
from georeg_plugin.levels.support import (SLIVER_RATIO, ZERO_PIVOT, LevelSupport, dof_location,
                                          level_restriction, mesh_seen)

if TYPE_CHECKING:  # pragma: no cover - typing only
    from georeg_plugin.levels.operators import MultilevelSpace

logger = logging.getLogger(__name__)

__all__ = ["GeometricRegularization", "SingularProjectionError"]

_ZERO_PIVOT = ZERO_PIVOT


class SingularProjectionError(GeoregPluginError, np.linalg.LinAlgError):
    """The projected system ``C_s H C_s^T`` (or ``C_s C_s^T``) is singular.

    A subclass of ``numpy.linalg.LinAlgError`` (hence of ``ValueError``).
    """


def _sparse_solve(A: sps.spmatrix, b: np.ndarray, level: int, what: str,
                  hint: str) -> np.ndarray:
    """Sparse direct solve of ``A x = b`` (A symmetric, (m, m)) with clear failures.

    A zero diagonal term names the spline dof that nothing constrains; a singular
    factorisation or a non-finite solution names the level.
    """
    return _sparse_factor(A, level, what, hint)(b)


def _sparse_factor(A: sps.spmatrix, level: int, what: str, hint):
    """The map ``b -> A^-1 b`` of :func:`_sparse_solve`, ``A`` factorized once. ``hint``: a
    format string with ``{dof}``, or a callable ``dof -> str`` naming the dof."""
    if isinstance(hint, str):
        hint = hint.format
    A = sps.csc_matrix(A)
    diag = A.diagonal()
    scale = float(np.max(np.abs(diag))) if diag.size else 0.0
    dead = np.flatnonzero(np.abs(diag) <= _ZERO_PIVOT * scale) if scale > 0 else \
        np.arange(diag.size)
    if dead.size:
        raise SingularProjectionError(
            f"{what} of spline level {level} is singular: {dead.size} of {diag.size} "
            f"spline dofs have a zero diagonal term (first: dof {int(dead[0])}); "
            f"{hint(dof=int(dead[0]))}")
    advice = ("the spline level is too fine for the data (rank deficiency): use a "
              "coarser level at this scale")
    try:
        lu = spla.splu(A)
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise SingularProjectionError(
            f"{what} of spline level {level} ({A.shape[0]} dofs) is singular ({exc}); "
            f"{advice}") from exc
    pivots = np.abs(lu.U.diagonal())
    k = int(np.argmin(pivots))
    if pivots[k] <= _ZERO_PIVOT * pivots.max():
        dof = int(lu.perm_c[k])
        raise SingularProjectionError(
            f"{what} of spline level {level} ({A.shape[0]} dofs) is numerically "
            f"singular (pivot ratio {pivots[k] / pivots.max():.1e} at spline dof {dof}; "
            f"{hint(dof=dof)}?); {advice}")

    def solve(b: np.ndarray) -> np.ndarray:
        x = lu.solve(np.asarray(b, dtype=float))
        if not np.all(np.isfinite(x)):
            raise SingularProjectionError(
                f"{what} of spline level {level} ({A.shape[0]} dofs) is numerically "
                "singular (non-finite solution): use a coarser level at this scale")
        return x
    return solve


def _seen_dofs(A: sps.spmatrix) -> np.ndarray:
    diag = np.abs(A.diagonal())
    return diag > _ZERO_PIVOT * (diag.max() if diag.size else 0.0)


@dataclasses.dataclass(frozen=True, eq=False)
class GeometricRegularization:
    """Multilevel spline regularization of a Gauss-Newton step (Eqs. 18-21).

    Parameters
    ----------
    space : MultilevelSpace
        The spline levels and their operators ``C_s`` (csr, (n_spline_s, n_fe)),
        ``s = 0`` the finest (Eq. 28).
    schedule : mapping image scale -> spline level, optional
        Default ``level = min(scale, n_levels - 1)``: the coarsest images use the
        coarsest splines (Fig. 5).
    hold_unseen : bool
        True (default): remove from each level the dofs no integration point sees (a zero
        row of ``C_s`` on the mesh, or a zero diagonal term of ``C_s H C_s^T``; they keep their
        value) and merge the slivers (:mod:`georeg_plugin.levels.support`); False: any
        unseen dof raises :class:`SingularProjectionError`.
    sliver_ratio : float
        :data:`~georeg_plugin.levels.support.SLIVER_RATIO`: the dofs counted as slivers.
    merge_slivers : bool
        Merge each sliver into a neighbour (off: the restricted system is only scaled by its
        diagonal, which leaves the step unchanged; see :mod:`georeg_plugin.levels.support`).
    """

    space: "MultilevelSpace"
    schedule: Mapping[int, int] | None = None
    hold_unseen: bool = True
    sliver_ratio: float = SLIVER_RATIO
    merge_slivers: bool = False
    #: the last :class:`LevelSupport` of each level solved at (filled by ``factorize``)
    _supports: dict = dataclasses.field(init=False, repr=False, compare=False,
                                        default_factory=dict)
    #: ``C_s^T`` of each level, csr (set by ``__post_init__``)
    _transposed: tuple = dataclasses.field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n_levels = len(self.space.operators)
        if n_levels == 0:
            raise ValueError("space: a MultilevelSpace with at least one operator is needed")
        if self.schedule is not None:
            bad = {k: v for k, v in self.schedule.items()
                   if not (0 <= int(v) < n_levels) or int(k) < 0}
            if bad:
                raise ValueError(f"schedule: levels must be in [0, {n_levels - 1}] and "
                                 f"scales >= 0, got {bad}")
            object.__setattr__(self, "schedule", MappingProxyType(
                {int(k): int(v) for k, v in self.schedule.items()}))
        # C_s^T once, as csr: the projection H C_s^T runs at every Gauss-Newton step
        object.__setattr__(self, "_transposed", tuple(sps.csr_matrix(C.T) for C in
                                                      self.space.operators))

    @property
    def n_levels(self) -> int:
        """Number of spline levels."""
        return len(self.space.operators)

    @property
    def landing_level(self) -> int:
        """The finest level of the schedule, whose step lands in its span (module docstring)."""
        return 0 if self.schedule is None else min(self.schedule.values())

    def level(self, scale: int) -> int:
        """Spline level used at image scale ``scale`` (0 = finest images)."""
        if scale < 0:
            raise ValueError(f"scale must be >= 0, got {scale}")
        if self.schedule is None:
            return min(int(scale), self.n_levels - 1)
        if scale not in self.schedule:
            raise ValueError(f"scale {scale} is not in the schedule {dict(self.schedule)}")
        return self.schedule[scale]

    def operator(self, level: int) -> sps.csr_matrix:
        """``C_s`` of a level, csr (n_spline_s, n_fe)."""
        if not 0 <= level < self.n_levels:
            raise ValueError(f"level must be in [0, {self.n_levels - 1}], got {level}")
        return self.space.operators[level]

    def project(self, H, b: np.ndarray, level: int) -> tuple[sps.csr_matrix, np.ndarray]:
        """Spline operators of a level from the FE ones.

        Parameters
        ----------
        H : sparse or dense (n_fe, n_fe); b : (n_fe,)

        Returns
        -------
        H_s : csr (m, m), ``C_s H C_s^T`` (Eqs. 18, 20)
        b_s : (m,), ``C_s b`` (Eqs. 19, 20)
        """
        C = self.operator(level)
        b = np.asarray(b, dtype=float)
        if H.shape != (C.shape[1], C.shape[1]) or b.shape != (C.shape[1],):
            raise ValueError(f"H {H.shape} and b {b.shape} do not match the {C.shape[1]} "
                             f"FE nodes of spline level {level}")
        H_s = sps.csr_matrix(C @ (sps.csr_matrix(H) @ self._transposed[level]))  # Eq. 18
        b_s = C @ b  # Eq. 19
        return H_s, b_s

    def solve(self, H, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        """Regularized step ``d = C_s^T (C_s H C_s^T)^-1 C_s b`` (Eqs. 18-21), (n_fe,).

        ``q`` (n_fe,), the current nodal unknown: at :attr:`landing_level` the step lands in
        the level's span, ``d = G_s (b + H q) - q`` with ``G_s = C_s^T (C_s H C_s^T)^-1 C_s``,
        on the dofs some integration point sees (the others keep their value); the same step
        for ``q`` in the span.
        """
        return self.factorize(H, scale)(b, q)

    @property
    def supports(self) -> Mapping[int, LevelSupport]:
        """Level -> what it kept of its dofs in the last step solved at it (read-only)."""
        return MappingProxyType(dict(self._supports))

    @property
    def dropped_dofs(self) -> Mapping[int, int]:
        """Level -> number of dofs it lost (unseen on the mesh or in the images)."""
        return MappingProxyType({s: v.dropped for s, v in sorted(self._supports.items())})

    def restriction(self, H_s: sps.spmatrix, level: int) -> sps.csr_matrix:
        """``E`` (m_kept, m) restricting level ``level`` to its seen dofs, slivers merged
        (:func:`~georeg_plugin.levels.support.level_restriction`); the identity with
        ``hold_unseen=False``. Records and logs the level's :class:`LevelSupport`."""
        m = H_s.shape[0]
        if not self.hold_unseen:
            return sps.identity(m, format="csr")
        E, support = level_restriction(H_s, mesh_seen(self.operator(level)), level,
                                       self.sliver_ratio, self.merge_slivers)
        if self._supports.get(level) != support and (support.dropped or support.slivers):
            logger.info("spline level %d: %d of %d dofs dropped (%d outside the mesh, %d that no "
                        "integration point sees), %d slivers %s", level,
                        support.dropped, m, support.unseen_mesh, support.unseen_images,
                        support.slivers, "merged into a neighbour" if self.merge_slivers
                        else "(diagonally scaled)")
        self._supports[level] = support
        return E

    def _describer(self, E: sps.csr_matrix, level: int) -> Callable[[int], str]:
        """``reduced dof -> text`` naming the level's dof and where it lies."""
        first = np.asarray(E.indices)[E.indptr[:-1]] if E.nnz else np.zeros(0, dtype=int)

        def describe(dof: int) -> str:
            full = int(first[dof]) if dof < first.size else dof
            where = dof_location(self.space, level, full)
            return f"spline dof {full}" + (f" ({where})" if where else "")
        return describe

    def factorize(self, H, scale: int) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        """The step's map ``(b, q) -> C_s^T (C_s H C_s^T)^-1 C_s b`` (Eqs. 18-21) with
        ``C_s H C_s^T`` factorized once: for a Gauss-Newton whose ``H`` does not change.
        With ``hold_unseen`` the level is first restricted to its seen dofs (``E``):
        ``C_s^T E^T (E C_s H C_s^T E^T)^-1 E C_s b``. At :attr:`landing_level` the map lands
        in the span (:meth:`solve`)."""
        s = self.level(scale)
        C, CT = self.operator(s), self._transposed[s]
        H_s, _ = self.project(H, np.zeros(C.shape[1]), s)
        E = self.restriction(H_s, s)
        H_r = sps.csr_matrix(E @ H_s @ E.T)
        # symmetric diagonal (Jacobi) scaling: the same step, but the slivers' tiny diagonals no
        # longer spoil the conditioning (6.6e6 -> 1.3e2 on a D outline, support.py)
        h = np.abs(H_r.diagonal())
        jacobi = 1.0 / np.sqrt(np.where(h > 0, h, 1.0)) if self.hold_unseen else np.ones(h.size)
        J = sps.diags(jacobi)
        describe = self._describer(E, s)
        factor = _sparse_factor(J @ H_r @ J, s, "projected Hessian C_s H C_s^T",
                                lambda dof: f"no integration point sees {describe(dof)}") \
            if E.shape[0] else None
        solve = None if factor is None else (lambda rhs: jacobi * factor(jacobi * rhs))
        logger.debug("scale %d -> spline level %d: %d of %d dofs", scale, s, E.shape[0],
                     C.shape[0])

        def spline_step(b: np.ndarray) -> np.ndarray:
            b_s = C @ b                                                # Eq. 19
            d_s = np.zeros(C.shape[0])
            if solve is not None:
                d_s = E.T @ solve(E @ b_s)
            return CT @ d_s                                            # Eq. 21

        land = s == self.landing_level
        H_csr = sps.csr_matrix(H)
        seen = _seen_dofs(H_csr) if land else np.zeros(C.shape[1], dtype=bool)

        def step(b: np.ndarray, q: np.ndarray) -> np.ndarray:
            b = np.asarray(b, dtype=float)
            if b.shape != (C.shape[1],):
                raise ValueError(f"b {b.shape} does not match the {C.shape[1]} FE nodes of "
                                 f"spline level {s}")
            d = spline_step(b)
            q = None if q is None else np.asarray(q, dtype=float)
            if land and q is not None and q.shape != b.shape:
                raise ValueError(f"q {q.shape} does not match the {C.shape[1]} FE nodes of "
                                 f"spline level {s}")
            if land and q is not None and np.any(q):
                outside = q - spline_step(H_csr @ q)    # q's part off the span (0 in the span)
                d -= np.where(seen, outside, 0.0)       # q + d = G_s (b + H q) where seen
            return d
        return step

    def projected_inverse(self, H, level: int) -> np.ndarray:
        """``E^T (E C_s H C_s^T E^T)^-1 E`` (m, m), dense: the inverse of the projected
        Hessian on the level's seen dofs, zero on the dropped ones (m small)."""
        H_s, _ = self.project(H, np.zeros(self.space.n_fe), level)
        E = self.restriction(H_s, level)
        M = np.zeros(H_s.shape)
        if E.shape[0]:
            Ed = E.toarray()
            M = Ed.T @ np.linalg.inv((E @ H_s @ E.T).toarray()) @ Ed
        return M

    def step_covariance(self, H,
                        scale: int) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        """Covariance of the step per unit noise, ``C_s^T (C_s H C_s^T)^-1 C_s`` (Eq. 21 applied
        to ``Cov(b) = H``): its diagonal (n_fe,) and its action ``V (n_fe, k) -> C V``."""
        s = self.level(scale)
        C, CT = self.operator(s), self._transposed[s]
        M = self.projected_inverse(H, s)                                        # m x m, m small
        CT_M = np.asarray(CT @ M)                                               # (n_fe, m)
        diag = np.asarray(CT.multiply(CT_M).sum(axis=1)).ravel()                # rows of C^T M C
        return diag, lambda V: CT_M @ (C @ np.asarray(V, dtype=float))

    def weaker(self, scale: int) -> "GeometricRegularization | None":
        """The regularization one notch weaker at ``scale``: the next finer spline level
        (whose step is :meth:`bias_step`), or None at the finest level (the unregularized
        step, the caller's)."""
        s = self.level(scale)
        return dataclasses.replace(self, schedule={scale: s - 1}) if s > 0 else None

    def bias_step(self, H, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        """The bias indicator: the step of the next finer spline level from the current state,
        ``C_{s-1}^T (C_{s-1} H C_{s-1}^T)^-1 C_{s-1} b`` (Eqs. 18-21), (n_fe,). At the finest
        level (``s = 0``) it is the unregularized step ``H^-1 b`` over the dofs a point sees."""
        finer = self.weaker(scale)
        if finer is not None:
            return finer.solve(H, b, q, scale)
        H = sps.csr_matrix(H)
        seen = _seen_dofs(H)
        d = np.zeros(H.shape[0])
        if seen.any():
            d[seen] = spla.spsolve(sps.csc_matrix(H[seen][:, seen]), np.asarray(b, float)[seen])
        return d

    def control_values(self, q: np.ndarray, level: int) -> np.ndarray:
        """Least-squares spline control values of a nodal field, (n_spline_s,).

        Solves ``min |C_s^T q_s - q|`` by the normal equations
        ``C_s C_s^T q_s = C_s q``; exact when ``q`` is in the range of ``C_s^T``.
        """
        C = self.operator(level)
        q = np.asarray(q, dtype=float)
        if q.shape != (C.shape[1],):
            raise ValueError(f"q has shape {q.shape}, expected ({C.shape[1]},)")
        if not self.hold_unseen:
            return _sparse_solve(C @ C.T, C @ q, level, "Gram matrix C_s C_s^T",
                                 "no FE node depends on spline dof {dof}")
        rows = mesh_seen(C)                         # the dofs outside the mesh keep 0
        q_s = np.zeros(C.shape[0])
        if rows.any():
            Ck = C[rows]
            q_s[rows] = _sparse_solve(Ck @ Ck.T, Ck @ q, level, "Gram matrix C_s C_s^T",
                                      "no FE node depends on spline dof {dof}")
        return q_s

    def to_nodes(self, q_s: np.ndarray, level: int) -> np.ndarray:
        """Nodal field ``q = C_s^T q_s`` (Eq. 21), (n_fe,)."""
        C = self.operator(level)
        q_s = np.asarray(q_s, dtype=float)
        if q_s.shape != (C.shape[0],):
            raise ValueError(f"q_s has shape {q_s.shape}, expected ({C.shape[0]},)")
        return C.T @ q_s
