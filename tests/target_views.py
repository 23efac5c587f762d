"""Rendered views of calibration targets with a known rig (shared by the calibration tests).

A rig of two 640 x 480 px cameras with radial distortion, and eight poses of a 9 x 12 dot
grid (8 mm pitch, 3.2 mm dots, three ring markers) tilted by up to 23 degrees; one pose puts
a corner of the target (a sixth to a quarter of its dots, no ring marker) outside both images. Rendered by the core's renderer with 3 x 3 rays
per pixel, blurred (0.7 px) and 2 gray levels of noise, 8-bit.
"""
from pathlib import Path

import cv2
import numpy as np

from fesdic_core.cameras.targets import Target
from fesdic_core.synthetic.render import demo_cameras, render_stereo
from fesdic_core.synthetic.target import posed_rig, target_specimen

DOTS = Target("dots", 9, 12, 8.0, markers=((2, 2), (2, 6), (9, 6)), dot_diameter_mm=3.2)
CUT_VIEW = 6          # the pose whose target leaves both images in part


def true_rig():
    return demo_cameras(image_size=(640, 480), field_mm=130.0,
                        dist=np.array([-0.08, 0.05, 0.0, 0.0, 0.0]))


def poses(n: int = 8, seed: int = 0):
    rng = np.random.default_rng(seed)
    out = [(np.array([rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), rng.uniform(-0.3, 0.3)]),
            np.array([rng.uniform(-10, 10), rng.uniform(-8, 8), rng.uniform(-30, 30)]))
           for _ in range(n)]
    out[CUT_VIEW] = (out[CUT_VIEW][0], np.array([30.0, 20.0, 0.0]))
    return out


def render_views(target: Target = DOTS, n: int = 8, supersample: int = 3):
    """[(cam0 image, cam1 image)] (8-bit arrays) of the target in each pose, and the rig."""
    rig, specimen, views = true_rig(), target_specimen(target), []
    for v, (rvec, tvec) in enumerate(poses(n)):
        images = render_stereo(specimen, posed_rig(rig, rvec, tvec), supersample=supersample,
                               noise_std=0.0, bit_depth=None, progress=False)
        rng = np.random.default_rng(100 + v)
        views.append(tuple(np.clip(np.rint(cv2.GaussianBlur(im, (0, 0), 0.7)
                                           + rng.normal(0.0, 2.0, im.shape)), 0, 255)
                           .astype(np.uint8) for im in images))
    return views, rig


def write_views(folder: Path, views) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for v, pair in enumerate(views):
        for c, image in enumerate(pair):
            cv2.imwrite(str(folder / f"target_{v:02d}_cam{c}.png"), image)
    return folder
