"""pyxel-dic adapter: spline-regularized 2-D FE-DIC in pyxel, without changing pyxel.

pyxel's ``Correlate(..., Basis=B)`` already restricts the Gauss-Newton updates to a
reduced basis: ``H -> B^T H B``, ``b -> B^T b``, ``U += B dU``. This is Eqs. 18-21
of the paper with ``B = C_s^T`` placed in pyxel's dof numbering, one block per
displacement component (:func:`pyxel_basis`). The adapter runs one ``Correlate``
per spline level, coarse to fine, each on its own image scale (pyxel's own
``Image.SubSample`` / ``Camera.SubSampleCopy`` / ``Mesh.DICIntegrationFast``, as in
its ``MultiscaleInit``), and handles three measured quirks of pyxel-dic 2026.10:

- only the updates are restricted to the basis, so the starting displacement of each
  level is first projected on the level's basis (least squares, :func:`project_on_basis`);
- ``MultiscaleInit(..., Basis=B)`` silently drops its Tikhonov term (``l0 = 0``), so
  the levels are run here, one ``Correlate`` each;
- ``Correlate`` integrates with ``m.DICIntegrationFast(cam, aes)`` against the
  signature ``(n, G)`` (it works by accident and also builds gradients); the adapter
  integrates each scale itself so that branch is never taken;
- ``Correlate`` returns ``(U, res)`` only and keeps no history: the number of
  Gauss-Newton iterations is counted on the DIC engine handed to it, whose
  ``ComputeRHS`` it calls exactly once per iteration (:class:`_CountingEngine`),
  not parsed from what it prints.

Integration rule of each scale: by default pyxel's pixel rule ``m.DICIntegration(cam_s)``
(about one point per pixel of the scale in every element, the rule of pyxel's own
examples). ``MultiscaleInit``'s rule ``m.DICIntegrationFast(n)``, n x n points in every
element with ``n = max(int(m.GetApproxElementSize(cam)) // 2**s, 2)``, is available as
``integration="fast"``; on a graded mesh it under-samples the large elements (2 x 2
points on a 10 px element at scale 1 of pyxel's composite mesh) and, without pyxel's
Tikhonov term, the spline dofs there drift by tens of pixels.

pyxel is imported lazily (inside the functions): the rest of the project works
without the optional ``pyxel`` extra.
"""
from __future__ import annotations

import contextlib
import io
import logging
from typing import Any

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from georeg_plugin.levels.operators import multilevel_space
from georeg_plugin.levels.support import ZERO_PIVOT
from georeg_plugin.spline.patch import SplinePatch

from adapters.protocol import LevelRecord, reduced_basis

logger = logging.getLogger(__name__)

__all__ = ["INTEGRATION_RULES", "PyxelAdapter", "independent_columns", "seen_columns", "pyxel_basis", "project_on_basis", "spline_for_mesh",
           "correlate_multilevel", "correlate_fe", "import_pyxel"]

#: integration rules of :class:`PyxelAdapter` (see the module docstring)
INTEGRATION_RULES = ("pixel", "fast")

_EXTRA_HINT = ('the pyxel adapter needs pyxel-dic (PyPI "pyxel-dic", import "pyxel"); '
               'install the optional extra:  python -m pip install -e ".[pyxel]"')


def import_pyxel() -> Any:
    """Import pyxel, or raise an ImportError naming the ``pyxel`` extra."""
    try:
        import pyxel
    except (ImportError, OSError) as exc:  # OSError: gmsh's libGLU & co. missing
        raise ImportError(f"{_EXTRA_HINT} ({type(exc).__name__}: {exc})") from exc
    return pyxel


