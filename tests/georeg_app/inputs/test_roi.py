"""``[geometry] kind = "roi"``: a specimen drawn on camera 0's image, placed by the calibrated rig.

A flat 60 x 40 mm plate rendered by the demo's rig (640 x 480 px), its cameras given in a world
frame that is NOT the plate's (rotated and shifted), so that nothing but the triangulation can
place it; the true plate is z = 0 of the rendering frame.
"""
import json

import cv2
import meshio
import numpy as np
import pytest
from user_data import write_user_data

from fesdic_core.cameras.rig import read_cameras_json
from fesdic_core.imaging.image import Image
from fesdic_core.synthetic.accuracy import shape_error_to_surface
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import Specimen
from georeg_app import cli
from georeg_app.config.measure import GeometryConfig, load_config
from georeg_app.config.roi import RoiConfig
from georeg_app.config.toml_schema import ConfigError
from georeg_app.errors import InputError
from georeg_app.inputs.roi import roi_specimen
from georeg_app.inputs.roi_surface import fit_surface
from cli_checks import fails_naming

MOVE_RVEC, MOVE_T = np.array([0.3, -0.2, 0.5]), np.array([10.0, -5.0, 300.0])

CONFIG = """
[images]
cam0 = "cam0.png"
cam1 = "cam1.png"
[cameras]
file = "{cameras}"
[geometry]
kind = "roi"
{roi}
elements = {elements}
[method]
name = "{method}"
levels = 2
scales = 2
calibrate = false
"""


def _moved(cameras):
    """The rig in the world frame X_new = R X + t (the plate z = 0 moves with it)."""
    R = cv2.Rodrigues(MOVE_RVEC)[0]
    return [c.with_extrinsics(np.concatenate([cv2.Rodrigues(c.R @ R.T)[0].ravel(),
                                              c.tvec - c.R @ R.T @ MOVE_T])) for c in cameras]


def _px(camera, xy):
    return camera.project(np.column_stack([xy, np.zeros(len(xy))]))


def _poly(camera, xy):
    return json.dumps(np.round(_px(camera, np.asarray(xy, float)), 2).tolist())


OUTER = [[-27, -18], [27, -18], [27, 18], [-27, 18]]
L_SHAPE = [[-27, -18], [27, -18], [27, 0], [0, 0], [0, 18], [-27, 18]]
HOLE = [[4, -12], [16, -12], [16, -4], [4, -4]]


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    cams = demo_cameras(image_size=(640, 480), field_mm=80.0)
    spec = Specimen(60.0, 40.0, speckle_mm=speckle_mm_for(cams[0], 4.0), seed=3)
    arrays = render_stereo(spec, cams, supersample=2, noise_std=2.0, seed=1, progress=False)
    folder = write_user_data(tmp_path_factory.mktemp("roi"), arrays, _moved(cams))
    return folder, spec, cams, arrays


@pytest.fixture
def noise_folder(tmp_path):
    """Files of a run without a render (for the checks made before any matching)."""
    rng = np.random.default_rng(0)
    cams = demo_cameras(image_size=(640, 480), field_mm=80.0)
    return write_user_data(tmp_path, [rng.integers(0, 255, (480, 640)) for _ in cams], cams)


def _config(folder, roi, name="roi.toml", elements=300, method="fe", cameras="cameras.json"):
    path = folder / name
    path.write_text(CONFIG.format(roi=roi, elements=elements, method=method, cameras=cameras))
    return path


def _to_plate(points, cameras_json, true_cam0):
    """Points of the specimen frame mapped to the rendering frame, through camera 0."""
    cam = read_cameras_json(cameras_json)[0]
    X_cam = points @ cam.R.T + cam.tvec
    return (X_cam - true_cam0.tvec) @ true_cam0.R


def test_fit_surface_recovers_a_tilted_plane_and_a_quadric_despite_outliers():
    rng = np.random.default_rng(4)
    xy = rng.uniform(-20, 20, (400, 2))
    z = 0.002 * xy[:, 0] ** 2 - 0.001 * xy[:, 0] * xy[:, 1] + rng.normal(0, 0.005, 400)
    z[:20] += 3.0                                                     # gross outliers
    R = cv2.Rodrigues(np.array([0.2, 0.1, -0.4]))[0]
    X = np.column_stack([xy, z]) @ R.T + [5, 6, 7]
    quad = fit_surface(X, "quadric")
    assert not quad.inliers[:20].any() and quad.inliers[20:].mean() > 0.97
    assert quad.rms_mm < 0.007
    flat = np.column_stack([xy, rng.normal(0, 0.005, 400)])
    flat[:20, 2] += 2.0
    plane = fit_surface(flat @ R.T + [5, 6, 7], "plane")
    assert np.degrees(np.arccos(abs(plane.normal @ R[:, 2]))) < 0.05
    assert abs((plane.point - [5, 6, 7]) @ R[:, 2]) < 0.002


