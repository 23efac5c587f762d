"""What a run measures: the nominal model of each geometry kind and the cameras."""

from georeg_app.inputs.cad import (CAD_SUFFIXES, STEP_SUFFIXES, check_cad_file, cad_faces, cad_part,
                                   cad_model, cad_refinements, face_refinements, cad_face_indices,
                                   cad_occluders, cad_triangles, read_cad_faces)
from georeg_app.inputs.cad_pose import CadPose, place_part
from georeg_app.inputs.cameras import load_cameras
from georeg_app.inputs.mesh_file import mesh_model
from georeg_app.inputs.nominal import (build_model, coarse_faces, refinements, MIN_PX_PER_ELEMENT,
                                      specimen_setup)
from georeg_app.inputs.placement import Placement, placement_check
from georeg_app.inputs.roi import RoiSpecimen, roi_loops, roi_specimen
from georeg_app.inputs.roi_surface import SurfaceFit, fit_surface, specimen_frame, ray_hits
from georeg_app.inputs.plate import coarse_patch

__all__ = ["CAD_SUFFIXES", "STEP_SUFFIXES", "check_cad_file", "cad_faces", "cad_part", "cad_model",
           "cad_refinements", "face_refinements", "cad_face_indices", "cad_occluders",
           "cad_triangles", "read_cad_faces", "load_cameras", "mesh_model", "build_model",
           "coarse_faces", "refinements", "MIN_PX_PER_ELEMENT", "coarse_patch", "specimen_setup",
           "RoiSpecimen", "roi_loops", "roi_specimen", "SurfaceFit", "fit_surface",
           "specimen_frame", "ray_hits", "Placement", "placement_check", "CadPose", "place_part"]