@contextlib.contextmanager
def _pyxel_output():
    """Capture what pyxel prints (it uses print) and hand it to the logger."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        yield buffer
    text = buffer.getvalue().strip()
    if text:
        logger.debug("pyxel: %s", text.replace("\n", " | "))


class _CountingEngine:
    """A pyxel DIC engine that counts the right-hand sides asked of it.

    ``pyxel.Correlate`` calls ``dic.ComputeRHS`` once at the start of every Gauss-Newton
    iteration (``ComputeRHS_EB`` with ``EB=True``, not used here) and returns no
    iteration count, so the count of those calls is the number of iterations. Every
    other attribute is the wrapped engine's.
    """

    def __init__(self, engine: Any) -> None:
        self._engine = engine
        self.rhs_calls = 0

    def ComputeRHS(self, *args: Any, **kwargs: Any) -> Any:  # noqa: N802 (pyxel's name)
        self.rhs_calls += 1
        return self._engine.ComputeRHS(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._engine, name)


def _connected(m: Any) -> Any:
    """The mesh with its dof numbering (``m.conn``, ``m.ndof``) built."""
    if len(m.conn) == 0:
        with _pyxel_output():
            m.Connectivity()
    return m


def _check_2d(f: Any, m: Any) -> None:
    if np.ndim(f.pix) != 2:
        raise ValueError(f"the pyxel adapter handles 2-D DIC only; reference image "
                         f"{getattr(f, 'fname', '?')!r} has shape {np.shape(f.pix)}")
    if int(m.dim) != 2:
        raise ValueError(f"the pyxel adapter handles 2-D meshes only, got mesh.dim = {m.dim}")


def pyxel_basis(m: Any, C: sps.spmatrix) -> sps.csr_matrix:
    """pyxel's reduced basis ``B = C^T`` in pyxel's dof numbering.

    Parameters
    ----------
    m : pyxel.Mesh, 2-D (``Connectivity()`` is called if needed).
    C : sparse (n_spline, n_nodes), ``n_nodes = len(m.n)``, ``C^T[I, J] = R_J(xi_I)``.

    Returns
    -------
    B : csr (m.ndof, 2 * n_spline), ``B[m.conn[I, c], c * n_spline + J] = C[J, I]``.
    """
    m = _connected(m)
    conn = np.asarray(m.conn, dtype=np.int64)
    if C.shape[1] != conn.shape[0]:
        raise ValueError(f"C has {C.shape[1]} columns but the pyxel mesh has "
                         f"{conn.shape[0]} nodes (m.n)")
    return reduced_basis(C, conn[:, :2], int(m.ndof))


def project_on_basis(B: sps.spmatrix, U: np.ndarray) -> np.ndarray:
    """Least-squares projection ``B a`` of ``U`` on the range of ``B``.

    Parameters
    ----------
    B : sparse (n_dof, k); U : (n_dof,).

    Returns
    -------
    (n_dof,) the closest vector to ``U`` in the range of ``B`` (minimum-norm ``a``).
    """
    U = np.asarray(U, dtype=float)
    if U.shape != (B.shape[0],):
        raise ValueError(f"U has shape {U.shape}, expected ({B.shape[0]},)")
    if not np.any(U):
        return np.zeros_like(U)
    a = spla.lsqr(B, U, atol=1e-14, btol=1e-14, iter_lim=20 * B.shape[1])[0]
    return B @ a


def spline_for_mesh(m: Any, margin: float = 0.0, degree: int = 2,
                    elements: tuple[int, int] = (1, 1)) -> SplinePatch:
    """A flat B-spline rectangle (z = 0) covering the bounding box of a 2-D mesh.

    Parameters
    ----------
    m : pyxel.Mesh (or anything with ``n`` (n, >= 2) node coordinates).
    margin : enlargement of the box on every side, in mesh units.
    degree : spline degree in both directions.
    elements : number of knot spans (u, v) of this (coarsest) patch.

    Returns
    -------
    SplinePatch with an identity parametrisation: ``x`` affine in ``u``, ``y`` in ``v``.
    """
    nodes = np.asarray(m.n, dtype=float)
    if nodes.ndim != 2 or nodes.shape[1] < 2 or len(nodes) == 0:
        raise ValueError(f"mesh nodes must be (n, >= 2), got {nodes.shape}")
    if margin < 0 or int(degree) < 1 or min(elements) < 1:
        raise ValueError(f"need margin >= 0, degree >= 1, elements >= 1; got {margin}, "
                         f"{degree}, {elements}")
    lo = nodes[:, :2].min(axis=0) - margin
    hi = nodes[:, :2].max(axis=0) + margin
    if np.any(hi <= lo):
        raise ValueError(f"the mesh bounding box {lo.tolist()} - {hi.tolist()} is degenerate")
    p = int(degree)
    knots = tuple(np.r_[np.zeros(p), np.linspace(0.0, 1.0, int(ne) + 1), np.ones(p)]
                  for ne in elements)
    # control points at the Greville abscissae give an affine (identity) map
    grev = [np.convolve(k[1:-1], np.ones(p) / p, mode="valid") for k in knots]
    gu, gv = np.meshgrid(lo[0] + grev[0] * (hi[0] - lo[0]),
                         lo[1] + grev[1] * (hi[1] - lo[1]), indexing="ij")
    control = np.stack([gu, gv, np.zeros_like(gu)], axis=-1)
    return SplinePatch(degrees=(p, p), knots=knots, control_points=control)


def seen_columns(B: sps.spmatrix, H=None) -> tuple[sps.csr_matrix, int]:
    """The columns of a reduced basis ``B = C_s^T`` (n_dof, k) that the data sees, and how
    many were dropped: a column zero on the mesh's nodes (a spline function outside the
    outline) is unseen whatever the images; with the host's ``H`` (n_dof, n_dof), a column
    with a zero diagonal of ``B^T H B`` (relative to the largest) is unseen in these images
    (:mod:`georeg_plugin.levels.support`)."""
    B = sps.csc_matrix(B)
    keep = B.getnnz(axis=0) > 0
    if H is not None and keep.any():
        diag = np.asarray((sps.csr_matrix(H) @ B).multiply(B).sum(axis=0)).ravel()
        keep &= np.abs(diag) > ZERO_PIVOT * np.abs(diag[keep]).max()
    return B[:, np.flatnonzero(keep)].tocsr(), int(np.count_nonzero(~keep))


def independent_columns(B: sps.csr_matrix, rtol: float = 1e-9) -> np.ndarray:
    """Indices of a maximal set of linearly independent columns of ``B`` (n_dof, k).

    A fine spline level can have more functions than a coarse or uneven legacy mesh can
    tell apart at its nodes (e.g. spans cut by a hole); ``B^T H B`` is then singular.
    The range of ``B`` (the displacements it can give) is kept, with a column-pivoted
    QR (LAPACK geqp3 via scipy) choosing the columns; ``rtol`` is relative to ``|R_00|``.
    """
    import scipy.linalg as sla

    gram = (B.T @ B).tocsc()
    try:  # cheap test first: a sparse LU of the Gram matrix
        diag = np.abs(spla.splu(gram).U.diagonal())
        if diag.min() > 1e-8 * diag.max():  # clearly regular: no QR needed
            return np.arange(B.shape[1])
    except RuntimeError:  # exactly singular
        pass
    _, R, pivots = sla.qr(B.toarray(), mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.count_nonzero(d > rtol * d[0]))
    return np.sort(pivots[:rank])


class PyxelAdapter:
    """A pyxel 2-D FE-DIC problem seen through the :class:`adapters.protocol.Adapter` protocol.

    Parameters
    ----------
    f, g : pyxel.Image, reference and deformed images.
    m : pyxel.Mesh (2-D); cam : pyxel.Camera (2-D).
    eps : pyxel's stopping criterion ``|dU| / |U|``; maxiter : Gauss-Newton iterations.
    direct : sparse direct solves (True) or pyxel's Jacobi-CG with rtol 0.1 (False).
    integration : "pixel" (``m.DICIntegration(cam_s)``, about one point per pixel of
        each scale) or "fast" (``MultiscaleInit``'s n x n points per element).

    The images, camera and integration rule of each image scale are built once, with
    pyxel's own coarsening, and cached.
    """

    def __init__(self, f: Any, g: Any, m: Any, cam: Any, *, eps: float = 1e-3,
                 maxiter: int = 30, direct: bool = True, integration: str = "pixel") -> None:
        pyxel = import_pyxel()
        _check_2d(f, m)
        if integration not in INTEGRATION_RULES:
            raise ValueError(f"integration must be one of {INTEGRATION_RULES}, "
                             f"got {integration!r}")
        self._pyxel, self.f, self.g, self.cam = pyxel, f, g, cam
        self.mesh = _connected(m)
        self.eps, self.maxiter, self.direct = float(eps), int(maxiter), bool(direct)
        self.integration = integration
        names = pyxel.mesh.eltype_n2s
        self.nodes = np.asarray(m.n, dtype=float)
        self.connectivity = {names.get(et, str(et)): np.asarray(e) for et, e in m.e.items()}
        self.dof_layout = np.asarray(m.conn, dtype=np.int64)[:, :2]
        self.n_dof = int(m.ndof)
        with _pyxel_output():
            self.element_size_px = float(m.GetApproxElementSize(cam))
        self._scales: dict[int, tuple] = {}

    def _scale(self, image_scale: int) -> tuple:
        """(f_s, g_s, m_s, cam_s, dic, H) at one image scale, as pyxel's MultiscaleInit."""
        if image_scale not in self._scales:
            s = int(image_scale)
            if s < 0:
                raise ValueError(f"image_scale must be >= 0, got {image_scale}")
            f, g = self.f.Copy(), self.g.Copy()
            if s > 0:
                f.SubSample(s)
                g.SubSample(s)
            cam = self.cam.SubSampleCopy(s)
            m = self.mesh.Copy()
            dic = self._pyxel.DICEngine()
            with _pyxel_output():
                if self.integration == "pixel":
                    m.DICIntegration(cam)  # ~1 point per pixel of this scale
                else:  # as MultiscaleInit; (n, G), not Correlate's (cam, aes) call
                    m.DICIntegrationFast(max(int(self.element_size_px) // 2 ** s, 2))
                H = dic.ComputeLHS(f, m, cam)
            logger.info("pyxel scale %d: image %s, %d integration points (%s rule)", s,
                        f.pix.shape, m.npg, self.integration)
            self._scales[s] = (f, g, m, cam, dic, H)
        return self._scales[int(image_scale)]

    def correlate(self, basis: sps.csr_matrix | None, U0: np.ndarray | None,
                  image_scale: int) -> tuple[np.ndarray, float, int]:
        """One pyxel ``Correlate`` at ``image_scale``; returns (U, residual std, iterations)."""
        f, g, m, cam, dic, H = self._scale(image_scale)
        U0 = np.zeros(self.n_dof) if U0 is None else np.asarray(U0, dtype=float)
        engine = _CountingEngine(dic)
        with _pyxel_output():
            U, res = self._pyxel.Correlate(f, g, m, cam, dic=engine, H=H, U0=U0, Basis=basis,
                                           eps=self.eps, maxiter=self.maxiter, disp=True,
                                           direct=self.direct)
        n_iterations = engine.rhs_calls
        if n_iterations >= self.maxiter:
            logger.warning("pyxel Correlate at scale %d stopped at maxiter = %d without "
                           "reaching eps = %g", image_scale, self.maxiter, self.eps)
        return np.asarray(U, dtype=float), float(np.std(res)), n_iterations

    def residual_std(self, U: np.ndarray, image_scale: int = 0) -> float:
        """Gray-level residual std of a displacement ``U`` (m.ndof,) at ``image_scale``."""
        f, g, m, cam, dic, H = self._scale(image_scale)
        with _pyxel_output():
            res = dic.ComputeRES(g, m, cam, np.asarray(U, dtype=float))
        return float(np.std(res))


def correlate_multilevel(f: Any, g: Any, m: Any, cam: Any, patch_coarse: SplinePatch,
                         n_levels: int, scales: tuple[int, ...] | None = None,
                         U0: np.ndarray | None = None, uv: np.ndarray | None = None,
                         eps: float = 1e-3, maxiter: int = 30, integration: str = "pixel"
                         ) -> tuple[np.ndarray, float, tuple[LevelRecord, ...]]:
    """Spline-regularized FE-DIC in pyxel, spline levels coarse to fine (Eqs. 18-21, 28).

    Parameters
    ----------
    f, g : pyxel.Image; m : pyxel.Mesh (2-D, any element types); cam : pyxel.Camera.
    patch_coarse : the coarsest spline (e.g. :func:`spline_for_mesh`), covering the mesh.
    n_levels : number of spline levels (each finer one halves every knot span).
    scales : image scale of each level run, coarse to fine (default
        ``(n_levels - 1, ..., 1, 0)``: the coarsest spline on the coarsest images).
    U0 : (m.ndof,) starting displacement (projected on the coarsest basis); default 0.
    uv : (len(m.n), 2) spline parameters of the nodes if known; default: point
        inversion of the nodes on ``patch_coarse`` (legacy meshes).
    eps, maxiter : pyxel's stopping criterion and iteration cap per level.
    integration : integration rule of each scale, "pixel" or "fast" (:class:`PyxelAdapter`).

    Returns
    -------
    U : (m.ndof,) displacement in pyxel's dof numbering (mesh units);
    residual_std : gray-level residual std at the end of the finest level;
    history : one :class:`LevelRecord` per level, in the order run.
    """
    adapter = PyxelAdapter(f, g, m, cam, eps=eps, maxiter=maxiter, integration=integration)
    n_levels = int(n_levels)
    scales = tuple(range(n_levels - 1, -1, -1)) if scales is None else tuple(scales)
    if n_levels < 1 or len(scales) != n_levels:
        raise ValueError(f"scales must give one image scale per level ({n_levels}), "
                         f"got {scales}")
    used = np.flatnonzero(adapter.dof_layout[:, 0] >= 0)
    nodes = np.c_[adapter.nodes[used, :2], np.zeros(len(used))]  # the plane z = 0
    space = multilevel_space(patch_coarse, n_levels, nodes,
                             uv=None if uv is None else np.asarray(uv)[used])
    U = np.zeros(adapter.n_dof) if U0 is None else np.asarray(U0, dtype=float)
    history = []
    for k, scale in enumerate(scales):  # coarse to fine
        level = n_levels - 1 - k  # Eq. 28 numbering: 0 is the finest
        B = reduced_basis(space.operators[level], adapter.dof_layout[used], adapter.n_dof)
        B, dropped = seen_columns(B, adapter._scale(scale)[-1])
        if dropped:
            logger.info("spline level %d: %d of %d basis functions dropped (zero on the mesh "
                        "or seen by no integration point)", level, dropped, B.shape[1] + dropped)
        keep = independent_columns(B)  # B^T H B must be regular
        if keep.size < B.shape[1]:
            logger.warning("spline level %d: %d of %d basis functions are linearly "
                           "dependent at the FE nodes; kept %d", level,
                           B.shape[1] - keep.size, B.shape[1], keep.size)
            B = B[:, keep].tocsr()
        U_start = project_on_basis(B, U)  # pyxel restricts the updates only
        U, residual_std, n_it = adapter.correlate(B, U_start, scale)  # Eqs. 18-21
        logger.info("spline level %d (%d basis functions) at image scale %d: residual "
                    "std %.3f gray levels after %d iterations", level, B.shape[1], scale,
                    residual_std, n_it)
        history.append(LevelRecord(level=level, image_scale=int(scale), n_basis=B.shape[1],
                                   residual_std=residual_std, n_iterations=n_it, U=U.copy(),
                                   dropped=dropped))
    return U, history[-1].residual_std, tuple(history)


def correlate_fe(f: Any, g: Any, m: Any, cam: Any, init_scales: tuple[int, ...] = (3, 2, 1),
                 U0: np.ndarray | None = None, eps: float = 1e-3, maxiter: int = 30,
                 integration: str = "pixel") -> tuple[np.ndarray, float]:
    """pyxel without the plugin: ``MultiscaleInit`` (its automatic Tikhonov length)
    then an unregularized ``Correlate`` on the full images (``integration`` rule, by
    default pyxel's pixel rule ``m.DICIntegration(cam)``), as pyxel's examples do.

    Returns
    -------
    U : (m.ndof,) displacement; residual_std : gray-level residual std (full scale).
    """
    pyxel = import_pyxel()
    adapter = PyxelAdapter(f, g, m, cam, eps=eps, maxiter=maxiter, integration=integration)
    U = np.zeros(adapter.n_dof) if U0 is None else np.asarray(U0, dtype=float)
    if init_scales:
        with _pyxel_output():
            U = pyxel.MultiscaleInit(f, g, adapter.mesh, cam, scales=list(init_scales),
                                     U0=U, eps=eps)
    U, residual_std, n_it = adapter.correlate(None, U, 0)
    logger.info("plain pyxel FE-DIC: residual std %.3f gray levels after %d iterations",
                residual_std, n_it)
    return U, residual_std
