"""3-D displacement FE stereo-DIC on renders of a displaced plate with known motion.

The scene: a flat 60 x 40 mm plate, two cameras at 25 deg, 320 x 240 px over 72 mm
(0.225 mm/px, about twice the demo's pixel), 4 px speckle, noise of 2 gray levels in
every image (independent seeds). The reference surface is the true plate (z = 0) meshed
over its central 44 x 30 mm. Bounds are about twice the errors measured at this scale
(rigid: 0.85 / 0.48 / 3.1 um RMS in x / y / z; stretch: E_xx RMS error 73 microstrain).
"""
import numpy as np
import pytest
import scipy.sparse as sps

from fesdic_core.displacement import residual as displacement_residual_module
from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                             measure_displacement)
from fesdic_core.displacement.residual import (chi_square, displacement_operators,
                                               displacement_residual, displacement_rhs,
                                               reference_view)
from fesdic_core.displacement.solvers import ComponentTikhonovSolver, componentwise
from fesdic_core.displacement.strain import surface_green_lagrange
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.fe.quadrature import pixel_quadrature
from fesdic_core.imaging.image import Image
from fesdic_core.solve.solvers import DirectSolver, StepSolver, sparse_solve
from fesdic_core.synthetic.motion import BendingMotion, RigidMotion, StretchMotion
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import flat_plate

RIGID = RigidMotion((0.3, -0.2, 0.1), rvec=(0.0, 0.003, 0.002))
STRETCH = StretchMotion(0.005)
BENDING = BendingMotion(0.5, 60.0)          # 0.5 mm at the plate's ends, 0.27 mm at the mesh's
SETTINGS = DisplacementSettings(scales=(2, 1, 0))


def _images(arrays, tag):
    return tuple(Image.from_array(a, source=f"{tag} cam{k}") for k, a in enumerate(arrays))


@pytest.fixture(scope="module")
def scene():
    cameras = demo_cameras(image_size=(320, 240), field_mm=72.0)
    specimen = flat_plate(60.0, 40.0, speckle_mm=speckle_mm_for(cameras[0], 4.0), seed=3)
    cache = {}

    def pair(motion):
        key = repr(motion)
        if key not in cache:
            seed = 1 if motion is None else 2
            cache[key] = _images(render_stereo(specimen, cameras, supersample=3, noise_std=2.0,
                                               seed=seed, progress=False, motion=motion),
                                 "reference" if motion is None else "deformed")
        return cache[key]
    return cameras, pair


def _reference(scene, family="Q4", nx=4, ny=3, settings=SETTINGS):
    cameras, pair = scene
    mesh = rectangle_mesh(44.0, 30.0, nx, ny, family=family)
    return mesh, displacement_reference(mesh, pair(None), cameras, settings)


def _rms(error):
    return np.sqrt(np.mean(error ** 2, axis=0))


def test_zero_displacement_on_identical_images(scene):
    mesh, reference = _reference(scene)
    m = measure_displacement(reference, reference.images)
    assert m.ok and m.converged, m.failure
    assert np.max(np.abs(m.U)) < 1e-12
    assert m.residual_percent < 1e-9


@pytest.mark.slow
def test_rigid_translation_and_rotation(scene):
    """0.3 / -0.2 / 0.1 mm and rotations of 3 and 2 mrad (up to 0.07 mm more at the mesh's
    corners) from rest: RMS error below 1.5 um in plane, 6 um out of plane."""
    mesh, reference = _reference(scene)
    m = measure_displacement(reference, scene[1](RIGID))
    assert m.ok and m.converged, m.failure
    rms = _rms(m.U - RIGID(mesh.nodes))
    assert np.all(rms[:2] < 1.5e-3) and rms[2] < 6e-3, f"RMS error {1e3 * rms} um"


@pytest.mark.slow
def test_in_plane_stretch_and_its_strain(scene):
    """A 0.5 % stretch along x (up to 0.11 mm at the mesh's ends): displacement RMS error
    below 1.5 um in plane, Green-Lagrange E_xx = 0.005 + 0.005**2 / 2 to 150 microstrain RMS
    and its mean to 100 microstrain, E_yy and E_xy zero to 150 microstrain RMS."""
    mesh, reference = _reference(scene)
    m = measure_displacement(reference, scene[1](STRETCH))
    assert m.ok and m.converged, m.failure
    rms = _rms(m.U - STRETCH(mesh.nodes))
    assert np.all(rms[:2] < 1.5e-3) and rms[2] < 6e-3, f"RMS error {1e3 * rms} um"
    strain = surface_green_lagrange(mesh, m.U)
    truth = np.array([0.005 + 0.5 * 0.005 ** 2, 0.0, 0.0])
    strain_rms = _rms(strain - truth)
    assert np.all(strain_rms < 150e-6), f"strain RMS error {1e6 * strain_rms} microstrain"
    assert abs(strain[:, 0].mean() - truth[0]) < 100e-6


