"""VIC-3D and DICe calibration files (XML) as core cameras.

VIC-3D (:func:`read_vic3d`): ``project.xml`` (alone or inside the ``.z3d`` zip). Schema as
read by DICe (github.com/dicengine/dice: ``src/core/DICe_CameraSystem.cpp`` and its test
file ``tests/component/cal/cal_a.xml``, a VIC-3D project) and by Sandia's SDynPy VIC-3D
helpers (``extract_vic_cal_parameters``, ``camera_matrix_from_vic_parameters``)::

    <calibration>
      <camera id="0">
        <intrinsics>cx cy fx fy skew</intrinsics>        (px)
        <distortion>kappa1 [kappa2 [kappa3]]</distortion>
        <orientation>alpha beta gamma tx ty tz</orientation>
      </camera> ...

or the older inline form ``<camera id="0">cx cy fx fy skew kappa1 kappa2 kappa3<orientation>
...</orientation></camera>``. Conventions adopted (both sources agree): the orientation is
world to camera, ``x_cam = R X + t`` with ``t`` in mm and ``R = Rz(gamma) Ry(beta) Rx(alpha)``
(right-handed, angles in degrees; SDynPy's transposed "Bryant" matrices give the same ``R``).
The distortion is taken as radial, in normalised coordinates, ``1 + kappa1 r^2 + kappa2 r^4 +
kappa3 r^6``, i.e. OpenCV's ``k1, k2, k3`` (pyxel's VIC reader also maps kappa1, kappa2 to
OpenCV's k1, k2). This is the least certain convention: DICe's ``VIC3D_LENS_DISTORTION``
comments that VIC's model is unconfirmed. The image size comes from ``image_size`` or the
project's first ``<polygonmask width= height=>``. The poses are kept as in the file.

DICe (:func:`read_dice`): the ``DICe_xml_camera_system_file`` ParameterList
(dicengine/dice ``src/core/DICe_CameraSystem.cpp``, ``DICe_Camera.cpp/.h``): sublists
``CAMERA 0``, ``CAMERA 1`` with ``CX CY FX FY FS`` (px; ``FS`` taken as the skew ``K[0, 1]``, as DICe's
VIC3D projection uses it), ``K1..K6 P1 P2 S1..S4 T1 T2``, ``LENS_DISTORTION_MODEL``
(``LD_MODEL`` in older files), ``TX TY TZ`` (mm), the rotation as ``ALPHA BETA GAMMA`` (deg,
``R = Rz(GAMMA) Ry(BETA) Rx(ALPHA)``, DICe's ``eulers_to_rotation_matrix``) or a
``rotation_3x3_matrix`` sublist (``ROW 0..2`` = ``"{ r, r, r }"``), ``IMAGE_HEIGHT_WIDTH``
= ``"{ h, w }"``; omitted values are 0. World to camera, unless
``extrinsics_relative_camera_to_camera`` is true (camera 1 then holds ``x_cam1 = R x_cam0 + t``).
Models: ``OPENCV_LENS_DISTORTION`` and ``K1R3_K2R5_K3R7`` (the same radial polynomial) map
to OpenCV's; ``NO_LENS_DISTORTION`` gives none (DICe ignores the coefficients); the others
(``VIC3D_LENS_DISTORTION``, ``K1R1_K2R2_K3R3``, ``K1R2_K2R4_K3R6``) are refused unless all
their coefficients are zero.
"""
from __future__ import annotations

import logging
import os
import xml.etree.ElementTree as ET
import zipfile

import numpy as np

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.io.values import (as_finite, as_rotation, as_size, as_sizes, existing_file,
                                           make_camera, rotation_from_angles_deg)
from fesdic_core.cameras.rig import CalibrationError, place_camera1

logger = logging.getLogger(__name__)

__all__ = ["read_vic3d", "read_dice"]


