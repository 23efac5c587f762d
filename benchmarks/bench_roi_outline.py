"""A specimen of any outline from a region of interest, against known truth (issue 22).

Renders with a known shape and known cameras of two specimens whose outline is not a
rectangle: a D (a rectangle closed by a half disc) with an off-centre circular hole in the
half disc,

- a flat plate, measured with ``[geometry] kind = "roi"``, ``surface = "plane"``;
- a cylindrical panel (radius 150 mm, axis along y, 2.5 mm of sag over the specimen),
  measured with ``surface = "quadric"``,

each rendered by the core's renderer (:func:`fesdic_core.synthetic.render.render_stereo`) and
by an independent one, riley-raster (PyPI; the camera conversion and the Q9 mesh of the
truth from ``bench_levels.py``; its elements on the outline's material, a 0.5 mm staircase
that the ROI, drawn 1.5 mm inside the outline, never reaches). 2 gray levels of noise,
8-bit images, 640 x 480 px, 4 px speckle, the demo's rig; the cameras are given in a world
frame that is not the specimen's, so that only the rig's triangulation places it.

For each render, ``georeg compare`` on the D-shaped ROI (its hole excluded) gives FE,
Tikhonov at 5, 10 and 20 mm and "auto", and georeg with automatic levels; ``georeg measure``
(georeg, automatic levels) on the rectangle inscribed in the D's straight part (a
four-vertex polygon) gives the inscribed figure. Errors are the distances of the measured
nodes to the true surface after the best bounded rigid alignment
(:func:`fesdic_core.synthetic.accuracy.shape_error_to_surface`), RMS in micrometres, over
all nodes of each ROI and over the nodes inside the inscribed rectangle (the common region).
The issue's criterion: georeg below FE and every Tikhonov length on the D, and its RMS on the
D at most 1.2 times its RMS on the inscribed rectangle.

Run (riley-raster and pyvale live in a separate environment, never a dependency)::

    python -m venv --system-site-packages VENV && VENV/bin/pip install riley-raster
    PYTHONPATH=. VENV/bin/python benchmarks/bench_roi_outline.py [--renderer core|riley|both]
        [--specimen flat cylinder] [--seeds N] [--keep DIR]
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import cv2
import meshio
import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parent)]
from bench_levels import riley_render  # noqa: E402
from fesdic_core.cameras.rig import read_cameras_json, write_cameras_json  # noqa: E402
from fesdic_core.synthetic.accuracy import shape_error_to_surface  # noqa: E402
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for  # noqa: E402
from fesdic_core.synthetic.specimen import Specimen, cylindrical_panel  # noqa: E402
from georeg_app import cli  # noqa: E402

LENGTH_MM, WIDTH_MM = 64.0, 44.0          # the specimen's bounding rectangle
ARC_CENTRE_X, ARC_RADIUS = 10.0, 22.0     # the D: x <= 10 a rectangle, then a half disc
HOLE_CENTRE, HOLE_RADIUS = (18.0, -5.0), 4.0
INSET_MM = 1.5                            # the ROI drawn this far inside the outline
ELEMENTS = 150                            # Q9 elements over the D (about 32 x 32 px each)
CYLINDER_RADIUS_MM = 150.0
IMAGE_SIZE, FIELD_MM, NOISE, SPECKLE_PX = (640, 480), 80.0, 2.0, 4.0
MOVE_RVEC, MOVE_T = np.array([0.3, -0.2, 0.5]), np.array([10.0, -5.0, 300.0])
#: the rectangle inscribed in the D's straight part, inset as the ROI
INSCRIBED = (-0.5 * LENGTH_MM + INSET_MM, ARC_CENTRE_X, -0.5 * WIDTH_MM + INSET_MM,
             0.5 * WIDTH_MM - INSET_MM)

#: the inscribed rectangle's share of the D's area: its mesh gets as large elements
_INSCRIBED_SHARE = 0.75

CONFIG = """[images]
cam0 = "cam0.png"
cam1 = "cam1.png"
[cameras]
file = "cameras.json"
[geometry]
kind = "roi"
surface = "{surface}"
polygon_px = {polygon}
{exclude}
elements = {elements}
[method]
name = "georeg"
levels = "auto"
tikhonov_length_mm = [5.0, 10.0, 20.0, "auto"]
"""


def d_shape(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Material of the D with its hole (the specimens' ``material``)."""
    inside = (x <= ARC_CENTRE_X) | ((x - ARC_CENTRE_X) ** 2 + y ** 2 <= ARC_RADIUS ** 2)
    return inside & ((x - HOLE_CENTRE[0]) ** 2 + (y - HOLE_CENTRE[1]) ** 2 >= HOLE_RADIUS ** 2)


