"""OpenCV's stereo checkerboard sample calibrated two ways, side by side (issue 24).

The classic real set of OpenCV's samples (``../shared/data/opencv_stereo_checkerboard``,
13 pairs, 640 x 480 px, 9 x 6 inner corners, square 10 units):

- **OpenCV's sample procedure** (``samples/cpp/stereo_calib.cpp``, its flags as published):
  the classic detector, ``cornerSubPix`` (11 x 11), ``initCameraMatrix2D`` and one
  ``stereoCalibrate`` with ``FIX_ASPECT_RATIO | ZERO_TANGENT_DIST | USE_INTRINSIC_GUESS |
  SAME_FOCAL_LENGTH | RATIONAL_MODEL | FIX_K3 | FIX_K4 | FIX_K5``;
- **ours**: ``georeg calibrate examples/calibration/opencv_checkerboard.toml``'s library path
  (default model ``k1k2p1p2k3``, intrinsics per camera then the stereo bundle, rejection).

Printed: views used, the stereo RMS (per coordinate, OpenCV's convention), both cameras'
focal lengths and principal points, the baseline (units of the square / 10) and the angle.

Run: ``PYTHONPATH=. python benchmarks/bench_checkerboard.py [--data ../shared/data]``
"""
from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fesdic_core.cameras.rig import stereo_transform  # noqa: E402
from fesdic_core.cameras.targets import Target, detect  # noqa: E402
from fesdic_core.cameras.targets.calibration import calibrate_stereo  # noqa: E402

SIZE, SQUARE = (9, 6), 10.0


def opencv_sample(left, right):
    objects, p0, p1 = [], [], []
    grid = np.zeros((SIZE[0] * SIZE[1], 3), np.float32)
    grid[:, :2] = np.mgrid[0:SIZE[0], 0:SIZE[1]].T.reshape(-1, 2) * SQUARE
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 30, 0.01)
    for a, b in zip(left, right):
        found = []
        for path in (a, b):
            g = cv2.imread(path, 0)
            ok, corners = cv2.findChessboardCorners(g, SIZE, flags=cv2.CALIB_CB_ADAPTIVE_THRESH |
                                                    cv2.CALIB_CB_NORMALIZE_IMAGE)
            if not ok:
                break
            found.append(cv2.cornerSubPix(g, corners, (11, 11), (-1, -1), criteria))
        if len(found) == 2:
            objects.append(grid), p0.append(found[0]), p1.append(found[1])
    size = cv2.imread(left[0], 0).shape[::-1]
    K0 = cv2.initCameraMatrix2D(objects, p0, size, 0)
    K1 = cv2.initCameraMatrix2D(objects, p1, size, 0)
    flags = (cv2.CALIB_FIX_ASPECT_RATIO | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_USE_INTRINSIC_GUESS
             | cv2.CALIB_SAME_FOCAL_LENGTH | cv2.CALIB_RATIONAL_MODEL | cv2.CALIB_FIX_K3
             | cv2.CALIB_FIX_K4 | cv2.CALIB_FIX_K5)
    rms, K0, d0, K1, d1, R, T, _, _ = cv2.stereoCalibrate(
        objects, p0, p1, K0, None, K1, None, size, flags=flags,
        criteria=(cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-5))
    return len(objects), rms, (K0, K1), R, T


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path,
                        default=Path(__file__).resolve().parents[2] / "shared" / "data")
    args = parser.parse_args(argv)
    folder = args.data / "opencv_stereo_checkerboard"
    left = sorted(glob.glob(str(folder / "left*.jpg")))
    right = sorted(glob.glob(str(folder / "right*.jpg")))
    if not left:
        raise SystemExit(f"{folder}: no left*.jpg (the data are not part of the project)")
    n, rms, K, R, T = opencv_sample(left, right)
    target = Target("checkerboard", SIZE[1], SIZE[0], SQUARE)
    d0 = [detect(cv2.imread(p, 0), target, p) for p in left]
    d1 = [detect(cv2.imread(p, 0), target, p) for p in right]
    cal = calibrate_stereo(d0, d1, target)
    Ro, To = stereo_transform(*cal.cameras)
    rows = [("views used", f"{n}", f"{sum(v.status == 'used' for v in cal.views)}"),
            ("stereo RMS per coordinate (px)", f"{rms:.4f}", f"{cal.rms_px / np.sqrt(2):.4f}")]
    for c in range(2):
        ours = cal.cameras[c].K
        rows.append((f"camera {c} fx, fy (px)", f"{K[c][0, 0]:.2f}, {K[c][1, 1]:.2f}",
                     f"{ours[0, 0]:.2f}, {ours[1, 1]:.2f}"))
        rows.append((f"camera {c} cx, cy (px)", f"{K[c][0, 2]:.2f}, {K[c][1, 2]:.2f}",
                     f"{ours[0, 2]:.2f}, {ours[1, 2]:.2f}"))
    rows.append(("baseline (squares / 10)", f"{np.linalg.norm(T):.3f}",
                 f"{cal.baseline_mm:.3f} +- {cal.std['baseline_mm']:.3f}"))
    rows.append(("stereo angle (deg)", f"{np.degrees(np.linalg.norm(cv2.Rodrigues(R)[0])):.3f}",
                 f"{np.degrees(np.linalg.norm(cv2.Rodrigues(Ro)[0])):.3f}"))
    print(f"{'':34s} {'OpenCV sample':>20s} {'georeg calibrate':>26s}")
    for label, a, b in rows:
        print(f"{label:34s} {a:>20s} {b:>26s}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
