"""The part measured in one run (``georeg measure specimen_part.toml``) against the face-by-face
measurement (``run.py``'s code), in ONE frame: the landmarks' reference frame (the CAD's).

    python examples/dic_challenge/compare_face_by_face.py PART_OUT

measures the base plate and both bars face by face (``challenge.measure``, as ``run.py``),
maps both runs' measured surfaces into the frame of the landmarks' camera 0 (each run through
its own final camera 0: the surface in the camera frame does not depend on the pose gauge),
and prints: the bars' best-fit cylinders; the two plates' height difference on the face-by-face
ring points; the crest above the plate ring for several rings (the figure's sensitivity to
the ring's sample) and on the face-by-face ring's points in both runs (like for like); then
the face-by-face run again at the one run's resolution (every bar's crest and the block top
with 4 spline levels from one span, 16 x 16 Q9 elements: the one run's finest spline level
is 8 x 8 spans on each of these faces) and on the block's whole top face (the face-by-face
nominal is inset 1.5 mm from the block's edges, the CAD face is not): the bars' radii and
fit RMS, the block top's RMS to its plane over the inset region.
"""
from __future__ import annotations

import dataclasses
import json
import sys
import tomllib
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import analyse_part as ap                                                  # noqa: E402
from challenge import analysis                                             # noqa: E402
from challenge.config import load_face                                     # noqa: E402
from challenge.measure import initial_cameras, load_images, measure_nominal  # noqa: E402
from challenge.pipeline import footprint                                   # noqa: E402
from fesdic_core.rig import read_cameras_json                              # noqa: E402

BARS = ("cylinder_h", "cylinder_v")
RINGS = {"1.5-6 mm (the figure's)": (1.5, 6.0, False), "3-6 mm": (3.0, 6.0, False),
         "1.5-6 mm, plate side": (1.5, 6.0, True), "3-6 mm, plate side": (3.0, 6.0, True)}


def face_by_face(faces, images, cameras) -> dict:
    """Sampled measured surfaces (reference frame) of the base and both bars, face by face."""
    out = {}
    for name in ("base", *BARS):
        nominal = next(n for n in faces[name].nominals if n.kind in ("cylinder", "quadrilateral"))
        r = measure_nominal(faces[name], nominal, images, list(cameras))
        out[name] = ap.sample_surface(r.nodes_mm, r.model.mesh.blocks[0].connectivity, "quad9")
    return out


def part(out_dir: Path, config: Path, reference) -> dict:
    """Sampled measured surfaces of the part, mapped to the reference frame."""
    names = [str(f) for f in tomllib.loads(config.read_text())["geometry"]["faces"]]
    points, _ = ap.read_part(out_dir, names)
    entry = next(m for m in json.loads((out_dir / "summary.json").read_text())["methods"]
                 if m["status"] == "ok")
    cam0 = read_cameras_json(out_dir / entry["mesh_file"].replace(".vtu", "_cameras.json"))[0]
    return {k: (P @ cam0.R.T + cam0.tvec - reference.tvec) @ reference.R for k, P in points.items()}


