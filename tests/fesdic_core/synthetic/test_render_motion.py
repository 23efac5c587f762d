"""The renderer's displaced specimen: the texture moves with the material points."""
import numpy as np
import pytest

from fesdic_core.synthetic.motion import (BendingMotion, RigidMotion, StretchMotion,
                                          intersect_displaced)
from fesdic_core.synthetic.rays import pixel_rays
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_texture
from fesdic_core.synthetic.specimen import Specimen, flat_plate

CAMERAS = demo_cameras(image_size=(96, 72), field_mm=40.0)


def _plate():
    return flat_plate(80.0, 60.0, speckle_mm=1.0, seed=3)       # edges outside the views


def test_a_translated_plate_shows_the_translated_texture():
    """Rendering the plate moved by t equals rendering a plate at height t_z painted with
    the texture shifted by (t_x, t_y) (the same rays, the same paint)."""
    plate = _plate()
    texture = speckle_texture(plate).evaluate
    t = (0.3, -0.2, 0.1)
    moved = render_stereo(plate, CAMERAS, supersample=2, bit_depth=None, progress=False,
                          motion=RigidMotion(t))
    painted = Specimen(80.0, 60.0, height=lambda x, y: np.full(np.shape(x), t[2]),
                       height_gradient=lambda x, y: (np.zeros(np.shape(x)),) * 2,
                       texture=lambda x, y: texture(x - t[0], y - t[1]))
    expected = render_stereo(painted, CAMERAS, supersample=2, bit_depth=None, progress=False)
    for a, b in zip(moved, expected):
        assert np.max(np.abs(a - b)) < 1e-4 and np.std(a) > 20


def test_a_bent_plate_is_the_plate_of_that_height():
    """A deflection u_z = w(x) only: the material point (x, y) sits at (x, y, w(x))."""
    plate = _plate()
    bend = BendingMotion(0.5, 40.0)
    moved = render_stereo(plate, CAMERAS, supersample=2, bit_depth=None, progress=False,
                          motion=bend)
    curved = Specimen(80.0, 60.0, height=lambda x, y: 0.5 * (2 * x / 40.0) ** 2,
                      height_gradient=lambda x, y: (0.5 * 8 * x / 1600.0, np.zeros(np.shape(y))),
                      texture=speckle_texture(plate).evaluate)
    expected = render_stereo(curved, CAMERAS, supersample=2, bit_depth=None, progress=False)
    for a, b in zip(moved, expected):
        assert np.max(np.abs(a - b)) < 1e-6


@pytest.mark.parametrize("motion", [RigidMotion((0.5, 0.2, -0.3), rvec=(0.01, -0.02, 0.03)),
                                    StretchMotion(0.02), BendingMotion(1.0, 30.0)])
def test_displaced_rays_hit_the_displaced_material_point(motion):
    """X + u(X) of the returned material point lies on the ray to 1e-9 mm."""
    plate = _plate()
    px = np.random.default_rng(0).uniform(0, 90, (400, 2))
    centre, d = pixel_rays(CAMERAS[0], px)
    x, y, lam = intersect_displaced(plate, motion, centre, d)
    assert np.all(np.isfinite(lam))
    X = np.column_stack([x, y, np.zeros_like(x)])
    np.testing.assert_allclose(X + motion(X), centre + lam[:, None] * d, atol=1e-9)


def test_rigid_motion_is_a_rotation_about_its_centre():
    m = RigidMotion((1.0, 0.0, 0.0), rvec=(0.0, 0.0, np.pi / 2), centre_mm=(1.0, 1.0, 0.0))
    X = np.array([[2.0, 1.0, 0.0], [1.0, 1.0, 5.0]])
    np.testing.assert_allclose(X + m(X), [[2.0, 2.0, 0.0], [2.0, 1.0, 5.0]], atol=1e-12)
