"""Stereo-rig files of other tools: OpenCV FileStorage, VIC-3D project XML, DICe camera system.

Every reader returns the two cameras as core :class:`~fesdic_core.cameras.camera.Camera` objects
(OpenCV model, ``x_cam = R(rvec) X + tvec``, mm, pixel centres at integers) and raises
:class:`~fesdic_core.cameras.rig.CalibrationError` naming the file and the field for a missing or
malformed field, a non-finite value, an unreadable file or a distortion model the core
cannot represent (it takes ``[k1, k2, p1, p2, k3]``; further non-zero terms are refused).

OpenCV (:func:`read_opencv_stereo`, :func:`write_opencv_stereo`), read and written with
``cv2.FileStorage`` (YAML, XML or JSON by the file's extension)::

    K1, K2 (or M1/M2, cameraMatrix1/2)   3x3 camera matrices, px
    D1, D2 (or distCoeffs1/2)             4, 5, 8, 12 or 14 coefficients (OpenCV order)
    R, T                                  stereo relation x_cam1 = R x_cam0 + T (R 3x3 or a
                                          Rodrigues vector), mm
    image_width, image_height (or imageSize = [w, h])   optional when image_size is given
    rvec1, tvec1, rvec2, tvec2            optional extrinsics (written by write_opencv_stereo)

Without ``rvec1``/``tvec1`` camera 0 is put at the world origin (as
:func:`fesdic_core.cameras.rig.read_pyvale_csv` does); the specimen is then posed from landmarks.

VIC-3D (:func:`read_vic3d`) and DICe (:func:`read_dice`) files are read by
:mod:`fesdic_core.cameras.io.vic3d_dice` (their conventions, and the sources followed, are in its
docstring); they are re-exported here so that all rig formats are one import away.
"""
from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from fesdic_core.atomic import atomic_path
from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.io.values import (OPENCV_DISTORTION_LENGTHS, as_dist5, as_finite,
                                           as_rotation, as_size, as_sizes, existing_file,
                                           make_camera, rotation_from_angles_deg)
from fesdic_core.cameras.io.vic3d_dice import read_dice, read_vic3d
from fesdic_core.cameras.rig import CalibrationError, place_camera1, stereo_transform

logger = logging.getLogger(__name__)

__all__ = ["read_opencv_stereo", "write_opencv_stereo", "read_vic3d", "read_dice",
           "rotation_from_angles_deg", "OPENCV_DISTORTION_LENGTHS"]

_OPENCV_SUFFIXES = (".yml", ".yaml", ".xml", ".json")


# ------------------------------------------------------------------ OpenCV FileStorage
_K_KEYS = ("K{}", "M{}", "cameraMatrix{}", "camera_matrix{}")
_D_KEYS = ("D{}", "distCoeffs{}", "dist_coeffs{}", "dist{}")


def _node_values(node):
    """Numbers of a FileStorage node: a matrix, a sequence of numbers or one number."""
    if node.isMap() and node.mat() is not None:
        return node.mat()
    if node.isSeq():
        items = [node.at(i) for i in range(node.size())]
        if all(item.isInt() or item.isReal() for item in items):
            return [item.real() for item in items]
    elif node.isInt() or node.isReal():
        return node.real()
    return node.string() if node.isString() else f"<{node.type()}>"


def _node(fs, keys: Sequence[str]):
    for key in keys:
        node = fs.getNode(key)
        if not node.empty() and not node.isNone():
            return key, node
    return None, None


