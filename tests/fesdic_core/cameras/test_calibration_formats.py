"""Rig files of other tools (OpenCV FileStorage, VIC-3D, DICe): projection against OpenCV, errors, fuzzing.

Each format is written here from a known rig with that tool's conventions (OpenCV's files by
``cv2.FileStorage`` itself), read back, and the read cameras must project known 3-D points
where ``cv2.projectPoints`` does with the file's own parameters.
"""
import json
import math
import string
import zipfile

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.io.formats import (read_dice, read_opencv_stereo, read_vic3d,
                                            rotation_from_angles_deg, write_opencv_stereo)
from fesdic_core.cameras.rig import (CalibrationError, read_cameras_json, stereo_transform,
                                     write_cameras_json)

SIZE = (640, 480)
K0 = np.array([[1500.0, 0.0, 322.5], [0.0, 1502.0, 241.0], [0.0, 0.0, 1.0]])
K1 = np.array([[1480.0, 0.0, 318.0], [0.0, 1479.0, 236.5], [0.0, 0.0, 1.0]])
D0 = np.array([-0.12, 0.05, 1e-4, -2e-4, 0.01])
D1 = np.array([-0.10, 0.04, -3e-4, 1e-4, -0.02])
ANGLES = (3.0, -24.0, 1.5)                         # deg, camera 1 seen from camera 0
T01 = np.array([210.0, -4.0, 35.0])                 # mm
POINTS = np.array([[x, y, z] for x in (-30.0, 0.0, 30.0) for y in (-20.0, 20.0) for z in (-1.0, 2.0)])
# (cv2.projectPoints ignores a skew K[0, 1]: the rigs compared with it have none; the skew
# fields of VIC-3D and DICe are checked to land in K[0, 1] separately)


def _elementary(axis, deg):
    """Right-handed rotation about one axis, built by hand (independent of scipy and cv2)."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _zyx(a, b, g):
    return _elementary("z", g) @ _elementary("y", b) @ _elementary("x", a)


R01 = _zyx(*ANGLES)
# world: the specimen frame, camera 0 about 400 mm away looking down -z... (a posed rig)
R_W0 = _zyx(180.0, 12.0, -2.0)
T_W0 = np.array([-20.0, 5.0, 420.0])


def _cv_project(X, R, t, K, D):
    rvec = cv2.Rodrigues(np.asarray(R, float))[0]
    return cv2.projectPoints(X.reshape(-1, 1, 3), rvec, np.asarray(t, float).reshape(3, 1),
                             K, np.asarray(D, float))[0].reshape(-1, 2)


def _points_cam0():
    """Known points in camera 0's frame, 380-420 mm in front of it."""
    return POINTS + np.array([0.0, 0.0, 400.0])


def _assert_rig(cam0, cam1, X, R0, t0, R1, t1, K=(K0, K1), D=(D0, D1), tol=1e-9):
    for cam, R, t, k, d in ((cam0, R0, t0, K[0], D[0]), (cam1, R1, t1, K[1], D[1])):
        ours, ref = cam.project(X), _cv_project(X, R, t, k, d)
        assert np.max(np.abs(ours - ref)) < tol, np.max(np.abs(ours - ref))


# ------------------------------------------------------------------ OpenCV FileStorage
def _write_fs(path, entries):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in entries.items():
        fs.write(key, value)
    fs.release()
    return path


def _stereo_entries(**over):
    e = {"cameraMatrix1": K0, "distCoeffs1": D0.reshape(1, 5), "cameraMatrix2": K1,
         "distCoeffs2": D1.reshape(1, 5), "R": R01, "T": T01.reshape(3, 1),
         "image_width": SIZE[0], "image_height": SIZE[1]}
    e.update(over)
    return {k: v for k, v in e.items() if v is not None}


@pytest.mark.parametrize("ext", ["yml", "xml", "json"])
def test_opencv_file_projects_like_cv2(tmp_path, ext):
    path = _write_fs(tmp_path / f"stereo.{ext}", _stereo_entries())
    cam0, cam1 = read_opencv_stereo(path)
    assert cam0.image_size == cam1.image_size == SIZE
    np.testing.assert_array_equal(cam0.extrinsics, np.zeros(6))       # camera 0 at the origin
    _assert_rig(cam0, cam1, _points_cam0(), np.eye(3), np.zeros(3), R01, T01)