# ------------------------------------------------------------------ XML helpers
def _parse_xml(data: bytes, path: str) -> ET.Element:
    try:
        return ET.fromstring(data)
    except ET.ParseError as exc:
        raise CalibrationError(f"{path}: not valid XML: {exc}") from None


def _numbers_text(text, path: str, field: str, n: int | None = None) -> np.ndarray:
    """Numbers separated by blanks or commas, optionally in braces (``"{ 1, 2 }"``)."""
    words = (text or "").replace("{", " ").replace("}", " ").replace(",", " ").split()
    try:
        values = [float(w) for w in words]
    except ValueError:
        raise CalibrationError(f"{path}: {field}: expected numbers, got {text!r}") from None
    if n is not None and len(values) != n:
        raise CalibrationError(f"{path}: {field}: expected {n} numbers, got {len(values)}")
    return as_finite(values, None, path, field)


# ------------------------------------------------------------------ VIC-3D
def _vic3d_xml(path: str) -> tuple[bytes, str]:
    if zipfile.is_zipfile(path):
        try:
            with zipfile.ZipFile(path) as zf:
                names = [n for n in zf.namelist() if n.rsplit("/", 1)[-1] == "project.xml"]
                if not names:
                    raise CalibrationError(f"{path}: project.xml: missing from the .z3d archive")
                return zf.read(min(names, key=len)), f"{path}!{min(names, key=len)}"
        except (zipfile.BadZipFile, OSError) as exc:
            raise CalibrationError(f"{path}: unreadable .z3d archive: {exc}") from None
    with open(path, "rb") as fh:
        return fh.read(), path


