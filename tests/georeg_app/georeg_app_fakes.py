"""Small stand-ins for the pipeline's MethodResult / RunResult (same fields), for the
application tests: a twisted 100 x 50 mm plate on a coarse Q4 mesh, several methods."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sps

from fesdic_core.gauge import best_fit_plane_distance
from fesdic_core.mesh import SurfaceMesh, rectangle_mesh


@dataclass(frozen=True)
class FakeSpec:
    name: str
    param: float | None
    scales: tuple[int, ...]
    label: str


@dataclass(frozen=True)
class FakeResidual:
    percent: np.ndarray
    mask: np.ndarray

    @property
    def std_percent(self) -> float:
        return float(np.std(self.percent[self.mask]))


@dataclass(frozen=True)
class FakeQuadrature:
    L: sps.csr_matrix
    element: np.ndarray

    def points(self, nodes: np.ndarray) -> np.ndarray:
        return self.L @ nodes


@dataclass(frozen=True)
class FakeMeasurement:
    q: np.ndarray
    nodes: np.ndarray
    normals: np.ndarray
    cameras: tuple
    residual: FakeResidual
    quadrature: FakeQuadrature
    history: tuple = field(repr=False)
    iterations: int = 0
    time_s: float = 0.0
    converged: bool = True

    @property
    def residual_percent(self) -> float:
        return self.residual.std_percent


@dataclass(frozen=True)
class FakeResult:
    spec: FakeSpec
    measurement: FakeMeasurement
    mesh: SurfaceMesh
    distance_to_bfp_mm: np.ndarray
    shape_rms_error_mm: float | None
    spline: object | None = None
    spline_values: np.ndarray | None = None


@dataclass(frozen=True)
class FakeRun:
    results: tuple
    truth_available: bool
    images: tuple
    one_fine_iteration_s: float


def quadrature(mesh: SurfaceMesh, n: int = 4) -> FakeQuadrature:
    """n x n points per element at sub-cell centres (one Q4 block)."""
    block = mesh.blocks[0]
    t = (np.arange(n) + 0.5) / n * 2 - 1
    xi = np.column_stack([np.repeat(t, n), np.tile(t, n)])
    N = block.family.shape_functions(xi)                                  # (m, nn)
    ne, m = block.n_elements, len(xi)
    rows = np.repeat(np.arange(ne * m), block.family.n_nodes)
    cols = np.repeat(block.connectivity, m, axis=0).ravel()
    vals = np.tile(N, (ne, 1)).ravel()
    L = sps.csr_matrix((vals, (rows, cols)), shape=(ne * m, mesh.n_nodes))
    return FakeQuadrature(L, np.repeat(np.arange(ne), m))


def history(n_scales: int, per_scale: int, start: float, final: float, dt: float) -> tuple:
    """Shape records decreasing geometrically from ``start`` to ``final`` residual (%)."""
    records, k, total = [], 0, n_scales * per_scale
    for s in range(n_scales - 1, -1, -1):
        for it in range(1, per_scale + 1):
            k += 1
            r = start * (final / start) ** (k / total)
            records.append({"scale": s, "fixed_point": 1, "stage": "shape", "iteration": it,
                            "residual_percent": r, "step": 0.1, "n_points": 100,
                            "time_s": k * dt * 4.0 ** (-s)})
    return tuple(records)


def result(mesh, quad, spec, noise_mm, error_mm, residual_pct, hist, seed, spline=None,
           truth=True) -> FakeResult:
    rng = np.random.default_rng(seed)
    x, y = mesh.nodes[:, 0], mesh.nodes[:, 1]
    q = 0.02 * x * y / 25 + noise_mm * rng.standard_normal(mesh.n_nodes)   # ~1 mm twist
    normals = np.tile([0.0, 0.0, 1.0], (mesh.n_nodes, 1))
    nodes = mesh.nodes + q[:, None] * normals
    g = quad.L.shape[0]
    mask = np.ones(g, bool)
    mask[::17] = False
    z = rng.standard_normal(g)
    z = (z - z[mask].mean()) / z[mask].std()                 # std over the mask exactly 1
    percent = np.where(mask, residual_pct * z, np.nan)
    m = FakeMeasurement(q=q, nodes=nodes, normals=normals, cameras=(), history=hist,
                        residual=FakeResidual(percent, mask), quadrature=quad,
                        iterations=len(hist), time_s=hist[-1]["time_s"] * 1.05, converged=True)
    values = None if spline is None else rng.standard_normal(
        int(np.prod(spline.control_points.shape[:2])))
    return FakeResult(spec, m, mesh, best_fit_plane_distance(nodes),
                      error_mm if truth else None, spline, values)


def fake_run(truth: bool = True, errors=None, with_spline: bool = True,
             mono_history=None, multi_history=None, residuals=None) -> FakeRun:
    """FE, 3 Tikhonov, georeg multiscale and monoscale on a 4 x 2 Q4 plate."""
    mesh = rectangle_mesh(100.0, 50.0, 4, 2, "Q4")
    quad = quadrature(mesh)
    errors = errors or {"fe": 0.05, "t5": 0.03, "t10": 0.025, "t20": 0.04, "geo": 0.01, "mono": 0.011}
    spline = None
    if with_spline:
        from georeg_plugin.geometries import rectangle
        spline = rectangle(100.0, 50.0)
    multi_history = multi_history or history(3, 4, 60.0, 2.0, 0.1)
    mono_history = mono_history or history(1, 10, 60.0, 2.0, 0.5)
    residuals = residuals or {}
    specs = [(FakeSpec("fe", None, (2, 1, 0), "FE (multiscale)"), 0.05, errors["fe"], None),
             (FakeSpec("tikhonov", 5.0, (2, 1, 0), "Tikhonov 5 mm"), 0.03, errors["t5"], None),
             (FakeSpec("tikhonov", 10.0, (2, 1, 0), "Tikhonov 10 mm"), 0.02, errors["t10"], None),
             (FakeSpec("tikhonov", 20.0, (2, 1, 0), "Tikhonov 20 mm"), 0.01, errors["t20"], None),
             (FakeSpec("georeg", None, (2, 1, 0), "georeg (multiscale)"), 0.0, errors["geo"], spline),
             (FakeSpec("georeg", None, (0,), "georeg (monoscale)"), 0.0, errors["mono"], spline)]
    results = []
    for k, (spec, noise, err, sp) in enumerate(specs):
        hist = mono_history if "monoscale" in spec.label else multi_history
        pct = residuals.get(spec.label, 2.0)
        results.append(result(mesh, quad, spec, noise, err, pct, hist, seed=k, spline=sp, truth=truth))
    images = (np.zeros((8, 8)), np.zeros((8, 8)))
    return FakeRun(tuple(results), truth, images, one_fine_iteration_s=0.5)