def crest_above(fit, ring: np.ndarray) -> float:
    centre, axes = analysis.plane_frame(ring)
    up = np.cross(analysis.unit(np.cross(fit.axis_direction, [0.0, 0.0, 1.0])), fit.axis_direction)
    return float((fit.axis_point_mm + fit.radius_mm * up - centre) @ axes[2])


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out_dir = Path(argv[0])
    faces = {n: load_face(HERE / f"{n}.toml") for n in ("base", "block_top", *BARS)}
    specimen = faces["base"].specimen
    images = load_images(specimen)
    cameras = initial_cameras(specimen, images)
    runs = {"face by face": face_by_face(faces, images, cameras),
            "one run": part(out_dir, HERE / "specimen_part.toml", cameras[0])}
    plates = {k: P["base"][ap.face_region("base", P["base"], faces)] for k, P in runs.items()}
    for name in BARS:
        cyl = next(n for n in faces[name].nominals if n.kind == "cylinder")
        line = np.asarray(cyl.line_mm, float)
        axis = analysis.unit(line[1] - line[0])
        lateral = analysis.unit(np.cross(axis, [0.0, 0.0, 1.0]))
        fits = {}
        for k, P in runs.items():
            fits[k] = analysis.fit_cylinder(P[name][ap.face_region(name, P[name], faces)], axis, cyl.radius_mm)
            f = fits[k]
            print(f"{name}, {k}: radius {f.radius_mm:.4f} mm, axis point {np.round(f.axis_point_mm, 4)}, "
                  f"crest z {f.crest_height_mm:.4f} mm, fit RMS {1e3 * f.rms_mm:.2f} um")
        fp = footprint(specimen.feature(name))
        d = analysis.distance_to_footprint(plates["face by face"], fp)
        common = plates["face by face"][(d >= 1.5) & (d <= 6.0)]
        nearest = plates["one run"][cKDTree(plates["one run"][:, :2]).query(common[:, :2])[1]]
        dz = 1e3 * (nearest[:, 2] - common[:, 2])
        print(f"{name}: plates on the face-by-face ring ({len(common)} points): one run minus face by "
              f"face {dz.mean():+.2f} um (std {dz.std():.2f})")
        print(f"  crest above the ring (mm) | face by face | one run | difference (um)")
        for label, (lo, hi, plate_side) in RINGS.items():
            row = []
            for k in runs:
                dist = analysis.distance_to_footprint(plates[k], fp)
                keep = (dist >= lo) & (dist <= hi)
                if plate_side:
                    keep &= (plates[k] - line[0]) @ lateral < 0
                row.append(crest_above(fits[k], plates[k][keep]))
            print(f"  {label:26s} | {row[0]:.4f} | {row[1]:.4f} | {1e3 * (row[1] - row[0]):+.1f}")
        row = [crest_above(fits["face by face"], common), crest_above(fits["one run"], nearest)]
        print(f"  {'the same ring points':26s} | {row[0]:.4f} | {row[1]:.4f} | {1e3 * (row[1] - row[0]):+.1f}")
    print("face by face at the one run's resolution (4 spline levels from one span, 16 x 16 Q9):")
    for name in BARS:
        nominal = next(n for n in faces[name].nominals if n.kind == "cylinder")
        fine = dataclasses.replace(nominal, levels=4, spline_elements=(1, 1), elements=(16, 16))
        r = measure_nominal(faces[name], fine, images, list(cameras))
        P = ap.sample_surface(r.nodes_mm, r.model.mesh.blocks[0].connectivity, "quad9")
        line = np.asarray(nominal.line_mm, float)
        f = analysis.fit_cylinder(P[ap.face_region(name, P, faces)], line[1] - line[0], nominal.radius_mm)
        print(f"  {name}: radius {f.radius_mm:.4f} mm, fit RMS {1e3 * f.rms_mm:.2f} um")
    top = faces["block_top"].nominals[0]
    corners = np.asarray(top.corners_mm, float)
    lo, hi = corners[:, :2].min(axis=0), corners[:, :2].max(axis=0)
    outward = np.sign(corners - corners.mean(axis=0)) * [1.0, 1.0, 0.0]
    for grow, levels, elements in ((0.0, 3, (8, 8)), (0.0, 4, (16, 16)), (1.5, 4, (16, 16))):
        nominal = dataclasses.replace(top, corners_mm=tuple(map(tuple, corners + grow * outward)),
                                      levels=levels, elements=elements)
        r = measure_nominal(faces["block_top"], nominal, images, list(cameras))
        P = r.points_mm[r.seen]
        P = P[np.all((P[:, :2] >= lo) & (P[:, :2] <= hi), axis=1)]
        print(f"  block top, nominal {'inset 1.5 mm' if grow == 0 else 'the whole top'}, {levels} levels, "
              f"{elements[0]} x {elements[1]} Q9: RMS to its plane over the inset region "
              f"{1e3 * analysis.rms(analysis.plane_residuals(P)):.2f} um")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
