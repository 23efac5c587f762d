"""The gray-level residual of a displacement between two stereo pairs (Eq. 3 in time).

The reference surface is the measured one: nodes ``X_I`` (the shape measurement's
``Measurement.nodes``) and integration points ``X_g = sum_I L_I(xi_g) X_I`` (Eq. 4) of a
pixel quadrature. The unknown is the displacement ``U_I`` (3 components per node), so the
points move to ``X_g + u_g`` with ``u_g = sum_I L_I(xi_g) U_I``. Each camera ``c`` compares
its reference image ``f_c`` at the reference points with its deformed image ``g_c`` at the
displaced ones (gray-level conservation of Eq. 3 between two instants, one camera):

    r_c(X_g) = (f_c(P_c(X_g)) - m_c) / s_c - (g_c(P_c(X_g + u_g)) - m'_c) / s'_c,

after each image is brought to zero mean and unit standard deviation over each element
(Remark 2; or over the region, or not at all), the two cameras' residuals summed in one
cost ``sum_c sum_g w_g r_c(X_g)**2``. Its derivative (the normalisation is not
differentiated, as for the shape) is

    dr_c / du_g = -J_c(X_g + u_g)^T grad g_c / s'_c,

and the Gauss-Newton operators (Eq. 8 with the three components of each node instead of
the normal one) are, for ``phi_g[3I + k] = L_I(xi_g) (dr_c/du_g)_k``,

    H = sum_c sum_g w_g phi phi^T,    b = -sum_c sum_g w_g phi r_c.

Dof layout: node-major, ``U.reshape(n, 3)``, dof ``3 I + k`` for component ``k``
(x, y, z in the world frame) of node ``I``. A scalar nodal operator ``C`` (a spline
extraction operator ``C_s``, a Tikhonov ``A``) acts on every component through
``kron(C, I_3)`` (:func:`fesdic_core.displacement.solvers.componentwise`).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.sparse as sps

from fesdic_core.fe.mesh import assemble
from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.parallel import for_each_block, for_each_span
from fesdic_core.residual.graylevel import NORMALISATIONS

__all__ = ["ReferenceView", "DisplacementResidual", "reference_view", "reference_jacobian",
           "displacement_residual", "displacement_operators", "displacement_rhs", "component_dofs"]

_SIGMA_FLOOR = 0.005   # fraction of the dynamic range below which an element is "uniform"
_BLOCK = 1 << 15       # points per block of whole elements (temporaries stay in cache)


@dataclass(frozen=True, eq=False)
class ReferenceView:
    """The reference state of one image scale: computed once, shared by every frame.

    Attributes
    ----------
    scale : image scale (0: full resolution)
    quad : the pixel quadrature of the reference surface at this scale
    X : (g, 3) reference integration points (mm)
    cameras : the two cameras at this scale
    images : the two reference images at this scale
    f : (2, g) reference gray levels of each camera at its projected points
    seen : (2, g) bool, point in front of the camera and inside its reference image
    dr_du : (2, g, 3) float32 ``w_g dr_c/du_g`` of the reference (:func:`reference_jacobian`,
        weights folded in), or None (the full Gauss-Newton's derivative at the current state)
    hessian : (3n, 3n) csr ``H`` of :attr:`dr_du` (:func:`displacement_operators`), or None
    """

    scale: int
    quad: PixelQuadrature
    X: np.ndarray
    cameras: tuple
    images: tuple
    f: np.ndarray
    seen: np.ndarray
    dr_du: np.ndarray | None = field(default=None, repr=False)
    hessian: sps.csr_matrix | None = field(default=None, repr=False)

    @property
    def dynamic_range(self) -> np.ndarray:
        """(2,) dynamic range of each camera's reference image (gray levels)."""
        return np.array([float(im.dynamic_range) for im in self.images])


def reference_view(quad: PixelQuadrature, nodes: np.ndarray, images: Sequence, cameras: Sequence,
                   scale: int, extra_mask: np.ndarray | None = None,
                   normalisation: str | None = None) -> ReferenceView:
    """Sample each reference image at the projection of the reference points ``L^T X_I``.

    With ``normalisation`` (the residual's), also the reference Jacobian and its ``H``
    (:func:`reference_jacobian`): the modified Gauss-Newton's constant operator.
    """
    X = quad.points(nodes)
    f = np.zeros((2, len(X)))
    pull = None if normalisation is None else np.zeros((2, len(X), 3))
    seen = np.ones((2, len(X)), dtype=bool) if extra_mask is None else \
        np.tile(np.asarray(extra_mask, bool), (2, 1))
    for c, (image, cam) in enumerate(zip(images, cameras)):
        x, lin = cam.linearise(X)
        with np.errstate(invalid="ignore"):
            seen[c] &= cam.in_front(X) & image.inside(x)
        x[~seen[c]] = 0.0
        if pull is None:
            f[c] = np.where(seen[c], image.evaluate(x), 0.0)
        else:
            value, grad = image.evaluate_with_gradient(x)
            f[c] = np.where(seen[c], value, 0.0)
            pull[c] = lin.pull_point(grad)                              # J_c^T grad f_c
    view = ReferenceView(scale=int(scale), quad=quad, X=X, cameras=tuple(cameras),
                         images=tuple(images), f=f, seen=seen)
    if pull is None or normalisation is None:                       # (both or neither)
        return view
    return reference_jacobian(view, pull, normalisation)


def reference_jacobian(view: ReferenceView, pull: np.ndarray, normalisation: str
                       ) -> ReferenceView:
    """The view with the modified Gauss-Newton's Jacobian and its operator ``H``.

    At the solution ``g_c(P_c(X_g + u_g)) ~= a f_c(P_c(X_g)) + b`` (the deformed image is
    the reference one moved, up to the brightness and contrast the normalisation removes),
    so the derivative of the residual is, up to the displacement gradient,

        dr_c/du_g = -J_c(X_g)^T grad f_c / s_c,

    with the reference image's gradient and contrast ``s_c`` at the reference points
    (``pull``: (2, g, 3) ``J_c^T grad f_c``): the classic FE-DIC modified Gauss-Newton
    (Besnard, Hild and Roux 2006). ``H`` is assembled once per scale and serves every
    iteration of every frame; the residual (hence the solution) is unchanged.
    """
    quad, dyn = view.quad, view.dynamic_range
    G = np.zeros(pull.shape)
    for c in range(2):
        _, s0 = _element_statistics(view.f[c], view.seen[c], quad, dyn[c], normalisation)
        G[c] = pull[c] * np.where(view.seen[c], -1.0 / s0, 0.0)[:, None]
    frozen = DisplacementResidual(r=np.zeros(view.f.shape), mask=view.seen, dr_du=G,
                                  sigma_ref=np.ones(view.f.shape), dynamic_range=dyn,
                                  std_percent=float("nan"))
    H, _ = displacement_operators(quad, frozen)
    w = np.where(view.seen, quad.weight_mm2, 0.0)
    wG = (G * w[:, :, None]).astype(np.float32)
    return dataclasses.replace(view, dr_du=wG, hessian=H)


@dataclass(frozen=True, eq=False)
class DisplacementResidual:
    """The residuals of both cameras at the integration points.

    Attributes
    ----------
    r : (2, g) normalised residual of each camera (0 where ``mask`` is False)
    mask : (2, g) bool, point seen in the camera's reference and deformed images
    dr_du : (2, g, 3) ``dr_c/du_g = -J_c^T grad g_c / s'_c``, or None
    sigma_ref : (2, g) gray-level scale of the reference image at the point (r in gray levels)
    dynamic_range : (2,) dynamic range of each reference image
    std_percent : standard deviation of :attr:`percent` over both cameras' masks (NaN if empty)
    """

    r: np.ndarray
    mask: np.ndarray
    dr_du: np.ndarray | None
    sigma_ref: np.ndarray
    dynamic_range: np.ndarray
    std_percent: float

    @property
    def percent(self) -> np.ndarray:
        """(2, g) residual in percent of each camera's reference dynamic range (NaN unseen)."""
        out = np.full(self.r.shape, np.nan)
        gray = 100.0 * self.r * self.sigma_ref / self.dynamic_range[:, None]
        out[self.mask] = gray[self.mask]
        return out

    @property
    def point_percent(self) -> np.ndarray:
        """(g,) root mean square of the two cameras' :attr:`percent` at each point (NaN
        where neither sees it): one residual map on the surface."""
        p = self.percent
        seen = self.mask.sum(axis=0)
        total = np.nansum(p * p, axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(seen > 0, np.sqrt(total / np.maximum(seen, 1)), np.nan)

    @property
    def n_points(self) -> int:
        """Number of (point, camera) pairs seen."""
        return int(np.count_nonzero(self.mask))


def _element_statistics(values: np.ndarray, mask: np.ndarray, quad: PixelQuadrature,
                        dynamic_range: float, normalisation: str) -> tuple[np.ndarray, np.ndarray]:
    """Mean and scale (g,) of ``values`` over each element's seen points (Remark 2), over
    the whole region ("global"), or 0 and 1 ("none"); scales floored at a fraction of the
    dynamic range (a uniform element)."""
    g = len(values)
    if normalisation == "none":
        return np.zeros(g), np.ones(g)
    starts = quad.element_runs[0] if normalisation == "element" else np.zeros(1, dtype=np.intp)
    return _run_statistics(values, mask, starts, _SIGMA_FLOOR * dynamic_range)


def _run_statistics(values: np.ndarray, mask: np.ndarray, starts: np.ndarray, floor: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation (g,) of ``values`` over the ``mask``-ed points of each run
    of points (runs from ``starts``, increasing, the first 0: an element's points are a
    run), at every point of the run; deviations floored at ``floor``."""
    seen = mask.astype(float)
    fm = values * seen
    count = np.maximum(np.add.reduceat(seen, starts), 1.0)
    mean = np.add.reduceat(fm, starts) / count
    sigma = np.maximum(np.sqrt(np.maximum(np.add.reduceat(fm * values, starts) / count
                                          - mean ** 2, 0.0)), floor)
    lengths = np.diff(np.append(starts, len(values)))
    return np.repeat(mean, lengths), np.repeat(sigma, lengths)


def _pooled_percent(percent: np.ndarray, mask: np.ndarray) -> float:
    """Standard deviation of the residual (percent) over every seen (point, camera) pair."""
    values = percent[mask]
    return float(np.std(values)) if values.size else float("nan")


def displacement_residual(U: np.ndarray, ref: ReferenceView, images: Sequence,
                          normalisation: str = "element", jacobian: bool = True
                          ) -> DisplacementResidual:
    """Both cameras' residuals for the nodal displacement ``U`` (n, 3) or (3n,) (node-major).

    ``images``: the two deformed images at the scale of ``ref``. Blocks of whole elements
    are shared out over threads for the projection, sampling and pull-back.
    """
    if normalisation not in NORMALISATIONS:
        raise ValueError(f"normalisation must be one of {NORMALISATIONS}, got {normalisation!r}")
    quad = ref.quad
    U = np.asarray(U, float).reshape(-1, 3)
    if U.shape[0] != quad.n_nodes:
        raise ValueError(f"U has {U.shape[0]} nodes, the reference surface {quad.n_nodes}")
    X = ref.X + quad.points(U)                                      # X_g + u_g
    g = len(X)
    mask = ref.seen.copy()
    value = np.zeros((2, g))
    pull = np.zeros((2, g, 3)) if jacobian else None
    r, sigma_ref = np.zeros((2, g)), np.empty((2, g))
    dyn = ref.dynamic_range
    blocks = quad.element_blocks(_BLOCK)
    run_starts = quad.element_runs[0]

    def normalise(c: int, span: slice, statistics) -> None:
        """Remark 2 on the points ``span`` of camera ``c``: the residual and its scales."""
        m, f, v = mask[c, span], ref.f[c, span], value[c, span]
        mean0, s0 = statistics(f, m, dyn[c])
        mean1, s1 = statistics(v, m, float(images[c].dynamic_range))
        r[c, span] = np.where(m, (f - mean0) / s0 - (v - mean1) / s1, 0.0)
        sigma_ref[c, span] = s0
        if pull is not None:                                      # (jacobian)
            pull[c, span] *= np.where(m, -1.0 / s1, 0.0)[:, None]  # dr_c/du = -J^T grad g / s'

    def sample(i: int) -> None:
        b, runs = blocks[i]
        for c, (image, cam) in enumerate(zip(images, ref.cameras)):
            x, lin = cam.linearise(X[b])
            with np.errstate(invalid="ignore"):
                mask[c, b] &= (lin.inv_z > 0.0) & image.inside(x)
            x[~mask[c, b]] = 0.0                                  # keep unseen points harmless
            if pull is not None:                                  # (jacobian)
                value[c, b], grad = image.evaluate_with_gradient(x)
                pull[c, b] = lin.pull_point(grad)                  # J_c^T grad g_c
            else:
                value[c, b] = image.evaluate(x)                   # (the value-only pass)
            if normalisation == "element":                        # the block's whole elements
                starts = run_starts[runs] - b.start
                normalise(c, b, lambda v, m, d: _run_statistics(v, m, starts, _SIGMA_FLOOR * d))

    for_each_span(sample, len(blocks))
    if normalisation != "element":                                # over the whole region
        for c in range(2):
            normalise(c, slice(None),
                      lambda v, m, d: _element_statistics(v, m, quad, d, normalisation))
    gray = 100.0 * r * sigma_ref / dyn[:, None]
    return DisplacementResidual(r=r, mask=mask, dr_du=pull, sigma_ref=sigma_ref,
                                dynamic_range=dyn, std_percent=_pooled_percent(gray, mask))


def component_dofs(connectivity: np.ndarray) -> np.ndarray:
    """Dofs (E, 3 nn) of elements' nodes in the node-major layout: ``3 I + k``."""
    conn = np.asarray(connectivity)
    return (3 * conn[:, :, None] + np.arange(3)).reshape(len(conn), -1)


#: the 6 distinct products ``G_k G_l`` of a symmetric 3 x 3 block, and where they go
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_PAIR_OF = np.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])
_OPERATOR_BLOCK = 1 << 18   # points per block of elements in the assembly


def displacement_operators(quad: PixelQuadrature, res: DisplacementResidual
                           ) -> tuple[sps.csr_matrix, np.ndarray]:
    """Assemble ``H`` (3n, 3n) and ``b`` (3n,) of the displacement's Gauss-Newton step.

    With ``phi_g[3 i + k] = L_i(xi_g) (dr_c/du_g)_k`` the element blocks are

        H_e[3 i + k, 3 j + l] = sum_g L_i L_j P_g[k, l],  P_g = sum_c w_g G_cg G_cg^T,
        b_e[3 i + k]          = -sum_g L_i B_g[k],        B_g = sum_c w_g r_cg G_cg,

    (``G_cg = dr_c/du_g``). The elements of a group share their shape functions ``L`` (m, nn)
    at the points (:class:`ElementGroup`), so every element's block comes from one matrix
    product ``(L_i L_j)^T P`` over the ``(nn (nn + 1) / 2, m) x (m, E * 6)`` of a block of elements (6
    distinct entries of the symmetric ``P``), then the scatter on the node-major dofs.
    The products are numpy's own loops (``einsum``), not BLAS: on a loaded machine OpenBLAS's
    threads, started inside the core's thread pool, made them 20 times slower.
    """
    if res.dr_du is None:
        raise ValueError("displacement_operators: the residual has no dr/du (computed without "
                         "its derivative)")
    dr_du = res.dr_du
    n = 3 * quad.n_nodes
    w = np.where(res.mask, quad.weight_mm2, 0.0)                  # (2, g)
    element_matrices, dofs, b = [], [], np.zeros(n)
    for group in quad.groups:
        E, (m, nn) = len(group.elements), group.N.shape
        upper = np.triu_indices(nn)                                     # L_i L_j = L_j L_i
        NN = group.N[:, upper[0]] * group.N[:, upper[1]]                # (m, nn (nn + 1) / 2)
        pair = np.empty((nn, nn), dtype=np.intp)
        pair[upper] = pair[upper[::-1]] = np.arange(len(upper[0]))
        He, be = np.empty((E, nn, 3, nn, 3)), np.empty((E, nn, 3))

        def element_block(span: slice) -> None:
            points = slice(group.start + span.start * m, group.start + span.stop * m)
            G = dr_du[:, points]                                            # (2, p, 3)
            wG = G * w[:, points, None]
            P = np.stack([np.einsum("cp,cp->p", wG[..., k], G[..., l]) for k, l in _PAIRS], -1)
            B = np.einsum("cp,cpk->pk", res.r[:, points], wG)               # (p, 3)
            e = span.stop - span.start
            P = P.reshape(e, m, 6).transpose(1, 0, 2).reshape(m, e * 6)
            H6 = np.einsum("mi,mj->ij", NN, P).reshape(-1, e, 6)[pair]     # (nn, nn, e, 6)
            He[span] = H6[..., _PAIR_OF].transpose(2, 0, 3, 1, 4)           # (e, nn, 3, nn, 3)
            Bm = B.reshape(e, m, 3).transpose(1, 0, 2).reshape(m, e * 3)
            be[span] = -np.einsum("mi,mj->ij", group.N, Bm).reshape(nn, e, 3).transpose(1, 0, 2)

        for_each_block(element_block, E, max(1, _OPERATOR_BLOCK // m))
        conn = component_dofs(group.connectivity)
        element_matrices.append(He.reshape(E, 3 * nn, 3 * nn))
        dofs.append(conn)
        b += np.bincount(conn.ravel(), weights=be.ravel(), minlength=n)
    return assemble(dofs, element_matrices, n), b


def displacement_rhs(quad: PixelQuadrature, weighted_dr_du: np.ndarray, r: np.ndarray
                     ) -> np.ndarray:
    """``b`` (3n,) of a Gauss-Newton step for a Jacobian given with its weights folded in,
    ``wG_cg = w_g dr_c/du_g`` (:attr:`ReferenceView.dr_du`), and residuals ``r`` (2, g)
    (0 at the points not seen):

        b[3 i + k] = -sum_g L_i(xi_g) sum_c r_cg wG_cg[k]     (b of Eq. 8, J^T r),

    the gather of :func:`displacement_operators`'s ``b`` without its element blocks of H.
    """
    n = 3 * quad.n_nodes
    b = np.zeros(n)
    for group in quad.groups:
        E, (m, nn) = len(group.elements), group.N.shape
        be = np.empty((E, nn, 3))

        def element_block(span: slice) -> None:
            points = slice(group.start + span.start * m, group.start + span.stop * m)
            B = np.einsum("cp,cpk->pk", r[:, points], weighted_dr_du[:, points],
                          dtype=float, casting="same_kind")                      # (p, 3)
            e = span.stop - span.start
            Bm = B.reshape(e, m, 3).transpose(1, 0, 2).reshape(m, e * 3)
            be[span] = -np.einsum("mi,mj->ij", group.N, Bm).reshape(nn, e, 3).transpose(1, 0, 2)

        for_each_block(element_block, E, max(1, _OPERATOR_BLOCK // m))
        b += np.bincount(component_dofs(group.connectivity).ravel(), weights=be.ravel(),
                         minlength=n)
    return b


def chi_square(res: DisplacementResidual, quad: PixelQuadrature) -> tuple[float, int]:
    """The cost ``sum_c sum_g w_g r_c**2`` and the number of (point, camera) pairs seen."""
    w = np.where(res.mask, quad.weight_mm2, 0.0)
    return float(np.sum(w * res.r * res.r)), res.n_points

