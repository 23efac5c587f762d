"""The initial cameras of a run from ``[cameras]``: the project's JSON, or another tool's
calibration (pyvale CSV, OpenCV FileStorage, VIC-3D, DICe) posed by the landmarks."""
from __future__ import annotations

import shutil
import tempfile
import weakref
from pathlib import Path
from typing import Sequence

import numpy as np

from fesdic_core.cameras.io.formats import read_dice, read_opencv_stereo, read_vic3d
from fesdic_core.cameras.rig import (initial_rig_pose, read_cameras_json, read_pyvale_csv,
                                     stereo_transform, write_cameras_json)
from fesdic_core.imaging.image import Image

from georeg_app.config.measure import CamerasConfig
from georeg_app.errors import InputError

__all__ = ["load_cameras", "temporary_cameras"]


def load_cameras(cameras: CamerasConfig, images: Sequence[Image]) -> list:
    """Initial cameras: the JSON file as is, or another tool's calibration (pyvale, OpenCV,
    VIC-3D, DICe) whose stereo relation is kept and posed by the landmarks; without
    landmarks (``[geometry] kind = "roi"``), the calibration's cameras as they are."""
    if cameras.file is not None:
        cams = read_cameras_json(cameras.file)
        if len(cams) != 2:
            raise InputError(f"{cameras.file}: a stereo pair needs 2 cameras, got {len(cams)}")
        return cams
    size = [(im.shape[1], im.shape[0]) for im in images]
    if cameras.opencv is not None:
        cam0, cam1 = read_opencv_stereo(cameras.opencv, size)
    elif cameras.vic3d is not None:
        cam0, cam1 = read_vic3d(cameras.vic3d, size)
    elif cameras.dice is not None:
        cam0, cam1 = read_dice(cameras.dice)
    else:
        cam0, cam1 = read_pyvale_csv(cameras.pyvale_csv, size)
    if not cameras.landmarks:        # [geometry] kind = "roi": the rig places the specimen
        return [cam0, cam1]
    R, t = stereo_transform(cam0, cam1)
    xyz = np.array([lm.xyz_mm for lm in cameras.landmarks])
    px0 = np.array([lm.cam0_px for lm in cameras.landmarks])
    px1 = np.array([lm.cam1_px for lm in cameras.landmarks])
    return list(initial_rig_pose(cam0, cam1, xyz, px0, px1, R, t))


def temporary_cameras(cameras: Sequence, prefix: str = "georeg_cameras_") -> CamerasConfig:
    """Cameras given as objects, written to a temporary ``cameras.json`` that the returned
    ``[cameras]`` owns: its folder is removed when no copy of the config refers to it any
    more (at the end of a run), at the latest at exit. Every step of the run then reads the
    cameras as the command line does (the demo, and cameras passed to :func:`georeg.measure`)."""
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    try:
        write_cameras_json(folder / "cameras.json", cameras)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    config = CamerasConfig(file=folder / "cameras.json")
    weakref.finalize(config, shutil.rmtree, folder, ignore_errors=True)   # kept by copies
    return config