@pytest.mark.slow
def test_out_of_plane_bending(scene):
    """A parabolic deflection (0.27 mm at the mesh's ends) on Q9 elements, which hold it
    exactly: RMS error below 3 um in plane, 10 um out of plane."""
    mesh, reference = _reference(scene, family="Q9")
    m = measure_displacement(reference, scene[1](BENDING))
    assert m.ok and m.converged, m.failure
    truth = BENDING(mesh.nodes)
    rms = _rms(m.U - truth)
    assert np.all(rms[:2] < 3e-3) and rms[2] < 10e-3, f"RMS error {1e3 * rms} um"
    assert np.ptp(truth[:, 2]) > 0.25


def _objective(U, view, images):
    res = displacement_residual(U, view, images, "none", jacobian=False)
    return 0.5 * np.sum(np.where(res.mask, view.quad.weight_mm2, 0.0) * res.r ** 2), res.mask


def test_b_is_minus_the_gradient_of_the_cost(scene):
    """Without normalisation the linearisation is exact: b = -dj/dU by central differences,
    for every component; H is symmetric positive semi-definite."""
    cameras, pair = scene
    mesh = rectangle_mesh(44.0, 30.0, 2, 2, family="Q9")
    quad = pixel_quadrature(mesh, cameras, points_per_px=0.7)
    view = reference_view(quad, mesh.nodes, pair(None), cameras, 0)
    images = pair(RIGID)
    rng = np.random.default_rng(0)
    U = RIGID(mesh.nodes) + 0.02 * rng.standard_normal((mesh.n_nodes, 3))
    H, b = displacement_operators(quad, displacement_residual(U, view, images, "none"))
    h = 1e-5
    for dof in rng.choice(3 * mesh.n_nodes, 9, replace=False):
        e = np.zeros(3 * mesh.n_nodes)
        e[dof] = h
        jp, mp = _objective(U.ravel() + e, view, images)
        jm, mm = _objective(U.ravel() - e, view, images)
        assert np.array_equal(mp, mm)
        np.testing.assert_allclose(-(jp - jm) / (2 * h), b[dof], rtol=2e-3,
                                   atol=1e-6 * np.abs(b).max())
    np.testing.assert_allclose((H - H.T).toarray(), 0.0, atol=1e-9 * abs(H).max())
    assert np.linalg.eigvalsh(H.toarray()).min() > -1e-9 * abs(H).max()


@pytest.mark.parametrize("nonsense", ["noise", "swapped"])
def test_a_nonsense_pair_is_reported_as_failed(scene, nonsense):
    """Pure-noise images, or the two deformed images swapped: a failure, never converged."""
    mesh, reference = _reference(scene)
    if nonsense == "noise":
        rng = np.random.default_rng(4)
        images = _images([rng.uniform(0, 255, (240, 320)) for _ in range(2)], "noise")
    else:
        images = scene[1](RIGID)[::-1]
    m = measure_displacement(reference, images)
    assert not m.ok and not m.converged
    assert ("texture" in m.failure) if nonsense == "noise" else ("noise explains" in m.failure)


class _RecordingSolver:
    def __init__(self):
        self.calls = []

    def solve(self, H, b, U, scale):
        self.calls.append((scale, H.shape, U.shape))
        return DirectSolver().solve(H, b, U, scale)


def test_the_step_solver_hook_sees_every_scale_and_the_3n_dofs(scene):
    mesh, reference = _reference(scene)
    solver = _RecordingSolver()
    assert isinstance(solver, StepSolver)
    measure_displacement(reference, scene[1](RIGID), solver)
    n = 3 * mesh.n_nodes
    assert {c[0] for c in solver.calls} == {2, 1, 0}
    assert all(c[1] == (n, n) and c[2] == (n,) for c in solver.calls)