def read_opencv_stereo(path: str | os.PathLike, image_size=None) -> tuple[Camera, Camera]:
    """Stereo rig of an OpenCV FileStorage file (YAML, XML or JSON; keys in the module docstring).

    Parameters
    ----------
    path : the FileStorage file
    image_size : (w, h) of both cameras, or ((w0, h0), (w1, h1)); needed if the file has
        no ``image_width``/``image_height``/``imageSize``, and must match them otherwise

    Returns
    -------
    (cam0, cam1) : camera 0 at the origin (or at ``rvec1, tvec1``), camera 1 placed by ``R, T``
    """
    path = existing_file(path)
    try:
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
        opened = fs.isOpened()
    except (cv2.error, SystemError) as exc:                   # cv2 wraps some parse errors so
        raise CalibrationError(f"{path}: not a readable OpenCV FileStorage file: "
                               f"{str(exc).strip().splitlines()[-1]}") from None
    if not opened:
        raise CalibrationError(f"{path}: not a readable OpenCV FileStorage file")
    try:
        def get(keys, what, required=True):
            key, node = _node(fs, keys)
            if node is None:
                if required:
                    raise CalibrationError(f"{path}: {keys[0]}: missing ({what})")
                return None, None
            return key, _node_values(node)

        sizes = as_sizes(image_size, path)
        _, width = get(["image_width"], "image width", required=False)
        _, height = get(["image_height"], "image height", required=False)
        key, both = get(["imageSize", "image_size"], "image size", required=False)
        file_sizes: list[tuple[int, int]] | None
        if both is not None:
            file_sizes = [as_size(both, path, key)] * 2
        elif width is not None or height is not None:
            if width is None or height is None:
                raise CalibrationError(f"{path}: image_{'width' if width is None else 'height'}: "
                                       f"missing (the other is given)")
            file_sizes = [as_size([width, height], path, "image_width/image_height")] * 2
        else:
            per = [get([f"imageSize{c}"], "", required=False)[1] for c in (1, 2)]
            file_sizes = (None if per[0] is None and per[1] is None else
                          [as_size(v, path, f"imageSize{c}") for c, v in zip((1, 2), per)])
        if file_sizes is not None:
            if sizes is not None and sizes != file_sizes:
                raise CalibrationError(f"{path}: image size {file_sizes} in the file differs from "
                                       f"the images' {sizes}")
            sizes = file_sizes
        if sizes is None:
            raise CalibrationError(f"{path}: image_width/image_height: missing (and no image size "
                                   f"given)")
        cams = []
        for c in (1, 2):
            kkey, K = get([k.format(c) for k in _K_KEYS], f"camera matrix of camera {c - 1}")
            K = as_finite(K, 9, path, kkey).reshape(3, 3)
            dkey, D = get([k.format(c) for k in _D_KEYS], f"distortion of camera {c - 1}")
            cams.append((K, as_dist5(D, path, dkey), kkey))
        R = as_rotation(get(["R"], "stereo rotation")[1], path, "R")
        T = as_finite(get(["T"], "stereo translation")[1], 3, path, "T")
        _, rvec0 = get(["rvec1"], "", required=False)
        _, tvec0 = get(["tvec1"], "", required=False)
    except (cv2.error, SystemError) as exc:
        raise CalibrationError(f"{path}: unreadable OpenCV FileStorage content: "
                               f"{str(exc).strip().splitlines()[-1]}") from None
    finally:
        fs.release()
    R0 = np.eye(3) if rvec0 is None else as_rotation(rvec0, path, "rvec1")
    t0 = np.zeros(3) if tvec0 is None else as_finite(tvec0, 3, path, "tvec1")
    (K0, D0, k0), (K1, D1, k1) = cams
    cam0 = make_camera(path, k0, K0, D0, R0, t0, sizes[0], "cam0")
    cam1 = make_camera(path, k1, K1, D1, np.eye(3), np.zeros(3), sizes[1], "cam1")
    logger.info("read OpenCV stereo calibration %s", path)
    return cam0, place_camera1(cam0, cam1, R, T)


def write_opencv_stereo(path: str | os.PathLike, cameras: Sequence[Camera]) -> Path:
    """Write a stereo pair as an OpenCV FileStorage file (format from the extension), atomically.

    Keys ``K1 D1 K2 D2 R T image_width image_height`` (``imageSize1/2`` if the sizes differ)
    and each camera's extrinsics ``rvec1 tvec1 rvec2 tvec2``; :func:`read_opencv_stereo`
    reads it back.
    """
    path = Path(path)
    if path.suffix.lower() not in _OPENCV_SUFFIXES:
        raise ValueError(f"{path}: expected one of {', '.join(_OPENCV_SUFFIXES)} for an OpenCV file")
    if len(cameras) != 2:
        raise ValueError(f"{path}: a stereo pair needs 2 cameras, got {len(cameras)}")
    cam0, cam1 = cameras
    R, T = stereo_transform(cam0, cam1)
    with atomic_path(path) as tmp:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        try:
            for c, cam in enumerate(cameras, start=1):
                fs.write(f"K{c}", cam.K)
                fs.write(f"D{c}", cam.dist.reshape(1, 5))
            fs.write("R", R)
            fs.write("T", T.reshape(3, 1))
            if cam0.image_size == cam1.image_size:
                fs.write("image_width", int(cam0.image_size[0]))
                fs.write("image_height", int(cam0.image_size[1]))
            else:
                for c, cam in enumerate(cameras, start=1):
                    fs.write(f"imageSize{c}", np.array(cam.image_size, dtype=np.int32).reshape(1, 2))
            for c, cam in enumerate(cameras, start=1):
                fs.write(f"rvec{c}", cam.rvec.reshape(3, 1))
                fs.write(f"tvec{c}", cam.tvec.reshape(3, 1))
        finally:
            fs.release()
    return path
