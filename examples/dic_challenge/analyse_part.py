"""The challenge's figures from the specimen measured as one part, compared with the laser and pyvale.

Usage::

    georeg measure examples/dic_challenge/specimen_part.toml --out OUT_DIR
    python examples/dic_challenge/analyse_part.py OUT_DIR [--out REPORT_DIR]
        [--config specimen_part.toml] [--analysis analysis.toml]
        [--reference REF.json] [--interim-base] [--json FILE]

``OUT_DIR`` is the output folder of ``georeg measure specimen_part.toml``: its
``summary.json`` names the georeg VTU, whose cell data ``face`` indexes the faces in the
order of the config's ``[geometry] faces``. The measured Q9 surfaces are sampled at
``SAMPLES x SAMPLES`` points per element (Eq. 4, the FE interpolation), each face restricted
to its region of ``analysis.toml`` (the base plate off the features by ``hole_margin_mm``,
the block top inset, the bars' arc about the crest and length), put in the world frame of
the measured base plane (z = 0), and handed to the example's comparison
(:func:`challenge.comparison.compare`: block height above the plate ring, cylinder fits with
radii and crest heights, base flatness in the README's polygon, the prisms' faces). Printed
as a table beside the laser's and pyvale's figures (and a reference's, ``--reference``: the
``--json`` or ``summary.json`` of another analysis).

``--out REPORT_DIR`` also writes, all files or none: ``summary.json`` (the figures and the
targets of issue 5), the PNG figures (``overview``, ``shape_maps``, ``cylinder_profiles``;
the gray-level residual maps are ``georeg measure``'s own ``residual_maps.png``) and the
self-contained ``report.html``; and prints the targets, PASS or FAIL.

Which points a camera saw: ``georeg measure``'s VTU holds the cell data ``seen_fraction``
(the share of each element's integration points that entered the residual). The figures use
the elements at least :data:`SEEN` seen: the strips a feature hides from one camera (next to
the bars and the block) carry only the spline's continuation, not a measurement.
"""
from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import tomllib
from pathlib import Path

import meshio
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from challenge import figures as pngs, report                            # noqa: E402
from challenge.comparison import MeasuredPart, compare, measured_part    # noqa: E402
from challenge.config import load_analysis                               # noqa: E402
from fesdic_core.fe.elements import family_from_meshio                      # noqa: E402
from fesdic_core.imaging.image import read_image                                 # noqa: E402
from fesdic_core.fe.mesh import CellBlock, map_points                       # noqa: E402
from georeg_app.shape.outputs import OutputWriter                              # noqa: E402

#: sample points per element along each parent direction (cell centres of a k x k split)
SAMPLES = 4
#: an element counts as measured when at least this share of its points entered the residual
SEEN = 0.5
DEFAULT_CONFIG = HERE / "specimen_part.toml"
DEFAULT_ANALYSIS = HERE / "analysis.toml"


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


def read_part(out_dir: Path, face_names: list[str], method: str = "georeg") -> tuple[dict, dict, dict]:
    """From ``georeg measure``'s output: the sampled points by face name, the share of each
    face's elements left out as not seen enough, and the method's entry of ``summary.json``."""
    summary = out_dir / "summary.json"
    entries = [m for m in json.loads(summary.read_text())["methods"]
               if m.get("name") == method and m.get("status") == "ok"]
    if not entries:
        raise ValueError(f"{summary}: no successful {method!r} method")
    vtu = out_dir / entries[0]["mesh_file"]
    mesh = meshio.read(vtu)
    cell_type, cells, face = _vtu_cells(mesh)
    if face is None:
        raise ValueError(f"{vtu}: no cell data 'face'")
    if face.max() >= len(face_names):
        raise ValueError(f"{vtu}: face index {face.max()} but only {len(face_names)} face names {face_names}")
    seen = _vtu_cells(mesh, "seen_fraction")[2]
    measured = np.ones(len(cells), bool) if seen is None else seen >= SEEN
    points, counts = {}, {}
    for k, name in enumerate(face_names):
        if np.any(face == k):      # pieces of the plate ("base_*", interim IGES) join "base"
            key = "base" if name.startswith("base") else name
            P = sample_surface(mesh.points, cells[(face == k) & measured], cell_type)
            points[key] = np.concatenate([points[key], P]) if key in points else P
            counts[key] = counts.get(key, 0) + np.array([np.sum((face == k) & ~measured), np.sum(face == k)])
    return points, {k: float(n / total) for k, (n, total) in counts.items()}, entries[0]


def in_rectangles(points: np.ndarray, rectangles) -> np.ndarray:
    """(n,) bool: the (x, y) of ``points`` inside any of ``rectangles`` ((x0, x1), (y0, y1))."""
    keep = np.zeros(len(points), bool)
    for (x0, x1), (y0, y1) in rectangles:
        keep |= (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)
    return keep


def _image_size(out_dir: Path, entry: dict) -> list | None:
    """cam0's image size (px) in the cameras JSON ``georeg measure`` wrote beside its VTU."""
    path = out_dir / (Path(entry["mesh_file"]).stem + "_cameras.json")
    return json.loads(path.read_text())["cameras"][0].get("image_size_px") if path.is_file() else None