class _ConstantPerComponent:
    """A one-level 'spline' per component: the constant function, ``C = 1^T`` (1, n), applied
    through ``kron(C, I3)``: the step is the best rigid translation (Eqs. 18-21)."""

    def __init__(self, n):
        self.C = componentwise(sps.csr_matrix(np.ones((1, n))))

    def solve(self, H, b, U, scale):
        return self.C.T @ sparse_solve(self.C @ H @ self.C.T, self.C @ b)


@pytest.mark.slow
def test_a_componentwise_operator_restricts_each_component(scene):
    """kron(C, I3) on the node-major dofs: with C the constant, the field is one translation,
    found to 1 um in plane and 3 um out of plane from a pure translation."""
    mesh, reference = _reference(scene)
    motion = RigidMotion((0.25, 0.15, -0.1))
    m = measure_displacement(reference, scene[1](motion), _ConstantPerComponent(mesh.n_nodes))
    assert m.ok, m.failure
    assert np.ptp(m.U, axis=0).max() < 1e-12                   # one translation for every node
    error = m.U[0] - np.array([0.25, 0.15, -0.1])
    assert np.all(np.abs(error[:2]) < 1e-3) and abs(error[2]) < 3e-3, f"error {1e3 * error} um"


def test_tikhonov_on_each_component_keeps_a_translation(scene):
    """A translation has no gradient: A3 = kron(A, I3) does not bias it (length 20 mm)."""
    mesh, reference = _reference(scene)
    motion = RigidMotion((0.25, 0.15, -0.1))
    solver = ComponentTikhonovSolver(mesh, 20.0)
    m = measure_displacement(reference, scene[1](motion), solver)
    assert m.ok, m.failure
    assert set(solver.component_lambdas) == {2, 1, 0}
    lam = solver.component_lambdas[0]            # the rig sees z less: a weaker weight on it
    assert lam[2] < 0.5 * min(lam[0], lam[1])
    assert solver.operator(0).shape == (3 * mesh.n_nodes,) * 2
    rms = _rms(m.U - motion(mesh.nodes))
    assert np.all(rms[:2] < 1.5e-3) and rms[2] < 6e-3, f"RMS error {1e3 * rms} um"


def test_tikhonov_on_each_component_keeps_a_homogeneous_stretch(scene):
    """A 3 % stretch along x has a uniform gradient, which A3 (the gradient's departure from
    its mean) does not penalise: Tikhonov at 20 mm reads it as FE does (RMS error below
    1.5 um in plane, E_xx to 150 microstrain; with the plain gradient operator A it read
    the stretch several percent low)."""
    stretch = StretchMotion(0.03)
    mesh, reference = _reference(scene)
    solver = ComponentTikhonovSolver(mesh, 20.0)
    m = measure_displacement(reference, scene[1](stretch), solver)
    assert m.ok, m.failure
    rms = _rms(m.U - stretch(mesh.nodes))
    assert np.all(rms[:2] < 1.5e-3) and rms[2] < 6e-3, f"RMS error {1e3 * rms} um"
    strain = surface_green_lagrange(mesh, m.U)
    assert abs(strain[:, 0].mean() - (0.03 + 0.5 * 0.03 ** 2)) < 150e-6


def test_tikhonov_step_equals_the_dense_solve():
    """The Woodbury step ``(H + A3)^-1 (b - A3 q)`` against a dense solve with
    ``A3 = kron(A - G^T G / |Omega|, Lam)``, and ``A3`` annihilates every affine field."""
    mesh = rectangle_mesh(20.0, 12.0, 4, 3, family="Q9")
    n = 3 * mesh.n_nodes
    rng = np.random.default_rng(4)
    B = rng.standard_normal((n, 2 * n))
    H = sps.csr_matrix(B @ B.T / n)
    solver = ComponentTikhonovSolver(mesh, 8.0)
    b, q = rng.standard_normal(n), rng.standard_normal(n)
    d = solver.solve(H, b, q, 0)
    W = solver.low_rank(0)
    A3 = solver.operator(0).toarray() - W @ W.T
    assert np.allclose(d, np.linalg.solve(H.toarray() + A3, b - A3 @ q), rtol=1e-9, atol=1e-9)
    x, y = mesh.nodes[:, 0], mesh.nodes[:, 1]
    affine = np.column_stack([0.01 * x - 0.02 * y + 1.0, 0.03 * y, -0.005 * x]).ravel()
    assert np.abs(A3 @ affine).max() < 1e-10 * np.abs(solver.operator(0) @ affine).max()


