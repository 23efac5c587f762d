"""The joint Gauss-Newton on the poses and the shape (fesdic_core.shape.joint).

The step, solved by the Schur complement through the StepSolver hook, is checked against
the whole (q, p) system with its gauge conditions solved densely (Lagrange multipliers for
``N^T (q + dq) = 0`` and for the frozen slides), for the plain FE solve, Tikhonov (whose step
has a term in q) and a projection on a coarse subspace (the plugin's form, Eq. 21); then
whole measurements, joint against the paper's fixed point.
"""
import numpy as np
import pytest
import scipy.sparse as sps

from fesdic_core.fe.mesh import nodal_areas, node_normals, rectangle_mesh
from fesdic_core.fe.quadrature import pixel_quadrature
from fesdic_core.imaging.image import pyramid
from fesdic_core.residual.graylevel import gray_level_residual
from fesdic_core.cameras.rig import stereo_transform
from fesdic_core.shape.driver import MeasurementSettings, measure
from fesdic_core.shape.gauge import move_cameras_with_specimen
from fesdic_core.shape.joint import joint_step, joint_system, point_derivative
from fesdic_core.solve.solvers import DirectSolver
from fesdic_core.solve.tikhonov import TikhonovSolver
from fesdic_core.synthetic.accuracy import shape_error_to_surface, stereo_correspondence_error

ROTATION = np.deg2rad(1.0) * np.array([1.0, 2.0, -1.0]) / np.sqrt(6.0)   # 1 degree
TRANSLATION = np.array([0.6, -0.48, 0.64])                                # 1 mm


class _Projection:
    """``d = P^T (P H P^T)^-1 P b`` on a random coarse subspace (the form of Eq. 21)."""

    def __init__(self, n: int, m: int, seed: int = 0):
        rng = np.random.default_rng(seed)
        self.P = sps.csr_matrix(rng.uniform(0.0, 1.0, (m, n)))

    def solve(self, H, b, q, scale):
        P = self.P
        return P.T @ np.linalg.solve((P @ H @ P.T).toarray(), P @ b)


def _state(scene, keep_stereo: bool, scale: int = 2):
    specimen, cameras, images = scene
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, family="Q4")
    start = move_cameras_with_specimen(cameras, TRANSLATION, ROTATION, np.zeros(3))
    cams = [c.scaled(scale) for c in start]
    imgs = [pyramid(im, scale + 1)[scale] for im in images]
    normals, weights = node_normals(mesh), nodal_areas(mesh)
    quad = pixel_quadrature(mesh, cams, 1.0, nodes=mesh.nodes)
    q = 0.01 * np.sin(mesh.nodes[:, 0] / 9.0)               # a state off the optimum
    X = quad.points(mesh.nodes + q[:, None] * normals)
    stereo = stereo_transform(*cams) if keep_stereo else None
    res = gray_level_residual(X, quad, imgs, cams, "element",
                              "point" if keep_stereo else "extrinsic")
    if not keep_stereo:
        import dataclasses
        res = dataclasses.replace(res, dr_dX=point_derivative(res, cams))
    system = joint_system(res, X, quad, mesh.nodes, normals, weights, cams, stereo)
    return system, q


def _dense_step(system, H_shape, rhs_shape, P=None):
    """The whole system with its gauge, solved at once: ``dq = P^T z`` (P None: dq free)."""
    s = system
    n, k = s.H_qp.shape
    P = np.eye(n) if P is None else P
    m, kn, kt = P.shape[0], s.N.shape[1], s.F.shape[1]
    D2F = s.F * np.diag(s.M)[:, None]          # slides frozen in Jacobi-scaled parameters
    K = np.zeros((m + k + kn + kt,) * 2)
    K[:m, :m] = P @ H_shape @ P.T
    K[:m, m:m + k] = P @ s.H_qp
    K[m:m + k, :m] = K[:m, m:m + k].T
    K[m:m + k, m:m + k] = s.M
    K[:m, m + k:m + k + kn] = P @ s.N
    K[m + k:m + k + kn, :m] = (P @ s.N).T
    K[m:m + k, m + k + kn:] = D2F
    K[m + k + kn:, m:m + k] = D2F.T
    return K, P, m, k


