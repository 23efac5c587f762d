"""Sub-pixel rigid motions on GT4-like renders: the default method within 2 % of the truth.

Issue 27 ("Frames 1-5"): the real GT4 series moves by at most 0.12 px and the codes disagree
by +-12 %. The scene reproduces GT4's rig and images at a crop-sized sensor (320 x 240 px,
focal 6600 px, 390 mm, stereo angle 18.2 deg), its gray levels (mean 72, standard deviation
28.5), its temporal noise (0.8 gray levels, 8 bits) and its hardest texture, camera 1's: a
2.5 px speckle sampled by one ray per pixel (aliased: 5 % of the energy at 0.35-0.5
cycles/px, GT4's camera 1 has 6 %), where the interpolation bias of the image model is the
largest: measured here -0.7 to -1.7 % at 0.05-0.2 px with the default prefilter of 0.5 px,
-1.9 to -3.0 % without it (which these tests would refuse). The true mesh; measured from
rest with the defaults of ``georeg track`` (fe, scales (2, 1, 0), modified Gauss-Newton,
element normalisation, cubic B-spline after a 0.5 px Gaussian).
"""
import numpy as np
import pytest

from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                             measure_displacement)
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.imaging.image import Image
from fesdic_core.synthetic.motion import RigidMotion
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import flat_plate

DISTANCE_MM, FOCAL_PX, ANGLE_DEG = 390.0, 6600.0, 18.2
MM_PER_PX = DISTANCE_MM / FOCAL_PX                               # in plane, at the plate
W_MM_PER_PX = MM_PER_PX / np.sin(np.radians(ANGLE_DEG / 2))      # out of plane: sideways px
GRAY_MEAN, GRAY_STD, NOISE = 71.6, 28.5, 0.8


@pytest.fixture(scope="module")
def gt4_like():
    cameras = demo_cameras(image_size=(320, 240), stereo_angle_deg=ANGLE_DEG,
                           distance_mm=DISTANCE_MM, focal_px=FOCAL_PX)
    plate = flat_plate(18.0, 14.0, speckle_mm=speckle_mm_for(cameras[0], 2.5), seed=5)
    rng = np.random.default_rng(27)
    clean_reference = render_stereo(plate, cameras, supersample=1, bit_depth=None, progress=False)
    view = clean_reference[0][60:180, 80:240]
    a = GRAY_STD / view.std()
    b = GRAY_MEAN - a * view.mean()

    def images(clean, tag):
        return [Image.from_array(np.clip(np.rint(a * c + b + rng.normal(0.0, NOISE, c.shape)), 0, 255),
                                 source=f"{tag} cam{k}") for k, c in enumerate(clean)]

    mesh = rectangle_mesh(12.0, 9.0, 4, 3, family="Q9")
    reference = displacement_reference(mesh, images(clean_reference, "reference"), cameras,
                                       DisplacementSettings(scales=(2, 1, 0)))

    def measure(translation_mm):
        clean = render_stereo(plate, cameras, supersample=1, bit_depth=None, progress=False,
                              motion=RigidMotion(translation_mm))
        m = measure_displacement(reference, images(clean, "deformed"))
        assert m.ok, m.failure
        return m.U.mean(axis=0)
    return measure


@pytest.mark.slow
@pytest.mark.parametrize("pixels", [0.05, 0.1, 0.2])
def test_a_sub_pixel_in_plane_translation_is_recovered_within_2_percent(gt4_like, pixels):
    truth = pixels * MM_PER_PX
    U = gt4_like((truth, 0.0, 0.0))
    assert abs(U[0] - truth) <= 0.02 * truth, (U[0] / truth - 1.0) * 100.0
    assert abs(U[1]) / MM_PER_PX <= 0.002 and abs(U[2]) / W_MM_PER_PX <= 0.002, U


@pytest.mark.slow
@pytest.mark.parametrize("pixels", [0.05, 0.1, 0.2])
def test_a_sub_pixel_out_of_plane_translation_is_recovered_within_2_percent(gt4_like, pixels):
    truth = pixels * W_MM_PER_PX
    U = gt4_like((0.0, 0.0, truth))
    assert abs(U[2] - truth) <= 0.02 * truth, (U[2] / truth - 1.0) * 100.0
    assert abs(U[0]) / MM_PER_PX <= 0.002 and abs(U[1]) / MM_PER_PX <= 0.002, U