def test_opencv_key_spellings_and_8_coefficients(tmp_path):
    D8 = np.concatenate([D1, [0.0, 0.0, 0.0]])
    path = _write_fs(tmp_path / "m.yml", _stereo_entries(
        cameraMatrix1=None, distCoeffs1=None, cameraMatrix2=None, distCoeffs2=None, image_width=None,
        image_height=None, M1=K0, D1=D0[:4].reshape(4, 1), K2=K1, D2=D8, imageSize=np.array([SIZE])))
    cam0, cam1 = read_opencv_stereo(path)
    D = (np.concatenate([D0[:4], [0.0]]), D1)
    _assert_rig(cam0, cam1, _points_cam0(), np.eye(3), np.zeros(3), R01, T01, D=D)


def test_opencv_write_read_round_trip(tmp_path):
    cam0 = Camera(K0, D0, cv2.Rodrigues(R_W0)[0].ravel(), T_W0, SIZE, "cam0")
    R1 = R01 @ R_W0
    cam1 = Camera(K1, D1, cv2.Rodrigues(R1)[0].ravel(), R01 @ T_W0 + T01, SIZE, "cam1")
    for ext in ("yml", "json"):
        path = write_opencv_stereo(tmp_path / f"rig.{ext}", [cam0, cam1])
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]   # no temp left
        back0, back1 = read_opencv_stereo(path)
        X = POINTS
        _assert_rig(back0, back1, X, R_W0, T_W0, R1, cam1.tvec)
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)       # plain cv2 sees R, T too
        R, T = fs.getNode("R").mat(), fs.getNode("T").mat().ravel()
        fs.release()
        np.testing.assert_allclose(R, R01, atol=1e-12)
        np.testing.assert_allclose(T, T01, atol=1e-9)


def test_opencv_image_size_from_argument_and_mismatch(tmp_path):
    path = _write_fs(tmp_path / "s.yml", _stereo_entries(image_width=None, image_height=None))
    with pytest.raises(CalibrationError, match=r"s\.yml: image_width/image_height: missing"):
        read_opencv_stereo(path)
    assert read_opencv_stereo(path, image_size=SIZE)[1].image_size == SIZE
    full = _write_fs(tmp_path / "f.yml", _stereo_entries())
    with pytest.raises(CalibrationError, match=r"f\.yml: image size"):
        read_opencv_stereo(full, image_size=(320, 240))


@pytest.mark.parametrize("over, field", [
    ({"distCoeffs2": np.array([[0.1, 0.2, 0.3]])}, r"distCoeffs2: expected 4, 5, 8, 12 or 14 coefficients, got 3"),
    ({"distCoeffs2": np.array([[0.1, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0]])}, r"distCoeffs2: non-zero"),
    ({"cameraMatrix1": None}, r"K1: missing"),
    ({"T": None}, r"T: missing"),
    ({"T": np.array([[1.0, 2.0]])}, r"T: expected 3 numbers, got 2"),
    ({"R": np.eye(3) * 2.0}, r"R: not a rotation matrix"),
    ({"cameraMatrix2": np.array([[1500.0, 0, np.nan], [0, 1500, 240], [0, 0, 1]])}, r"cameraMatrix2: non-finite"),
    ({"image_width": -640}, r"image_width/image_height: expected two positive integers"),
])
def test_opencv_errors_name_file_and_field(tmp_path, over, field):
    path = _write_fs(tmp_path / "stereo.yml", _stereo_entries(**over))
    with pytest.raises(CalibrationError, match=r"stereo\.yml: " + field):
        read_opencv_stereo(path)


def test_opencv_unreadable_and_missing_files(tmp_path):
    bad = tmp_path / "broken.yml"
    bad.write_text("%YAML:1.0\nK1: [1, 2\n")
    with pytest.raises(CalibrationError, match=r"broken\.yml"):
        read_opencv_stereo(bad)
    with pytest.raises(CalibrationError, match=r"nothing\.yml: calibration file not found"):
        read_opencv_stereo(tmp_path / "nothing.yml")


# ------------------------------------------------------------------ VIC-3D
def _vic_angles(R):
    """(alpha, beta, gamma) deg of R = Rz(g) Ry(b) Rx(a), by hand (non-degenerate case)."""
    return (math.degrees(math.atan2(R[2, 1], R[2, 2])), math.degrees(-math.asin(R[2, 0])),
            math.degrees(math.atan2(R[1, 0], R[0, 0])))