def load_part(out_dir: Path, config: Path = DEFAULT_CONFIG, analysis: Path = DEFAULT_ANALYSIS,
              base_rectangles=None) -> MeasuredPart:
    """The part measured by ``georeg measure`` into ``out_dir`` (faces named by ``config``'s
    ``[geometry] faces``), restricted to the regions of ``analysis``, base plane z = 0.

    ``base_rectangles``: keep only the plate's points in these ((x0, x1), (y0, y1)) (mm).
    """
    regions = load_analysis(analysis)
    try:
        faces = tomllib.loads(Path(config).read_text())["geometry"]["faces"]
    except (tomllib.TOMLDecodeError, KeyError, TypeError) as err:
        raise ValueError(f"{config}: [geometry] faces: {err}") from None
    points, masked, entry = read_part(Path(out_dir), [str(f) for f in faces])
    if base_rectangles is not None and "base" in points:
        points["base"] = points["base"][in_rectangles(points["base"], base_rectangles)]
    size = _image_size(Path(out_dir), entry)
    full = size is not None and list(size) == list(read_image(regions.specimen.cam0).shape[::-1])
    time_s = entry.get("time_s")
    return measured_part(regions, points, math.nan if time_s is None else float(time_s),
                         scales=None if entry.get("scales") is None else tuple(entry["scales"]),
                         full_resolution=full, residual_percent=float(entry.get("residual_percent") or math.nan),
                         masked_fraction=masked)


def write_report(out_dir: Path, part: MeasuredPart, comparison, command: str) -> list[Path]:
    """summary.json, the PNG figures and report.html, all or nothing (``OutputWriter``)."""
    figures = {"overview": (pngs.overview(part.points), "Height of the measured faces above the base plane (mm)."),
               "shape_maps": (pngs.shape_maps(part.points, comparison, part.analysis.plate.flatness_polygon_mm),
                              "Deviation from the best-fit plane or cylinder; dashed: the README's base region.")}
    profiles = pngs.cylinder_profiles(comparison)
    if profiles is not None:
        figures["cylinder_profiles"] = (profiles, "Radial residual of the measured bars against the angle from "
                                                  "the crest, for the best-fit radius and for the laser's and "
                                                  "pyvale's radii imposed.")
    with OutputWriter(out_dir) as w:
        for name, (png, _) in figures.items():
            w.write_bytes(f"{name}.png", png)
        w.write_json("summary.json", report.summary(part, comparison))
        w.write_text("report.html", report.report_html(part, comparison, figures, command))
    return w.published


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
    """Markdown table: quantity, this run, the reference (``--reference``), laser, pyvale."""
    lines = ["| quantity | this run | reference | laser | pyvale |", "| --- | --- | --- | --- | --- |"]
    for label, path, digits in ROWS:
        refs = [REFERENCES[w].get(path, "") for w in ("laser", "pyvale")]
        lines.append(f"| {label} | {_get(this, path, digits)} | {_get(reference, path, digits)} | "
                     + " | ".join(str(r) for r in refs) + " |")
    for name, prism in this.get("prisms", {}).items():
        rms = " / ".join(f"{v:.2f}" for v in prism["rms_plane_um"].values())
        lines += [f"| {name}: RMS of its faces to their planes (um), {' / '.join(prism['rms_plane_um'])} "
                  f"| {rms} | | | |",
                  f"| {name}: included angle (deg; nominal {prism['nominal_angle_deg']:.2f}) "
                  f"| {prism['included_angle_deg']:.3f} | | {report.LASER['prism_angle_deg']} | |",
                  f"| {name}: ridge above the base plane (mm) | {prism['ridge_height_mm']:.4f} | | "
                  f"{report.LASER['ridge_mm']} | |"]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out_dir", type=Path, help="output folder of georeg measure")
    p.add_argument("--out", type=Path, default=None,
                   help="also write summary.json, the PNG figures and report.html to this folder")
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG,
                   help="the georeg measure config (its [geometry] faces name the VTU's faces)")
    p.add_argument("--analysis", type=Path, default=DEFAULT_ANALYSIS,
                   help="the analysis config (the regions of the figures)")
    p.add_argument("--reference", type=Path, default=None,
                   help="the --json (or --out summary.json) of another analysis, printed beside")
    p.add_argument("--interim-base", action="store_true",
                   help="keep only the plate within the interim IGES's rectangles "
                        "(make_specimen_cad.INTERIM_BASE_MM), to compare parts measured from the "
                        "STEP and from the interim IGES on the same plate region")
    p.add_argument("--json", type=Path, default=None, help="write the figures to this JSON file")
    args = p.parse_args(argv)
    command = "python " + " ".join(shlex.quote(a) for a in [str(Path(sys.argv[0])), *(argv or sys.argv[1:])])
    try:
        rectangles = None
        if args.interim_base:
            from make_specimen_cad import INTERIM_BASE_MM
            rectangles = list(INTERIM_BASE_MM.values())
        part = load_part(args.out_dir, args.config, args.analysis, rectangles)
        comparison = compare(part)
        this = report.summary(part, comparison)
        reference = None if args.reference is None else json.loads(args.reference.read_text())
        if args.out is not None:
            write_report(args.out, part, comparison, command)
    except (OSError, ValueError, KeyError) as err:
        print(f"analyse_part.py: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 1
    print(table(this, reference))
    if args.out is not None:
        for name, ok, detail in report.targets(part, comparison):
            print(f"{'NOT CHECKED' if ok is None else ('PASS' if ok else 'FAIL'):>11}  {name}: {detail}")
        print(f"wrote summary.json, the figures and report.html to {args.out}")
    if args.json is not None:
        args.json.write_text(json.dumps(this, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