@pytest.mark.parametrize("keep_stereo", [True, False], ids=["6 unknowns", "12 unknowns"])
@pytest.mark.parametrize("kind", ["fe", "tikhonov", "projection"])
def test_the_schur_step_is_the_dense_step(twisted_scene, keep_stereo, kind):
    """The step through the hook equals the whole (q, p) system solved directly, to 1e-8."""
    system, q = _state(twisted_scene, keep_stereo)
    n = len(q)
    H = system.H.toarray()
    if kind == "fe":
        solver, H_shape, rhs_shape, P = DirectSolver(), H, system.b, None
    elif kind == "tikhonov":
        mesh = rectangle_mesh(60.0, 40.0, 6, 4, family="Q4")
        solver = TikhonovSolver(mesh, 30.0)
        solver.solve(system.H, system.b, q, 2)                 # chooses lam at this scale
        lam, A = solver.last_lambda, solver.A.toarray()
        H_shape, rhs_shape, P = H + lam * A, system.b - lam * A @ q, None
    else:
        solver = _Projection(n, 12)
        H_shape, rhs_shape, P = H, system.b, solver.P.toarray()
    dq, dp = joint_step(system, solver, q, 2)
    K, Pm, m, k = _dense_step(system, H_shape, rhs_shape, P)
    rhs = np.r_[Pm @ rhs_shape, system.b_p, -system.N.T @ q, np.zeros(system.F.shape[1])]
    x = np.linalg.lstsq(K, rhs, rcond=1e-13)[0]
    dq_dense, dp_dense = Pm.T @ x[:m], x[m:m + k]
    assert np.abs(dq).max() > 1e-4 and np.abs(dp).max() > 1e-6            # a real step
    np.testing.assert_allclose(dq, dq_dense, rtol=0, atol=1e-8 * np.abs(dq_dense).max())
    np.testing.assert_allclose(dp, dp_dense, rtol=0, atol=1e-8 * np.abs(dp_dense).max())
    np.testing.assert_allclose(system.N.T @ (q + dq), 0.0, atol=1e-10)      # the gauge
    jacobi2 = np.diag(system.M)
    np.testing.assert_allclose(system.F.T @ (jacobi2 * dp), 0.0,
                               atol=1e-8 * np.abs(system.F.T * jacobi2).sum() * np.abs(dp).max())
    assert system.predicted_fall(dq, dp) > 0.0


def test_the_point_derivative_from_the_extrinsic_one(twisted_scene):
    """``dr/dX = dr/dt0 R0 + dr/dt1 R1`` agrees with the residual's own ``dr/dX``."""
    _, cameras, images = twisted_scene
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, family="Q4")
    quad = pixel_quadrature(mesh, cameras, 1.0)
    X = quad.points(mesh.nodes)
    a = gray_level_residual(X, quad, images, cameras, "element", "extrinsic")
    b = gray_level_residual(X, quad, images, cameras, "element", "point")
    scale = np.abs(b.dr_dX[b.mask]).max()
    np.testing.assert_allclose(point_derivative(a, cameras)[a.mask], b.dr_dX[a.mask],
                               rtol=0, atol=1e-10 * scale)


def _errors(m, specimen, cameras):
    shape = shape_error_to_surface(m.nodes, specimen)
    stereo = stereo_correspondence_error(m.nodes, m.cameras, cameras, specimen)
    return float(np.sqrt(np.mean(shape ** 2))), float(np.sqrt(np.mean(stereo ** 2)))


@pytest.mark.slow
def test_joint_against_the_fixed_point(twisted_scene):
    """From poses 1 degree and 1 mm off, 12 unknowns: the joint Gauss-Newton ends at a lower
    residual than the fixed point, no worse in shape and stereo correspondence, and stagnant at
    the finest scale (its last plain step predicts less than one unit of chi-square, or
    moves nothing)."""
    specimen, cameras, images = twisted_scene
    mesh = rectangle_mesh(60.0, 40.0, 12, 8, family="Q4")
    start = move_cameras_with_specimen(cameras, TRANSLATION, ROTATION, np.zeros(3))
    start[1] = move_cameras_with_specimen(start[1:], np.zeros(3),
                                          np.deg2rad(0.1) * np.array([0, 1.0, 0]), np.zeros(3))[0]
    out = {c: measure(mesh, images, start, DirectSolver(),
                      MeasurementSettings(scales=(2, 1, 0), calibrate=True, keep_stereo=False,
                                          coupling=c)) for c in ("joint", "alternate")}
    joint, alternate = out["joint"], out["alternate"]
    assert joint.ok and joint.scales[-1].converged
    assert joint.residual_percent <= alternate.residual_percent
    (js, jc), (as_, ac) = _errors(joint, specimen, cameras), _errors(alternate, specimen, cameras)
    assert js <= 1.05 * as_ and jc <= 1.05 * ac, (js, as_, jc, ac)
    assert js < 0.01 and jc < 0.05
    stages = [(r["scale"], r["stage"]) for r in joint.history]
    first = [k for k, (scale, _) in enumerate(stages) if scale != 2][0]
    assert {stage for _, stage in stages[first:]} == {"joint"}              # then joint only
    assert {stage for _, stage in stages[:first]} == {"calibration", "joint"}  # poses first