def _vic_camera(i, K, kappa, R, t, inline):
    a, b, g = _vic_angles(R)
    cx, cy, fx, fy, s = K[0, 2], K[1, 2], K[0, 0], K[1, 1], K[0, 1]
    f = lambda v: " ".join(repr(float(x)) for x in v)                 # noqa: E731
    orient = f"<orientation>{f([a, b, g, *t])}</orientation>"
    if inline:
        return f'<camera id="{i}">{f([cx, cy, fx, fy, s, *kappa])}{orient}\n  </camera>'
    return (f'<camera id="{i}"><intrinsics>{f([cx, cy, fx, fy, s])}</intrinsics>'
            f'<distortion>{f(kappa)}</distortion>{orient}</camera>')


def _vic_project(R0, t0, R1, t1, kappa=((-0.12, 0.05, 0.01), (-0.1, 0.04, -0.02)), inline=False,
                 size=SIZE):
    cams = "\n".join(_vic_camera(i, K, k, R, t, inline)
                     for i, (K, k, R, t) in enumerate(((K0, kappa[0], R0, t0), (K1, kappa[1], R1, t1))))
    return ('<?xml version="1.0" encoding="ISO-8859-1"?>\n<!DOCTYPE vpml>\n<project dir="C:/x">\n'
            f' <calibration lri="calibration">\n{cams}\n </calibration>\n'
            f' <projectaois><aoinode><polygonmask width="{size[0]}" height="{size[1]}"/></aoinode>'
            '</projectaois>\n</project>\n')


def _vic_rig():
    R1 = R01 @ R_W0
    return R_W0, T_W0, R1, R01 @ T_W0 + T01


@pytest.mark.parametrize("inline", [False, True])
def test_vic3d_project_projects_like_cv2(tmp_path, inline):
    R0, t0, R1, t1 = _vic_rig()
    path = tmp_path / "project.xml"
    path.write_text(_vic_project(R0, t0, R1, t1, inline=inline), encoding="ISO-8859-1")
    cam0, cam1 = read_vic3d(path)
    assert cam0.image_size == SIZE
    D = (np.array([-0.12, 0.05, 0, 0, 0.01]), np.array([-0.1, 0.04, 0, 0, -0.02]))
    _assert_rig(cam0, cam1, POINTS, R0, t0, R1, t1, D=D)
    R, t = stereo_transform(cam0, cam1)
    np.testing.assert_allclose(R, R01, atol=1e-12)
    np.testing.assert_allclose(t, T01, atol=1e-9)


def test_vic3d_z3d_zip(tmp_path):
    R0, t0, R1, t1 = _vic_rig()
    z3d = tmp_path / "test.z3d"
    with zipfile.ZipFile(z3d, "w") as zf:
        zf.writestr("project.xml", _vic_project(R0, t0, R1, t1, kappa=((0.0,), (0.0,))))
        zf.writestr("other.dat", b"\x00\x01")
    cam0, cam1 = read_vic3d(z3d)
    _assert_rig(cam0, cam1, POINTS, R0, t0, R1, t1, D=(np.zeros(5), np.zeros(5)))
    empty = tmp_path / "empty.z3d"
    with zipfile.ZipFile(empty, "w") as zf:
        zf.writestr("readme.txt", "no project")
    with pytest.raises(CalibrationError, match=r"empty\.z3d: project\.xml: missing"):
        read_vic3d(empty)


def test_vic3d_angle_convention_against_rodrigues():
    """Angles (deg) in the file -> R = Rz Ry Rx, checked against cv2.Rodrigues of axis-angle."""
    a, b, g = 10.0, -35.0, 60.0
    # the same rotation composed from three axis-angle vectors, each turned into a matrix by cv2
    Rx = cv2.Rodrigues(np.array([[math.radians(a)], [0.0], [0.0]]))[0]
    Ry = cv2.Rodrigues(np.array([[0.0], [math.radians(b)], [0.0]]))[0]
    Rz = cv2.Rodrigues(np.array([[0.0], [0.0], [math.radians(g)]]))[0]
    np.testing.assert_allclose(rotation_from_angles_deg(a, b, g), Rz @ Ry @ Rx, atol=1e-14)
    np.testing.assert_allclose(_vic_angles(Rz @ Ry @ Rx), (a, b, g), atol=1e-12)