@pytest.mark.slow
def test_roi_specimen_places_the_plate_from_the_rig(plate):
    folder, _, cams, arrays = plate
    moved = _moved(cams)
    images = [Image.from_array(a) for a in arrays]
    geometry = GeometryConfig("roi", elements=300, polygon_px=_px(cams[0], np.array(OUTER, float)),
                              exclude_px=(_px(cams[0], np.array(HOLE, float)),))
    r = roi_specimen(geometry, moved, images, 2)
    R = cv2.Rodrigues(MOVE_RVEC)[0]
    z_true = R[:, 2]                                   # the plate's normal in the given frame
    angle = np.degrees(np.arccos(r.frame_rotation[:, 2] @ z_true))
    assert angle < 0.05, angle                         # z towards the cameras, on the normal
    # the origin: on the plate, at the area centroid of the outline minus the hole
    hole_area, hole_centre = 12 * 8, np.array([10.0, -8.0])
    centroid = -hole_area * hole_centre / (54 * 36 - hole_area)
    origin = R.T @ (r.frame_origin - MOVE_T)                         # in the plate's frame
    np.testing.assert_allclose(origin, [*centroid, 0.0], atol=0.01)
    assert r.fit.rms_mm < 0.02 and r.misfit_px < 0.2 and r.unseen_share == 0.0
    nodes = r.model.mesh.nodes
    assert np.max(np.abs(nodes[:, 2])) < 1e-9                        # a plane: z = 0
    plate_xy = (nodes @ r.frame_rotation.T + r.frame_origin - MOVE_T) @ R
    inside = lambda p, box: (p[:, 0] > box[0][0] - 1e-6) & (p[:, 0] < box[1][0] + 1e-6) & \
        (p[:, 1] > box[0][1] - 1e-6) & (p[:, 1] < box[1][1] + 1e-6)
    assert inside(plate_xy, ((-27.2, -18.2), (27.2, 18.2))).all()   # inside the outline
    centres = plate_xy[r.model.mesh.blocks[0].connectivity].mean(axis=1)
    assert len(centres) > 150
    assert not inside(centres, ((4, -12), (16, -4))).any()           # none in the hole
    # the staircase boundary loses at most one element width along the outline
    conn = r.model.mesh.blocks[0].connectivity
    area = r.model.mesh.n_elements * np.prod(np.ptp(nodes[conn[0], :2], axis=0))
    assert 0.75 * (54 * 36 - 96) < area <= 54 * 36 - 96
    # four vertices, no hole: the quadrilateral of the cast corners, meshed whole
    quad = roi_specimen(GeometryConfig("roi", elements=300, polygon_px=geometry.polygon_px),
                        moved, images, 2)
    conn = quad.model.mesh.blocks[0].connectivity
    ratio = quad.model.mesh.n_elements / np.prod(quad.model.patch.n_elements)
    assert ratio >= 300 / 2 and 4 ** round(np.log(ratio) / np.log(4)) == ratio   # none dropped
    plate_xy = (quad.model.mesh.nodes @ quad.frame_rotation.T + quad.frame_origin - MOVE_T) @ R
    np.testing.assert_allclose(plate_xy[:, :2].min(axis=0), [-27, -18], atol=0.05)
    np.testing.assert_allclose(plate_xy[:, :2].max(axis=0), [27, 18], atol=0.05)
    np.testing.assert_allclose(R.T @ (quad.frame_origin - MOVE_T), 0.0, atol=0.01)


