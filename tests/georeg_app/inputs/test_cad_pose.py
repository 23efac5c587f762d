"""[geometry] kind = "cad" without landmarks (issue 22, item 4): the rig's triangulation places
the part (``pose = "auto"`` or a rough pose), then the measurement as with landmarks.

The scene is issue 11's folded plate (tests/scenes.py: two flat faces meeting at a crease,
rendered with its truth), its rig written as a calibration gives it: camera 0 at the origin,
nothing said of where the part is.
"""
import dataclasses

import numpy as np
import pytest

from fesdic_core.cameras.icp import rotation_vector
from fesdic_core.cameras.io.formats import write_opencv_stereo
from fesdic_core.imaging.image import read_image
from georeg_app.config.cad import RoughPose
from georeg_app.config.measure import ConfigError, load_config
from georeg_app.errors import InputError
from georeg_app.inputs.cad_pose import in_frame, place_part
from georeg_app.inputs.cameras import load_cameras
from georeg_app.shape.demo import Truth
from georeg_app.shape.methods import georeg_spec
from georeg_app.shape.pipeline import run_methods
from georeg_plugin.io.spline_io import write_iges
from georeg_plugin.spline.geometries import quadrilateral
from scenes import cad_nominal, cad_scene
from shape_truth import bounded_shape_error, rms
from user_data import user_config, write_user_data

pytestmark = pytest.mark.slow         # a CAD part rendered and measured

CAMERAS = 'opencv = "stereo.yml"'
#: the truth of the pose, over the part's corners: along its normal (what the shape sees) and
#: in its plane; the slide along the crease is set by the plate's ends alone (matches stop a
#: few px short of an edge), hence about 2 px there (0.15 mm a px), and the real part's
#: slope (0.105 for the CAD's 0.1) moves the best fit of the CAD along its normal by tens of um
MAX_NORMAL_MM, MAX_SLIDE_MM, MAX_ANGLE_DEG = 0.1, 0.3, 0.2


@pytest.fixture(scope="module")
def folded(tmp_path_factory):
    """The folded plate's files (images, IGES, the rig in camera 0's frame) and its scene."""
    scene = cad_scene("folded")
    folder = write_user_data(tmp_path_factory.mktemp("folded"), scene.arrays, scene.cameras)
    write_iges(folder / "part.igs", cad_nominal("folded"), names=["left", "right"])
    R0, t0 = scene.cameras[0].R, scene.cameras[0].tvec
    write_opencv_stereo(folder / "stereo.yml", [in_frame(c, R0.T, -R0.T @ t0)
                                                for c in scene.cameras])
    return folder, scene


def _config(folder, geometry_extra, cameras=CAMERAS, top=""):
    geometry = f'kind = "cad"\nfile = "part.igs"\nelements = 64\n{geometry_extra}'
    path = folder / "config.toml"
    path.write_text(top + user_config(geometry, "levels = 2\nscales = 2", cameras=cameras))
    return path


def _pose_error(cameras, truth):
    """Camera 0's pose against the truth: the rotation (deg), and the largest displacement
    of the part's corners along its normal and in its plane (mm)."""
    angle = np.degrees(np.linalg.norm(rotation_vector(cameras[0].R @ truth[0].R.T)))
    corners = np.array([[x, y, 0.0] for x in (-30, 30) for y in (-20, 20)])
    d = (truth[0].R.T @ ((cameras[0].R @ corners.T).T + cameras[0].tvec - truth[0].tvec).T).T
    d -= corners                          # the corners' displacement in the part's frame
    return angle, float(np.max(np.abs(d[:, 2]))), float(np.max(np.linalg.norm(d[:, :2], axis=1)))


def _assert_near_the_truth(cameras, truth):
    angle, normal, slide = _pose_error(cameras, truth)
    assert angle < MAX_ANGLE_DEG and normal < MAX_NORMAL_MM and slide < MAX_SLIDE_MM, \
        (angle, normal, slide)


def _images(config):
    return [read_image(p) for p in (config.images.cam0, config.images.cam1)]


def _placed(folder, pose_line):
    config = load_config(_config(folder, pose_line))
    images = _images(config)
    return config, images, place_part(config.geometry, load_cameras(config.cameras, images), images)


def test_auto_pose_lands_on_the_true_pose(folded):
    folder, scene = folded
    _, _, pose = _placed(folder, 'pose = "auto"')
    _assert_near_the_truth(pose.cameras, scene.cameras)
    summary = pose.summary()
    assert summary["start"] == "auto" and summary["inliers"] >= 50
    assert summary["misfit_mm"] < 3 * summary["noise_mm"] + 0.01, summary


