"""The challenge's figures from a measured VTU: the specimen measured as one part, or face by face.

    python examples/dic_challenge/analyse_part.py OUT_DIR [--config specimen_part.toml]
        [--reference REF_DIR/summary.json] [--interim-base] [--json FILE]

``OUT_DIR`` is either the output folder of ``georeg measure specimen_part.toml`` (its
``summary.json`` names the georeg VTU, whose cell data ``face`` indexes the faces in the
order of the config's ``[geometry] faces``) or that of ``run.py`` (one VTU per nominal:
``base.vtu``, ``block_top.vtu``, ``cylinder_h.vtu``, ...). The measured Q9 surfaces are
sampled at ``SAMPLES x SAMPLES`` points per element (Eq. 4, the FE interpolation), each face
restricted to what the face-by-face run measures (``base.toml``, ``block_top.toml``,
``cylinder_*.toml``: the base plate off the features by ``hole_margin_mm``, the block top
inset, the bars' arc about the crest and length), put in the world frame of the measured
base plane (z = 0), and handed to the example's own comparison
(:func:`challenge.pipeline.compare`: block height above the plate ring, cylinder fits with
radii and crest heights, base flatness in the README's polygon). Printed beside the
face-by-face run's ``summary.json`` (``--reference``), the laser's and pyvale's figures.

Which points a camera saw: ``georeg measure``'s VTU holds the cell data ``seen_fraction``
(the share of each element's integration points that entered the residual). The figures use
the elements at least :data:`SEEN` seen, as the face-by-face run uses its seen integration
points: the strips a feature hides from one camera (next to the bars and the block) carry
only the spline's continuation, not a measurement. ``run.py``'s VTUs do not hold it: there
every sampled point is used.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tomllib
import types
from pathlib import Path

import meshio
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from challenge import analysis, report                                   # noqa: E402
from challenge.config import load_face                                   # noqa: E402
from challenge.measure import base_plane_frame                           # noqa: E402
from challenge.pipeline import FACES, ChallengeRun, compare, footprint   # noqa: E402
from fesdic_core.elements import family_from_meshio                      # noqa: E402
from fesdic_core.mesh import CellBlock, map_points                       # noqa: E402

#: sample points per element along each parent direction (cell centres of a k x k split)
SAMPLES = 4
#: an element counts as measured when at least this share of its points entered the residual
SEEN = 0.5
DEFAULT_CONFIG = HERE / "specimen_part.toml"


def sample_surface(points: np.ndarray, cells: np.ndarray, cell_type: str, k: int = SAMPLES) -> np.ndarray:
    """(ne * k * k, 3) points of the measured surface: ``k x k`` cell centres per element, Eq. 4."""
    block = CellBlock(family_from_meshio(cell_type), np.asarray(cells))
    c = -1.0 + (2.0 * np.arange(k) + 1.0) / k
    xi = np.stack(np.meshgrid(c, c, indexing="ij"), -1).reshape(-1, 2)
    return map_points(points, block, xi).reshape(-1, 3)


def _vtu_cells(mesh: meshio.Mesh, name: str = "face") -> tuple[str, np.ndarray, np.ndarray | None]:
    """The one surface cell block of a VTU, and its cell data ``name`` if any."""
    blocks = [(k, c) for k, c in enumerate(mesh.cells) if c.type in ("quad9", "quad", "triangle", "triangle6")]
    if len(blocks) != 1:
        raise ValueError(f"expected one surface cell block, got {[c.type for c in mesh.cells]}")
    k, cells = blocks[0]
    data = mesh.cell_data.get(name)
    return cells.type, np.asarray(cells.data), None if data is None else np.asarray(data[k]).ravel()


def read_part(out_dir: Path, face_names: list[str], method: str = "georeg") -> tuple[dict, float | None]:
    """Sampled points by face name from ``georeg measure``'s output; and the method's time (s)."""
    summary = json.loads((out_dir / "summary.json").read_text())
    entries = [m for m in summary["methods"] if m["name"] == method and m["status"] == "ok"]
    if not entries:
        raise ValueError(f"{out_dir / 'summary.json'}: no successful {method!r} method")
    mesh = meshio.read(out_dir / entries[0]["mesh_file"])
    cell_type, cells, face = _vtu_cells(mesh)
    if face is None:
        raise ValueError(f"{out_dir / entries[0]['mesh_file']}: no cell data 'face'")
    if face.max() >= len(face_names):
        raise ValueError(f"face index {face.max()} but only {len(face_names)} face names {face_names}")
    seen = _vtu_cells(mesh, "seen_fraction")[2]
    measured = np.ones(len(cells), bool) if seen is None else seen >= SEEN
    points = {}
    for k, name in enumerate(face_names):
        if np.any(face == k):      # pieces of the plate ("base_*", interim IGES) join "base"
            key = "base" if name.startswith("base") else name
            P = sample_surface(mesh.points, cells[(face == k) & measured], cell_type)
            points[key] = np.concatenate([points[key], P]) if key in points else P
    return points, entries[0]["time_s"]


def read_face_by_face(out_dir: Path) -> tuple[dict, float | None]:
    """Sampled points by nominal name from ``run.py``'s output (one VTU per nominal)."""
    points = {}
    for path in sorted(out_dir.glob("*.vtu")):
        mesh = meshio.read(path)
        cell_type, cells, _ = _vtu_cells(mesh)
        points[path.stem] = sample_surface(mesh.points, cells, cell_type)
    summary = out_dir / "summary.json"
    time_s = json.loads(summary.read_text()).get("time_s") if summary.is_file() else None
    return points, time_s


