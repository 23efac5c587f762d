"""Synthetic scaffolding: a stereo renderer with a known surface and accuracy against that truth."""

from fesdic_core.synthetic.accuracy import (MAX_ALIGN_ROTATION_RAD, MAX_ALIGN_SHIFT_FRACTION,
                                            shape_error_to_surface, stereo_correspondence_error)
from fesdic_core.synthetic.motion import (Motion, RigidMotion, BendingMotion, StretchMotion,
                                          HeightMotion, intersect_displaced)
from fesdic_core.synthetic.rays import pixel_rays, intersect_surface
from fesdic_core.synthetic.render import (GRAY_RANGE, TEXELS_PER_SPECKLE, MAX_TEXELS, CHUNK_RAYS,
                                          SpeckleTexture, speckle_texture, speckle_mm_for,
                                          render_stereo, look_at, demo_cameras, true_surface_points,
                                          true_normal_offset)
from fesdic_core.synthetic.specimen import (Specimen, twisted_plate, flat_plate, HeightFunction,
                                            GradientFunction)

__all__ = ["MAX_ALIGN_ROTATION_RAD", "MAX_ALIGN_SHIFT_FRACTION", "shape_error_to_surface",
           "stereo_correspondence_error", "Motion", "RigidMotion", "BendingMotion", "StretchMotion",
           "HeightMotion",
           "intersect_displaced", "pixel_rays", "intersect_surface", "GRAY_RANGE",
           "TEXELS_PER_SPECKLE", "MAX_TEXELS", "CHUNK_RAYS", "SpeckleTexture", "speckle_texture",
           "speckle_mm_for", "render_stereo", "look_at", "demo_cameras", "true_surface_points",
           "true_normal_offset", "Specimen", "twisted_plate", "flat_plate", "HeightFunction",
           "GradientFunction"]