def test_a_rough_pose_off_by_degrees_and_mm_lands_on_the_same_pose(folded):
    folder, scene = folded
    cam0 = scene.cameras[0]
    rotation = np.degrees(rotation_vector(cam0.R)) + [4.0, -3.0, 5.0]
    translation = cam0.tvec + [3.0, -4.0, 5.0]
    line = (f"pose = {{rotation_deg = {rotation.tolist()}, "
            f"translation_mm = {translation.tolist()}}}")
    config, _, pose = _placed(folder, line)
    assert isinstance(config.geometry.pose, RoughPose)
    _assert_near_the_truth(pose.cameras, scene.cameras)
    assert pose.summary()["start"] == "given"


def test_measured_without_landmarks_within_5_um_of_the_truth(folded):
    """As test_cad's posed run (georeg 2 levels, RMS error <= 5 um), the pose found here."""
    folder, scene = folded
    config = load_config(_config(folder, 'pose = "auto"'))
    run = run_methods(config, [georeg_spec(2, (1, 0))], images=scene.images,
                      truth=Truth(scene.specimen, scene.cameras))
    result = run.results[0]
    assert result.ok, result.failure
    error = rms(bounded_shape_error(result.measurement.nodes, scene.specimen))
    assert error <= 5e-3, error
    _assert_near_the_truth(result.measurement.cameras, scene.cameras)
    assert run.specimen["placed_by"] == "icp"                     # summary.json says how


def test_neither_landmarks_nor_a_pose_is_refused_naming_both(folded):
    folder, _ = folded
    with pytest.raises(ConfigError) as err:
        load_config(_config(folder, ""))
    message = str(err.value)
    assert "[cameras] opencv: needs at least 4 [[landmarks]]" in message
    assert 'pose = "auto"' in message


def test_a_pose_and_landmarks_together_are_refused(folded):
    folder, _ = folded
    landmarks = "".join(f"[[landmarks]]\nxyz_mm = [{x}, 0.0, 0.0]\ncam0_px = [1.0, 2.0]\n"
                        f"cam1_px = [3.0, 4.0]\n" for x in range(4))
    with pytest.raises(ConfigError, match=r"\[cameras\] landmarks: not used with \[geometry\] pose"):
        load_config(_config(folder, 'pose = "auto"', top=landmarks))


@pytest.mark.parametrize("line, match", [
    ('pose = "landmarks"', r'\[geometry\] pose: expected "auto" or a table'),
    ("pose = {rotation_deg = [1.0, 2.0]}", r"\[geometry\] pose rotation_deg: expected a list of 3"),
    ("pose = {rotation_deg = [0.0, 0.0, 0.0]}", r"\[geometry\] pose translation_mm: missing"),
    ("pose = {rotation_deg = [0, 0, 0], translation_mm = [0, 0, 1], scale = 2}",
     r"\[geometry\] pose scale: unknown key"),
])
def test_bad_pose_tables_are_refused_naming_the_key(folded, line, match):
    folder, _ = folded
    with pytest.raises(ConfigError, match=match):
        load_config(_config(folder, line))


def test_a_pose_with_another_kind_is_refused(tmp_path):
    (tmp_path / "cam0.png").write_bytes(b"")
    (tmp_path / "cam1.png").write_bytes(b"")
    (tmp_path / "cameras.json").write_text("{}")
    path = tmp_path / "config.toml"
    path.write_text(user_config('kind = "rectangle"\nlength_mm = 10.0\nwidth_mm = 5.0\n'
                                'pose = "auto"'))
    with pytest.raises(ConfigError, match=r'\[geometry\] pose: not used with kind = "rectangle"'):
        load_config(path)


def test_points_off_the_faces_are_refused_with_the_numbers(folded):
    """The wrong CAD (a fold of slope 0.3 for the part's 0.105: no pose fits both faces) is an
    error naming the numbers, not a pose handed to the measurement."""
    folder, _ = folded
    half, w, z = 30.0, 20.0, -9.0
    write_iges(folder / "wrong.igs",
               [quadrilateral([[-half, -w, z], [0, -w, 0], [0, w, 0], [-half, w, z]]),
                quadrilateral([[0, -w, 0], [half, -w, z], [half, w, z], [0, w, 0]])],
               names=["left", "right"])
    config = load_config(_config(folder, 'pose = "auto"'))
    geometry = dataclasses.replace(config.geometry, file=folder / "wrong.igs")
    images = _images(config)
    with pytest.raises(InputError, match=r"\[geometry\] pose: .* (points|um RMS)"):
        place_part(geometry, load_cameras(config.cameras, images), images)


def test_the_report_s_configuration_holds_the_rough_pose_as_a_table(folded):
    import tomllib

    from georeg_app.report.provenance import config_toml
    folder, _ = folded
    line = "pose = {rotation_deg = [180.0, 0.0, 10.0], translation_mm = [1.0, 2.0, 400.0]}"
    shown = tomllib.loads(config_toml(load_config(_config(folder, line))))
    assert shown["geometry"]["pose"] == {"rotation_deg": [180.0, 0.0, 10.0],
                                         "translation_mm": [1.0, 2.0, 400.0]}