def test_a_frame_of_another_size_is_refused(scene):
    mesh, reference = _reference(scene)
    small = _images([np.zeros((200, 300)), np.zeros((200, 300))], "small")
    with pytest.raises(ValueError, match="small cam0: image is 300 x 200 px"):
        measure_displacement(reference, small)


@pytest.mark.parametrize("family", ["Q4", "Q9", "T6"])
def test_operators_equal_the_dense_products(scene, family):
    """H = sum_c Phi_c^T W_c Phi_c and b = -sum_c Phi_c^T W_c r_c with the dense
    Phi_c[g, 3I + k] = L_I(xi_g) (dr_c/du_g)_k: the blocked assembly to round-off."""
    cameras, pair = scene
    mesh = rectangle_mesh(44.0, 30.0, 3, 2, family=family)
    quad = pixel_quadrature(mesh, cameras, points_per_px=0.5)
    view = reference_view(quad, mesh.nodes, pair(None), cameras, 0)
    U = 0.01 * np.random.default_rng(0).standard_normal(3 * mesh.n_nodes)
    res = displacement_residual(U, view, pair(RIGID))
    H, b = displacement_operators(quad, res)
    L = quad.L.toarray()
    w = np.where(res.mask, quad.weight_mm2, 0.0)
    H_dense, b_dense = np.zeros((3 * mesh.n_nodes,) * 2), np.zeros(3 * mesh.n_nodes)
    for c in range(2):
        Phi = (L[:, :, None] * res.dr_du[c][:, None, :]).reshape(len(L), -1)
        H_dense += Phi.T @ (w[c][:, None] * Phi)
        b_dense -= Phi.T @ (w[c] * res.r[c])
    np.testing.assert_allclose(H.toarray(), H_dense, rtol=0, atol=1e-12 * np.abs(H_dense).max())
    np.testing.assert_allclose(b, b_dense, rtol=0, atol=1e-12 * np.abs(b_dense).max())
    # b = J^T r from a Jacobian with the weights folded in (the modified Gauss-Newton's)
    wG = (res.dr_du * w[:, :, None]).astype(np.float32)
    b_dense = np.zeros(3 * mesh.n_nodes)
    for c in range(2):
        b_dense -= (L[:, :, None] * wG[c][:, None, :].astype(float)).reshape(len(L), -1).T @ res.r[c]
    b = displacement_rhs(quad, wG, res.r)
    np.testing.assert_allclose(b, b_dense, rtol=0, atol=1e-12 * np.abs(b_dense).max())


@pytest.mark.parametrize("normalisation", ["element", "global"])
def test_the_reference_hessian_is_the_full_one_at_rest(scene, normalisation):
    """At U = 0 on the reference images themselves, the full Gauss-Newton's derivative (the
    deformed images' gradient and contrast at the displaced points) is the reference's:
    the modified Gauss-Newton's H equals the full one to round-off, and its weighted
    Jacobian is the full one's times the weights (in float32)."""
    cameras, pair = scene
    mesh = rectangle_mesh(44.0, 30.0, 3, 2, family="Q9")
    quad = pixel_quadrature(mesh, cameras, points_per_px=0.5)
    view = reference_view(quad, mesh.nodes, pair(None), cameras, 0, normalisation=normalisation)
    res = displacement_residual(np.zeros(3 * mesh.n_nodes), view, view.images, normalisation)
    assert np.array_equal(res.mask, view.seen) and np.max(np.abs(res.r)) < 1e-12
    H, _ = displacement_operators(quad, res)
    scale = np.abs(H).max()
    np.testing.assert_allclose(view.hessian.toarray(), H.toarray(), rtol=0, atol=1e-12 * scale)
    w = np.where(view.seen, quad.weight_mm2, 0.0)[:, :, None]
    np.testing.assert_allclose(view.dr_du, res.dr_du * w, rtol=1e-6,
                               atol=1e-6 * np.abs(res.dr_du * w).max())