@pytest.mark.parametrize("edit, field", [
    (lambda s: s.replace("<orientation>", "<orient>").replace("</orientation>", "</orient>"),
     r"camera\[id=0\]/orientation: missing"),
    (lambda s: s.replace('<camera id="1">', '<camera id="7">'), r"camera\[id=1\]: missing"),
    (lambda s: s.replace("<intrinsics>", "<intrinsics>nan ", 1), r"camera\[id=0\]/intrinsics: expected 5"),
    (lambda s: s.replace("<distortion>", "<distortion>inf ", 1), r"camera\[id=0\]/distortion: non-finite"),
    (lambda s: s.replace("</distortion>", " 0.0 0.3</distortion>", 1), r"distortion: more than 3"),
    (lambda s: s.replace('width="640"', ""), r"polygonmask width/height: missing"),
    (lambda s: s.replace("<calibration", "<calib").replace("</calibration", "</calib"), r"calibration: missing"),
    (lambda s: s.replace("</project>", ""), r"not valid XML"),
])
def test_vic3d_errors_name_file_and_field(tmp_path, edit, field):
    path = tmp_path / "project.xml"
    path.write_text(edit(_vic_project(*_vic_rig())))
    with pytest.raises(CalibrationError, match=r"project\.xml: .*" + field):
        read_vic3d(path)


# ------------------------------------------------------------------ DICe
def _dice_param(name, value, kind="double"):
    return f'    <Parameter name="{name}" type="{kind}" value="{value}" />\n'


def _dice_camera(i, K, D, R, t, size, rotation="matrix", model="OPENCV_LENS_DISTORTION"):
    body = _dice_param("CAMERA_ID", f"cam{i}", "string")
    for name, v in (("CX", K[0, 2]), ("CY", K[1, 2]), ("FX", K[0, 0]), ("FY", K[1, 1]), ("FS", K[0, 1]),
                    ("K1", D[0]), ("K2", D[1]), ("P1", D[2]), ("P2", D[3]), ("K3", D[4])):
        if v != 0:                                                     # zeros may be omitted
            body += _dice_param(name, repr(float(v)))
    body += _dice_param("LENS_DISTORTION_MODEL", model, "string")
    for name, v in zip(("TX", "TY", "TZ"), t):
        body += _dice_param(name, repr(float(v)))
    if rotation == "matrix":
        rows = "".join(_dice_param(f"ROW {r}", "{ " + ", ".join(repr(float(x)) for x in R[r]) + " }",
                                   "string") for r in range(3))
        body += f'    <ParameterList name="rotation_3x3_matrix">\n{rows}    </ParameterList>\n'
    else:
        for name, v in zip(("ALPHA", "BETA", "GAMMA"), _vic_angles(R)):
            body += _dice_param(name, repr(v))
    body += _dice_param("IMAGE_HEIGHT_WIDTH", f"{{ {size[1]}, {size[0]} }}", "string")
    return f'  <ParameterList name="CAMERA {i}">\n{body}  </ParameterList>\n'


def _dice_file(R0, t0, R1, t1, relative=False, **kw):
    head = _dice_param("xml_file_format", "DICe_xml_camera_system_file", "string")
    head += _dice_param("system_type_3D", "OPENCV", "string")
    head += _dice_param("extrinsics_relative_camera_to_camera", str(relative).lower(), "bool")
    cams = _dice_camera(0, K0, D0, R0, t0, SIZE, **kw) + _dice_camera(1, K1, D1, R1, t1, (800, 600), **kw)
    return f'<?xml version="1.0" encoding="utf-8"?>\n<ParameterList>\n{head}{cams}</ParameterList>\n'


@pytest.mark.parametrize("rotation", ["matrix", "angles"])
def test_dice_file_projects_like_cv2(tmp_path, rotation):
    R0, t0, R1, t1 = _vic_rig()
    path = tmp_path / "cal.xml"
    path.write_text(_dice_file(R0, t0, R1, t1, rotation=rotation))
    cam0, cam1 = read_dice(path)
    assert (cam0.image_size, cam1.image_size) == (SIZE, (800, 600))
    assert (cam0.name, cam1.name) == ("cam0", "cam1")
    _assert_rig(cam0, cam1, POINTS, R0, t0, R1, t1)


