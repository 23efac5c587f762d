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

``--peers`` (pyvale in the benchmark environment, never a dependency): pyvale's
``calculate_3d`` (subset 27, step 4, its defaults otherwise, one seed at the ROI's most
interior pixel, no initial guess) and ``georeg track`` with each method, both with the DICe
calibration ``cal_dice_pyaldic.xml`` and the ROI of ``examples/gt4_roi/specimen.toml`` (its
polygon, the cut-out excluded), on the ``--frames`` from frame 0000. Ours is interpolated
(linearly, on the specimen's plane) at pyvale's subset centres in the reference state,
pyvale's points where our valid nodes are; printed per frame and method: the RMS of the
displacement difference in % of the RMS of pyvale's displacement, the median difference per
component, and the points compared, and the RMS difference of the surface Green-Lagrange strains
(in %, absolute) computed alike for both codes from their displacements at pyvale's points
(:func:`fitted_strain`, local planes of radius ``STRAIN_RADIUS_MM``). (pyvale's coordinates
are the deformed positions: the reference ones are ``X - U``.) al-dic-3d (``al-dic-3d run``
with its defaults, the ROI as a mask, when installed in the same environment) likewise, and
against pyvale.

Run: ``PYTHONPATH=. python benchmarks/bench_real_series.py [--data ../shared/data]
[--methods fe tikhonov georeg] [--frames 0001 0005 0129 large_motion] [--peers]``
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
sys.path[:0] = [str(REPO), str(REPO / "benchmarks")]
from georeg_app import cli  # noqa: E402

#: the radius (mm) of the local planes that give every code's strain alike (fitted_strain)
STRAIN_RADIUS_MM = 2.0

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


def specimen_config(data: Path, calibration: str = "vic3d") -> str:
    """The example's configuration, reading ``data``, with the VIC-3D or DICe calibration."""
    spec = (REPO / "examples" / "gt4_roi" / "specimen.toml").read_text()
    spec = spec.replace('"../../../shared/data', f'"{data.as_posix()}')
    if calibration == "dice":                        # the example's commented alternative
        spec = spec.replace("\nvic3d = ", "\n# vic3d = ").replace("\n# dice = ", "\ndice = ")
    return spec


def track(data: Path, frames, method: str, folder: Path, calibration: str = "vic3d",
          reference: Path | None = None, uncertainty: bool = True) -> dict:
    spec = specimen_config(data, calibration)
    if reference is not None:      # a `georeg measure` folder: its cameras, surface, method
        images = spec[spec.index("[images]"):spec.index("[cameras]")]
        spec = images + f'\n[reference]\ndir = "{reference.as_posix()}"\n'
    cam0 = ", ".join(f'"{_image(data, f, 0).as_posix()}"' for f in frames)
    cam1 = ", ".join(f'"{_image(data, f, 1).as_posix()}"' for f in frames)
    config = folder / f"track_{method}.toml"
    config.write_text(spec + f'\n[series]\ncam0 = [{cam0}]\ncam1 = [{cam1}]\n\n'
                      f'[displacement]\nmethod = "{method}"\nincremental = false\n'
                      f'uncertainty = {str(uncertainty).lower()}\n')
    out = folder / f"out_{method}"
    t0 = time.perf_counter()
    code = cli.main(["-q", "track", str(config), "--out", str(out), "--overwrite"])
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").is_file() else {}
    return dict(code=code, time_s=time.perf_counter() - t0, summary=summary, out=out)


def roi_mask(shape: tuple[int, int]) -> np.ndarray:
    """Camera 0's pixels (h, w) inside the example's ROI polygon and outside its cut-out."""
    import tomllib
    import cv2
    example = REPO / "examples" / "gt4_roi" / "specimen.toml"
    geometry = tomllib.loads(example.read_text())["geometry"]
    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.round(geometry["polygon_px"]).astype(np.int32)], 1)
    for hole in geometry.get("exclude_px", []):
        cv2.fillPoly(mask, [np.round(hole).astype(np.int32)], 0)
    return mask > 0


