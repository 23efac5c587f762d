"""Tikhonov regularization of the shape problem (Eq. 10), as a step solver of the core.

``(H + lam A) d = b - lam A q`` where ``A`` is the surface-gradient operator:
``q^T A q = int_Omega |grad_s S|^2 dX`` for the normal correction field ``S = L^T q``.

How the regularization length maps to ``lam``
---------------------------------------------
As in pyxel and in Passieux et al.'s FE-SDIC, ``lam`` is chosen so that a cosine
field of wavelength ``length_mm`` costs as much in the regularization term as in
the gray-level term:

    lam = (v^T H v) / (v^T A v),   v_I = cos(2 pi x_I . e / length_mm),

averaged over the two in-plane principal directions ``e`` of the mesh. Components of
the shape with wavelengths longer than ``length_mm`` are ruled by the images, shorter
ones by the regularization (a low-pass filter of cut-off ``length_mm``). Since
``v^T A v`` grows like ``length_mm**-2``, ``lam`` grows like ``length_mm**2``.

One weight per image scale (Remark 3)
-------------------------------------
``lam`` is chosen once per image scale, from the ``H`` of the first Gauss-Newton step of
that scale, and then kept for every step of the scale (the objective of the scale's
Gauss-Newton does not move under it). Coarse images get a strong regularization, fine
ones a weaker one: a fixed length ``l`` stands for ``l * 2**s`` at scale ``s`` (a coarse
pixel is ``2**s`` fine pixels; scale 0 uses ``l`` itself). ``length_mm="auto"`` chooses
the weight at each scale by Mallows' Cp over a grid of lengths
(:mod:`fesdic_core.solve.tikhonov_choice`), which needs the noise of that scale
(:meth:`TikhonovSolver.start_scale`).
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Callable

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from fesdic_core.fe.elements import gauss_rule
from fesdic_core.fe.mesh import SurfaceMesh, assemble
from fesdic_core.solve.solvers import sparse_solve
from fesdic_core.solve.tikhonov_choice import CpCurve, covariance_diagonal, length_grid, mallows_cp

if TYPE_CHECKING:  # typing only: the shape package imports this one
    from fesdic_core.shape.uncertainty import NoiseModel

logger = logging.getLogger(__name__)

__all__ = ["surface_gradient_operator", "surface_gradient_integral", "tikhonov_weight",
           "WEAKER_FACTOR", "TikhonovSolver"]

#: a cosine probe whose ``v^T A v`` is below this fraction of ``|v|^T |A| |v|`` has no
#: gradient (round-off)
_ROUND_OFF = 1e-9


def surface_gradient_operator(mesh: SurfaceMesh) -> sps.csr_matrix:
    """Assemble ``A`` with ``q^T A q = int |grad_s (L^T q)|^2 dX`` (the operator of Eq. 10).

    The surface gradient of a shape function is ``J (J^T J)^-1 dN/dxi`` with
    ``J = [dX/dxi, dX/deta]`` (3 x 2); then ``A_IJ = sum_g w_g grad_s N_I . grad_s N_J``.
    """
    element_matrices = [np.einsum("em,emid,emjd->eij", dA, grad, grad)   # (ne, nn, nn)
                        for dA, grad in _surface_gradients(mesh)]
    return assemble([b.connectivity for b in mesh.blocks], element_matrices, mesh.nodes.shape[0])


def _surface_gradients(mesh: SurfaceMesh):
    """Per block: the area weights ``dA`` (ne, m) of its Gauss points and the surface
    gradients ``grad_s N`` (ne, m, nn, 3) of its shape functions there."""
    for block in mesh.blocks:
        xi, w = gauss_rule(block.family, 3)
        dN = block.family.shape_derivatives(xi)                    # (m, nn, 2)
        Xe = mesh.nodes[block.connectivity]                          # (ne, nn, 3)
        J = np.einsum("eid,mia->emda", Xe, dN)                       # (ne, m, 3, 2)
        G = np.einsum("emda,emdb->emab", J, J)                       # metric J^T J
        detG = G[..., 0, 0] * G[..., 1, 1] - G[..., 0, 1] ** 2
        Ginv = np.stack([np.stack([G[..., 1, 1], -G[..., 0, 1]], -1),
                         np.stack([-G[..., 1, 0], G[..., 0, 0]], -1)], -2) / detG[..., None, None]
        yield np.sqrt(detG) * w, np.einsum("emda,emab,mib->emid", J, Ginv, dN)


def surface_gradient_integral(mesh: SurfaceMesh) -> tuple[np.ndarray, float]:
    """``G`` (3, n) with ``G q = int grad_s (L^T q) dX``, and the area ``|Omega|`` (mm^2).

    Then ``q^T (A - G^T G / |Omega|) q = int |grad_s S - <grad_s S>|^2 dX``: the gradient's
    departure from its mean, zero for every field whose gradient is uniform.
    """
    n = mesh.nodes.shape[0]
    G, area = np.zeros((3, n)), 0.0
    for block, (dA, grad) in zip(mesh.blocks, _surface_gradients(mesh)):
        contribution = np.einsum("em,emid->eid", dA, grad)            # (ne, nn, 3)
        np.add.at(G.T, block.connectivity.ravel(), contribution.reshape(-1, 3))
        area += float(dA.sum())
    return G, area


def tikhonov_weight(H: sps.spmatrix, A: sps.spmatrix, nodes: np.ndarray, length_mm: float) -> float:
    """``lam`` such that a cosine of wavelength ``length_mm`` costs the same in H and lam A.

    A direction in which the probe has no gradient at the nodes (``v^T A v`` at round-off
    level, e.g. a wavelength that divides the node spacing: the cosine aliases to a
    constant) is left out; ValueError if both are.
    """
    centred = nodes - nodes.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    ratios = []
    absA = abs(A)
    for e in axes[:2]:
        v = np.cos(2.0 * np.pi * (centred @ e) / length_mm)
        vAv = float(v @ (A @ v))
        if vAv > _ROUND_OFF * float(np.abs(v) @ (absA @ np.abs(v))):
            ratios.append(float(v @ (H @ v)) / vAv)
    if not ratios:
        raise ValueError(f"tikhonov length {length_mm:g} mm: the cosine probe has no gradient at "
                         "the nodes of this mesh (a wavelength shorter than twice the node "
                         "spacing aliases), so it gives no regularization weight")
    return float(np.mean(ratios))


#: the bias indicator's weaker notch: the length halved, i.e. ``lam / 4`` (``lam ~ l**2``)
WEAKER_FACTOR = 0.25


def _checked_length(length_mm) -> float | str:
    """A positive finite number of mm, or the string "auto"."""
    if isinstance(length_mm, str) and length_mm == "auto":
        return "auto"
    number = (isinstance(length_mm, (int, float, np.integer, np.floating))
              and not isinstance(length_mm, bool))
    if not (number and np.isfinite(length_mm) and length_mm > 0):
        raise ValueError(f"tikhonov_length_mm must be a positive finite number (mm) or 'auto', "
                         f"got {length_mm!r}")
    return float(length_mm)


class TikhonovSolver:
    """Step solver of Eq. 10: ``(H + lam A) d = b - lam A q``, one ``lam`` per image scale.

    Parameters
    ----------
    mesh : SurfaceMesh
        The nominal FE mesh (to build ``A``).
    length_mm : float or "auto"
        Regularization length at scale 0 (mm; ``length_mm * 2**s`` at scale ``s``), see
        the module docstring; or "auto": at each scale, the length of the grid
        :func:`~fesdic_core.solve.tikhonov_choice.length_grid` whose weight minimises Mallows' Cp
        of the linearised problem (:func:`~fesdic_core.solve.tikhonov_choice.mallows_cp`). The
        automatic choice needs the noise variance ``kappa`` of the scale, given by
        :meth:`start_scale`; without it :meth:`solve` raises ValueError (no fallback:
        with as many data as unknowns in the normal equations, generalized
        cross-validation has no residual degrees of freedom to work with).

    Attributes
    ----------
    lambdas : dict scale -> lam chosen for that scale
    chosen_lengths_mm : dict scale -> the cosine-probe length that ``lam`` stands for
    cp_curves : dict scale -> :class:`~fesdic_core.solve.tikhonov_choice.CpCurve` ("auto" only)
    last_lambda : the weight of the last step (None before the first)

    Notes
    -----
    The weight of a scale is chosen at the first :meth:`solve` of that scale and kept for
    the rest of it. :meth:`start_scale` marks the start of a scale; without it, the first
    solve at a new ``scale`` does. A scale coarser than the current one starts a new
    coarse-to-fine pass: the choices of the previous pass are forgotten. One solver serves
    one measurement (or call :meth:`reset` between two).
    """

    def __init__(self, mesh: SurfaceMesh, length_mm: float | str):
        self.length_mm = _checked_length(length_mm)
        self.nodes = mesh.nodes
        self.A = surface_gradient_operator(mesh)
        self.auto = self.length_mm == "auto"
        if not isinstance(self.length_mm, str):     # fail now if scale 0's cosine probe aliases
            tikhonov_weight(sps.identity(mesh.n_nodes, format="csr"), self.A, self.nodes,
                            self.length_mm)
        self.grid_mm = length_grid(mesh) if self.auto else None
        self.lambdas: dict[int, float] = {}
        self.chosen_lengths_mm: dict[int, float] = {}
        self.cp_curves: dict[int, CpCurve] = {}
        self.last_lambda: float | None = None
        self._kappa: dict[int, float] = {}
        self._scale: int | None = None

    def reset(self) -> None:
        """Forget every choice (a new measurement)."""
        self.lambdas.clear()
        self.chosen_lengths_mm.clear()
        self.cp_curves.clear()
        self._kappa.clear()
        self._scale = None

    def _enter(self, scale: int) -> None:
        if self._scale is not None and scale > self._scale:
            logger.debug("tikhonov: scale %d after %d starts a new pass", scale, self._scale)
            self.reset()
        self._scale = scale

    def start_scale(self, scale: int, noise: NoiseModel | None = None) -> None:
        """Mark the start of image scale ``scale`` (coarse to fine; Remark 3).

        ``noise``: the scale's noise model, read for ``noise.variance`` (``kappa``, with
        ``Cov(b) ~= kappa H``; :class:`fesdic_core.shape.uncertainty.NoiseModel`); needed by
        ``length_mm="auto"``. Called again for the same scale (a later fixed-point
        iteration), it keeps the weight and the noise already in force.
        """
        scale = int(scale)
        self._enter(scale)
        variance = getattr(noise, "variance", None)
        if variance is not None and scale not in self._kappa:
            self._kappa[scale] = float(variance)

    def _choose(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> None:
        grid = self.grid_mm                                            # None: a fixed length
        if grid is None:
            length = float(self.length_mm) * 2.0 ** scale              # Remark 3
            lam = tikhonov_weight(H, self.A, self.nodes, length)
            logger.info("tikhonov scale %d: length %.4g mm (%.4g mm x 2**%d), lambda %.4g",
                        scale, length, self.length_mm, scale, lam)
        else:
            kappa = self._kappa.get(scale)
            if kappa is None or not (np.isfinite(kappa) and kappa > 0):
                raise ValueError(
                    f"tikhonov_length_mm='auto' needs the noise variance of scale {scale} "
                    f"(got {kappa!r}): call start_scale(scale, noise) before solving")
            lams = np.array([tikhonov_weight(H, self.A, self.nodes, l) for l in grid])
            curve = mallows_cp(H, b, q, self.A, lams, kappa, grid)
            self.cp_curves[scale] = curve
            best = curve.best
            length, lam = float(grid[best]), float(lams[best])
            edge = " (at the edge of the grid)" if best in (0, len(lams) - 1) else ""
            logger.info("tikhonov scale %d: Mallows' Cp over %d lengths %.3g..%.3g mm (kappa "
                        "%.3g, %s trace): length %.4g mm%s, lambda %.4g, %.1f of %d dofs", scale,
                        len(lams), grid[0], grid[-1], kappa,
                        "exact" if curve.exact_trace else "Hutchinson", length, edge, lam,
                        curve.dof[best], H.shape[0])
        self.lambdas[scale] = float(lam)
        self.chosen_lengths_mm[scale] = float(length)

    def _lambda(self, scale: int) -> float:
        if scale not in self.lambdas:
            raise ValueError(f"tikhonov: no weight chosen for scale {scale} yet (chosen: "
                             f"{sorted(self.lambdas)}); solve a step of that scale first")
        return self.lambdas[scale]

    def solve(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        """The step ``d`` of Eq. 10 with the weight of ``scale`` (chosen at its first call)."""
        scale = int(scale)
        self._enter(scale)
        if scale not in self.lambdas:
            self._choose(H, b, q, scale)
        lam = self.lambdas[scale]
        self.last_lambda = lam
        return sparse_solve(H + lam * self.A, b - lam * (self.A @ q), what="H_FE + lam A")  # Eq. 10

    def covariance_diagonal(self, H: sps.spmatrix, scale: int) -> np.ndarray:
        """``diag(G H G)``, ``G = (H + lam_s A)^-1`` the map ``b -> d`` of Eq. 10 at the
        weight of ``scale``: the variance of each dof of a step is ``kappa`` times it.

        Exact: dense Cholesky inverse up to
        :data:`~fesdic_core.solve.tikhonov_choice.DENSE_COVARIANCE_MAX_DOFS` dofs, sparse LU and
        the columns of ``G`` by blocks above (:func:`tikhonov_choice.covariance_diagonal`).
        """
        return covariance_diagonal(H, self.A, self._lambda(int(scale)))

    def step_covariance(self, H: sps.spmatrix,
                        scale: int) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        """The step's covariance per unit noise for :func:`fesdic_core.shape.uncertainty.shape_std`:
        ``diag(G H G)`` (:meth:`covariance_diagonal`) and its action ``V -> G H G V``."""
        K = sps.csc_matrix(H + self._lambda(int(scale)) * self.A)
        lu = spla.splu(K)
        H = sps.csr_matrix(H)
        return (self.covariance_diagonal(H, scale),
                lambda V: lu.solve(np.asarray(H @ lu.solve(np.asarray(V, dtype=float)))))

    def bias_step(self, H: sps.spmatrix, b: np.ndarray, q: np.ndarray, scale: int) -> np.ndarray:
        """How much the shape would move with the regularization one notch weaker.

        The notch is the length halved, as a spline level and the next finer one differ
        by halved knot spans: ``lam' = lam_s / 4`` (:data:`WEAKER_FACTOR`; the cosine-probe
        weight grows like the length squared), and the indicator is the Eq. 10 step at
        ``lam'`` from the state ``(H, b, q)``:

            d' = (H + lam' A)^-1 (b - lam' A q).

        At a converged state of scale ``s`` (``b = lam_s A q``) it is
        ``(H + lam' A)^-1 (lam_s - lam') A q``; on a linear problem, exactly the change
        from the solution at ``lam_s`` to the solution at ``lam'``.
        """
        lam = WEAKER_FACTOR * self._lambda(int(scale))
        return sparse_solve(H + lam * self.A, b - lam * (self.A @ q), what="H_FE + lam A")  # Eq. 10

    def __repr__(self) -> str:
        return f"TikhonovSolver(length_mm={self.length_mm!r})"
