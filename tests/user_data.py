"""Test helpers: a user's files of a synthetic scene, and the demo's pose error."""
import cv2
import numpy as np

from fesdic_core.cameras.rig import write_cameras_json
from fesdic_core.shape.gauge import move_cameras_with_specimen


def perturbed_pose(cameras, angle_deg=0.5, shift_mm=0.5):
    """The cameras with the specimen pose off by ``angle_deg`` and ``shift_mm`` (as the demo)."""
    rotation = np.radians(angle_deg) * np.array([0.6, -0.48, 0.64])
    translation = shift_mm * np.array([0.48, 0.64, -0.6])
    return move_cameras_with_specimen(cameras, translation, rotation, np.zeros(3))


def write_user_data(folder, arrays, cameras):
    """The files a user has: ``cam0.png``, ``cam1.png`` (8 bit) and ``cameras.json``."""
    for k, a in enumerate(arrays):
        cv2.imwrite(str(folder / f"cam{k}.png"), np.asarray(a).astype(np.uint8))
    write_cameras_json(folder / "cameras.json", cameras)
    return folder


#: the nominal plates of the tests' configurations ([geometry] tables)
PLATE_WITH_HOLE = 'kind = "plate_with_hole"\nlength_mm = 100.0\nwidth_mm = 50.0\nhole_radius_mm = 14.0'
RECTANGLE_100 = 'kind = "rectangle"\nlength_mm = 100.0\nwidth_mm = 50.0'


def user_config(geometry: str, method: str = "", cam0: str = "cam0.png", cam1: str = "cam1.png",
                cameras: str = 'file = "cameras.json"') -> str:
    """The TOML of a run on a user's files: ``[images]``, ``[cameras]``, then the given
    ``[geometry]`` and ``[method]`` lines (one test configuration written once)."""
    return (f'[images]\ncam0 = "{cam0}"\ncam1 = "{cam1}"\n[cameras]\n{cameras}\n'
            f"[geometry]\n{geometry}\n[method]\n{method}\n")