def face_region(name: str, points: np.ndarray, faces: dict) -> np.ndarray:
    """(n,) bool: the points of face ``name`` inside what the face-by-face run measures."""
    base = faces["base"]
    if name == "base":
        nominal = base.nominals[0]
        keep = analysis.inside_polygon(points, np.asarray(nominal.corners_mm)[:, :2])
        for hole in nominal.holes:
            feature = base.specimen.feature(hole)
            keep &= analysis.distance_to_footprint(points, footprint(feature)) > nominal.hole_margin_mm
        return keep
    if name == "block_top":
        return analysis.inside_polygon(points, np.asarray(faces[name].nominals[0].corners_mm)[:, :2])
    if name in ("cylinder_h", "cylinder_v"):
        cyl = next(n for n in faces[name].nominals if n.kind == "cylinder")
        line = np.asarray(cyl.line_mm, float)
        axis = analysis.unit(line[1] - line[0])
        lateral = analysis.unit(np.cross(axis, [0.0, 0.0, 1.0]))
        arm = points - line[0]
        along = arm @ axis
        angle = np.degrees(np.arctan2(arm @ lateral, arm @ np.cross(lateral, axis)))
        return (along >= 0) & (along <= np.linalg.norm(line[1] - line[0])) & (np.abs(angle) <= cyl.arc_deg / 2)
    return np.ones(len(points), bool)


def in_rectangles(points: np.ndarray, rectangles) -> np.ndarray:
    """(n,) bool: the (x, y) of ``points`` inside any of ``rectangles`` ((x0, x1), (y0, y1))."""
    keep = np.zeros(len(points), bool)
    for (x0, x1), (y0, y1) in rectangles:
        keep |= (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)
    return keep