def test_dice_relative_extrinsics(tmp_path):
    R0, t0, R1, t1 = _vic_rig()
    path = tmp_path / "cal.xml"
    path.write_text(_dice_file(R0, t0, R01, T01, relative=True))
    cam0, cam1 = read_dice(path)
    _assert_rig(cam0, cam1, POINTS, R0, t0, R1, t1)


@pytest.mark.parametrize("edit, field", [
    (lambda s: s.replace('<Parameter name="FX"', '<Parameter name="FXX"', 1), r"CAMERA 0: FX: missing"),
    (lambda s: s.replace('"{ 480, 640 }"', '"{ 480 }"', 1), r"CAMERA 0: IMAGE_HEIGHT_WIDTH: expected 2"),
    (lambda s: s.replace('name="TY" type="double" value="', 'name="TY" type="double" value="nan', 1),
     r"CAMERA 0: TY"),
    (lambda s: s.replace("OPENCV_LENS_DISTORTION", "FISHEYE", 1), r"CAMERA 0: LENS_DISTORTION_MODEL: unknown"),
    (lambda s: s.replace("OPENCV_LENS_DISTORTION", "VIC3D_LENS_DISTORTION", 1), r"no OpenCV equivalent"),
    (lambda s: s.replace('<Parameter name="K3"', '<Parameter name="K4" type="double" value="0.1" />'
                         '<Parameter name="K3"', 1), r"CAMERA 0: K4: non-zero"),
    (lambda s: s.replace('name="CAMERA 1"', 'name="CAMERA 3"'), r"a stereo pair needs 2 cameras, got 1"),
    (lambda s: s.replace("DICe_xml_camera_system_file", "other"), r"xml_file_format"),
    (lambda s: s.replace('"ROW 1"', '"ROW 9"', 1), r"CAMERA 0: rotation_3x3_matrix: ROW 1: missing"),
])
def test_dice_errors_name_file_and_field(tmp_path, edit, field):
    path = tmp_path / "cal.xml"
    path.write_text(edit(_dice_file(*_vic_rig())))
    with pytest.raises(CalibrationError, match=r"cal\.xml: .*" + field):
        read_dice(path)


# ------------------------------------------------------------------ fuzzing
_junk = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                  st.floats(allow_nan=True, allow_infinity=True), st.text(string.printable, max_size=8),
                  st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=10),
                  st.lists(st.lists(st.floats(-1e4, 1e4), max_size=4), max_size=4))
_FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _good_json():
    return {"cameras": [{"name": f"cam{i}", "image_size_px": list(SIZE), "K": K.tolist(),
                         "dist": D.tolist(), "rvec": [0.1, -0.2, 0.05], "tvec_mm": [1.0, 2.0, 400.0]}
                        for i, (K, D) in enumerate(((K0, D0), (K1, D1)))]}


def _must_fail_cleanly(read, path, name):
    try:
        read(path)
    except ValueError as exc:                   # CalibrationError is a ValueError
        assert name in str(exc), str(exc)


@_FUZZ
@given(cam=st.integers(0, 1), key=st.sampled_from(["image_size_px", "K", "dist", "rvec", "tvec_mm", "name"]),
       value=_junk, drop=st.booleans())
def test_fuzz_json_reader(tmp_path, cam, key, value, drop):
    data = _good_json()
    if drop:
        del data["cameras"][cam][key]
    else:
        data["cameras"][cam][key] = value
    path = tmp_path / "fuzz_cameras.json"
    path.write_text(json.dumps(data))
    _must_fail_cleanly(read_cameras_json, path, "fuzz_cameras.json")


@_FUZZ
@given(key=st.sampled_from(["K1", "D1", "K2", "D2", "R", "T", "image_width", "image_height"]),
       value=_junk, drop=st.booleans())
def test_fuzz_opencv_reader(tmp_path, key, value, drop):
    entries = {"K1": K0.tolist(), "D1": D0.tolist(), "K2": K1.tolist(), "D2": D1.tolist(),
               "R": R01.tolist(), "T": T01.tolist(), "image_width": SIZE[0], "image_height": SIZE[1]}
    if drop:
        del entries[key]
    else:
        entries[key] = value
    path = tmp_path / "fuzz_stereo.json"                # FileStorage reads plain JSON
    path.write_text(json.dumps(entries).replace("NaN", "nan").replace("Infinity", "inf"))
    _must_fail_cleanly(read_opencv_stereo, path, "fuzz_stereo.json")


