"""Synthetic stereo renderer: ray casting of a speckled plate ``z = f(x, y)``.

The images obey the gray-level conservation of Eq. 3 by construction: every
pixel of every camera shows the texture ``f(x, y)`` painted on the material
point ``X = (x, y, height(x, y))`` its ray hits, so ``f0(P_0(X)) = f1(P_1(X))``
up to the pixel integration (supersampling) and the noise.

Cameras are duck-typed: anything with ``K`` (3, 3) (skew ``K[0, 1]``), ``dist``
(5,) OpenCV ``[k1, k2, p1, p2, k3]``, ``rvec`` (3,), ``tvec`` (3,) in mm
(``x_cam = R(rvec) X + tvec``) and ``image_size`` (w, h) renders.
"""

from __future__ import annotations

import logging
import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Sequence

import cv2
import numpy as np
from scipy import ndimage
from tqdm import tqdm

from fesdic_core.cameras.camera import Camera
from fesdic_core.synthetic.motion import Motion, intersect_displaced
from fesdic_core.synthetic.rays import intersect_surface, pixel_rays
from fesdic_core.synthetic.specimen import Specimen

logger = logging.getLogger(__name__)

__all__ = ["GRAY_RANGE", "TEXELS_PER_SPECKLE", "MAX_TEXELS", "CHUNK_RAYS", "SpeckleTexture",
           "speckle_texture", "speckle_mm_for", "render_stereo", "look_at", "demo_cameras",
           "true_surface_points", "true_normal_offset"]

GRAY_RANGE = (30.0, 220.0)  # gray levels of the dots and of the paint
TEXELS_PER_SPECKLE = 6  # texel size = speckle_mm / 6
MAX_TEXELS = 100_000_000
CHUNK_RAYS = 1 << 19  # rays per chunk (~130 MB of work arrays; one chunk per thread)