@pytest.mark.slow
def test_measure_an_l_shaped_roi_with_a_hole_with_fe_and_georeg(plate, tmp_path):
    folder, spec, cams, _ = plate
    rms = {}
    for method in ("fe", "georeg"):
        config = _config(folder, f"polygon_px = {_poly(cams[0], L_SHAPE)}\n"
                                 f"exclude_px = [{_poly(cams[0], HOLE)}]", name=f"l_{method}.toml",
                         method=method)
        out = tmp_path / method
        assert cli.main(["-q", "measure", str(config), "--out", str(out)]) == 0, method
        summary = json.loads((out / "summary.json").read_text())
        (result,) = summary["methods"]
        assert result["status"] == "ok" and summary["specimen"]["matches"] > 500
        stem = result["mesh_file"].removesuffix(".vtu")
        points = _to_plate(meshio.read(out / result["mesh_file"]).points,
                           out / f"{stem}_cameras.json", cams[0])
        assert not np.any((points[:, 0] > 1) & (points[:, 1] > 1))      # the L's notch is empty
        # no alignment to the truth: the rendering frame through camera 0
        rms[method] = float(np.sqrt(np.mean(points[:, 2] ** 2)))
        assert abs(np.median(points[:, 2])) < 0.002, method              # the ROI's placement
        error = shape_error_to_surface(points, spec)
        assert np.sqrt(np.mean(error ** 2)) < 0.02, (method, np.sqrt(np.mean(error ** 2)))
    # the finest level's spline dof over the L's notch sees no node: dropped, not singular
    assert result["dropped_dofs"]["0"]["unseen_mesh"] >= 1
    # FE's own noise on this mesh: 14 um RMS; georeg's spline levels: 0.35 um
    assert rms["fe"] < 0.02 and rms["georeg"] < 0.002 and rms["georeg"] < 0.2 * rms["fe"], rms


@pytest.mark.slow
def test_measure_a_rectangular_roi_with_georeg_and_tikhonov(plate, tmp_path):
    folder, spec, cams, _ = plate
    for method in ("georeg", "tikhonov"):
        out = tmp_path / method
        config = _config(folder, f"polygon_px = {_poly(cams[0], OUTER)}", name=f"{method}.toml",
                         method=method)
        config.write_text(config.read_text() + "tikhonov_length_mm = 20.0\n")
        assert cli.main(["-q", "measure", str(config), "--out", str(out)]) == 0, method
        (result,) = json.loads((out / "summary.json").read_text())["methods"]
        stem = result["mesh_file"].removesuffix(".vtu")
        points = _to_plate(meshio.read(out / result["mesh_file"]).points,
                           out / f"{stem}_cameras.json", cams[0])
        z = points[:, 2]                     # measured about 0.4 um RMS for both methods
        assert np.sqrt(np.mean(z ** 2)) < 0.002, (method, np.sqrt(np.mean(z ** 2)))


def test_roi_keys_are_checked_by_the_config_reader(noise_folder):
    folder = noise_folder
    poly = "polygon_px = [[10, 10], [100, 10], [100, 90]]"
    cases = [("", "exactly one of `polygon_px` and `mask`"),
             (poly + '\nmask = "cam0.png"', "got both"),
             ("polygon_px = [[10, 10], [100, 10]]", "polygon_px"),
             ("polygon_px = [[10, 10], [100, 10], [200, 10]]", "enclosing an area"),
             (poly + '\nsurface = "sphere"', "surface"),
             ('mask = "missing.png"', "mask"),
             (poly + "\nexclude_px = [[1, 2]]", "exclude_px")]
    for roi, expected in cases:
        with pytest.raises(ConfigError, match="geometry") as err:
            load_config(_config(folder, roi))
        assert expected in str(err.value), (roi, str(err.value))
    rect = folder / "rect.toml"
    rect.write_text(_config(folder, poly).read_text().replace('kind = "roi"', 'kind = "rectangle"\n'
                                                              "length_mm = 1\nwidth_mm = 1"))
    with pytest.raises(ConfigError, match='polygon_px: not used with kind = "rectangle"'):
        load_config(rect)
    marks = folder / "marks.toml"
    marks.write_text(_config(folder, poly).read_text() + "[[landmarks]]\nxyz_mm = [0, 0, 0]\n"
                     "cam0_px = [1, 1]\ncam1_px = [1, 1]\n")
    with pytest.raises(ConfigError, match='landmarks: not used with .geometry. kind = "roi"'):
        load_config(marks)


def test_an_roi_outside_the_image_is_one_error_and_nothing_written(noise_folder, capsys):
    tmp_path = noise_folder
    config = _config(noise_folder, "polygon_px = [[10, 10], [700, 10], [300, 200]]", name="out.toml")
    fails_naming(capsys, config, tmp_path / "out", "polygon_px", "outside camera 0's image")