def _vic3d_camera(cam: ET.Element, i: int, path: str, size) -> Camera:
    where = f"calibration/camera[id={i}]"
    intrinsics = cam.find("intrinsics")
    if intrinsics is not None:                                  # VIC-3D 7+ (.z3d project.xml)
        cx, cy, fx, fy, skew = _numbers_text(intrinsics.text, path, f"{where}/intrinsics", 5)
        node = cam.find("distortion")
        kappa = (np.zeros(0) if node is None else
                 _numbers_text(node.text, path, f"{where}/distortion"))
        kfield = f"{where}/distortion"
    else:                                                       # inline: cx cy fx fy s k1 k2 k3
        values = _numbers_text(cam.text, path, f"{where} (intrinsics text)")
        if values.size < 5:
            raise CalibrationError(f"{path}: {where}: intrinsics: expected 'cx cy fx fy skew "
                                   f"kappa1 kappa2 kappa3', got {values.size} numbers")
        (cx, cy, fx, fy, skew), kappa = values[:5], values[5:]
        kfield = f"{where} (kappa)"
    if np.any(kappa[3:] != 0):
        raise CalibrationError(f"{path}: {kfield}: more than 3 non-zero coefficients "
                               f"({kappa.tolist()}): unknown VIC-3D distortion model")
    k = np.concatenate([kappa[:3], np.zeros(3 - min(kappa.size, 3))])
    node = cam.find("orientation")
    if node is None:
        node = cam.find("extrinsics")
    if node is None:
        raise CalibrationError(f"{path}: {where}/orientation: missing")
    a, b, g, tx, ty, tz = _numbers_text(node.text, path, f"{where}/orientation", 6)
    K = [[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]
    return make_camera(path, where, K, [k[0], k[1], 0.0, 0.0, k[2]], rotation_from_angles_deg(a, b, g),
                   [tx, ty, tz], size, f"cam{i}")


def read_vic3d(path: str | os.PathLike, image_size=None) -> tuple[Camera, Camera]:
    """Stereo rig of a VIC-3D ``project.xml`` or ``.z3d`` project (conventions in the module docstring).

    Parameters
    ----------
    path : ``project.xml`` or the ``.z3d`` zip holding it
    image_size : (w, h) of both cameras or ((w0, h0), (w1, h1)); default: the project's
        ``<polygonmask width= height=>``

    Returns
    -------
    (cam0, cam1) : posed as in the file (world to camera)
    """
    path = existing_file(path)
    data, where = _vic3d_xml(path)
    root = _parse_xml(data, where)
    calibration = root if root.tag == "calibration" else root.find(".//calibration")
    if calibration is None:
        raise CalibrationError(f"{where}: calibration: missing")
    sizes = as_sizes(image_size, where)
    if sizes is None:
        mask = root.find(".//polygonmask")
        if mask is None or "width" not in mask.attrib or "height" not in mask.attrib:
            raise CalibrationError(f"{where}: polygonmask width/height: missing (no image size "
                                   f"in the project; give image_size)")
        sizes = [as_size([mask.get("width"), mask.get("height")], where, "polygonmask width/height")] * 2
    by_id = {c.get("id"): c for c in calibration.findall("camera")}
    cams = []
    for i in (0, 1):
        if str(i) not in by_id:
            raise CalibrationError(f"{where}: calibration/camera[id={i}]: missing")
        cams.append(_vic3d_camera(by_id[str(i)], i, where, sizes[i]))
    logger.info("read VIC-3D calibration %s", where)
    return cams[0], cams[1]


# ------------------------------------------------------------------ DICe
_DICE_FORMATS = {"DICe_xml_camera_system_file", "DICe_XML_Calibration_File"}
_DICE_OPENCV = {"OPENCV_LENS_DISTORTION", "OPENCV_DIS", "K1R3_K2R5_K3R7"}
_DICE_NONE = {"NO_LENS_DISTORTION", "NONE"}
_DICE_OTHER = {"VIC3D_LENS_DISTORTION", "VIC3D_DIS", "K1R1_K2R2_K3R3", "K1R2_K2R4_K3R6"}
_DICE_COEFFS = ("K1", "K2", "K3", "K4", "K5", "K6", "P1", "P2", "S1", "S2", "S3", "S4", "T1", "T2")


def _dice_params(plist: ET.Element) -> tuple[dict[str | None, str | None],
                                              dict[str | None, ET.Element]]:
    params = {p.get("name"): p.get("value") for p in plist.findall("Parameter")}
    sublists = {p.get("name"): p for p in plist.findall("ParameterList")}
    return params, sublists


def _dice_bool(value: str | None, path: str, field: str) -> bool:
    if value is None:
        return False
    if value.strip().lower() not in ("true", "false", "1", "0"):
        raise CalibrationError(f"{path}: {field}: expected true or false, got {value!r}")
    return value.strip().lower() in ("true", "1")


def _dice_camera(plist: ET.Element, i: int, path: str) -> tuple[Camera, np.ndarray, np.ndarray]:
    where = f"CAMERA {i}"
    params, sublists = _dice_params(plist)

    def num(name: str, required: bool = False) -> float:
        if name not in params:
            if required:
                raise CalibrationError(f"{path}: {where}: {name}: missing")
            return 0.0
        return float(_numbers_text(params[name], path, f"{where}: {name}", 1)[0])

    if "IMAGE_HEIGHT_WIDTH" not in params:
        raise CalibrationError(f"{path}: {where}: IMAGE_HEIGHT_WIDTH: missing")
    h, w = _numbers_text(params["IMAGE_HEIGHT_WIDTH"], path, f"{where}: IMAGE_HEIGHT_WIDTH", 2)
    size = as_size([w, h], path, f"{where}: IMAGE_HEIGHT_WIDTH")
    K = [[num("FX", True), num("FS"), num("CX")], [0.0, num("FY", True), num("CY")], [0.0, 0.0, 1.0]]
    c = {name: num(name) for name in _DICE_COEFFS}
    mkey = "LENS_DISTORTION_MODEL" if "LENS_DISTORTION_MODEL" in params else "LD_MODEL"
    model = (params.get(mkey) or "NO_LENS_DISTORTION").strip().upper()
    if model in _DICE_OPENCV:
        extra = [n for n in _DICE_COEFFS[3:6] + _DICE_COEFFS[8:] if c[n] != 0]
        if model == "K1R3_K2R5_K3R7":
            extra = [n for n in _DICE_COEFFS[3:] if c[n] != 0]
        if extra:
            raise CalibrationError(f"{path}: {where}: {', '.join(extra)}: non-zero coefficients "
                                   f"beyond [k1 k2 p1 p2 k3] are not supported")
        dist = [c["K1"], c["K2"], c["P1"], c["P2"], c["K3"]]
    elif model in _DICE_NONE:
        dist = [0.0] * 5
    elif model in _DICE_OTHER:
        nonzero = [n for n in _DICE_COEFFS if c[n] != 0]
        if nonzero:
            raise CalibrationError(f"{path}: {where}: {mkey}: {model} with non-zero "
                                   f"{', '.join(nonzero)} has no OpenCV equivalent; not supported")
        dist = [0.0] * 5
    else:
        raise CalibrationError(f"{path}: {where}: {mkey}: unknown lens distortion model {model!r}")
    angles = [n for n in ("ALPHA", "BETA", "GAMMA") if n in params]
    if angles and "rotation_3x3_matrix" in sublists:
        raise CalibrationError(f"{path}: {where}: rotation_3x3_matrix: given together with "
                               f"{'/'.join(angles)}; keep one")
    if "rotation_3x3_matrix" in sublists:
        rows, _ = _dice_params(sublists["rotation_3x3_matrix"])
        for r in range(3):
            if f"ROW {r}" not in rows:
                raise CalibrationError(f"{path}: {where}: rotation_3x3_matrix: ROW {r}: missing")
        R = as_rotation([_numbers_text(rows[f"ROW {r}"], path,
                                     f"{where}: rotation_3x3_matrix: ROW {r}", 3) for r in range(3)],
                      path, f"{where}: rotation_3x3_matrix")
    else:
        R = rotation_from_angles_deg(num("ALPHA"), num("BETA"), num("GAMMA"))
    t = np.array([num("TX"), num("TY"), num("TZ")])
    name = params.get("CAMERA_ID") or f"cam{i}"
    return make_camera(path, where, K, dist, np.eye(3), np.zeros(3), size, name), R, t


def read_dice(path: str | os.PathLike) -> tuple[Camera, Camera]:
    """Stereo rig of a DICe camera-system XML file (conventions in the module docstring).

    Returns
    -------
    (cam0, cam1) : posed as in the file (world to camera; with
        ``extrinsics_relative_camera_to_camera``, camera 1 placed from camera 0)
    """
    path = existing_file(path)
    with open(path, "rb") as fh:
        root = _parse_xml(fh.read(), path)
    if root.tag != "ParameterList":
        raise CalibrationError(f"{path}: expected a DICe <ParameterList>, got <{root.tag}>")
    params, sublists = _dice_params(root)
    if not _DICE_FORMATS & {params.get("xml_file_format"), params.get("cal_file_ID")}:
        raise CalibrationError(f"{path}: xml_file_format: missing or not DICe_xml_camera_system_file")
    n = 0
    while f"CAMERA {n}" in sublists:
        n += 1
    if n != 2:
        raise CalibrationError(f"{path}: CAMERA 0, CAMERA 1: a stereo pair needs 2 cameras, got {n}")
    relative = _dice_bool(params.get("extrinsics_relative_camera_to_camera"), path,
                          "extrinsics_relative_camera_to_camera")
    (c0, R0, t0), (c1, R1, t1) = (_dice_camera(sublists[f"CAMERA {i}"], i, path) for i in (0, 1))
    cam0 = make_camera(path, "CAMERA 0", c0.K, c0.dist, R0, t0, c0.image_size, c0.name)
    if relative:
        cam1 = place_camera1(cam0, c1, R1, t1)
    else:
        cam1 = make_camera(path, "CAMERA 1", c1.K, c1.dist, R1, t1, c1.image_size, c1.name)
    logger.info("read DICe camera system %s", path)
    return cam0, cam1