def challenge_run(points: dict, time_s: float | None, base_rectangles=None) -> ChallengeRun:
    """The points as the example's :class:`ChallengeRun` (every point seen), base plane z = 0.

    ``base_rectangles``: keep only the plate's points in these ((x0, x1), (y0, y1)) (mm).
    """
    faces = {name: load_face(HERE / f"{name}.toml") for name in FACES}
    kept = {name: P[face_region(name.removesuffix("_flat"), P, faces)] if name.removesuffix("_flat") in faces else P
            for name, P in points.items()}
    if base_rectangles is not None and "base" in kept:
        kept["base"] = kept["base"][in_rectangles(kept["base"], base_rectangles)]
    if "base" not in kept:
        raise ValueError("no base plate among the measured faces (it defines the base plane)")
    R, t = base_plane_frame(kept["base"])
    results = {}
    for name, P in kept.items():
        measurement = types.SimpleNamespace(residual_percent=math.nan)
        results[name] = types.SimpleNamespace(points_mm=P @ R.T + t, seen=np.ones(len(P), bool),
                                              measurement=measurement)
    measured = {}
    for name, face in faces.items():
        if name not in results:
            continue
        nominals = tuple(n for n in face.nominals if n.name in results)   # no flat nominal in a part
        measured[name] = dataclasses.replace(face, nominals=nominals)
    return ChallengeRun(measured, results, math.nan if time_s is None else float(time_s), None, None)


#: the band of a prism's faces that the figures use, as fractions of the nominal ridge height
#: (off the ridge and the foot, where a nominal of the wrong slope folds the measured face)
PRISM_BAND = (0.2, 0.8)


def prism_figures(run: ChallengeRun) -> dict:
    """Per prism measured on both slanted faces, in the band ``PRISM_BAND`` of heights: each
    face's RMS to its best-fit plane (um), the included angle between the two planes and
    their slopes (deg), beside the nominal angle."""
    out = {}
    specimen = run.faces["base"].specimen
    for f in (f for f in specimen.features if f.kind == "wedge"):
        sides = sorted(k for k in run.results if k.startswith(f.name + "_"))
        if len(sides) != 2:
            continue
        lo, hi = np.array(PRISM_BAND) * f.line_mm[0][2]
        P = [p[(p[:, 2] >= lo) & (p[:, 2] <= hi)] for p in (run.results[k].points_mm for k in sides)]
        n = [analysis.plane_frame(p)[1][2] for p in P]
        out[f.name] = {"rms_plane_um": {k: 1e3 * analysis.rms(analysis.plane_residuals(p)) for k, p in zip(sides, P)},
                       "included_angle_deg": 180.0 - float(np.degrees(np.arccos(np.clip(n[0] @ n[1], -1, 1)))),
                       "slope_deg": {k: float(np.degrees(np.arccos(v[2]))) for k, v in zip(sides, n)},
                       "nominal_angle_deg": float(2 * np.degrees(np.arctan2(f.half_width_mm, f.line_mm[0][2])))}
    return out


def figures(run: ChallengeRun) -> dict:
    """The figures of the run (the schema of run.py's summary.json, and ``prisms``)."""
    out = report.summary(run, compare(run))
    prisms = prism_figures(run)
    if prisms:
        out["prisms"] = prisms
    return out


ROWS = (("base plate, README region: RMS to plane (um)", ("base", "plane_rms_um"), 2),
        ("base plate, README region: RMS to quadric (um)", ("base", "quadric_rms_um"), 2),
        ("base plate, whole: RMS to plane (um)", ("base", "whole_plane_rms_um"), 2),
        ("block top: RMS to its plane (um)", ("block", "top_rms_plane_um"), 2),
        ("block height above the plate ring (mm)", ("block", "height_mm"), 4),
        ("cylinder_v: radius (mm)", ("cylinder_v", "radius_mm"), 4),
        ("cylinder_h: radius (mm)", ("cylinder_h", "radius_mm"), 4),
        ("cylinder_v: crest above the ring (mm)", ("cylinder_v", "crest_above_ring_mm"), 4),
        ("cylinder_h: crest above the ring (mm)", ("cylinder_h", "crest_above_ring_mm"), 4),
        ("cylinder_v: fit RMS (um)", ("cylinder_v", "fit_rms_um"), 2),
        ("cylinder_h: fit RMS (um)", ("cylinder_h", "fit_rms_um"), 2),
        ("time (s)", ("time_s",), 1))