@pytest.mark.slow
def test_bad_rois_are_one_error_each_and_nothing_written(plate, tmp_path, capsys):
    folder, _, cams, arrays = plate
    blank = folder / "blank"
    blank.mkdir()
    write_user_data(blank, [np.full_like(a, 120.0) for a in arrays], _moved(cams))
    config = _config(blank, f"polygon_px = {_poly(cams[0], OUTER)}")
    fails_naming(capsys, config, tmp_path / "a", "polygon_px", "no texture")
    # camera 1 sees another texture (its image upside down): no match on an epipolar line
    other = folder / "other"
    other.mkdir()
    write_user_data(other, [arrays[0], arrays[1][::-1]], _moved(cams))
    config = _config(other, f"polygon_px = {_poly(cams[0], OUTER)}")
    fails_naming(capsys, config, tmp_path / "b", "polygon_px", "too few stereo matches")
    # a wrong calibration: camera 1 shifted 2 mm, the matches leave their epipolar lines
    wrong = _moved(cams)
    wrong[1] = wrong[1].with_extrinsics(wrong[1].extrinsics + [0, 0, 0, 0, 2.0, 0])
    from fesdic_core.cameras.rig import write_cameras_json
    write_cameras_json(folder / "wrong.json", wrong)
    config = _config(folder, f"polygon_px = {_poly(cams[0], OUTER)}", name="wrong.toml",
                     cameras="wrong.json")
    fails_naming(capsys, config, tmp_path / "c", "polygon_px", "stereo matches")


def test_build_model_refuses_the_roi_kind_without_images():
    from georeg_app.inputs.nominal import build_model
    with pytest.raises(InputError, match="specimen_setup"):
        build_model(GeometryConfig("roi", polygon_px=((0, 0), (1, 0), (0, 1))), 2)


@pytest.mark.slow
def test_a_quadric_roi_follows_a_twisted_plate_that_a_plane_misses(twisted_scene, caplog):
    specimen, cams, images = twisted_scene                # z = k x y, 0.5 mm at the corners
    polygon = _px(cams[0], np.array(OUTER, float))
    caplog.set_level("WARNING")
    flat = roi_specimen(GeometryConfig("roi", elements=200, polygon_px=polygon), cams, images, 2)
    assert any("departs from it" in r.message for r in caplog.records)
    r = roi_specimen(GeometryConfig("roi", elements=200, polygon_px=polygon, surface="quadric"),
                     cams, images, 2)
    assert r.misfit_px < 0.3 * flat.misfit_px and r.misfit_px < 2 * r.epipolar_px
    world = r.model.mesh.nodes @ r.frame_rotation.T + r.frame_origin
    error = world[:, 2] - specimen.height(world[:, 0], world[:, 1])
    assert np.sqrt(np.mean(error ** 2)) < 0.005, np.sqrt(np.mean(error ** 2))
    assert np.ptp(r.model.mesh.nodes[:, 2]) > 0.5         # the nominal mesh is curved


def test_a_mask_gives_the_outline_and_the_holes_of_its_polygons(tmp_path):
    from georeg_app.inputs.roi import roi_loops
    outer = np.array([[40, 30], [600, 40], [590, 440], [50, 430]], float)
    hole = np.array([[200, 200], [300, 200], [300, 280], [200, 280]], float)
    mask = np.zeros((480, 640), np.uint8)
    cv2.fillPoly(mask, [outer.astype(np.int32)], 255)
    cv2.fillPoly(mask, [hole.astype(np.int32)], 0)
    cv2.imwrite(str(tmp_path / "roi.png"), mask)
    from_mask, loops = roi_loops(RoiConfig(mask=tmp_path / "roi.png"), (480, 640))
    from_polygons, _ = roi_loops(RoiConfig(polygon=outer, exclude=(hole,)), (480, 640))
    assert len(loops) == 2                                   # the outline and the hole
    assert abs(cv2.contourArea(loops[1].astype(np.float32)) - 100 * 80) < 0.05 * 8000
    differ = np.count_nonzero(from_mask != from_polygons)
    assert differ < 0.01 * from_polygons.sum(), differ       # the boundary pixels only
    cv2.imwrite(str(tmp_path / "small.png"), mask[:100])
    with pytest.raises(InputError, match="mask: .* is 640 x 100 px, camera 0's image 640 x 480"):
        roi_loops(RoiConfig(mask=tmp_path / "small.png"), (480, 640))
    cv2.imwrite(str(tmp_path / "empty.png"), 0 * mask)
    with pytest.raises(InputError, match="no nonzero region"):
        roi_loops(RoiConfig(mask=tmp_path / "empty.png"), (480, 640))