@_FUZZ
@given(tag=st.sampled_from(["intrinsics", "distortion", "orientation"]), cam=st.integers(0, 1),
       text=st.one_of(st.text(string.printable.replace("<", "").replace("&", ""), max_size=30),
                      st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=8).map(
                          lambda v: " ".join(map(repr, v)))))
def test_fuzz_vic3d_reader(tmp_path, tag, cam, text):
    import re
    xml = _vic_project(*_vic_rig())
    parts = xml.split(f'<camera id="{cam}">')
    parts[1] = re.sub(f"<{tag}>[^<]*</{tag}>", lambda m: f"<{tag}>{text}</{tag}>", parts[1], count=1)
    path = tmp_path / "fuzz_project.xml"
    path.write_text(f'<camera id="{cam}">'.join(parts))
    _must_fail_cleanly(read_vic3d, path, "fuzz_project.xml")


@_FUZZ
@given(name=st.sampled_from(["FX", "FY", "CX", "FS", "K1", "K4", "P2", "TX", "TZ", "IMAGE_HEIGHT_WIDTH",
                             "LENS_DISTORTION_MODEL", "ROW 0", "ROW 2", "extrinsics_relative_camera_to_camera"]),
       text=st.one_of(st.text(string.printable.replace('"', "").replace("<", "").replace("&", ""), max_size=20),
                      st.floats(allow_nan=True, allow_infinity=True).map(repr)))
def test_fuzz_dice_reader(tmp_path, name, text):
    import re
    xml = _dice_file(*_vic_rig())
    xml = re.sub(f'(name="{name}" type="[a-z]+" value=")[^"]*"', lambda m: m.group(1) + text + '"', xml,
                 count=1)
    path = tmp_path / "fuzz_cal.xml"
    path.write_text(xml)
    _must_fail_cleanly(read_dice, path, "fuzz_cal.xml")


@pytest.mark.parametrize("read", [read_opencv_stereo, read_vic3d, read_dice, read_cameras_json])
@pytest.mark.parametrize("content", [b"", b"\x00\xff\xfe garbage \x89PNG", b"<not closed", b"[1, 2, 3]"])
def test_every_reader_refuses_garbage_and_missing_files_by_name(tmp_path, read, content):
    path = tmp_path / "garbage.dat"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=r"garbage\.dat"):
        read(path)
    with pytest.raises((ValueError, FileNotFoundError), match=r"absent\.dat"):
        read(tmp_path / "absent.dat")


_json_docs = st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
                          lambda kids: st.lists(kids, max_size=4) | st.dictionaries(
                              st.sampled_from(["cameras", "K", "K1", "D1", "R", "T", "dist", "rvec"]), kids,
                              max_size=4), max_leaves=12)


@_FUZZ
@given(doc=_json_docs)
def test_fuzz_whole_documents(tmp_path, doc):
    path = tmp_path / "fuzz_doc.json"
    path.write_text(json.dumps(doc).replace("NaN", "nan").replace("Infinity", "inf"))
    for read in (read_cameras_json, read_opencv_stereo):
        _must_fail_cleanly(read, path, "fuzz_doc.json")


def test_json_writer_and_opencv_writer_agree(tmp_path):
    """The two written rig files (JSON and OpenCV YAML) hold the same cameras."""
    cam0 = Camera(K0, D0, cv2.Rodrigues(R_W0)[0].ravel(), T_W0, SIZE, "cam0")
    cam1 = Camera(K1, D1, cv2.Rodrigues(R01 @ R_W0)[0].ravel(), R01 @ T_W0 + T01, SIZE, "cam1")
    write_cameras_json(tmp_path / "rig.json", [cam0, cam1])
    a = read_cameras_json(tmp_path / "rig.json")
    b = read_opencv_stereo(write_opencv_stereo(tmp_path / "rig.yml", [cam0, cam1]))
    for x, y in zip(a, b):
        assert np.max(np.abs(x.project(POINTS) - y.project(POINTS))) < 1e-9
