"""Pick the landmarks and the nominal geometry of the Stereo DIC Challenge specimen, once.

This is the one-time preparation of ``specimen.toml``, ``analysis.toml`` and the landmarks
of ``specimen_part.toml``; nothing else calls it. It prints TOML snippets; the values stored
in the configurations are these, rounded (0.01 mm for landmarks, 0.1 mm for the geometry).

1. Sparse stereo by normalised cross-correlation (NCC) along epipolar lines: a 41 px
   template around a point of camera 0 is compared with camera 1 at points of the
   camera-0 ray; the best depth (then a 2-D sub-pixel refinement) gives the match,
   and the two rays are intersected (midpoint). Works on the speckle, not on edges.
2. Base plane: plane through matched points of the plate (away from the features).
3. Plate edges: two points per edge picked by eye in camera 0 on zoomed crops (at the
   transition between the speckled top face and the plate side or the background);
   the four edge lines intersect at the (virtual, sharp) corners, which are put on the
   base plane. World frame: origin at the centre of the four corners, z along the base
   normal towards the cameras, x along the bottom edge (left to right in the images),
   y = z x x (up in the images). The four sides come out 100.4-101.7 mm (4 in = 101.6).
4. Heights above the base plane, on a 4 px grid over each feature (NCC of a 13 px
   template along the camera-0 ray, heights -1..8 mm by 0.05 mm): outline of the block
   top, cylinder axes (robust circle fit of the cross-sections), prism ridges and
   footprints. These place the CAD's features and the analysis regions; they are not results.
5. Landmarks: speckle points at chosen world positions (plate near its corners, block
   top, cylinder crests) matched in both views and triangulated: their world
   coordinates and pixels in both (cropped) images.

Usage: ``python examples/dic_challenge/pick_landmarks.py`` (about 1 minute).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import least_squares

from fesdic_core.cameras.rig import read_pyvale_csv

DATA = Path(__file__).resolve().parents[2] / "data" / "dic_challenge_stereo"

#: points of the plate in camera 0 (cropped pixels), away from the features
BASE_SEEDS = [(816, 1522), (216, 1472), (116, 772), (816, 922), (1516, 922), (1516, 1522),
              (916, 822), (1266, 472), (1166, 1222)]
#: two points of each plate edge in camera 0 (cropped pixels), picked on zoomed crops
PLATE_EDGES = {"left": [(64.5, 472), (75.5, 1272)], "right": [(1639, 472), (1661.5, 1272)],
               "top": [(516, 47.5), (1216, 57)], "bottom": [(516, 1638), (1216, 1636.5)]}
#: boxes of camera 0 (cropped pixels, x0 x1 y0 y1) around each feature
FEATURE_BOXES = {"block": (236, 746, 832, 1322), "cylinder_v": (1376, 1606, 112, 792),
                 "cylinder_h": (86, 846, 72, 322), "prism_v": (976, 1236, 112, 802),
                 "prism_h": (86, 846, 462, 712)}
#: landmark positions (world x, y in mm) and the surface they lie on
LANDMARK_TARGETS = [((-45.0, -45.0), "plate"), ((45.0, -45.0), "plate"), ((28.0, 40.0), "plate"),
                    ((-45.0, 27.0), "plate"), ((0.0, 0.0), "plate"), ((-30.0, -10.0), "block"),
                    ((-18.0, -22.0), "block"), ((40.9, 25.0), "cylinder_v"),
                    ((-25.0, 40.2), "cylinder_h")]


class Stereo:
    """Camera 0 at the identity pose, camera 1 by the stereo transform, cropped images."""

    def __init__(self):
        self.images = [cv2.imread(str(DATA / f"cam{c}.png"), cv2.IMREAD_GRAYSCALE).astype(np.float32)
                       for c in (0, 1)]
        h, w = self.images[0].shape
        self.cams = read_pyvale_csv(DATA / "calibration_cropped.csv", (w, h))

    def rays(self, c: int, px) -> np.ndarray:
        """Unit directions (n, 3), in the camera-0 frame, of the rays of camera ``c``."""
        cam = self.cams[c]
        xn = cv2.undistortPoints(np.asarray(px, np.float64).reshape(-1, 1, 2), np.array(cam.K),
                                 np.array(cam.dist)).reshape(-1, 2)
        d = np.column_stack([xn, np.ones(len(xn))]) @ cam.R       # R^T d, row-wise
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def triangulate(self, px0, px1) -> tuple[np.ndarray, np.ndarray]:
        """Midpoints of the closest points of the two rays (n, 3) and the ray gaps (n,)."""
        C0, C1 = self.cams[0].center, self.cams[1].center
        d0, d1 = self.rays(0, px0), self.rays(1, px1)
        w = C0 - C1
        a, b, c = np.sum(d0 * d0, 1), np.sum(d0 * d1, 1), np.sum(d1 * d1, 1)
        d, e = d0 @ w, d1 @ w
        s, t = (b * e - c * d) / (a * c - b * b), (a * e - b * d) / (a * c - b * b)
        P0, P1 = C0 + s[:, None] * d0, C1 + t[:, None] * d1
        return 0.5 * (P0 + P1), np.linalg.norm(P0 - P1, axis=1)

    def match(self, p0, depths=np.arange(630.0, 720.0, 0.25), half: int = 20):
        """Camera-1 pixel of the camera-0 pixel ``p0`` (NCC along the epipolar line) and its score."""
        p0 = np.asarray(p0, float)
        d = self.rays(0, p0[None])[0]
        size = (2 * half + 1, 2 * half + 1)
        T = cv2.getRectSubPix(self.images[0], size, (float(p0[0]), float(p0[1])))
        g = self.cams[1].project(d[None] * (depths / d[2])[:, None])
        scores = [_ncc(T, cv2.getRectSubPix(self.images[1], size, (float(x), float(y)))) for x, y in g]
        gx, gy = np.round(g[int(np.argmax(scores))]).astype(int)
        s = 4
        W = self.images[1][gy - half - s:gy + half + s + 1, gx - half - s:gx + half + s + 1]
        R = cv2.matchTemplate(W, T, cv2.TM_CCOEFF_NORMED)
        iy, ix = np.unravel_index(np.argmax(R), R.shape)
        return np.array([gx - s + _peak(R[iy, :], ix), gy - s + _peak(R[:, ix], iy)]), float(R[iy, ix])

    def on_plane(self, px, centre, normal, height=0.0) -> np.ndarray:
        """Camera-0 rays through ``px`` intersected with the plane ``(X - centre) . n = height``."""
        d = self.rays(0, np.atleast_2d(px))
        return d * ((height + centre @ normal) / (d @ normal))[:, None]

    def heights(self, xs, ys, centre, normal, half=6, hs=np.arange(-1.0, 8.0, 0.05)):
        """Heights above the plane (NCC along the camera-0 rays) on a pixel grid, and the scores."""
        H = np.full((len(ys), len(xs)), np.nan)
        S = np.zeros_like(H)
        off = np.arange(-half, half + 1, dtype=np.float32)
        ox, oy = np.meshgrid(off, off)
        for i, y in enumerate(ys):
            d = self.rays(0, np.column_stack([xs, np.full(len(xs), y)]).astype(float))
            for j, x in enumerate(xs):
                T = self.images[0][y - half:y + half + 1, x - half:x + half + 1]
                T = T - T.mean()
                X = d[j][None] * ((hs + centre @ normal) / (d[j] @ normal))[:, None]
                g = self.cams[1].project(X).astype(np.float32)
                mx = (g[:, 0, None, None] + ox).reshape(-1, 2 * half + 1)
                my = (g[:, 1, None, None] + oy).reshape(-1, 2 * half + 1)
                P = cv2.remap(self.images[1], mx, my, cv2.INTER_LINEAR).reshape(len(hs), 2 * half + 1, -1)
                P = P - P.mean(axis=(1, 2), keepdims=True)
                v = (P * T).sum(axis=(1, 2)) / (np.sqrt((T * T).sum() * (P * P).sum(axis=(1, 2))) + 1e-9)
                k = int(np.argmax(v))
                H[i, j], S[i, j] = hs[k], v[k]
        return H, S


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum() + 1e-12))


def _peak(r: np.ndarray, i: int) -> float:
    """Sub-pixel position of a maximum by a parabola through three samples."""
    if 0 < i < len(r) - 1 and (den := r[i - 1] - 2 * r[i] + r[i + 1]) != 0:
        return i + 0.5 * (r[i - 1] - r[i + 1]) / den
    return float(i)


def _intersect(l1, l2) -> np.ndarray:
    (p, q), (r, s) = [np.asarray(v, float) for v in l1], [np.asarray(v, float) for v in l2]
    t = np.linalg.solve(np.column_stack([q - p, r - s]), r - p)
    return p + t[0] * (q - p)


def world_frame(st: Stereo):
    """Base plane (camera-0 frame) and the world frame: ``X_world = R (X_cam0 - origin)``."""
    px1 = []
    for p in BASE_SEEDS:
        m, score = st.match(p)
        px1.append(m)
    X, gap = st.triangulate(np.array(BASE_SEEDS, float), np.array(px1))
    centre = X.mean(axis=0)
    normal = np.linalg.svd(X - centre)[2][2]
    normal = -normal if normal[2] > 0 else normal              # towards camera 0
    print(f"# base plane from {len(X)} points: residuals {np.abs((X - centre) @ normal).max():.3f} mm, "
          f"ray gaps < {gap.max():.3f} mm")
    e = PLATE_EDGES
    corners_px = np.array([_intersect(e["top"], e["left"]), _intersect(e["top"], e["right"]),
                           _intersect(e["bottom"], e["right"]), _intersect(e["bottom"], e["left"])])
    P = st.on_plane(corners_px, centre, normal)
    sides = [np.linalg.norm(P[i] - P[(i + 1) % 4]) for i in range(4)]
    print("# plate sides (mm): " + ", ".join(f"{s:.2f}" for s in sides))
    origin = P.mean(axis=0)
    ex = P[2] - P[3]
    ex -= (ex @ normal) * normal
    ex /= np.linalg.norm(ex)
    R = np.array([ex, np.cross(normal, ex), normal])
    return centre, normal, origin, R


def _points(st, box, centre, normal, origin, R, smin=0.85):
    xs, ys = np.arange(box[0], box[1], 4), np.arange(box[2], box[3], 4)
    H, S = st.heights(xs, ys, centre, normal)
    X, Y = np.meshgrid(xs, ys)
    ok = S.ravel() > smin
    px = np.column_stack([X.ravel(), Y.ravel()])[ok].astype(float)
    Xc = np.concatenate([st.on_plane(p[None], centre, normal, h) for p, h in zip(px, H.ravel()[ok])])
    return (Xc - origin) @ R.T


def features(st, centre, normal, origin, R) -> None:
    """Print the nominal geometry of each feature (world frame, mm)."""
    for name, box in FEATURE_BOXES.items():
        W = _points(st, box, centre, normal, origin, R)
        vertical = name.endswith("_v")
        along, lateral = (1, 0) if vertical else (0, 1)
        raised = W[W[:, 2] > 2.0]
        span = np.percentile(raised[:, along], [0.5, 99.5])
        if name == "block":
            top = W[W[:, 2] > 5.0]
            print(f"# block: top {np.median(top[:, 2]):.3f} mm above the base, x {np.percentile(top[:, 0], [0.5, 99.5]).round(2)}, "
                  f"y {np.percentile(top[:, 1], [0.5, 99.5]).round(2)}")
        elif name.startswith("cylinder"):
            X = raised

            def residual(p):
                return np.hypot(X[:, lateral] - p[0], X[:, 2] - p[1]) - p[2]

            fit = least_squares(residual, [np.median(X[:, lateral]), 0.0, 6.3], loss="soft_l1", f_scale=0.05)
            c, z, r = fit.x
            print(f"# {name}: axis at {'x' if vertical else 'y'} = {c:.2f}, z = {z:.2f}, radius {r:.2f}, "
                  f"crest {z + r:.2f}; along {span.round(2)}")
        else:
            bins = np.arange(np.floor(W[:, lateral].min()), W[:, lateral].max(), 0.5)
            idx = np.digitize(W[:, lateral], bins)
            prof = np.array([[bins[i - 1] + 0.25, np.median(W[idx == i, 2])]
                             for i in range(1, len(bins)) if np.any(idx == i)])
            foot = prof[prof[:, 1] > 0.3, 0]
            print(f"# {name}: ridge at {prof[np.argmax(prof[:, 1]), 0]:.2f}, footprint "
                  f"{foot.min():.2f}..{foot.max():.2f}, along {span.round(2)}")


def landmarks(st, centre, normal, origin, R, heights: dict[str, float]) -> None:
    """Print the [[landmarks]] tables: speckle points matched in both views."""
    for (x, y), surface in LANDMARK_TARGETS:
        X = origin + R.T @ np.array([x, y, heights[surface]])
        p0 = st.cams[0].project(X[None])[0]
        p1, score = st.match(p0)
        Xc, gap = st.triangulate(p0[None], p1[None])
        W = (Xc[0] - origin) @ R.T
        print(f"\n[[landmarks]]    # {surface}, NCC {score:.3f}, ray gap {gap[0] * 1e3:.1f} um\n"
              f"xyz_mm = [{W[0]:.3f}, {W[1]:.3f}, {W[2]:.3f}]\n"
              f"cam0_px = [{p0[0]:.2f}, {p0[1]:.2f}]\ncam1_px = [{p1[0]:.2f}, {p1[1]:.2f}]")


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    st = Stereo()
    centre, normal, origin, R = world_frame(st)
    features(st, centre, normal, origin, R)
    landmarks(st, centre, normal, origin, R,
              {"plate": 0.0, "block": 6.3, "cylinder_v": 6.15, "cylinder_h": 6.14})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
