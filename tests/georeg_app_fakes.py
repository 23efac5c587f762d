"""Small stand-ins for the pipeline's MethodResult / RunResult (same fields), for the
application tests of presentation (report, figures, outputs, CLI wiring): a twisted
100 x 50 mm plate on a coarse Q4 mesh, several methods; optionally failed methods
(without measurement, or with their best one), per-node errors against the truth and
what produced the run (config, inputs with checksums, version, start date)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sps

from fesdic_core.cameras.camera import Camera
from fesdic_core.fe.mesh import SurfaceMesh, rectangle_mesh
from fesdic_core.shape.gauge import best_fit_plane_distance


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
    noise_percent: float = 1.8

    @property
    def residual_percent(self) -> float:
        return self.residual.std_percent


@dataclass(frozen=True)
class FakeResult:
    spec: FakeSpec
    measurement: FakeMeasurement | None
    mesh: SurfaceMesh
    distance_to_bfp_mm: np.ndarray | None
    shape_rms_error_mm: float | None
    spline: object | None = None
    spline_values: np.ndarray | None = None
    status: str = "ok"
    failure: str | None = None
    shape_error_mm: np.ndarray | None = None
    dropped_dofs: dict | None = None


@dataclass(frozen=True)
class FakeRun:
    results: tuple
    truth_available: bool
    images: tuple
    one_fine_iteration_s: float
    config: object | None = None
    inputs: tuple = ()
    version: str = ""
    started: str = ""


@dataclass(frozen=True)
class FakeImages:
    cam0: str
    cam1: str


@dataclass(frozen=True)
class FakeLandmark:
    xyz_mm: np.ndarray
    cam0_px: np.ndarray


@dataclass(frozen=True)
class FakeCameras:
    file: str | None
    landmarks: tuple


@dataclass(frozen=True)
class FakeConfig:
    """Sections as dataclasses, like georeg_app.config.measure.Config."""

    images: FakeImages
    cameras: FakeCameras
    source: str


FAKE_INPUTS = (("image cam0", "/data/left.tif", "ab" * 32), ("image cam1", "/data/right.tif", "cd" * 32),
               ("cameras", "/data/cameras.json", "ef" * 32))

#: why the failed methods of :func:`fake_run` failed
FAILURE = "residual 35.5% is 12.3 x the 2.9% that the image noise explains"


def cameras(shift: float = 0.0) -> tuple:
    """A stereo pair of cameras (rvec, tvec moved by ``shift``)."""
    K = np.array([[4000.0, 0.0, 612.0], [0.0, 4000.0, 408.0], [0.0, 0.0, 1.0]])
    return (Camera(K, np.zeros(5), np.array([0.0, 0.0, shift]), np.array([0.0, 0.0, 500.0 + shift]),
                   (1224, 816), "cam0"),
            Camera(K, np.zeros(5), np.array([0.0, -0.44, shift]), np.array([220.0, 0.0, 520.0]),
                   (1224, 816), "cam1"))


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
           truth=True, node_errors=False, failed=None) -> FakeResult:
    """One method; ``failed`` None (ok), "none" (failed without measurement) or "best"
    (failed, with its best measurement)."""
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
    m = FakeMeasurement(q=q, nodes=nodes, normals=normals, cameras=cameras(0.001 * seed), history=hist,
                        residual=FakeResidual(percent, mask), quadrature=quad,
                        iterations=len(hist), time_s=hist[-1]["time_s"] * 1.05, converged=True)
    values = None if spline is None else rng.standard_normal(
        int(np.prod(spline.control_points.shape[:2])))
    per_node = None
    if truth and node_errors:
        per_node = error_mm * rng.standard_normal(mesh.n_nodes)
    if failed == "none":
        return FakeResult(spec, None, mesh, None, None, status="failed", failure=FAILURE)
    return FakeResult(spec, m, mesh, best_fit_plane_distance(nodes), error_mm if truth else None,
                      spline, values, status="failed" if failed else "ok",
                      failure=FAILURE if failed else None, shape_error_mm=per_node)


def fake_run(truth: bool = True, errors=None, with_spline: bool = True,
             mono_history=None, multi_history=None, residuals=None, failed=None,
             node_errors: bool = False, provenance: bool = False) -> FakeRun:
    """FE, 3 Tikhonov, georeg multiscale and monoscale on a 4 x 2 Q4 plate.

    ``failed``: label -> "none" | "best" (see :func:`result`); ``node_errors``: per-node
    errors against the truth (``shape_error_mm``); ``provenance``: config, inputs with
    checksums, version and start date.
    """
    mesh = rectangle_mesh(100.0, 50.0, 4, 2, "Q4")
    quad = quadrature(mesh)
    errors = errors or {"fe": 0.05, "t5": 0.03, "t10": 0.025, "t20": 0.04, "geo": 0.01, "mono": 0.011}
    spline = None
    if with_spline:
        from georeg_plugin.spline.geometries import rectangle
        spline = rectangle(100.0, 50.0)
    multi_history = multi_history or history(3, 4, 60.0, 2.0, 0.1)
    mono_history = mono_history or history(1, 10, 60.0, 2.0, 0.5)
    residuals = residuals or {}
    failed = failed or {}
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
        results.append(result(mesh, quad, spec, noise, err, pct, hist, seed=k, spline=sp, truth=truth,
                              node_errors=node_errors, failed=failed.get(spec.label)))
    images = (np.zeros((8, 8)), np.zeros((8, 8)))
    if not provenance:
        return FakeRun(tuple(results), truth, images, one_fine_iteration_s=0.5)
    landmark = FakeLandmark(np.array([-50.0, -25.0, 0.0]), np.array([812.3, 1040.8]))
    config = FakeConfig(FakeImages("/data/left.tif", "/data/right.tif"),
                        FakeCameras(None, (landmark,)), "/data/config.toml")
    return FakeRun(tuple(results), truth, images, 0.5, config=config, inputs=FAKE_INPUTS,
                   version="9.8.7", started="2026-11-29T10:00:00+00:00")