@pytest.mark.parametrize("motion", [RIGID, STRETCH], ids=["rigid", "stretch"])
def test_the_modified_and_the_full_gauss_newton_reach_the_same_field(scene, motion):
    """Both minimise the same residual: their fields differ by less than the images' noise
    can tell. Each stops when a step changes the fit by less than 1 unit of chi-square, so
    each is within about 1 unit of the minimum in the norm of H, and the two within
    (1 + 1)**2 = 4 units: ``dU^T H dU n / chi2 < 4`` (measured 1.4 and 1.7), half of their
    error against the truth at most (a noise of some 60 units over the 60 dofs); the
    modified one needs at most twice the full one's iterations (measured 9 against 11 and 7
    against 8)."""
    mesh, modified_ref = _reference(scene)
    _, full_ref = _reference(scene, settings=DisplacementSettings(scales=(2, 1, 0),
                                                                  jacobian="current"))
    images = scene[1](motion)
    modified = measure_displacement(modified_ref, images)
    full = measure_displacement(full_ref, images)
    assert modified.ok and full.ok, (modified.failure, full.failure)
    view = full_ref.view(0)
    res = displacement_residual(full.U, view, images)
    H, _ = displacement_operators(view.quad, res)
    cost, n = chi_square(res, view.quad)
    dU = (modified.U - full.U).ravel()
    distance = float(dU @ (H @ dU)) * n / cost                    # chi-square units
    assert distance < 4.0, f"the fields differ by {distance:.3g} units of chi-square"
    error = _rms(full.U - motion(mesh.nodes))
    assert np.all(_rms(modified.U - full.U) < 0.5 * error), (1e3 * _rms(modified.U - full.U),
                                                            1e3 * error)
    assert modified.iterations <= 2 * full.iterations, (modified.iterations, full.iterations)


def test_settings_are_checked():
    with pytest.raises(ValueError, match="coarse to fine"):
        DisplacementSettings(scales=(0, 1))
    with pytest.raises(ValueError, match="normalisation"):
        DisplacementSettings(normalisation="local")
    with pytest.raises(ValueError, match="jacobian must be one of .*'deformed'"):
        DisplacementSettings(jacobian="deformed")


def test_the_per_block_normalisation_is_the_per_element_one(scene, monkeypatch):
    """The residual normalises each element within its block of points (threads; blocks of
    about 2000 points here, several elements each): the same residual and scales as the
    means and deviations over each element's points taken over the whole region
    (element_sum), to round-off."""
    monkeypatch.setattr(displacement_residual_module, "_BLOCK", 2000)
    cameras, pair = scene
    mesh = rectangle_mesh(44.0, 30.0, 4, 3, family="Q9")
    quad = pixel_quadrature(mesh, cameras, points_per_px=1.0)
    assert len(quad.element_blocks(2000)) > 3
    view = reference_view(quad, mesh.nodes, pair(None), cameras, 0)
    images = pair(RIGID)
    U = RIGID(mesh.nodes)
    res = displacement_residual(U, view, images, "element", jacobian=False)
    X = view.X + quad.points(U)
    for c in range(2):
        m = res.mask[c]
        g = np.where(m, images[c].evaluate(np.where(m[:, None], cameras[c].project(X), 0.0)), 0.0)
        expected = np.zeros(quad.n_points)
        scales = []
        for values, dyn in ((view.f[c], view.dynamic_range[c]),
                            (g, float(images[c].dynamic_range))):
            seen = m.astype(float)
            count = np.maximum(quad.element_sum(seen), 1.0)
            mean = quad.element_sum(values * seen) / count
            sd = np.sqrt(np.maximum(quad.element_sum(values ** 2 * seen) / count - mean ** 2, 0))
            sd = np.maximum(sd, 0.005 * dyn)
            scales.append(sd[quad.element])
            expected = (values - mean[quad.element]) / sd[quad.element] - expected
        np.testing.assert_allclose(res.r[c], np.where(m, -expected, 0.0), rtol=0, atol=1e-9)
        np.testing.assert_allclose(res.sigma_ref[c], scales[0], rtol=1e-12)


def test_displacement_operators_refuse_a_residual_without_its_derivative():
    """The Gauss-Newton operators need dr/du: a residual computed without it is refused by
    name (before the quadrature is read)."""
    from fesdic_core.displacement.residual import DisplacementResidual
    res = DisplacementResidual(r=np.zeros((2, 3)), mask=np.ones((2, 3), bool), dr_du=None,
                               sigma_ref=np.ones((2, 3)), dynamic_range=np.ones(2),
                               std_percent=0.0)
    with pytest.raises(ValueError, match="no dr/du"):
        displacement_operators(None, res)