def pyvale_frames(data: Path, frames, folder: Path) -> dict:
    """pyvale's calculate_3d of ``frames`` from frame 0000 with the DICe calibration:
    {frame: (reference points (p, 3), U (p, 3))} in our cameras' world frame; and seconds."""
    import cv2
    from bench_vs_pyvale import SUBSET_PX, pyvale_calib
    from fesdic_core.cameras.io.vic3d_dice import read_dice
    from pyvale import dic
    cams = read_dice(data / "stereo_dic_sample3" / "cal_dice_pyaldic.xml")
    read = lambda f, k: cv2.imread(str(_image(data, f, k)), cv2.IMREAD_GRAYSCALE)
    reference = [read("0000", k) for k in (0, 1)]
    mask = roi_mask(reference[0].shape)
    depth = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5)
    seed_y, seed_x = np.unravel_index(int(np.argmax(depth)), depth.shape)
    folder.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    dic.calculate_3d(reference=reference,
                     deformed=[np.stack([read(f, k) for f in frames]) for k in (0, 1)],
                     calibration=pyvale_calib(cams), roi_mask=mask, seed=[int(seed_x), int(seed_y)],
                     subset_size=SUBSET_PX, subset_step=4, num_threads=2,
                     output_basepath=folder, output_binary=True, print_level=0)
    seconds = time.perf_counter() - t
    s = dic.import_3d(data=str(folder / "dic_results_*"), delimiter=",", binary=True,
                      layout="column", print_level=0).stereo
    R0 = cv2.Rodrigues(np.asarray(cams[0].rvec, float).reshape(3, 1))[0]
    t0 = np.asarray(cams[0].tvec, float).ravel()
    out = {}
    for i, f in enumerate(frames):
        X = np.column_stack([np.ravel(a[i]) for a in (s.x_mm, s.y_mm, s.z_mm)])
        U = np.column_stack([np.ravel(a[i]) for a in (s.u_mm, s.v_mm, s.w_mm)])
        ok = np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(U), axis=1)
        out[f] = ((X[ok] - U[ok] - t0) @ R0, U[ok] @ R0)
    return out, seconds


def aldic_frames(data: Path, frames, folder: Path) -> tuple[dict, float]:
    """al-dic-3d's headless run (``al-dic-3d run``, its defaults, the ROI as a mask on the
    left reference image, the DICe calibration) of ``frames`` from frame 0000, as
    :func:`pyvale_frames`; frames it leaves without a point are absent."""
    import subprocess
    import cv2
    from fesdic_core.cameras.io.vic3d_dice import read_dice
    calibration = data / "stereo_dic_sample3" / "cal_dice_pyaldic.xml"
    cams = read_dice(calibration)
    (folder / "img").mkdir(parents=True, exist_ok=True)
    names = ["0000", *frames]
    for i, f in enumerate(names):           # its pairing check wants one frame index per name
        for k, side in enumerate("LR"):
            link = folder / "img" / f"{side}_{i:04d}.png"
            link.unlink(missing_ok=True)
            link.symlink_to(_image(data, f, k))
    shape = cv2.imread(str(_image(data, "0000", 0)), cv2.IMREAD_GRAYSCALE).shape
    cv2.imwrite(str(folder / "roi.png"), roi_mask(shape).astype(np.uint8) * 255)
    side = lambda s: ", ".join(f'"img/{s}_{i:04d}.png"' for i in range(len(names)))
    (folder / "config.toml").write_text(
        f'[calibration]\nfile = "{calibration.as_posix()}"\nformat = "dice"\n\n'
        f'[sequence]\nleft = [{side("L")}]\nright = [{side("R")}]\n\n'
        '[roi]\nmask = "roi.png"\n\n[output]\ndir = "out"\n')
    t = time.perf_counter()
    subprocess.run([str(Path(sys.executable).parent / "al-dic-3d"), "run", "-q",
                    str(folder / "config.toml"), "--formats", "npz"], check=True)
    seconds = time.perf_counter() - t
    result = np.load(folder / "out" / "run.npz")
    R0 = cv2.Rodrigues(np.asarray(cams[0].rvec, float).reshape(3, 1))[0]
    t0 = np.asarray(cams[0].tvec, float).ravel()
    X0 = result["points3D"][0]
    out = {}
    for i, f in enumerate(frames, start=1):
        U = result["displacement3D"][i]
        ok = np.all(np.isfinite(X0), axis=1) & np.all(np.isfinite(U), axis=1)
        if ok.any():
            out[f] = ((X0[ok] - t0) @ R0, U[ok] @ R0)
    return out, seconds