REFERENCES = {"laser": {("block", "height_mm"): report.LASER["block_height_mm"],
                        ("cylinder_v", "radius_mm"): report.LASER["radius_mm"]["cylinder_v"],
                        ("cylinder_h", "radius_mm"): report.LASER["radius_mm"]["cylinder_h"],
                        ("cylinder_v", "crest_above_ring_mm"): report.LASER["crest_mm"],
                        ("cylinder_h", "crest_above_ring_mm"): report.LASER["crest_mm"]},
              "pyvale": {("base", "plane_rms_um"): report.PYVALE["base_plane_um"],
                         ("base", "quadric_rms_um"): report.PYVALE["base_quadric_um"],
                         ("block", "top_rms_plane_um"): report.PYVALE["block_top_um"],
                         ("block", "height_mm"): report.PYVALE["block_height_mm"],
                         ("cylinder_v", "radius_mm"): report.PYVALE["radius_mm"]["cylinder_v"],
                         ("cylinder_h", "radius_mm"): report.PYVALE["radius_mm"]["cylinder_h"],
                         ("cylinder_v", "crest_above_ring_mm"): report.PYVALE["crest_mm"],
                         ("cylinder_h", "crest_above_ring_mm"): report.PYVALE["crest_mm"],
                         ("cylinder_v", "fit_rms_um"): report.PYVALE["cylinder_rms_um"],
                         ("cylinder_h", "fit_rms_um"): report.PYVALE["cylinder_rms_um"]}}


def _get(d: dict | None, path: tuple, digits: int) -> str:
    for key in path:
        if not isinstance(d, dict) or key not in d:
            return ""
        d = d[key]
    return f"{d:.{digits}f}" if isinstance(d, (int, float)) and math.isfinite(d) else ("" if d is None else str(d))


def table(this: dict, reference: dict | None) -> str:
    """Markdown table: quantity, this run, the face-by-face run, laser, pyvale."""
    lines = ["| quantity | this run | face by face (run.py) | laser | pyvale |", "| --- | --- | --- | --- | --- |"]
    for label, path, digits in ROWS:
        refs = [REFERENCES[w].get(path, "") for w in ("laser", "pyvale")]
        lines.append(f"| {label} | {_get(this, path, digits)} | {_get(reference, path, digits)} | "
                     + " | ".join(str(r) for r in refs) + " |")
    for name, prism in this.get("prisms", {}).items():
        rms = " / ".join(f"{v:.2f}" for v in prism["rms_plane_um"].values())
        lines += [f"| {name}: RMS of its faces to their planes (um), {' / '.join(prism['rms_plane_um'])} "
                  f"| {rms} | | | |",
                  f"| {name}: included angle (deg; nominal {prism['nominal_angle_deg']:.2f}) "
                  f"| {prism['included_angle_deg']:.3f} | | | |"]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out_dir", type=Path, help="output folder of georeg measure or of run.py")
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG,
                   help="the georeg measure config (its [geometry] faces name the VTU's faces)")
    p.add_argument("--reference", type=Path, default=None, help="summary.json of a run.py run")
    p.add_argument("--interim-base", action="store_true",
                   help="keep only the plate within the interim IGES's rectangles "
                        "(make_specimen_cad.INTERIM_BASE_MM), to compare a face-by-face run with "
                        "a part measured from the interim IGES on the same plate region")
    p.add_argument("--json", type=Path, default=None, help="write the figures to this JSON file")
    args = p.parse_args(argv)
    try:
        if (args.out_dir / "base.vtu").is_file():
            points, time_s = read_face_by_face(args.out_dir)
        else:
            faces = tomllib.loads(args.config.read_text())["geometry"]["faces"]
            points, time_s = read_part(args.out_dir, [str(f) for f in faces])
        rectangles = None
        if args.interim_base:
            from make_specimen_cad import INTERIM_BASE_MM
            rectangles = list(INTERIM_BASE_MM.values())
        this = figures(challenge_run(points, time_s, rectangles))
        reference = None if args.reference is None else json.loads(args.reference.read_text())
    except (OSError, ValueError, KeyError) as err:
        print(f"analyse_part.py: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 1
    print(table(this, reference))
    if args.json is not None:
        args.json.write_text(json.dumps(this, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
