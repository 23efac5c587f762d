"""Calibration of the extrinsics at fixed shape (Eq. 6), with the frozen (gauge) directions."""
import dataclasses

import numpy as np
import pytest

import fesdic_core.shape.calibration as calibration
from fesdic_core.cameras.rig import stereo_extrinsic_jacobian, stereo_transform
from fesdic_core.fe.mesh import node_normals, rectangle_mesh
from fesdic_core.fe.quadrature import pixel_quadrature
from fesdic_core.imaging.image import pyramid
from fesdic_core.residual.graylevel import gray_level_residual
from fesdic_core.shape.calibration import (_parameter_gradients, calibrate_extrinsics,
                                           rigid_rig_gradients, truncated_solve)
from fesdic_core.shape.gauge import move_cameras_with_specimen, pose_directions, tangential_motions
from fesdic_core.shape.operators import current_nodes
from fesdic_core.synthetic.accuracy import stereo_correspondence_error
from fesdic_core.synthetic.render import true_normal_offset

ROTATION = np.deg2rad(1.0) * np.array([1.0, 2.0, -1.0]) / np.sqrt(6.0)   # 1 degree
TRANSLATION = np.array([0.6, -0.48, 0.64])                                # 1 mm


@pytest.fixture(scope="module")
def problem(twisted_scene):
    """True surface nodes of a Q4 12 x 8 mesh, the perturbed rig and its frozen directions."""
    specimen, cameras, images = twisted_scene
    mesh = rectangle_mesh(60.0, 40.0, 12, 8, family="Q4")
    normals = node_normals(mesh)
    nodes = current_nodes(mesh.nodes, normals, true_normal_offset(specimen, mesh.nodes, normals))
    start = move_cameras_with_specimen(cameras, TRANSLATION, ROTATION, np.zeros(3))
    quads = {s: pixel_quadrature(mesh, [c.scaled(s) for c in cameras]) for s in (1, 0)}
    slides, centre = tangential_motions(mesh.nodes, normals, quads[0].L.T @ quads[0].weight_mm2)
    frozen = pose_directions(start, slides, centre, keep_stereo=True)
    pyramids = [pyramid(im, 2) for im in images]
    return dict(specimen=specimen, cameras=cameras, nodes=nodes, start=start, quads=quads,
                frozen=frozen, images={s: [p[s] for p in pyramids] for s in (1, 0)},
                stereo=stereo_transform(*cameras))


def _calibrate(problem, cams, scale, **kwargs):
    quad = problem["quads"][scale]
    return calibrate_extrinsics(quad.points(problem["nodes"]), quad, problem["images"][scale],
                                [c.scaled(scale) for c in cams], stereo=problem["stereo"],
                                frozen=problem["frozen"], **kwargs)


def test_calibration_at_the_true_shape_recovers_the_rig(problem):
    """From the 1 deg / 1 mm pose error, coarse (scale 1) then fine: stereo error << 0.05 px."""
    specimen, cameras, nodes = problem["specimen"], problem["cameras"], problem["nodes"]
    quad = problem["quads"][0]
    before = gray_level_residual(quad.points(nodes), quad, problem["images"][0], problem["start"],
                                 jacobian=None)
    coarse = _calibrate(problem, problem["start"], 1)
    cams = [c.with_extrinsics(s.extrinsics) for c, s in zip(problem["start"], coarse.cameras)]
    fine = _calibrate(problem, cams, 0)
    assert coarse.converged and fine.converged
    assert fine.residual.std_percent < 0.1 * before.std_percent
    stereo_before = stereo_correspondence_error(nodes, problem["start"], cameras, specimen)
    stereo = stereo_correspondence_error(nodes, fine.cameras, cameras, specimen)
    assert np.sqrt(np.mean(stereo_before ** 2)) > 1.0
    assert np.sqrt(np.mean(stereo ** 2)) < 0.05, np.sqrt(np.mean(stereo ** 2))
    # the stereo relation is kept exactly
    for got, want in zip(stereo_transform(*fine.cameras), problem["stereo"]):
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_calibration_step_never_moves_the_frozen_slides(problem):
    """One Gauss-Newton step is orthogonal to the slides in the Jacobi-scaled metric of Eq. 6."""
    quad, start = problem["quads"][1], problem["start"]
    scaled = [c.scaled(1) for c in start]
    X = quad.points(problem["nodes"])
    one = _calibrate(problem, start, 1, max_iter=1)
    dp = one.cameras[0].extrinsics - scaled[0].extrinsics
    res = gray_level_residual(X, quad, problem["images"][1], scaled, jacobian="extrinsic")
    G = _parameter_gradients(res, stereo_extrinsic_jacobian(scaled[0], *problem["stereo"]))
    diag_M = np.einsum("g,gk,gk->k", np.where(res.mask, quad.weight_mm2, 0.0), G, G)
    frozen = problem["frozen"]
    assert frozen.shape == (6, 3)
    metric = diag_M * dp                                    # diag(M) dp
    assert np.linalg.norm(dp) > 1e-3                        # a real step...
    np.testing.assert_allclose(frozen.T @ metric, 0.0,      # ...with no component on the slides
                               atol=1e-9 * np.linalg.norm(frozen, axis=0).max() * np.linalg.norm(metric))


