"""``[geometry] kind = "roi"``: a specimen from a region of interest in camera 0's image.

No CAD and no landmarks: the calibrated rig places the specimen.

1. The ROI: the polygon ``polygon_px`` minus the ``exclude_px`` polygons, or the nonzero
   pixels of ``mask`` (its outer contour and holes), in camera 0's reference image.
2. Its surface: SIFT matches inside the ROI (eroded by :data:`FEATURE_MARGIN_PX`), kept
   within :data:`~fesdic_core.cameras.triangulation.DEFAULT_MAX_EPIPOLAR_PX` of the epipolar
   line of the calibrated pair, triangulated, and a robust plane (or quadric) fit
   (:mod:`georeg_app.inputs.roi_surface`). The fit is judged in camera 1's pixels: each
   match's ray from camera 0 meets the surface, the hit projected into camera 1 lands some
   distance from the match. That distance is mostly along the epipolar line; across it, the
   matches' epipolar distance measures what the calibration and the matching give. A misfit
   above :data:`WARN_MISFIT` times that is a warning, above :data:`MAX_MISFIT` times (and
   :data:`MIN_MISFIT_PX`) an error: the surface kind is wrong for the specimen.
3. The specimen frame (:func:`~georeg_app.inputs.roi_surface.specimen_frame`; origin at the
   area centroid of the ROI cast through camera 0 on the surface, holes subtracted): the
   cameras are expressed in it, and the mesh of a plane lies in ``z = 0``.
4. The mesh: the ROI's outline cast through camera 0 onto the surface (each edge sampled
   every pixel or so), its bounding rectangle in the frame's ``(x, y)`` is the nominal
   spline (near-square knot spans; for a quadric its control points fit ``z = f(x, y)``,
   exactly), meshed with Q9 elements (Eq. 17) and trimmed as a trimmed CAD face is
   (:mod:`georeg_plugin.spline.trimmed`): an element is kept when its nine nodes lie inside
   the outline and outside every exclusion. Every kept element is an undistorted rectangle
   of the grid (a staircase boundary, well shaped by construction, at most one element
   width inside the outline). A polygon of four vertices without exclusions (a rectangle
   drawn on the image: a quadrilateral on a plane, as a pinhole maps lines to lines) is
   its own spline instead, the bilinear patch of its four cast corners, meshed whole
   (no element cut, none dropped: every spline dof is seen). Elements with a node that
   camera 1 does not see are left out, and the share of the ROI that camera 1 does not see
   is logged.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Sequence

import cv2
import numpy as np

from adapters.fesdic_core import NominalModel, nominal_model
from fesdic_core.cameras.camera import Camera
from fesdic_core.cameras.triangulation import StereoPoints, normalised_points, stereo_points
from fesdic_core.fe.mesh import CellBlock, SurfaceMesh
from fesdic_core.imaging.image import Image
from georeg_plugin.spline.geometries import quadrilateral, rectangle
from georeg_plugin.spline.refine import refine_to_elements
from georeg_plugin.spline.trimmed import inside_loops
from georeg_app.config.measure import GeometryConfig
from georeg_app.config.roi import RoiConfig
from georeg_app.errors import InputError
from georeg_app.inputs.cad import cad_refinements
from georeg_app.inputs.roi_surface import (SurfaceFit, fit_surface, height_fit, ray_hits,
                                           specimen_frame)

logger = logging.getLogger(__name__)

__all__ = ["RoiSpecimen", "roi_loops", "roi_specimen", "MIN_MATCHES", "MIN_TEXTURE",
           "FEATURE_MARGIN_PX", "WARN_MISFIT", "MAX_MISFIT", "MIN_MISFIT_PX"]

MIN_MATCHES = 30            # triangulated matches a surface fit needs
MIN_TEXTURE = 0.02          # gray-level std inside the ROI / the image's dynamic range
FEATURE_MARGIN_PX = 6       # features this close to the ROI's outline are not used
WARN_MISFIT, MAX_MISFIT, MIN_MISFIT_PX = 3.0, 20.0, 2.0
_SEEN_MARGIN_PX = 2.0       # a point camera 1 sees is this far inside its image


@dataclasses.dataclass(frozen=True, eq=False)
class RoiSpecimen:
    """What the ROI gives a run.

    Attributes
    ----------
    model : the nominal model in the specimen frame.
    cameras : the two cameras expressed in the specimen frame.
    frame_rotation, frame_origin : (3, 3), (3,): ``X_calibration = R X_specimen + origin``.
    points : the triangulated matches (calibration frame); ``fit`` the surface fitted to them.
    misfit_px : RMS of the matches' distance in camera 1 to the surface's prediction.
    epipolar_px : RMS of the matches' distance to their epipolar line.
    unseen_share : share of the ROI (area, in camera 0) that camera 1 does not see.
    """

    model: NominalModel
    cameras: tuple[Camera, Camera]
    frame_rotation: np.ndarray
    frame_origin: np.ndarray
    points: StereoPoints
    fit: SurfaceFit
    misfit_px: float
    epipolar_px: float
    unseen_share: float

    def summary(self) -> dict:
        """The frame and the fit as JSON-ready numbers (for the outputs)."""
        return {"frame_origin_mm": self.frame_origin.tolist(),
                "frame_axes": self.frame_rotation.T.tolist(), "surface_rms_mm": self.fit.rms_mm,
                "matches": int(self.points.n_points), "inliers": int(self.fit.inliers.sum()),
                "misfit_px": self.misfit_px, "epipolar_px": self.epipolar_px,
                "unseen_share": self.unseen_share}


def _where(roi: RoiConfig) -> str:
    return "[geometry] mask" if roi.mask is not None else "[geometry] polygon_px"


def roi_loops(roi: RoiConfig, shape: tuple[int, int]) -> tuple[np.ndarray, list[np.ndarray]]:
    """The ROI's mask (h, w) bool and its loops in px (outer first, then the holes)."""
    h, w = shape
    if roi.mask is not None:
        raw = cv2.imread(str(roi.mask), cv2.IMREAD_GRAYSCALE)
        if raw is None:
            raise InputError(f"[geometry] mask: cannot read {roi.mask} as an image")
        if raw.shape != (h, w):
            raise InputError(f"[geometry] mask: {roi.mask} is {raw.shape[1]} x {raw.shape[0]} px, "
                             f"camera 0's image {w} x {h} px")
        mask = raw > 0
        contours, hierarchy = cv2.findContours(mask.astype(np.uint8), cv2.RETR_CCOMP,
                                               cv2.CHAIN_APPROX_NONE)
        outers = [k for k in range(len(contours)) if hierarchy[0][k][3] < 0 and len(contours[k]) >= 3]
        if not outers:
            raise InputError(f"[geometry] mask: {roi.mask} has no nonzero region")
        outer = max(outers, key=lambda k: cv2.contourArea(contours[k]))
        holes = [contours[k] for k in range(len(contours))
                 if hierarchy[0][k][3] == outer and len(contours[k]) >= 3]
        loops = [c.reshape(-1, 2).astype(float) for c in [contours[outer], *holes]]
        return mask, loops
    loops = [roi.polygon, *roi.exclude]
    for k, loop in enumerate(loops):
        if loop.min() < 0 or np.any(loop[:, 0] > w - 1) or np.any(loop[:, 1] > h - 1):
            key = "polygon_px" if k == 0 else f"exclude_px[{k - 1}]"
            raise InputError(f"[geometry] {key}: vertices outside camera 0's image "
                             f"({w} x {h} px: x in [0, {w - 1}], y in [0, {h - 1}]): "
                             f"x {loop[:, 0].min():g}..{loop[:, 0].max():g}, "
                             f"y {loop[:, 1].min():g}..{loop[:, 1].max():g}")
    rows, cols = np.mgrid[0:h, 0:w]
    mask = inside_loops(np.column_stack([cols.ravel(), rows.ravel()]).astype(float),
                        loops).reshape(h, w)
    if not mask.any():
        raise InputError("[geometry] polygon_px: the ROI holds no pixel")
    return mask, loops


