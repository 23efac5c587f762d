"""The science of ``georeg calibrate``: detect the target in every view, calibrate the rig,
compare it with another tool's calibration and check it on a speckle pair.

- :func:`detect_views`: the target's points in each image of each camera
  (:func:`fesdic_core.cameras.targets.detect`).
- :func:`fesdic_core.cameras.targets.calibration.calibrate_stereo`: the rig.
- :func:`compare_rigs`: each parameter beside another calibration's, the difference in units
  of our standard deviation (the stereo relation compared as ``(R, T)`` from camera 0).
- :func:`speckle_check`: SIFT matches of a speckle pair and their symmetric epipolar distance
  with each calibration: what the rig gives a measurement, independent of the target.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import Callable, Sequence

import cv2
import numpy as np
from tqdm.auto import tqdm

from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.rig import stereo_transform
from fesdic_core.cameras.targets.calibration import StereoCalibration, calibrate_stereo
from fesdic_core.cameras.targets.covariance import INTRINSIC_NAMES
from fesdic_core.cameras.targets.target import Detection, detect
from fesdic_core.cameras.triangulation import epipolar_distance_px, match_features
from fesdic_core.imaging.image import read_image

from georeg_app.calibrate.config import CalibrateConfig
from georeg_app.errors import InputError
from georeg_app.inputs.cameras import load_cameras

logger = logging.getLogger(__name__)

__all__ = ["CalibrationRun", "read_gray", "detect_views", "compare_rigs", "speckle_check", "run_calibration"]


@dataclasses.dataclass(frozen=True, eq=False)
class CalibrationRun:
    """A calibration and what it was checked against."""

    config: CalibrateConfig
    detections: tuple[tuple[Detection, ...], tuple[Detection, ...]]
    calibration: StereoCalibration
    comparison: list[dict] | None
    check: dict | None
    time_s: float


def read_gray(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH)
    if image is None:
        raise InputError(f"{path}: not an image OpenCV can read")
    return image


def detect_views(config: CalibrateConfig,
                 progress: bool | Callable[[str, int, int], None] = False
                 ) -> tuple[tuple[Detection, ...], tuple[Detection, ...]]:
    """The target's detections in every image, per camera, in the configuration's order."""
    paths = [*config.cam0, *config.cam1]
    found: list[Detection] = []
    with tqdm(total=len(paths), desc="target", unit="image", disable=progress is not True) as bar:
        for k, path in enumerate(paths):
            d = detect(read_gray(path), config.target, str(path))
            if d.n_points == 0:
                logger.warning("%s: target not found: %s", path, d.note)
            else:
                logger.debug("%s: %d target points", path, d.n_points)
            found.append(d)
            bar.update(1)
            if callable(progress):
                progress("target", k + 1, len(paths))
    n = len(config.cam0)
    return tuple(found[:n]), tuple(found[n:])


def _parameters(cameras: Sequence[Camera]) -> dict[str, float]:
    R, T = stereo_transform(*cameras)
    values = {}
    for c, cam in enumerate(cameras):
        intr = [cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2], *cam.dist]
        values.update({f"cam{c}.{n}": float(v) for n, v in zip(INTRINSIC_NAMES, intr)})
    rvec = cv2.Rodrigues(R)[0].ravel()
    values.update({f"rvec[{i}]": float(v) for i, v in enumerate(rvec)})
    values.update({f"T[{i}]": float(v) for i, v in enumerate(np.ravel(T))})
    values["baseline_mm"] = float(np.linalg.norm(T))
    values["stereo_angle_deg"] = float(np.degrees(np.linalg.norm(rvec)))
    return values


def _std_of(std: dict, name: str) -> float | None:
    if "[" in name:                                   # "rvec[1]", "T[2]"
        key, index = name.split("[")
        return float(std[key][int(index[:-1])])
    value = std.get(name)
    return None if value is None else float(value)


def compare_rigs(ours: StereoCalibration, theirs: Sequence[Camera]) -> list[dict]:
    """Rows ``{name, ours, std, theirs, difference, sigmas}`` for every parameter (``std``
    and ``sigmas`` None for a parameter we did not estimate)."""
    mine, other = _parameters(ours.cameras), _parameters(theirs)
    rows = []
    for name, value in mine.items():
        std = _std_of(ours.std, name)
        diff = value - other[name]
        rows.append(dict(name=name, ours=value, std=std, theirs=other[name], difference=diff,
                         sigmas=None if not std else diff / std))
    return rows


def speckle_check(images: Sequence[np.ndarray], rigs: dict[str, Sequence[Camera]]) -> dict:
    """SIFT matches of a speckle pair, and per rig the median and RMS of their symmetric
    epipolar distance (px) after a robust cut of gross mismatches (10 px)."""
    px0, px1, _ = match_features(images[0], images[1])
    out: dict = {"matches": int(len(px0))}
    for label, cams in rigs.items():
        d = 0.5 * (epipolar_distance_px(cams[0], cams[1], px0, px1)
                   + epipolar_distance_px(cams[1], cams[0], px1, px0))
        d = d[d < 10.0]
        out[label] = dict(median_px=float(np.median(d)) if len(d) else None,
                          rms_px=float(np.sqrt(np.mean(d ** 2))) if len(d) else None,
                          kept=int(len(d)))
    return out


def run_calibration(config: CalibrateConfig,
                    progress: bool | Callable[[str, int, int], None] = False) -> CalibrationRun:
    """Detect, calibrate, compare and check (:class:`CalibrationRun`)."""
    t0 = time.perf_counter()
    detections = detect_views(config, progress)
    both = sum(1 for a, b in zip(*detections) if a.n_points and b.n_points)
    logger.info("target found in both images of %d of %d views", both, len(config.cam0))
    calibration = calibrate_stereo(*detections, config.target, config.model)
    comparison = check = None
    rigs: dict[str, Sequence[Camera]] = {"ours": calibration.cameras}
    if config.compare is not None:
        theirs = load_cameras(config.compare, [_Sized(d.image_size) for d in
                                               (detections[0][0], detections[1][0])])
        comparison = compare_rigs(calibration, theirs)
        rigs[config.compare.source] = theirs
    if config.check is not None:
        images = [read_image(p).values for p in config.check]
        check = speckle_check(images, rigs)
        check["images"] = [str(p) for p in config.check]
        for label in rigs:
            logger.info("speckle check (%d SIFT matches): median symmetric epipolar distance "
                        "%.4f px with the %s calibration", check["matches"],
                        check[label]["median_px"] or float("nan"), label)
    return CalibrationRun(config=config, detections=detections, calibration=calibration,
                          comparison=comparison, check=check, time_s=time.perf_counter() - t0)


class _Sized:
    """An image's shape, which is all :func:`load_cameras` reads of the images."""

    def __init__(self, size: tuple[int, int]):
        self.shape = (size[1], size[0])