def test_rigid_rig_gradients_equal_the_extrinsic_derivative(problem):
    """With the stereo relation kept, dr/dp0 from dr/dX (the rig's motion is the specimen's
    rigid motion) equals the extrinsic derivative through both cameras (camera 1 following)."""
    quad, start = problem["quads"][1], problem["start"]
    scaled = [c.scaled(1) for c in start]
    X = quad.points(problem["nodes"])
    both = [gray_level_residual(X, quad, problem["images"][1], scaled, jacobian=j)
            for j in ("extrinsic", "point")]
    want = _parameter_gradients(both[0], stereo_extrinsic_jacobian(scaled[0], *problem["stereo"]))
    got = rigid_rig_gradients(both[1].dr_dX, X, scaled[0])
    seen = both[0].mask
    assert seen.sum() > 1000
    scale = np.abs(want[seen]).max(axis=0)                  # per parameter (rad vs mm)
    np.testing.assert_allclose(got[seen] / scale, want[seen] / scale, rtol=0, atol=1e-7)


def test_truncated_solve_is_orthogonal_to_the_frozen_directions():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(40, 6)) * [1.0, 10.0, 100.0, 1.0, 0.1, 5.0]
    M = A.T @ A
    rhs = rng.normal(size=6)
    frozen = rng.normal(size=(6, 2))
    x = truncated_solve(M, rhs, 1e-12, frozen)
    np.testing.assert_allclose(frozen.T @ (np.diag(M) * x), 0.0, atol=1e-9 * np.abs(np.diag(M) * x).max())
    # the residual of M x = rhs is orthogonal to the free directions (a constrained least squares)
    free = np.linalg.svd((frozen * np.diag(M)[:, None]).T)[2][2:].T        # x = free @ y
    np.testing.assert_allclose(free.T @ (M @ x - rhs), 0.0, atol=1e-9 * np.abs(rhs).max())
    np.testing.assert_allclose(truncated_solve(M, rhs, 1e-12), np.linalg.solve(M, rhs), rtol=1e-8)


def test_a_small_step_that_fails_is_not_damped(problem, monkeypatch):
    """``undamped_px``: a step below it that does not lower the residual ends the
    calibration at once (p stagnant), where the Levenberg-Marquardt guard would evaluate
    the images again for every tenfold damping."""
    coarse = _calibrate(problem, problem["start"], 1)
    cams = [c.with_extrinsics(s.extrinsics) for c, s in zip(problem["start"], coarse.cameras)]
    fine = _calibrate(problem, cams, 0)
    best = [c.with_extrinsics(s.extrinsics) for c, s in zip(cams, fine.cameras)]
    quad = problem["quads"][0]
    X = quad.points(problem["nodes"])
    # a start near the optimum that claims a fit 2 % better than the images give there: its
    # Gauss-Newton step (to the optimum, about 0.003 px) cannot reach the residual claimed
    near = move_cameras_with_specimen(best, np.array([2e-4, 0.0, 0.0]), np.zeros(3), np.zeros(3))
    shift = max(np.max(np.linalg.norm(a.project(X) - b.project(X), axis=1))
                for a, b in zip(near, best))
    assert 1e-3 < shift < 0.01                 # the start is near the optimum, below 0.01 px
    real = gray_level_residual(X, quad, problem["images"][0], near, jacobian="point")
    start = dataclasses.replace(real, std_percent=0.98 * real.std_percent)
    calls = []
    original = calibration.gray_level_residual
    monkeypatch.setattr(calibration, "gray_level_residual",
                        lambda *a, **k: calls.append(1) or original(*a, **k))

    def evaluations(undamped_px):
        calls.clear()
        out = calibrate_extrinsics(X, quad, problem["images"][0], near, stereo=problem["stereo"],
                                   frozen=problem["frozen"], start=start, undamped_px=undamped_px)
        return out, len(calls)
    stopped, count = evaluations(0.01)
    assert stopped.converged and stopped.steps == 0 and count == 1
    _, count = evaluations(0.0)
    assert count > 1                           # the guard tried damped steps