def _densify(loop: np.ndarray, step_px: float = 1.0) -> np.ndarray:
    """The closed polyline ``loop`` (k, 2) with vertices every ``step_px`` or so."""
    out = []
    for a, b in zip(loop, np.roll(loop, -1, axis=0)):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step_px)))
        out.append(a + np.arange(n)[:, None] / n * (b - a))
    return np.concatenate(out)


def _rays(camera: Camera, px: np.ndarray) -> np.ndarray:
    xn = normalised_points(camera, px)
    return np.column_stack([xn, np.ones(len(xn))]) @ camera.R


def _in_frame(camera: Camera, R_f: np.ndarray, origin: np.ndarray) -> Camera:
    """``camera`` expressed in the frame ``X_w = R_f X_s + origin``."""
    R = camera.R @ R_f
    t = camera.R @ origin + camera.tvec
    return camera.with_extrinsics(np.concatenate([cv2.Rodrigues(R)[0].ravel(), t]))


def _seen(camera: Camera, X: np.ndarray) -> np.ndarray:
    w, h = camera.image_size
    p = camera.project(X)
    m = _SEEN_MARGIN_PX
    return (camera.in_front(X) & (p[:, 0] >= m) & (p[:, 0] <= w - 1 - m)
            & (p[:, 1] >= m) & (p[:, 1] <= h - 1 - m))


