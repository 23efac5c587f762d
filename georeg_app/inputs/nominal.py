"""The nominal model of a run: one function, :func:`build_model`, over the geometry kinds.

Each kind of ``[geometry]`` has its own small module: the plates (:mod:`~georeg_app.inputs.plate`),
a legacy mesh (:mod:`~georeg_app.inputs.mesh_file`), a CAD part
(:mod:`~georeg_app.inputs.cad`; with a ``pose``, placed by the rig's triangulation through
:mod:`~georeg_app.inputs.cad_pose`) and a region of interest of camera 0's image triangulated by
the rig (:mod:`~georeg_app.inputs.roi`, through :func:`specimen_setup`: it needs the images
and the cameras, which it expresses in the specimen's frame). Each gives the nominal spline(s) and the analysis-suitable
FE mesh (Eq. 17) that the plugin's levels and the core's measurement share.
"""
from __future__ import annotations

from typing import Sequence

from adapters.fesdic_core import NominalModel, nominal_model
from fesdic_core.cameras.camera import Camera
from fesdic_core.imaging.image import Image

from georeg_app.config.measure import GeometryConfig
from georeg_app.inputs.cad import cad_faces, cad_model, cad_refinements
from georeg_app.inputs.cad_pose import CadPose, place_part
from georeg_app.inputs.mesh_file import mesh_model
from georeg_app.errors import InputError
from georeg_app.inputs.plate import coarse_patch
from georeg_app.inputs.roi import RoiSpecimen, roi_specimen

__all__ = ["specimen_setup", "build_model", "coarse_faces", "refinements", "MIN_PX_PER_ELEMENT"]

MIN_PX_PER_ELEMENT = 16     # pixels an FE element needs at full resolution (9 Q9 nodes)


def coarse_faces(geometry: GeometryConfig) -> tuple:
    """The coarsest splines: the CAD's selected faces, or the plate's one patch."""
    if geometry.kind == "cad":
        return cad_faces(geometry.file, geometry.faces)[0]
    return (coarse_patch(geometry),)


def refinements(geometry: GeometryConfig, levels: int) -> int:
    """Dyadic refinements from the coarsest spline to the FE mesh (see :func:`build_model`)."""
    return cad_refinements(coarse_faces(geometry), geometry.elements, levels)


def build_model(geometry: GeometryConfig, levels: int) -> NominalModel:
    """Nominal spline and analysis-suitable Q9 mesh (Eq. 17), or a legacy mesh read from file.

    The FE mesh refines the finest spline level dyadically until it has about
    ``geometry.elements`` elements (default: at least 1000, the paper's mesh).
    """
    if geometry.kind == "mesh":
        return mesh_model(geometry.file)
    if geometry.kind == "roi":
        raise InputError('[geometry] kind = "roi" is built from the images and the cameras: '
                         "use specimen_setup")
    if geometry.kind == "cad":
        return cad_model(geometry.file, geometry.faces, geometry.elements, levels)
    return nominal_model(coarse_patch(geometry), refinements(geometry, levels), "Q9",
                         name=geometry.kind)


def specimen_setup(geometry: GeometryConfig, levels: int, cameras: Sequence[Camera],
                   images: Sequence[Image]
                   ) -> tuple[NominalModel, list, RoiSpecimen | CadPose | None]:
    """The nominal model and the cameras a run measures with, for every geometry kind.

    Returns ``(model, cameras, placed)``: for ``kind = "roi"`` the cameras are expressed in
    the specimen frame and ``placed`` says how it was placed
    (:class:`~georeg_app.inputs.roi.RoiSpecimen`); for ``kind = "cad"`` with a ``pose``, in
    the CAD's frame, ``placed`` the ICP's pose (:class:`~georeg_app.inputs.cad_pose.CadPose`);
    for the other kinds the cameras are returned as given and ``placed`` is None. Either
    record has a ``summary()`` for the outputs.
    """
    if geometry.kind == "roi":
        roi = roi_specimen(geometry, cameras, images, levels)
        return roi.model, list(roi.cameras), roi
    model = build_model(geometry, levels)
    if geometry.kind == "cad" and geometry.pose is not None:
        pose = place_part(geometry, cameras, images)
        return model, list(pose.cameras), pose
    return model, list(cameras), None