def fitted_strain(x: np.ndarray, U: np.ndarray, radius_mm: float) -> np.ndarray:
    """Surface Green-Lagrange strain (p, 3) ``[E_xx, E_yy, E_xy]`` at points ``x`` (p, 2) of
    the specimen's plane from displacements ``U`` (p, 3) in the specimen frame: at each
    point the least-squares plane of ``U`` through the points within ``radius_mm`` gives the
    gradient ``G = dU/dx`` (3 x 2), and ``E = 1/2 (G_2^T + G_2 + G^T G)`` (``G_2`` its
    in-plane rows). The same for every code, so that strains are computed alike."""
    from scipy.sparse import csr_matrix
    from scipy.spatial import cKDTree
    pairs = cKDTree(x).query_pairs(radius_mm, output_type="ndarray")
    p = len(x)
    i = np.concatenate([pairs[:, 0], pairs[:, 1], np.arange(p)])
    j = np.concatenate([pairs[:, 1], pairs[:, 0], np.arange(p)])
    A = csr_matrix((np.ones(len(i)), (i, j)), shape=(p, p))
    n = np.asarray(A.sum(axis=1)).ravel()
    mean = lambda v: (A @ v) / n[:, None]
    xbar, Ubar = mean(x), mean(U)
    Cxx = mean(np.einsum("pa,pb->pab", x, x).reshape(p, 4)).reshape(p, 2, 2) - \
        np.einsum("pa,pb->pab", xbar, xbar)
    CxU = mean(np.einsum("pa,pk->pak", x, U).reshape(p, 6)).reshape(p, 2, 3) - \
        np.einsum("pa,pk->pak", xbar, Ubar)
    G = np.linalg.solve(Cxx, CxU).transpose(0, 2, 1)               # (p, 3, 2): dU_k/dx_a
    E = 0.5 * (G[:, :2, :] + G[:, :2, :].transpose(0, 2, 1) +
               np.einsum("pka,pkb->pab", G, G))
    return np.column_stack([E[:, 0, 0], E[:, 1, 1], E[:, 0, 1]])


def against_peer(vtu, X: np.ndarray, U: np.ndarray, radius_mm: float = STRAIN_RADIUS_MM
                 ) -> tuple[float, np.ndarray, int, np.ndarray, np.ndarray]:
    """Our valid nodes' displacement interpolated at a peer's reference points (on the
    specimen's best plane): (RMS difference in % of the peer's RMS, median difference (3,)
    um, points compared, RMS strain difference (3,) in % (absolute) of ``[E_xx, E_yy,
    E_xy]`` computed alike by :func:`fitted_strain` on the peer's points, the peer's median
    principal strains (2,) in %)."""
    from scipy.interpolate import LinearNDInterpolator
    valid = np.asarray(vtu.point_data.get("valid", np.ones(len(vtu.points))), bool)
    nodes = np.asarray(vtu.points, float)[valid]
    ours = np.asarray(vtu.point_data["displacement_mm"])[valid]
    centre = nodes.mean(axis=0)
    axes = np.linalg.svd(nodes - centre, full_matrices=False)[2][:2]
    at = LinearNDInterpolator((nodes - centre) @ axes.T, ours)((X - centre) @ axes.T)
    common = np.all(np.isfinite(at), axis=1)
    diff = at[common] - U[common]
    rms = float(np.sqrt(np.mean(np.sum(diff ** 2, axis=1))) /
                np.sqrt(np.mean(np.sum(U[common] ** 2, axis=1))))
    x = X[common, :2]                    # the specimen frame: z along the normal
    theirs = fitted_strain(x, U[common], radius_mm)
    strain = 100.0 * np.sqrt(np.mean((fitted_strain(x, at[common], radius_mm) - theirs) ** 2,
                                     axis=0))
    mean, half = 0.5 * (theirs[:, 0] + theirs[:, 1]), 0.5 * (theirs[:, 0] - theirs[:, 1])
    radius = np.sqrt(half ** 2 + theirs[:, 2] ** 2)
    principal = 100.0 * np.array([np.median(mean + radius), np.median(mean - radius)])
    return 100.0 * rms, 1e3 * np.median(diff, axis=0), int(common.sum()), strain, principal