# ----------------------------------------------------------------------------- texture
@dataclass(frozen=True)
class SpeckleTexture:
    """Gray levels on a regular texel grid in plate coordinates (mm).

    ``values[j, i]`` is the gray level at ``(x0 + i texel_mm, y0 + j texel_mm)``.
    """

    values: np.ndarray
    origin_mm: tuple[float, float]
    texel_mm: float

    def evaluate(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear interpolation of the texture at ``(x, y)`` (mm), any shape."""
        coords = np.stack([(np.ravel(y) - self.origin_mm[1]) / self.texel_mm,
                           (np.ravel(x) - self.origin_mm[0]) / self.texel_mm])
        out = ndimage.map_coordinates(self.values, coords, order=1, mode="nearest")
        return out.reshape(np.shape(x)).astype(float)


def speckle_texture(specimen: Specimen) -> SpeckleTexture:
    """Seeded, band-limited random-dot speckle covering the plate.

    Dots of diameter ``speckle_mm`` at Poisson-random centres (50 % coverage)
    are rasterised on texels of ``speckle_mm / 6``, Gaussian-smoothed
    (sigma = 1 texel) and stretched to the gray levels ``GRAY_RANGE``.
    """
    texel = specimen.speckle_mm / TEXELS_PER_SPECKLE
    margin = 4 * texel
    nx = int(math.ceil((specimen.length_mm + 2 * margin) / texel)) + 1
    ny = int(math.ceil((specimen.width_mm + 2 * margin) / texel)) + 1
    if nx * ny > MAX_TEXELS:
        raise ValueError(
            f"Specimen.speckle_mm={specimen.speckle_mm} is too small for a "
            f"{specimen.length_mm} x {specimen.width_mm} mm plate ({nx * ny} texels > {MAX_TEXELS})"
        )
    rng = np.random.default_rng(specimen.seed)
    radius = 0.5 * TEXELS_PER_SPECKLE  # dot radius in texels
    n_dots = rng.poisson(math.log(2.0) * nx * ny / (math.pi * radius**2))  # 1 - exp(-n a) = 1/2
    dots = np.zeros((ny, nx), dtype=bool)
    dots[rng.integers(0, ny, n_dots), rng.integers(0, nx, n_dots)] = True
    r = int(math.ceil(radius))
    jj, ii = np.mgrid[-r:r + 1, -r:r + 1]
    dots = ndimage.binary_dilation(dots, structure=ii**2 + jj**2 <= radius**2)
    smooth = ndimage.gaussian_filter(np.where(dots, 0.0, 1.0).astype(np.float32), sigma=1.0)
    lo, hi = float(smooth.min()), float(smooth.max())
    values = GRAY_RANGE[0] + (GRAY_RANGE[1] - GRAY_RANGE[0]) * (smooth - lo) / max(hi - lo, 1e-12)
    origin = (-0.5 * specimen.length_mm - margin, -0.5 * specimen.width_mm - margin)
    return SpeckleTexture(values=values.astype(np.float32), origin_mm=origin, texel_mm=texel)


def speckle_mm_for(camera, speckle_px: float = 4.0) -> float:
    """Speckle size (mm) that appears ``speckle_px`` pixels wide at the world origin."""
    depth = float(np.asarray(camera.tvec, float)[2])  # z_cam of the origin
    return speckle_px * depth / float(np.asarray(camera.K, float)[0, 0])


# ----------------------------------------------------------------------------- rays


def _render_rows(specimen, camera, texture, rows, offsets, background, motion=None) -> np.ndarray:
    """Gray levels (len(rows), w) of some image rows: s x s rays per pixel, averaged.

    With a ``motion``, each ray finds the material point ``(x, y)`` whose displaced
    position it hits (:func:`intersect_displaced`): the texture moves with the material.
    """
    w, s = int(camera.image_size[0]), len(offsets)
    v = (rows[:, None] + offsets[None, :])[:, :, None, None]  # (nr, s, 1, 1)
    u = (np.arange(w)[:, None] + offsets[None, :])[None, None, :, :]  # (1, 1, w, s)
    u, v = np.broadcast_arrays(u, v)
    centre, directions = pixel_rays(camera, np.column_stack([u.ravel(), v.ravel()]))
    if motion is None:
        lam = intersect_surface(specimen, centre, directions)
        hit = np.isfinite(lam) & (lam > 0)
        x = np.where(hit, centre[0] + lam * directions[:, 0], np.inf)
        y = np.where(hit, centre[1] + lam * directions[:, 1], np.inf)
    else:
        x, y, lam = intersect_displaced(specimen, motion, centre, directions)
        hit = np.isfinite(lam) & (lam > 0)
        x, y = np.where(hit, x, np.inf), np.where(hit, y, np.inf)
    material = hit & specimen.contains(x, y)
    gray = np.full(lam.shape, float(background))
    gray[material] = texture(x[material], y[material])
    return gray.reshape(len(rows), s, w, s).mean(axis=(1, 3))  # pixel integration


def _render_view(specimen, camera, texture, supersample, background, progress, motion=None) -> np.ndarray:
    """Supersampled gray levels (h, w) of one camera, row chunks cast on a thread pool."""
    w, h = (int(v) for v in camera.image_size)
    s = int(supersample)
    offsets = (np.arange(s) + 0.5) / s - 0.5  # sample positions inside [-0.5, 0.5]
    rows_per_chunk = max(1, CHUNK_RAYS // (w * s * s))
    chunks = [np.arange(r0, min(r0 + rows_per_chunk, h)) for r0 in range(0, h, rows_per_chunk)]
    image = np.empty((h, w))
    name = getattr(camera, "name", "camera")
    with ThreadPoolExecutor(max_workers=min(os.cpu_count() or 1, len(chunks))) as pool:
        work = pool.map(lambda rows: _render_rows(specimen, camera, texture, rows, offsets, background, motion),
                        chunks)
        for rows, gray in zip(chunks, tqdm(work, total=len(chunks), desc=f"render {name}", unit="chunk",
                                           disable=not progress)):
            image[rows] = gray
    return image


def render_stereo(
    specimen: Specimen,
    cameras: Sequence,
    supersample: int = 3,
    noise_std: float = 0.0,
    seed: int = 0,
    background: float = 10.0,
    bit_depth: int | None = 8,
    speckle_mm: float | None = None,
    progress: bool | None = None,
    motion: "Motion | None" = None,
) -> list[np.ndarray]:
    """Render one gray-level image (h, w) float per camera.

    Each pixel (centre at integer coordinates, covering ``[x - 0.5, x + 0.5]``)
    averages ``supersample**2`` rays cast through the camera model (distortion
    and skew included) onto ``z = height(x, y)``; material points show the
    texture, the rest ``background``. Seeded Gaussian noise of ``noise_std``
    gray levels is then added, and the result rounded and clipped to
    ``[0, 2**bit_depth - 1]`` unless ``bit_depth`` is None. ``speckle_mm``
    overrides ``specimen.speckle_mm``; ``progress`` (default: logging at INFO)
    shows a tqdm bar per camera. ``motion`` (a :data:`Motion`, e.g.
    :class:`RigidMotion`) renders the specimen displaced: the material point ``X``
    of the surface, with its paint, sits at ``X + motion(X)`` (default: not displaced).
    """
    if int(supersample) < 1:
        raise ValueError(f"supersample must be a positive integer, got {supersample!r}")
    if not noise_std >= 0:
        raise ValueError(f"noise_std must be >= 0, got {noise_std!r}")
    if bit_depth is not None and not 1 <= int(bit_depth) <= 32:
        raise ValueError(f"bit_depth must be None or in [1, 32], got {bit_depth!r}")
    if speckle_mm is not None:
        specimen = replace(specimen, speckle_mm=speckle_mm)
    if progress is None:
        progress = logger.isEnabledFor(logging.INFO)
    texture = specimen.texture if specimen.texture is not None else speckle_texture(specimen).evaluate
    rng = np.random.default_rng(seed)
    images = []
    for camera in cameras:
        image = _render_view(specimen, camera, texture, supersample, background, progress, motion)
        if noise_std > 0:
            image += rng.normal(0.0, noise_std, image.shape)
        if bit_depth is not None:
            image = np.clip(np.rint(image), 0.0, 2.0 ** int(bit_depth) - 1.0)
        images.append(image)
        logger.info("rendered %s: %d x %d px, supersample %d", getattr(camera, "name", "camera"),
                    image.shape[1], image.shape[0], supersample)
    return images


# ----------------------------------------------------------------------------- rigs and truth
def look_at(centre: np.ndarray) -> np.ndarray:
    """World-to-camera rotation (3, 3) of a camera at ``centre`` looking at the origin.

    Image x follows world x, image y (down) follows world -y (camera above z = 0).
    """
    z_cam = -np.asarray(centre, float) / np.linalg.norm(centre)
    x_cam = np.array([1.0, 0.0, 0.0]) - z_cam[0] * z_cam
    x_cam /= np.linalg.norm(x_cam)
    return np.stack([x_cam, np.cross(z_cam, x_cam), z_cam])


def demo_cameras(
    image_size: tuple[int, int] = (1200, 800),
    stereo_angle_deg: float = 25.0,
    distance_mm: float = 400.0,
    field_mm: float = 80.0,
    focal_px: float | None = None,
    dist: np.ndarray | None = None,
) -> tuple[Camera, Camera]:
    """Two cameras at ``distance_mm`` from the origin, symmetric about the y-z plane.

    cam0 sits at ``x < 0``, cam1 at ``x > 0``, each tilted by half the stereo
    angle; by default the focal length makes ``field_mm`` (along x, at the
    origin) fill the image width. Principal point at the image centre.
    """
    w, h = (int(v) for v in image_size)
    if w < 1 or h < 1:
        raise ValueError(f"image_size must be two positive integers (w, h), got {image_size!r}")
    if not (distance_mm > 0 and field_mm > 0 and 0 <= stereo_angle_deg < 180):
        raise ValueError(
            f"need distance_mm > 0, field_mm > 0 and stereo_angle_deg in [0, 180), got "
            f"{distance_mm!r}, {field_mm!r}, {stereo_angle_deg!r}"
        )
    half = math.radians(0.5 * stereo_angle_deg)
    focal = w * distance_mm / (field_mm * math.cos(half)) if focal_px is None else float(focal_px)
    K = np.array([[focal, 0.0, 0.5 * (w - 1)], [0.0, focal, 0.5 * (h - 1)], [0.0, 0.0, 1.0]])
    dist = np.zeros(5) if dist is None else np.asarray(dist, float).ravel()
    cams = []
    for i, side in enumerate((-1.0, 1.0)):
        centre = distance_mm * np.array([side * math.sin(half), 0.0, math.cos(half)])
        R = look_at(centre)
        cams.append(Camera(K=K.copy(), dist=dist.copy(), rvec=cv2.Rodrigues(R)[0].ravel(),
                           tvec=-R @ centre, image_size=(w, h), name=f"cam{i}"))
    return cams[0], cams[1]


def true_surface_points(specimen: Specimen, xy: np.ndarray) -> np.ndarray:
    """Points (n, 3) of the actual surface above plate coordinates ``xy`` (n, 2) mm."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    return np.column_stack([xy, specimen.height(xy[:, 0], xy[:, 1])])


def true_normal_offset(specimen: Specimen, X_nominal: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Offsets ``q`` (n,) with ``X_nominal + q normals`` on the actual surface (Remark 1)."""
    X = np.asarray(X_nominal, float).reshape(-1, 3)
    n = np.asarray(normals, float).reshape(-1, 3)
    return intersect_surface(specimen, X, n)  # Newton from the plane z = 0 (q = 0 on it)