def _misfit(cams: Sequence[Camera], points: StereoPoints, fit: SurfaceFit) -> float:
    hits = ray_hits(cams[0], _rays(cams[0], points.px0), fit)
    d = np.linalg.norm(cams[1].project(hits) - points.px1, axis=1)[fit.inliers]
    return float(np.sqrt(np.mean(d ** 2)))


def _surface(roi: RoiConfig, cams, images, mask) -> tuple[StereoPoints, SurfaceFit, float, float]:
    where = _where(roi)
    values0 = images[0].values
    spread = float(np.std(values0[mask]))
    if spread < MIN_TEXTURE * max(images[0].dynamic_range, 1e-12):
        raise InputError(f"{where}: the ROI has no texture in camera 0's image (gray-level std "
                         f"{spread:.3g}, {MIN_TEXTURE:g} x the image's range needed)")
    inner = cv2.erode(mask.astype(np.uint8), np.ones((2 * FEATURE_MARGIN_PX + 1,) * 2, np.uint8))
    points = stereo_points(cams[0], cams[1], values0, images[1].values, inner > 0)
    if points.n_points < MIN_MATCHES:
        raise InputError(f"{where}: too few stereo matches inside the ROI to place the specimen: "
                         f"{points.n_points} triangulated of {points.n_matches} matched, at "
                         f"least {MIN_MATCHES} needed (is the ROI on the specimen, seen by "
                         "both cameras, and the calibration the rig's?)")
    fit = fit_surface(points.xyz_mm, roi.surface)
    epipolar = float(np.sqrt(np.mean(points.epipolar_px[fit.inliers] ** 2)))
    misfit = _misfit(cams, points, fit)
    logger.info("ROI surface (%s): %d of %d matches fit it, RMS %.3g um; in camera 1 %.3g px "
                "off the surface's prediction (epipolar distance %.3g px)", roi.surface,
                int(fit.inliers.sum()), points.n_points, fit.rms_mm * 1e3, misfit, epipolar)
    if misfit > max(MAX_MISFIT * epipolar, MIN_MISFIT_PX) or fit.inliers.mean() < 0.5:
        raise InputError(f"{where}: the stereo matches do not fit a {roi.surface}: {misfit:.3g} px "
                         f"RMS off it in camera 1 against {epipolar:.3g} px from the calibration's "
                         f"epipolar lines, {int(fit.inliers.sum())} of {points.n_points} matches "
                         'kept (try surface = "quadric", or check the calibration)')
    if misfit > WARN_MISFIT * epipolar:
        logger.warning("ROI: the %s misses the matches by %.3g px RMS in camera 1, %.1f times "
                       "their epipolar distance: the specimen departs from it (the measurement "
                       "corrects the nominal)", roi.surface, misfit, misfit / max(epipolar, 1e-12))
    return points, fit, misfit, epipolar