def test_only_a_convex_four_vertex_roi_is_meshed_as_its_quadrilateral():
    from georeg_app.inputs.roi import _convex
    assert _convex(np.array([[0, 0], [4, 0], [4, 3], [0, 3]], float))
    assert _convex(np.array([[0, 0], [0, 3], [4, 3], [4, 0]], float))        # either turn
    assert not _convex(np.array([[0, 0], [4, 0], [1, 1], [0, 4]], float))    # a dart: it folds


@pytest.mark.slow
def test_the_part_of_the_roi_camera_1_does_not_see_is_measured_and_left_out():
    """A plate larger than the views, the ROI the whole of camera 0's image: camera 1's view
    is shifted (the rig's stereo angle), so a strip of the ROI is outside it."""
    cams = demo_cameras(image_size=(320, 240), field_mm=80.0)
    spec = Specimen(160.0, 120.0, speckle_mm=speckle_mm_for(cams[0], 4.0), seed=3)
    arrays = render_stereo(spec, cams, supersample=1, noise_std=2.0, seed=1, progress=False)
    images = [Image.from_array(a) for a in arrays]
    polygon = ((4, 4), (315, 4), (315, 235), (4, 235))
    r = roi_specimen(GeometryConfig("roi", elements=200, polygon_px=polygon), cams, images, 2)
    # the truth: camera 0's ROI pixels cast on the plate z = 0, seen by camera 1 or not
    rows, cols = np.mgrid[4:236, 4:316]
    px = np.column_stack([cols.ravel(), rows.ravel()]).astype(float)
    rays = np.column_stack([(px - cams[0].K[:2, 2]) / cams[0].K[0, 0], np.ones(len(px))]) @ cams[0].R
    X = cams[0].center + (-cams[0].center[2] / rays[:, 2])[:, None] * rays
    p1 = cams[1].project(X)
    seen = (p1[:, 0] >= 2) & (p1[:, 0] <= 317) & (p1[:, 1] >= 2) & (p1[:, 1] <= 237)
    truth = 1 - seen.mean()
    assert truth > 0.005 and abs(r.unseen_share - truth) < 0.1 * truth, (r.unseen_share, truth)
    p = r.cameras[1].project(r.model.mesh.nodes)                     # the mesh: all in view
    assert p[:, 0].min() >= 2 and p[:, 0].max() <= 317


def test_an_roi_configuration_written_back_by_the_report_reads_again(noise_folder):
    from georeg_app.report.provenance import config_toml
    config = load_config(_config(noise_folder, "polygon_px = [[10, 10], [100, 10], [100, 90]]\n"
                                               "exclude_px = [[[40, 20], [60, 20], [60, 40]]]\n"
                                               'surface = "quadric"'))
    again = noise_folder / "again.toml"
    again.write_text(config_toml(config))
    assert load_config(again).geometry == config.geometry
    assert config.geometry.roi.exclude[0].shape == (3, 2) and config.geometry.roi.surface == "quadric"
    plain = load_config(_config(noise_folder, "polygon_px = [[10, 10], [100, 10], [100, 90]]",
                                name="plain.toml"))
    assert plain.geometry.roi.surface == "plane"


@pytest.mark.slow
def test_preview_of_an_roi_states_the_specimen_frame(plate, tmp_path):
    folder, _, cams, _ = plate
    config = _config(folder, f"polygon_px = {_poly(cams[0], L_SHAPE)}", name="preview.toml")
    out = tmp_path / "preview"
    assert cli.main(["-q", "preview", str(config), "--out", str(out)]) == 0
    summary = json.loads((out / "preview.json").read_text())
    assert summary["geometry"] == "roi" and summary["specimen"]["matches"] > 500
    assert summary["elements_seen_fraction"]["both"] == 1.0      # every element in both views
    np.testing.assert_allclose(np.array(summary["specimen"]["frame_axes"]) @
                               np.array(summary["specimen"]["frame_axes"]).T, np.eye(3), atol=1e-9)


def test_an_roi_geometry_goes_through_the_python_front(noise_folder):
    from georeg.inputs import geometry_config
    g = load_config(_config(noise_folder, "polygon_px = [[10, 10], [100, 10], [100, 90]]\n"
                                          "exclude_px = [[[40, 20], [60, 20], [60, 40]]]")).geometry
    assert geometry_config(g, noise_folder) == g
    assert geometry_config({"kind": "roi", "polygon_px": np.array(g.polygon_px)},
                           noise_folder).roi.exclude == ()
