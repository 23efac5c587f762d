"""A rendered loading series on disk, as a user of ``georeg track`` has it (shared by tests).

The plate and rig of tests/fesdic_core/displacement/test_displacement.py: a flat 60 x 40 mm
plate with 4 px speckle, two cameras of 320 x 240 px, 2 gray levels of noise, 8-bit PNG. The
reference folder is what ``georeg measure`` writes (``summary.json``, ``fe.vtu``,
``fe_cameras.json``), made from the nominal mesh and the exact cameras so that the series
alone is under test.
"""
import json
from pathlib import Path

import cv2
import numpy as np

from fesdic_core.cameras.rig import write_cameras_json
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.fe.mesh_io import write_mesh
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import flat_plate

#: the reference folder's FE mesh (Q4, inside the plate's view)
MESH = dict(length_mm=44.0, width_mm=30.0, nx=4, ny=3, family="Q4")


def write_series(folder: Path, motions, frames: str = "", supersample: int = 3):
    """``ref_cam0.png``, ``ref_cam1.png``, ``<frames>/f<i>_cam<k>.png`` for each motion (a
    motion None is a pair of pure noise) and the reference folder ``shape_out``; returns the
    cameras and the reference mesh."""
    cameras = demo_cameras(image_size=(320, 240), field_mm=72.0)
    plate = flat_plate(60.0, 40.0, speckle_mm=speckle_mm_for(cameras[0], 4.0), seed=3)

    def save(arrays, stem):
        for k, a in enumerate(arrays):
            cv2.imwrite(str(folder / f"{stem}_cam{k}.png"), a.astype(np.uint8))

    save(render_stereo(plate, cameras, supersample=supersample, noise_std=2.0, seed=1,
                       progress=False), "ref")
    rng = np.random.default_rng(5)
    (folder / frames).mkdir(exist_ok=True)
    for i, motion in enumerate(motions, start=1):
        arrays = ([rng.uniform(0, 255, (240, 320)) for _ in range(2)] if motion is None else
                  render_stereo(plate, cameras, supersample=supersample, noise_std=2.0,
                                seed=10 + i, progress=False, motion=motion))
        save(arrays, str(Path(frames) / f"f{i}"))
    ref = folder / "shape_out"
    ref.mkdir()
    mesh = rectangle_mesh(MESH["length_mm"], MESH["width_mm"], MESH["nx"], MESH["ny"],
                          family=MESH["family"])
    write_mesh(ref / "fe.vtu", mesh)
    write_cameras_json(ref / "fe_cameras.json", cameras)
    (ref / "summary.json").write_text(json.dumps(
        {"methods": [{"label": "FE", "status": "ok", "mesh_file": "fe.vtu"}]}))
    return cameras, mesh