def _patch(outline: np.ndarray, fit: SurfaceFit | None, corners: np.ndarray | None = None):
    """The nominal spline: the rectangle bounding ``outline`` (k, 2), or the quadrilateral
    of ``corners`` (4, 2); z of the quadric ``fit`` (least squares) or 0."""
    if corners is None:
        lo, hi = outline.min(axis=0), outline.max(axis=0)
        size = hi - lo
        patch = rectangle(size[0], size[1], center=tuple(0.5 * (lo + hi)))
    else:
        c = corners if _signed_area(corners) > 0 else corners[::-1]    # normal +z
        patch = quadrilateral(np.column_stack([c, np.zeros(4)]))
        size = np.array([0.5 * (np.linalg.norm(c[1] - c[0]) + np.linalg.norm(c[2] - c[3])),
                         0.5 * (np.linalg.norm(c[3] - c[0]) + np.linalg.norm(c[2] - c[1]))])
    aspect = size[0] / size[1]
    n_u, n_v = (max(1, round(aspect)), 1) if aspect >= 1 else (1, max(1, round(1 / aspect)))
    if (n_u, n_v) != (1, 1):
        patch = refine_to_elements(patch, n_u, n_v)[0]
    if fit is not None and fit.quadric is not None:        # z = f(x, y) is in the space
        g = np.stack(np.meshgrid(np.linspace(0, 1, 4 * n_u + 3), np.linspace(0, 1, 4 * n_v + 3),
                                 indexing="ij"), axis=-1).reshape(-1, 2)
        B = patch.basis(g)
        z = np.linalg.lstsq(B.toarray(), fit.height(patch.evaluate(g)[:, :2]), rcond=None)[0]
        cp = np.array(patch.control_points)
        cp[..., 2] = z.reshape(cp.shape[:-1])
        patch = dataclasses.replace(patch, control_points=cp)
    return patch


def _signed_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _mesh(outline_loops, patch, elements: int | None, levels: int, cam1: Camera, where: str,
          trim: bool = True):
    area = abs(_signed_area(outline_loops[0]))
    box = float(np.prod(np.ptp(outline_loops[0], axis=0))) if trim else area
    target = int((elements or 1000) * box / max(area, 1e-12))
    model = nominal_model(patch, cad_refinements([patch], target, levels), "Q9", name="roi")
    nodes, conn = model.mesh.nodes, model.mesh.blocks[0].connectivity
    pts = nodes[conn][..., :2]
    shrunk = pts + 1e-7 * (pts.mean(axis=1, keepdims=True) - pts)
    keep = (inside_loops(shrunk.reshape(-1, 2), outline_loops).reshape(conn.shape).all(axis=1)
            if trim else np.ones(len(conn), bool))
    seen = _seen(cam1, nodes)[conn].all(axis=1)
    if not (keep & seen).any():
        raise InputError(f"{where}: no FE element fits inside the ROI (and in camera 1's view); "
                         "draw a larger ROI or ask for more elements")
    conn = conn[keep & seen]
    used, renumber = np.unique(conn, return_inverse=True)
    block = CellBlock(family=model.mesh.blocks[0].family, connectivity=renumber.reshape(conn.shape))
    mesh = SurfaceMesh(nodes=nodes[used], blocks=(block,), name="roi")
    logger.info("ROI mesh: %d of the %d Q9 elements of the %s lie inside the outline%s",
                len(conn), int(keep.size), "bounding rectangle" if trim else "quadrilateral",
                "" if seen[keep].all() else f" ({int((keep & ~seen).sum())} left out: camera 1 "
                                              "does not see them)")
    return NominalModel(patch=model.patch, mesh=mesh, uv=model.uv[used])


def _area_centroid(loops: Sequence[np.ndarray]) -> np.ndarray:
    """Centroid (2,) of the area inside ``loops[0]`` and outside ``loops[1:]``."""
    total, moment = 0.0, np.zeros(2)
    for k, loop in enumerate(loops):
        x, y = loop[:, 0], loop[:, 1]
        cross = x * np.roll(y, -1) - np.roll(x, -1) * y
        a = 0.5 * cross.sum()
        c = np.array([((x + np.roll(x, -1)) * cross).sum(), ((y + np.roll(y, -1)) * cross).sum()])
        sign = 1.0 if k == 0 else -1.0                          # holes subtract
        total += sign * abs(a)
        moment += sign * np.sign(a) * c / 6.0
    return moment / total


