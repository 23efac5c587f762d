"""Checks of a measurement's inputs, made before the first Gauss-Newton step.

Shared by the shape (:mod:`fesdic_core.shape.driver`) and the displacement
(:mod:`fesdic_core.displacement.driver`) drivers: the images and cameras fit together and
the mesh projects into them, the coarsest scale leaves an image to correlate, and the
images show a texture above their noise over the specimen. Each raises
:class:`MeasurementInputError` naming the image, camera or value at fault.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from fesdic_core.errors import FesdicCoreError
from fesdic_core.fe.mesh import SurfaceMesh, validate_mesh
from fesdic_core.imaging.image import Image
from fesdic_core.imaging.noise import MIN_TEXTURE_RATIO, residual_noise_floor

__all__ = ["MeasurementInputError", "check_inputs", "check_scales", "check_texture"]


class MeasurementInputError(FesdicCoreError, ValueError):
    """Inputs of a measurement that do not fit together (sizes, visibility)."""


def check_inputs(mesh: SurfaceMesh, images: Sequence[Image], cameras: Sequence) -> None:
    """Raise :class:`MeasurementInputError` naming the image or camera at fault.

    The mesh is validated too (:class:`~fesdic_core.fe.mesh.MeshError` names a degenerate or
    inverted element).
    """
    validate_mesh(mesh)
    if len(images) != 2 or len(cameras) != 2:
        raise MeasurementInputError(f"a stereo pair needs 2 images and 2 cameras, got "
                                    f"{len(images)} and {len(cameras)}")
    if images[0].shape != images[1].shape:
        raise MeasurementInputError(
            f"images of different sizes in one stereo pair: {images[0].source} is "
            f"{images[0].shape[1]} x {images[0].shape[0]} px, {images[1].source} is "
            f"{images[1].shape[1]} x {images[1].shape[0]} px")
    models = [(getattr(im, "prefilter_px", 0.0), getattr(im, "order", 3)) for im in images]
    if models[0] != models[1]:                   # the residual compares the two interpolants
        raise MeasurementInputError(
            f"images of different image models in one stereo pair: {images[0].source} has "
            f"prefilter_px {models[0][0]:g}, order {models[0][1]}; {images[1].source} has "
            f"prefilter_px {models[1][0]:g}, order {models[1][1]}")
    for image, cam in zip(images, cameras):
        w, h = cam.image_size
        if (h, w) != tuple(image.shape):
            raise MeasurementInputError(
                f"{image.source}: image is {image.shape[1]} x {image.shape[0]} px but camera "
                f"{cam.name} expects {w} x {h} px")
        x = cam.project(mesh.nodes)
        seen = cam.in_front(mesh.nodes) & image.inside(x)
        if not np.any(seen):
            raise MeasurementInputError(
                f"mesh {mesh.name!r} projects entirely outside {image.source} (camera {cam.name}): "
                "check the camera poses (landmarks) and the mesh units (mm)")


def check_scales(images: Sequence[Image], scales: Sequence[int], min_px: int = 32) -> None:
    """Raise :class:`MeasurementInputError` if the coarsest scale leaves too small an image."""
    h, w = images[0].shape
    s = max(scales)
    if min(h, w) >> s < min_px:
        raise MeasurementInputError(
            f"image scale {s} is too coarse for {images[0].source} ({w} x {h} px): the coarsest "
            f"image would be {w >> s} x {h >> s} px after {s} halvings, at least {min_px} px a "
            f"side are needed; use at most {max(0, int(np.log2(min(h, w) / min_px)))} halvings")


def check_texture(X: np.ndarray, mask: np.ndarray, images: Sequence[Image], cameras: Sequence) -> None:
    """Raise :class:`MeasurementInputError` if an image shows no texture above its noise
    over the region the points ``X`` cover (full-resolution images and cameras)."""
    floor = residual_noise_floor(X, mask, images, cameras)
    for image, ratio, contrast, sigma in zip(images, floor.texture_ratio(), floor.contrast,
                                             floor.sigma_gray):
        if not ratio >= MIN_TEXTURE_RATIO:
            raise MeasurementInputError(
                f"{image.source}: no texture to correlate over the specimen: contrast "
                f"{contrast:.3g} gray levels against noise {sigma:.3g} (ratio {ratio:.3g}, at least "
                f"{MIN_TEXTURE_RATIO:g} needed): a uniform or pure-noise image, or the wrong image")
