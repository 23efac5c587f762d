"""The demo: the paper's twisted open-hole plate rendered in memory, with its truth.

``georeg demo`` measures it with every method (section 4 of the paper); its images, cameras
(with a perturbed pose the fixed point must find) and true surface come from
:func:`demo_config`.
"""
from __future__ import annotations

import dataclasses
import logging
import sys
from pathlib import Path

import numpy as np

from fesdic_core.imaging.image import Image
from fesdic_core.shape.gauge import move_cameras_with_specimen
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import Specimen, twisted_plate

from georeg_app.config.measure import Config, GeometryConfig, ImagesConfig, MethodConfig, OutputConfig
from georeg_app.inputs.cameras import temporary_cameras

logger = logging.getLogger(__name__)

__all__ = ["DEMO", "Truth", "demo_specimen", "demo_config"]

#: the demo specimen (paper, section 4: 180 x 50 mm plate, hole 28 mm, seen over 100 mm)
DEMO = dict(length_mm=180.0, width_mm=50.0, view_mm=100.0, hole_radius_mm=14.0,
            corner_mm=1.0, waviness_mm=0.2, noise_std=2.0, image_size=(1224, 816),
            field_mm=112.0, stereo_angle_deg=25.0, pose_error_deg=0.5, pose_error_mm=0.5)


@dataclasses.dataclass(frozen=True, eq=False)
class Truth:
    """What a synthetic run knows: the actual surface and the exact cameras."""

    specimen: Specimen
    cameras: tuple


def demo_specimen() -> Specimen:
    """The paper's twisted open-hole specimen (section 4.2), with a smooth waviness."""
    return twisted_plate(DEMO["length_mm"], DEMO["width_mm"], corner_mm=DEMO["corner_mm"],
                         hole_radius_mm=DEMO["hole_radius_mm"], waviness_mm=DEMO["waviness_mm"],
                         view_length_mm=DEMO["view_mm"], seed=7)


def demo_config(out_dir) -> tuple[Config, tuple, Truth]:
    """Render the demo stereo pair and return its config, images and truth.

    Two cameras at 25 degrees, about 1 Mpx each, 4 px speckle, noise of 2 gray levels.
    The cameras of the config are the exact ones with the specimen pose perturbed by
    0.5 degree and 0.5 mm (the fixed point must find it). They are written to a temporary
    folder (the output folder only receives the results) that belongs to the returned
    ``config.cameras`` (shared by copies such as ``config.with_output_dir``): it is removed
    when that is no longer referenced (at the end of the run), at the latest at exit.
    """
    cams = demo_cameras(image_size=DEMO["image_size"], stereo_angle_deg=DEMO["stereo_angle_deg"],
                        field_mm=DEMO["field_mm"])
    specimen = dataclasses.replace(demo_specimen(), speckle_mm=speckle_mm_for(cams[0], 4.0))
    arrays = render_stereo(specimen, cams, supersample=3, noise_std=DEMO["noise_std"], seed=11,
                           progress=logger.isEnabledFor(logging.INFO) and sys.stderr.isatty())
    method = MethodConfig()
    images = tuple(Image.from_array(a, source=f"demo cam{k}", prefilter_px=method.prefilter_px,
                                    order=method.interpolation_order) for k, a in enumerate(arrays))
    rotation = np.radians(DEMO["pose_error_deg"]) * np.array([0.6, -0.48, 0.64])
    translation = DEMO["pose_error_mm"] * np.array([0.48, 0.64, -0.6])
    initial = move_cameras_with_specimen(cams, translation, rotation, np.zeros(3))
    cameras = temporary_cameras(initial, prefix="georeg_demo_")
    inputs = cameras.file.parent
    config = Config(
        images=ImagesConfig(cam0=inputs / "cam0 (rendered in memory)", cam1=inputs / "cam1 (rendered in memory)"),
        cameras=cameras,
        geometry=GeometryConfig(kind="plate_with_hole", length_mm=DEMO["view_mm"],
                                width_mm=DEMO["width_mm"], hole_radius_mm=DEMO["hole_radius_mm"]),
        method=method,
        output=OutputConfig(dir=Path(out_dir)),
        source=inputs / "demo (embedded)")
    return config, images, Truth(specimen=specimen, cameras=tuple(cams))
