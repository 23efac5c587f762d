"""The real GT4 loading series tracked by ``georeg track`` (issue 27, item 5).

From frame 0000 alone (the shape of ``examples/gt4_roi/specimen.toml``: the D-shaped
specimen's region of interest, the VIC-3D calibration), ``georeg track`` with each method
(``fe``, ``tikhonov``, ``georeg``) over frames 0001-0005, 0110, 0129 and ``large_motion``,
each frame from rest and from the default feature start. Printed per frame: status,
residual against the noise floor, the share of valid nodes, the median displacement of the
valid nodes in the specimen frame (z along its normal), the median principal surface
Green-Lagrange strains, and the time per frame; and, for frames 1-5, DICe's regression gold
(``reference_dice/DICe_solution.e``: the median ``MODEL_DISPLACEMENT_Z`` over its subsets, in
its best-fit-plane frame) beside our median out-of-plane displacement.

Not yet here: pyvale and al-dic-3d on the same frames (optional benchmark peers).

Run: ``PYTHONPATH=. python benchmarks/bench_real_series.py [--data ../shared/data]
[--methods fe tikhonov georeg] [--frames 0001 0005 0129 large_motion]``
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import meshio
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from georeg_app import cli  # noqa: E402

FRAMES = ("0001", "0002", "0003", "0004", "0005", "0110", "0129", "large_motion")


def _image(data: Path, frame: str, camera: int) -> Path:
    stem = frame if frame == "large_motion" else f"GT4-{frame}"
    return data / "stereo_dic_sample3" / "images" / f"{stem}_{camera}.png"


def dice_medians(data: Path) -> list[float]:
    """DICe's median MODEL_DISPLACEMENT_Z (mm) for frames 1-5."""
    from scipy.io import netcdf_file
    f = netcdf_file(str(data / "stereo_dic_sample3" / "reference_dice" / "DICe_solution.e"), "r",
                    mmap=False)
    names = [b"".join(n).decode().strip() for n in f.variables["name_nod_var"].data]
    z = np.array(f.variables[f"vals_nod_var{names.index('MODEL_DISPLACEMENT_Z') + 1}"].data)
    return [float(np.median(z[k])) for k in range(1, min(6, len(z)))]


def principal(vtu) -> tuple[float, float]:
    exx, eyy, exy = (np.asarray(vtu.point_data[k], float) for k in ("strain_xx", "strain_yy",
                                                                   "strain_xy"))
    mean, radius = 0.5 * (exx + eyy), np.sqrt((0.5 * (exx - eyy)) ** 2 + exy ** 2)
    valid = np.asarray(vtu.point_data.get("valid", np.ones(len(exx))), bool)
    return float(np.median((mean + radius)[valid])), float(np.median((mean - radius)[valid]))


def track(data: Path, frames, method: str, folder: Path) -> dict:
    spec = (REPO / "examples" / "gt4_roi" / "specimen.toml").read_text()
    spec = spec.replace('"../../../shared/data', f'"{data.as_posix()}')
    cam0 = ", ".join(f'"{_image(data, f, 0).as_posix()}"' for f in frames)
    cam1 = ", ".join(f'"{_image(data, f, 1).as_posix()}"' for f in frames)
    config = folder / f"track_{method}.toml"
    config.write_text(spec + f'\n[series]\ncam0 = [{cam0}]\ncam1 = [{cam1}]\n\n'
                      f'[displacement]\nmethod = "{method}"\nincremental = false\n')
    out = folder / f"out_{method}"
    t0 = time.perf_counter()
    code = cli.main(["-q", "track", str(config), "--out", str(out), "--overwrite"])
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").is_file() else {}
    return dict(code=code, time_s=time.perf_counter() - t0, summary=summary, out=out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--methods", nargs="+", default=["fe", "tikhonov", "georeg"])
    parser.add_argument("--frames", nargs="+", default=list(FRAMES))
    args = parser.parse_args(argv)
    if not (args.data / "stereo_dic_sample3" / "images").is_dir():
        raise SystemExit(f"{args.data}: no stereo_dic_sample3/images (the data are not part of "
                         "the project)")
    print(f"# bench_real_series: {platform.node()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    dice = dice_medians(args.data)
    with tempfile.TemporaryDirectory() as tmp:
        for method in args.methods:
            run = track(args.data, args.frames, method, Path(tmp))
            print(f"\n## {method}: exit {run['code']}, {run['time_s']:.0f} s in all (reference "
                  "shape included)", flush=True)
            print(f"{'frame':13s} {'status':7s} {'residual/noise %':>17s} {'valid':>6s} "
                  f"{'median U x, y, z (um)':>24s} {'e1, e2 (%)':>14s} {'time (s)':>8s} "
                  f"{'DICe z (um)':>11s}")
            for name, f in zip(args.frames, run["summary"].get("frames", [])):
                row = f"{name:13s} {f['status']:7s}"
                if not f.get("mesh_file"):
                    print(f"{row} {f.get('failure', '')[:90]}")
                    continue
                vtu = meshio.read(run["out"] / f["mesh_file"])
                valid = np.asarray(vtu.point_data.get("valid", np.ones(len(vtu.points))), bool)
                U = np.median(np.asarray(vtu.point_data["displacement_mm"])[valid], axis=0) * 1e3
                e1, e2 = principal(vtu)
                gold = (f"{dice[int(name) - 1] * 1e3:11.1f}"
                        if name.isdigit() and 1 <= int(name) <= len(dice) else "")
                print(f"{row} {f['residual_percent']:8.3f}/{f['noise_percent']:<8.3f} "
                      f"{f.get('valid_share') or float('nan'):6.3f} "
                      f"{U[0]:8.1f}{U[1]:8.1f}{U[2]:8.1f} {100 * e1:6.2f}{100 * e2:7.2f} "
                      f"{f['time_s']:8.1f} {gold}")
                if f["status"] != "ok":
                    print(f"{'':13s} {f.get('failure', '')[:110]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
