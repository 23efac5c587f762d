"""Measure the faces: fixed point of calibration (6 pose unknowns, stereo relation kept) and
shape, geometric regularization over the spline levels, coarse to fine image scales.

Every face is measured on its own; its final cameras place it relative to the rig. The
measured surface in the camera-0 frame does not depend on that gauge (a rigid motion of
the specimen and of the cameras together leaves the residual unchanged, section 2.2), so
all faces are put in one world frame through camera 0: ``X_world = R_ref^T (R_0 X + t_0
- t_ref)``, ``(R_0, t_0)`` the face's final camera 0 and ``(R_ref, t_ref)`` the camera 0
of the landmarks; :func:`base_plane_frame` then puts the measured base plane at z = 0.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Sequence

import numpy as np
from tqdm.auto import tqdm

from adapters.fesdic_core import NominalModel, measured_spline, multilevel_for_mesh
from fesdic_core.driver import Measurement, MeasurementSettings, measure
from fesdic_core.image import Image, read_image
from fesdic_core.mesh import node_normals
from fesdic_core.rig import initial_rig_pose, read_pyvale_csv, stereo_transform
from georeg_plugin.patch import SplinePatch
from georeg_plugin.solver import GeometricRegularization, SingularProjectionError

from .config import Face, Nominal, Specimen
from .geometry import face_model, feature_solid
from .visibility import visibility

logger = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, eq=False)
class FaceResult:
    """One nominal surface of one face, measured.

    ``points_mm`` (g, 3) are the integration points on the measured surface and
    ``residual_percent`` (g,) their gray-level residual (NaN where masked); ``nodes_mm``
    the measured FE nodes; all in the common world frame (see the module docstring).
    """

    face: str
    nominal: Nominal
    model: NominalModel
    measurement: Measurement
    nodes_mm: np.ndarray
    points_mm: np.ndarray
    residual_percent: np.ndarray
    spline: SplinePatch | None
    time_s: float

    @property
    def seen(self) -> np.ndarray:
        return np.isfinite(self.residual_percent)


def load_images(specimen: Specimen, crop: tuple[int, int, int, int] | None = None
                ) -> tuple[Image, Image]:
    """The stereo pair, optionally cropped to ``(x0, y0, w, h)`` (px, same for both)."""
    images = [read_image(specimen.cam0), read_image(specimen.cam1)]
    if crop is not None:
        x0, y0, w, h = crop
        images = [Image.from_array(im.values[y0:y0 + h, x0:x0 + w], f"{im.source}[crop]")
                  for im in images]
    return images[0], images[1]


def initial_cameras(specimen: Specimen, images: Sequence[Image],
                    crop: tuple[int, int, int, int] | None = None) -> list:
    """The calibrated rig posed on the specimen by the landmarks (both views, stereo kept)."""
    size = (images[0].shape[1], images[0].shape[0])
    cam0, cam1 = read_pyvale_csv(specimen.pyvale_csv, size)
    shift = np.zeros(2) if crop is None else np.array(crop[:2], float)
    if crop is not None:                                  # principal points follow the crop
        cams = []
        for cam in (cam0, cam1):
            K = np.array(cam.K)
            K[:2, 2] -= shift
            cams.append(dataclasses.replace(cam, K=K))
        cam0, cam1 = cams
    R, t = stereo_transform(cam0, cam1)
    xyz = np.array([lm.xyz_mm for lm in specimen.landmarks])
    px0 = np.array([lm.cam0_px for lm in specimen.landmarks]) - shift
    px1 = np.array([lm.cam1_px for lm in specimen.landmarks]) - shift
    return list(initial_rig_pose(cam0, cam1, xyz, px0, px1, R, t))


def to_reference(X: np.ndarray, camera, reference) -> np.ndarray:
    """Points of a face measured with ``camera`` (its camera 0) in the frame of ``reference``."""
    Xc = X @ camera.R.T + camera.tvec
    return (Xc - reference.tvec) @ reference.R


def measure_nominal(face: Face, nominal: Nominal, images, cameras, *, scales=None,
                    progress: bool = False) -> FaceResult:
    """Measure one nominal surface of ``face`` with geometric regularization."""
    specimen = face.specimen
    holes = tuple(feature_solid(specimen.feature(h)) for h in nominal.holes)
    model = face_model(nominal, holes)
    curved = nominal.kind == "cylinder"
    # image scale s uses spline level min(s, levels - 1); spline dofs that no integration
    # point sees (supports inside the holes) keep their value
    solver = GeometricRegularization(multilevel_for_mesh(model, nominal.levels, curved),
                                     hold_unseen=True)
    scales = tuple(face.method.scales if scales is None else scales)
    settings = MeasurementSettings(scales=scales, calibrate=True, keep_stereo=True,
                                   max_fixed_point=face.method.max_fixed_point,
                                   max_iter=face.method.max_iter,
                                   points_per_px=face.method.points_per_px)
    occluders = tuple(feature_solid(specimen.feature(o)) for o in face.occluders)
    seen = visibility(occluders, face.method.visibility_margin_mm) if occluders else None
    t0 = time.perf_counter()
    with tqdm(total=len(scales), desc=nominal.name, unit="scale", disable=not progress,
              leave=False) as bar:
        m = measure(model.mesh, images, cameras, solver, settings, normals=node_normals(model.mesh),
                    visibility=seen, progress=lambda k, n, report: bar.update(1))
    if not m.ok:
        logger.warning("%s: %s", nominal.name, m.failure)
    elapsed = time.perf_counter() - t0
    try:
        spline, _ = measured_spline(solver, m.q, 0)
    except SingularProjectionError:       # a spline dof without FE node (a hole): no spline
        spline = None
    ref = cameras[0]
    points = to_reference(m.quadrature.points(m.nodes), m.cameras[0], ref)
    logger.info("%s: residual %.3f%% of the dynamic range, %d iterations, %.1f s, %s",
                nominal.name, m.residual_percent, m.iterations, elapsed,
                "converged" if m.converged else "NOT converged")
    return FaceResult(face=face.name, nominal=nominal, model=model, measurement=m,
                      nodes_mm=to_reference(m.nodes, m.cameras[0], ref), points_mm=points,
                      residual_percent=np.asarray(m.residual.percent, float),
                      spline=spline, time_s=elapsed)


def base_plane_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid motion ``(R, t)``, ``X -> R X + t``, putting the best-fit plane of ``points`` at
    z = 0 with the least rotation (x keeps its direction in the plane)."""
    centre = points.mean(axis=0)
    n = np.linalg.svd(points - centre, full_matrices=False)[2][2]
    n = n if n[2] > 0 else -n
    ex = np.array([1.0, 0.0, 0.0]) - n[0] * n
    ex /= np.linalg.norm(ex)
    R = np.array([ex, np.cross(n, ex), n])
    t = -R @ centre
    t[:2] += centre[:2]                  # keep the in-plane position of the centre
    return R, t


def moved(result: FaceResult, R: np.ndarray, t: np.ndarray) -> FaceResult:
    """The result with its points and nodes moved by ``X -> R X + t``."""
    return dataclasses.replace(result, nodes_mm=result.nodes_mm @ R.T + t,
                               points_mm=result.points_mm @ R.T + t)