def _frame(camera0: Camera, fit: SurfaceFit, loops: Sequence[np.ndarray]
           ) -> tuple[np.ndarray, np.ndarray]:
    """The specimen frame (rotation, origin): its axes from the fit and camera 0, its origin
    at the area centroid of the ROI cast on the surface (the plane's, then back on the
    surface through camera 0)."""
    rays = [_rays(camera0, _densify(loop)) for loop in loops]
    R_f, o = specimen_frame(fit, camera0, fit.point)
    on_plane = dataclasses.replace(fit, quadric=None)
    xy = _area_centroid([((ray_hits(camera0, r, on_plane) - o) @ R_f)[:, :2] for r in rays])
    centre = o + R_f[:, :2] @ xy
    origin = ray_hits(camera0, _rays(camera0, camera0.project(centre[None])), fit)[0]
    return specimen_frame(fit, camera0, origin)


def _convex(corners: np.ndarray) -> bool:
    """True if the quadrilateral ``corners`` (4, 2) is strictly convex."""
    e = np.roll(corners, -1, axis=0) - corners
    turn = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
    return bool(np.all(turn > 0) or np.all(turn < 0))


def roi_specimen(geometry: GeometryConfig, cameras: Sequence[Camera], images: Sequence[Image],
                 levels: int) -> RoiSpecimen:
    """The nominal model and the cameras of ``kind = "roi"`` (see the module docstring).

    Parameters
    ----------
    geometry : ``[geometry]`` with its ``roi``.
    cameras : the calibrated pair as read (any world frame).
    images : the reference pair (camera 0's holds the ROI).
    levels : the spline levels the FE mesh must refine (Eq. 16).

    Raises
    ------
    InputError
        Naming the key: an ROI outside the image, without texture, with too few stereo
        matches, whose matches do not fit the surface, or holding no element.
    """
    roi = geometry.roi
    if roi is None:
        raise InputError('[geometry] kind = "roi" without its region of interest')
    where = _where(roi)
    mask, loops = roi_loops(roi, images[0].shape)
    points, fit, misfit, epipolar = _surface(roi, cameras, images, mask)
    R_f, origin = _frame(cameras[0], fit, loops)
    cams = tuple(_in_frame(c, R_f, origin) for c in cameras)

    def cast(px: np.ndarray) -> np.ndarray:          # camera 0's pixels on the surface, (x, y)
        return ((ray_hits(cameras[0], _rays(cameras[0], px), fit) - origin) @ R_f)[:, :2]

    local_fit = (height_fit((points.xyz_mm - origin) @ R_f, fit.inliers)
                 if roi.surface == "quadric" else None)   # z = f(x, y) in the specimen's axes
    outline = [cast(_densify(loop)) for loop in loops]
    corners = None
    if roi.polygon is not None and len(roi.polygon) == 4 and not roi.exclude:
        corners = cast(roi.polygon)
        if not _convex(corners):                         # a bilinear map would fold
            corners = None
    model = _mesh(outline, _patch(outline[0], local_fit, corners), geometry.elements, levels,
                  cams[1], where, trim=corners is None)
    samples = np.argwhere(mask)[:, ::-1].astype(float)     # every pixel (0.7 s for 1.2 Mpx)
    on_surface = ray_hits(cameras[0], _rays(cameras[0], samples), fit)
    unseen = 1.0 - float(_seen(cameras[1], on_surface).mean())
    if unseen > 0:
        logger.warning("ROI: camera 1 does not see %.1f %% of it (left out of the mesh)",
                       100 * unseen)
    logger.info("specimen frame (in the calibration's frame): origin %s mm, x %s, y %s, "
                "z %s (towards the cameras)", np.round(origin, 3).tolist(),
                *(np.round(R_f[:, k], 5).tolist() for k in range(3)))
    return RoiSpecimen(model=model, cameras=cams, frame_rotation=R_f, frame_origin=origin,
                       points=points, fit=fit, misfit_px=misfit, epipolar_px=epipolar,
                       unseen_share=unseen)