def peer_difference(a: tuple, b: tuple, within_mm: float = 2.0) -> float:
    """RMS of ``a``'s displacement at ``b``'s nearest points (within ``within_mm``) minus
    ``b``'s, in % of ``b``'s RMS displacement there."""
    from scipy.spatial import cKDTree
    gap, nearest = cKDTree(a[0]).query(b[0])
    near = gap <= within_mm
    diff = a[1][nearest[near]] - b[1][near]
    return 100.0 * float(np.sqrt(np.mean(np.sum(diff ** 2, axis=1)) /
                                 np.mean(np.sum(b[1][near] ** 2, axis=1))))


def peers(args) -> None:
    """``--peers``: pyvale and ours on the same frames with the DICe calibration."""
    try:
        import pyvale  # noqa: F401
    except ImportError:
        print("peers: skipped: pyvale is not importable by this python (a benchmark peer: "
              "python -m venv --system-site-packages VENV && VENV/bin/pip install pyvale)")
        return
    with tempfile.TemporaryDirectory() as tmp:
        codes = {}
        theirs, seconds = pyvale_frames(args.data, args.frames, Path(tmp) / "pyvale")
        codes["pyvale"] = theirs
        print(f"\n## pyvale calculate_3d (subset 27, step 4): {seconds:.0f} s for "
              f"{len(args.frames)} frames ({seconds / len(args.frames):.1f} s per frame)")
        if (Path(sys.executable).parent / "al-dic-3d").is_file():
            aldic, seconds = aldic_frames(args.data, args.frames, Path(tmp) / "aldic")
            codes["al-dic-3d"] = aldic
            counts = ", ".join(f"{f}: {len(aldic[f][0])}" if f in aldic else f"{f}: none"
                               for f in args.frames)
            print(f"## al-dic-3d run (its defaults): {seconds:.0f} s for {len(args.frames)} "
                  f"frames; points {counts}")
        else:
            print("## al-dic-3d: not installed in this environment (pip install al-dic-3d)")
        for f in args.frames:
            if f in theirs and f in codes.get("al-dic-3d", {}):
                print(f"{f}: al-dic-3d against pyvale (al-dic-3d at pyvale's points, nearest "
                      f"within 2 mm): {peer_difference(codes['al-dic-3d'][f], theirs[f]):.3f} % "
                      "of pyvale's RMS displacement")
        shape = Path(tmp) / "shape"
        config = Path(tmp) / "shape.toml"
        config.write_text(specimen_config(args.data, "dice"))
        code = cli.main(["-q", "measure", str(config), "--out", str(shape)])
        frame = json.loads((shape / "summary.json").read_text())["specimen"]
        origin, axes = np.asarray(frame["frame_origin_mm"]), np.asarray(frame["frame_axes"])
        print(f"\n## the reference shape (DICe calibration): exit {code}")
        for method in args.methods:
            run = track(args.data, args.frames, method, Path(tmp), calibration="dice",
                        reference=shape)
            print(f"\n## {method} (DICe calibration) against pyvale: exit {run['code']}, "
                  f"{run['time_s']:.0f} s in all (reference shape included)")
            print(f"{'frame':13s} {'peer':10s} {'status':7s} {'RMS diff (% of RMS U)':>22s} "
                  f"{'median diff x, y, z (um)':>26s} {'points':>7s} {'peer RMS U (mm)':>16s} "
                  f"{'strain RMS diff xx, yy, xy (%)':>31s} {'peer e1, e2 (%)':>16s}")
            for name, f in zip(args.frames, run["summary"].get("frames", [])):
                if not f.get("mesh_file"):
                    print(f"{name:13s} {'':10s} {f['status']:7s} no output: "
                          f"{f.get('failure', '')[:80]}")
                    continue
                vtu = meshio.read(run["out"] / f["mesh_file"])
                for code, points in codes.items():
                    if name not in points:
                        print(f"{name:13s} {code:10s} (no point)")
                        continue
                    X, U = points[name]               # to the specimen frame of our outputs
                    X, U = (X - origin) @ axes.T, U @ axes.T
                    rms, med, n, strain, e12 = against_peer(vtu, X, U)
                    print(f"{name:13s} {code:10s} {f['status']:7s} {rms:22.3f} {med[0]:8.2f}"
                          f"{med[1]:9.2f}{med[2]:9.2f} {n:7d} "
                          f"{np.sqrt(np.mean(np.sum(U ** 2, axis=1))):16.4f} "
                          f"{strain[0]:11.3f}{strain[1]:10.3f}{strain[2]:10.3f} "
                          f"{e12[0]:8.2f}{e12[1]:8.2f}")
                if f["status"] != "ok":
                    print(f"{'':13s} {f.get('failure', '')[:120]}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--methods", nargs="+", default=["fe", "tikhonov", "georeg"])
    parser.add_argument("--frames", nargs="+", default=list(FRAMES))
    parser.add_argument("--no-uncertainty", action="store_true",
                        help="frames without their displacement uncertainty (its cost)")
    parser.add_argument("--peers", action="store_true",
                        help="pyvale and ours with the DICe calibration, instead of the table")
    args = parser.parse_args(argv)
    if not (args.data / "stereo_dic_sample3" / "images").is_dir():
        raise SystemExit(f"{args.data}: no stereo_dic_sample3/images (the data are not part of "
                         "the project)")
    print(f"# bench_real_series: {platform.node()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    if args.peers:
        peers(args)
        return 0
    dice = dice_medians(args.data)
    with tempfile.TemporaryDirectory() as tmp:
        for method in args.methods:
            run = track(args.data, args.frames, method, Path(tmp),
                        uncertainty=not args.no_uncertainty)
            print(f"\n## {method}: exit {run['code']}, {run['time_s']:.0f} s in all (reference "
                  "shape included)", flush=True)
            chosen = run["summary"].get("displacement", {}).get("levels_chosen")
            if chosen:
                print(f"levels chosen on {Path(chosen['frame']).name}: {chosen['levels']} (dofs "
                      f"{chosen['dofs']}; agreement with the finer levels "
                      f"{', '.join(f'{a:.3g}' for a in chosen['agreement'])} std)")
            print(f"{'frame':13s} {'status':7s} {'residual/noise %':>17s} {'valid':>6s} "
                  f"{'median U x, y, z (um)':>24s} {'e1, e2 (%)':>14s} {'time (s)':>8s} "
                  f"{'DICe z (um)':>11s} {'median uncertainty x, y, z (um)':>32s}")
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
                      f"{f['time_s']:8.1f} {gold:>11s} {_spread(f)}")
                if f["status"] != "ok":
                    print(f"{'':13s} {f.get('failure', '')[:110]}")
    return 0


def _spread(frame: dict) -> str:
    """The median uncertainty of each component over the valid nodes (um), or ''."""
    u = frame.get("displacement_uncertainty_mm")
    return "" if not u else " ".join(f"{1e3 * v:8.2f}" for v in u["median"])


if __name__ == "__main__":
    raise SystemExit(main())