def specimens(cameras) -> dict[str, tuple[Specimen, str]]:
    speckle = speckle_mm_for(cameras[0], SPECKLE_PX)
    return {"flat": (Specimen(LENGTH_MM, WIDTH_MM, speckle_mm=speckle, seed=3, material=d_shape),
                     "plane"),
            "cylinder": (cylindrical_panel(LENGTH_MM, WIDTH_MM, CYLINDER_RADIUS_MM,
                                           speckle_mm=speckle, seed=3, material=d_shape),
                         "quadric")}


def _outline_xy() -> np.ndarray:
    """The D's outline inset by INSET_MM, counter-clockwise, (m, 2) mm."""
    r, h = ARC_RADIUS - INSET_MM, 0.5 * WIDTH_MM - INSET_MM
    x0 = -0.5 * LENGTH_MM + INSET_MM
    arc = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 25)
    return np.vstack([[[x0, -h], [ARC_CENTRE_X, -h]],
                      np.column_stack([ARC_CENTRE_X + r * np.cos(arc), r * np.sin(arc)])[1:-1],
                      [[ARC_CENTRE_X, h], [x0, h]]])


def _hole_xy() -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
    r = HOLE_RADIUS + INSET_MM
    return np.column_stack([HOLE_CENTRE[0] + r * np.cos(t), HOLE_CENTRE[1] + r * np.sin(t)])


def _pixels(camera, specimen: Specimen, xy: np.ndarray) -> list:
    X = np.column_stack([xy, specimen.height(xy[:, 0], xy[:, 1])])
    return np.round(camera.project(X), 2).tolist()


def _moved(cameras):
    """The rig in a world frame that is not the specimen's (X_new = R X + t)."""
    R = cv2.Rodrigues(MOVE_RVEC)[0]
    return [c.with_extrinsics(np.concatenate([cv2.Rodrigues(c.R @ R.T)[0].ravel(),
                                              c.tvec - c.R @ R.T @ MOVE_T])) for c in cameras]


def _to_truth(points: np.ndarray, cameras_json: Path, true_cam0) -> np.ndarray:
    """Points of the specimen frame mapped to the rendering frame through camera 0."""
    cam = read_cameras_json(cameras_json)[0]
    return (points @ cam.R.T + cam.tvec - true_cam0.tvec) @ true_cam0.R


def _errors(out: Path, specimen: Specimen, true_cam0) -> dict[str, dict]:
    summary = json.loads((out / "summary.json").read_text())
    x0, x1, y0, y1 = INSCRIBED
    rows = {}
    for result in summary["methods"]:
        if result.get("status") != "ok" or not result.get("mesh_file"):
            rows[result["label"]] = dict(status=result.get("status"))
            continue
        stem = result["mesh_file"].removesuffix(".vtu")
        X = _to_truth(meshio.read(out / result["mesh_file"]).points, out / f"{stem}_cameras.json",
                      true_cam0)
        error = shape_error_to_surface(X, specimen) * 1e3
        common = (X[:, 0] >= x0) & (X[:, 0] <= x1) & (X[:, 1] >= y0) & (X[:, 1] <= y1)
        rows[result["label"]] = dict(status="ok", rms_um=float(np.sqrt(np.mean(error ** 2))),
                                     common_um=float(np.sqrt(np.mean(error[common] ** 2))),
                                     nodes=int(len(X)), levels=result.get("levels"),
                                     dropped=result.get("dropped_dofs"))
    return rows


def run_case(folder: Path, name: str, specimen: Specimen, surface: str, renderer: str,
             cameras, seed: int = 11) -> dict:
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if renderer == "core":
        arrays = render_stereo(specimen, cameras, supersample=4, noise_std=NOISE, seed=seed,
                               progress=False)
    else:
        arrays, _ = riley_render(specimen, cameras, NOISE, seed=seed)
    render_s = time.perf_counter() - t0
    for k, a in enumerate(arrays):
        cv2.imwrite(str(folder / f"cam{k}.png"), np.clip(np.rint(a), 0, 255).astype(np.uint8))
    write_cameras_json(folder / "cameras.json", _moved(cameras))
    d = CONFIG.format(surface=surface, elements=ELEMENTS, polygon=json.dumps(_pixels(cameras[0], specimen, _outline_xy())),
                      exclude=f"exclude_px = [{json.dumps(_pixels(cameras[0], specimen, _hole_xy()))}]")
    x0, x1, y0, y1 = INSCRIBED
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    r = CONFIG.format(surface=surface, elements=int(round(ELEMENTS * _INSCRIBED_SHARE)), polygon=json.dumps(_pixels(cameras[0], specimen, corners)),
                      exclude="")
    (folder / "d.toml").write_text(d)
    (folder / "rect.toml").write_text(r)
    times = {}
    for command, config, out in (("compare", "d.toml", "d_out"), ("measure", "rect.toml", "rect_out")):
        t0 = time.perf_counter()
        code = cli.main(["-q", command, str(folder / config), "--out", str(folder / out),
                         "--overwrite"])
        times[out] = time.perf_counter() - t0
        if code not in (0, 1):
            raise SystemExit(f"{name}/{renderer}: georeg {command} exit {code}")
    return dict(d=_errors(folder / "d_out", specimen, cameras[0]),
                rect=_errors(folder / "rect_out", specimen, cameras[0]), render_s=render_s,
                times=times)


