"""Measure the Stereo DIC Challenge specimen on the real stereo pair, all four faces.

    python examples/dic_challenge/run.py --out DIR

measures the base plate, the block top and the two half-cylinders (each from an exact
NURBS cylinder and from a flat nominal at crest height) with geometric regularization,
the fixed point of calibration (6 pose unknowns, stereo relation kept) and shape, from
the landmarks of ``specimen.toml``; writes into DIR (all files or none):
``base.vtu``, ``block_top.vtu``, ``cylinder_h.vtu``, ``cylinder_v.vtu`` (and the flat
nominals' ``cylinder_h_flat.vtu``, ``cylinder_v_flat.vtu``; world frame, mm, base plane
z = 0), ``summary.json``, the PNG figures and the self-contained ``report.html``.
"""
from __future__ import annotations

import argparse
import logging
import shlex
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from challenge import figures, report                                    # noqa: E402
from challenge.pipeline import FACES, compare, run_challenge             # noqa: E402
from fesdic_core.mesh_io import write_mesh                               # noqa: E402
from georeg_app.outputs import OutputWriter                              # noqa: E402

logger = logging.getLogger("dic_challenge")


def _scales(text: str) -> tuple[int, ...]:
    try:
        scales = tuple(int(s) for s in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected integers separated by commas, got {text!r}") from None
    if any(s < 0 for s in scales) or list(scales) != sorted(set(scales), reverse=True):
        raise argparse.ArgumentTypeError(f"scales must be >= 0 and decrease, got {text!r}")
    return scales


def _crop(text: str) -> tuple[int, int, int, int]:
    try:
        x0, y0, w, h = (int(s) for s in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x0,y0,w,h (px), got {text!r}") from None
    return x0, y0, w, h


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--faces", default=",".join(FACES),
                   help=f"faces to measure, comma separated (default: {','.join(FACES)})")
    p.add_argument("--scales", type=_scales, default=None,
                   help="image scales for every face, coarse to fine, e.g. 3,2 (default: each "
                        "face's [method] scales, ending at 0)")
    p.add_argument("--crop", type=_crop, default=None,
                   help="measure on a crop x0,y0,w,h of the stored images (px)")
    p.add_argument("--quiet", action="store_true", help="warnings only, no progress bars")
    p.add_argument("--verbose", action="store_true", help="debug log")
    return p


def write_outputs(out_dir: Path, run, comparison, command: str) -> list[Path]:
    """Every output of the run, all or nothing (``georeg_app.outputs.OutputWriter``)."""
    pngs = {"overview": (figures.overview(run.results),
                         "Height of the measured faces above the base plane (mm)."),
            "shape_maps": (figures.shape_maps(run.results, comparison,
                                              run.faces["base"].analysis.flatness_polygon_mm),
                           "Deviation from the best-fit plane or cylinder; dashed: the README's "
                           "base region."),
            "residual_maps": (figures.residual_maps(run.results),
                              "Gray-level residual at the integration points (Fig. 12 of the paper).")}
    profiles = figures.cylinder_profiles(comparison)
    if profiles is not None:
        pngs["cylinder_profiles"] = (profiles, "Radial residual of the measured bars against the angle "
                                               "from the crest, for the best-fit radius and for the "
                                               "laser's and pyvale's radii imposed.")
    with OutputWriter(out_dir) as w:
        for name, r in run.results.items():
            mesh = r.model.mesh.with_nodes(r.nodes_mm)
            write_mesh(w.path(f"{name}.vtu"), mesh,
                       point_data={"shape_correction_mm": r.measurement.q,
                                   "height_mm": r.nodes_mm[:, 2]})
        for name, (png, _) in pngs.items():
            w.write_bytes(f"{name}.png", png)
        w.write_json("summary.json", report.summary(run, comparison))
        w.write_text("report.html", report.report_html(run, comparison, pngs, command))
    return w.published


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    level = logging.WARNING if args.quiet else (logging.DEBUG if args.verbose else logging.INFO)
    logging.basicConfig(level=level, format="%(asctime)s %(name)s: %(message)s", datefmt="%H:%M:%S")
    faces = tuple(f.strip() for f in args.faces.split(",") if f.strip())
    unknown = sorted(set(faces) - set(FACES))
    if unknown:
        print(f"run.py: error: unknown face(s) {', '.join(unknown)} (known: {', '.join(FACES)})",
              file=sys.stderr)
        return 1
    command = "python " + " ".join(shlex.quote(a) for a in [str(Path(sys.argv[0])), *(argv or sys.argv[1:])])
    t0 = time.perf_counter()
    try:
        run = run_challenge(HERE, faces, scales=args.scales, crop=args.crop,
                            progress=not args.quiet)
        comparison = compare(run)
        written = write_outputs(Path(args.out), run, comparison, command)
    except (ValueError, OSError, RuntimeError) as err:        # bad input: one line, exit 1
        if args.verbose:
            raise
        print(f"run.py: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 1
    for name, ok, detail in report.targets(run, comparison):
        print(f"{'NOT CHECKED' if ok is None else ('PASS' if ok else 'FAIL'):>11}  {name}: {detail}")
    print(f"wrote {len(written)} files to {args.out} in {time.perf_counter() - t0:.1f} s "
          f"(measurement {run.time_s:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
