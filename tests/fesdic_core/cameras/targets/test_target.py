"""Calibration targets: their points, their checks, and OpenCV's detectors on rendered boards."""
import numpy as np
import pytest

from fesdic_core.cameras.targets import Target, detect
from fesdic_core.synthetic.render import demo_cameras, render_stereo
from fesdic_core.synthetic.target import plate_points, posed_rig, target_specimen


def test_object_points_follow_the_grid_and_its_pitch():
    dots = Target("dots", 3, 4, 5.0, markers=((0, 0), (0, 2), (3, 2)))
    points = dots.object_points()
    assert points.shape == (12, 3) and np.allclose(points[5], [5.0, 5.0, 0.0])
    asym = Target("asymmetric_circles", 3, 4, 5.0).object_points()
    assert np.allclose(asym[4], [5.0, 5.0, 0.0]) and np.allclose(asym[1], [10.0, 0.0, 0.0])
    charuco = Target("charuco", 5, 7, 10.0, marker_mm=7.0)
    assert len(charuco.object_points()) == 4 * 6 and np.allclose(charuco.object_points()[0], [10, 10, 0])


@pytest.mark.parametrize("kwargs, message", [
    (dict(kind="spots"), "kind must be one of"),
    (dict(rows=1), "rows must be an integer of at least 2"),
    (dict(pitch_mm=-1.0), "pitch_mm must be a positive number"),
    (dict(markers=((0, 0), (1, 1))), "at least 3 ring markers"),
    (dict(markers=((0, 0), (1, 1), (2, 2))), "collinear"),
    (dict(markers=((0, 0), (1, 1), (20, 2))), "inside the 4 x 3 grid"),
    (dict(dot_diameter_mm=6.0), "dot_diameter_mm must lie in"),
])
def test_a_bad_target_is_refused_naming_the_field(kwargs, message):
    base = dict(kind="dots", rows=3, columns=4, pitch_mm=5.0, markers=((0, 0), (0, 2), (3, 2)))
    with pytest.raises(ValueError, match=message):
        Target(**{**base, **kwargs})


def test_the_checkerboard_detector_finds_the_rendered_corners_at_their_projection():
    target = Target("checkerboard", 6, 9, 6.0)
    rig = demo_cameras(image_size=(480, 360), field_mm=100.0)
    rvec, tvec = np.array([0.2, -0.15, 0.1]), np.zeros(3)
    cams = posed_rig(rig, rvec, tvec)
    image = render_stereo(target_specimen(target), cams[:1], supersample=3, noise_std=1.0,
                          progress=False)[0].astype(np.uint8)
    d = detect(image, target, "board.png")
    assert d.n_points == 54 and not d.note
    truth = cams[0].project(plate_points(target)[d.ids])
    error = np.linalg.norm(d.px - truth, axis=1)
    assert np.sqrt(np.mean(error ** 2)) < 0.1 and np.max(error) < 0.2, error   # 0.07, 0.13


def test_a_uniform_image_gives_an_empty_detection_with_a_reason():
    for target in (Target("checkerboard", 6, 9, 6.0),
                   Target("dots", 3, 4, 5.0, markers=((0, 0), (0, 2), (3, 2))),
                   Target("circles", 4, 5, 5.0)):
        d = detect(np.full((100, 120), 200, np.uint8), target, "flat.png")
        assert d.n_points == 0 and d.note