def pooled(rows: list[dict]) -> dict:
    """The runs of several noise draws as one: RMS errors pooled (root mean square over the
    draws), times summed; a method failed in any draw is failed."""
    out = dict(rows[0], seeds=len(rows), render_s=sum(r["render_s"] for r in rows),
               times={k: sum(r["times"][k] for r in rows) for k in rows[0]["times"]})
    for part in ("d", "rect"):
        merged = {}
        for label, first in rows[0][part].items():
            runs = [r[part].get(label, {}) for r in rows]
            if any(r.get("status") != "ok" for r in runs):
                merged[label] = dict(status="failed")
                continue
            merged[label] = dict(first, **{k: float(np.sqrt(np.mean([r[k] ** 2 for r in runs])))
                                           for k in ("rms_um", "common_um")})
        out[part] = merged
    return out


def report(name: str, renderer: str, row: dict) -> bool:
    print(f"\n## {name} ({renderer} renderer): D-shaped ROI with an off-centre hole "
          f"({row['seeds']} noise draws, errors pooled)")
    print(f"{'method':34s} {'RMS all (um)':>13s} {'RMS common (um)':>16s} {'nodes':>6s}")
    for label, r in row["d"].items():
        if r["status"] != "ok":
            print(f"{label:34s} {r['status']:>13s}")
            continue
        print(f"{label:34s} {r['rms_um']:13.2f} {r['common_um']:16.2f} {r['nodes']:6d}")
    (rect,) = row["rect"].values()
    print(f"{'inscribed rectangle, georeg auto':34s} {rect.get('rms_um', float('nan')):13.2f} "
          f"{rect.get('common_um', float('nan')):16.2f} {rect.get('nodes', 0):6d}")
    georeg = row["d"].get("georeg auto (multiscale)", {})
    others = [r["rms_um"] for label, r in row["d"].items()
              if r["status"] == "ok" and (label.startswith("FE") or label.startswith("Tikhonov"))]
    ok = (georeg.get("status") == "ok" and rect.get("status") == "ok"
          and all(georeg["rms_um"] < o for o in others)
          and georeg["rms_um"] <= 1.2 * rect["rms_um"])
    if georeg.get("status") == "ok":
        print(f"georeg auto on the D: levels {georeg['levels']}, dropped dofs {georeg['dropped']}")
        print(f"georeg on the D / on the inscribed rectangle: "
              f"{georeg['rms_um'] / rect.get('rms_um', float('nan')):.2f} (at most 1.2); "
              f"below FE and every Tikhonov length: {all(georeg['rms_um'] < o for o in others)}")
    print(f"times: render {row['render_s']:.1f} s, compare on the D {row['times']['d_out']:.1f} s, "
          f"measure on the rectangle {row['times']['rect_out']:.1f} s; criterion met: {ok}")
    return ok


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--renderer", choices=("core", "riley", "both"), default="both")
    parser.add_argument("--specimen", nargs="+", choices=("flat", "cylinder"),
                        default=["flat", "cylinder"])
    parser.add_argument("--keep", type=Path, help="keep the renders and outputs in this folder")
    parser.add_argument("--seeds", type=int, default=1,
                        help="noise draws per case, their errors pooled (default 1)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    print(f"# bench_roi_outline: {platform.node()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.2f}, {platform.python_version()}")
    cameras = demo_cameras(image_size=IMAGE_SIZE, field_mm=FIELD_MM)
    renderers = ("core", "riley") if args.renderer == "both" else (args.renderer,)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        for name in args.specimen:
            specimen, surface = specimens(cameras)[name]
            for renderer in renderers:
                row = pooled([run_case(root / f"{name}_{renderer}_{seed}", name, specimen, surface,
                                       renderer, cameras, seed=11 + seed)
                              for seed in range(args.seeds)])
                results.append(report(name, renderer, row))
    print(f"\nall criteria met: {all(results)}")
    return 0 if all(results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
