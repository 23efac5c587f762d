"""Stereo calibration against a known rig, rendered by two independent renderers (issue 24).

The rig and the eight poses of a 9 x 12 dot target of ``tests/target_views.py`` (640 x 480
px, 8 mm pitch, 3.2 mm dots, three ring markers, tilts up to 23 degrees, one view cut by the
border, 0.7 px blur and 2 gray levels of noise), without lens distortion here because riley's
camera has none:

- ``core``: the project's renderer (3 x 3 rays per pixel, the paint evaluated exactly);
- ``riley``: riley-raster (PyPI; the camera conversion of ``bench_levels.py``), the paint
  rasterised on 0.1 mm texels (4 x 4 samples each) and sampled by riley's bilinear shader,
  4 x 4 sub-pixels.

For each, :func:`fesdic_core.cameras.targets.calibration.calibrate_stereo` (distortion
``k1k2``): the reprojection RMS, and each parameter's error against the truth in units of
its predicted standard deviation (the claim: within 3). Then a speckled twisted plate is
rendered by the core's renderer with the true rig and measured by ``georeg measure``
(``kind = "roi"``, georeg, automatic levels) once with the recovered cameras and once with
the true ones: the RMS shape error against the truth with each and the median predicted
``shape_std_mm`` (each run places the specimen in its own frame, from its own cameras: the
errors against the truth are compared, not the nodes).

Run (riley-raster in a separate environment, never a dependency)::

    PYTHONPATH=. VENV/bin/python benchmarks/bench_calibration.py [--renderer core|riley|both]
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

import cv2
import meshio
import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parent),
                str(Path(__file__).resolve().parents[1] / "tests")]
import target_views  # noqa: E402
from bench_levels import _riley_camera, riley_surface  # noqa: E402
from fesdic_core.cameras.rig import read_cameras_json, stereo_transform, write_cameras_json  # noqa: E402
from fesdic_core.cameras.targets import detect  # noqa: E402
from fesdic_core.cameras.targets.calibration import CalibrationModel, calibrate_stereo  # noqa: E402
from fesdic_core.synthetic.accuracy import shape_error_to_surface  # noqa: E402
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for  # noqa: E402
from fesdic_core.synthetic.specimen import twisted_plate  # noqa: E402
from fesdic_core.synthetic.target import posed_rig, target_specimen  # noqa: E402
from georeg_app import cli  # noqa: E402

TEXEL_MM, TEXEL_SAMPLES = 0.1, 4


def rig():
    return demo_cameras(image_size=(640, 480), field_mm=130.0)


def _finish(images, seed: int):
    rng = np.random.default_rng(seed)
    return tuple(np.clip(np.rint(cv2.GaussianBlur(np.asarray(im, np.float32), (0, 0), 0.7)
                                 + rng.normal(0.0, 2.0, np.shape(im))), 0, 255).astype(np.uint8)
                 for im in images)


def riley_views(specimen, cameras, poses):
    import riley
    coords, connect, _ = riley_surface(specimen, element_mm=4.0)
    x0, y0 = coords[:, 0].min(), coords[:, 1].min()
    nx = int(np.ceil((coords[:, 0].max() - x0) / TEXEL_MM)) + 1
    ny = int(np.ceil((coords[:, 1].max() - y0) / TEXEL_MM)) + 1
    s = (np.arange(TEXEL_SAMPLES) + 0.5) / TEXEL_SAMPLES - 0.5
    gx = x0 + (np.arange(nx)[:, None] + s[None]).ravel() * TEXEL_MM
    gy = y0 + (np.arange(ny)[:, None] + s[None]).ravel() * TEXEL_MM
    X, Y = np.meshgrid(gx, gy)
    values = specimen.texture(X, Y).reshape(ny, TEXEL_SAMPLES, nx, TEXEL_SAMPLES).mean(axis=(1, 3))
    uvs = np.column_stack([(coords[:, 0] - x0) / (TEXEL_MM * (nx - 1)),
                           (coords[:, 1] - y0) / (TEXEL_MM * (ny - 1))])
    shader = riley.TextureShader(uvs=uvs, texture=values.astype(np.float64)[None],
                                 sample=riley.TextureSample.linear)
    mesh = riley.create_mesh(convention=riley.ConnectConvention(riley.EElemType.QUAD9,
                                                                riley.EConnectAxis.ROW, 0,
                                                                riley.ENodeOrder.VTK),
                             mesh_type=riley.MeshType.quad9, coords=coords, connect=connect,
                             shader=shader)
    config = riley.RasterConfig(parallel=os.cpu_count() or 1,
                                save_strategy=riley.SaveStrategy.memory, report=0)
    config.background_value = 10.0
    views = []
    for v, (rvec, tvec) in enumerate(poses):
        cams = posed_rig(cameras, rvec, tvec)
        out = riley.raster([mesh], [_riley_camera(riley, c, 4) for c in cams], config)
        views.append(_finish([np.squeeze(out[k]) for k in range(2)], 100 + v))
    return views


def core_views(specimen, cameras, poses):
    return [_finish(render_stereo(specimen, posed_rig(cameras, rvec, tvec), supersample=3,
                                  noise_std=0.0, bit_depth=None, progress=False), 100 + v)
            for v, (rvec, tvec) in enumerate(poses)]


def calibration_errors(views, truth):
    target = target_views.DOTS
    d0 = [detect(a, target, f"v{v}c0") for v, (a, _) in enumerate(views)]
    d1 = [detect(b, target, f"v{v}c1") for v, (_, b) in enumerate(views)]
    cal = calibrate_stereo(d0, d1, target, CalibrationModel("k1k2"))
    rows = []
    for c, (est, true) in enumerate(zip(cal.cameras, truth)):
        for name, e, t in (("fx", est.K[0, 0], true.K[0, 0]), ("fy", est.K[1, 1], true.K[1, 1]),
                           ("cx", est.K[0, 2], true.K[0, 2]), ("cy", est.K[1, 2], true.K[1, 2]),
                           ("k1", est.dist[0], true.dist[0]), ("k2", est.dist[1], true.dist[1])):
            rows.append((f"cam{c}.{name}", e - t, cal.std[f"cam{c}.{name}"]))
    (R, T), (Rm, Tm) = stereo_transform(*truth), stereo_transform(*cal.cameras)
    dr = cv2.Rodrigues(Rm)[0].ravel() - cv2.Rodrigues(R)[0].ravel()
    rows += [(f"rvec[{i}]", dr[i], cal.std["rvec"][i]) for i in range(3)]
    rows += [(f"T[{i}]", Tm.ravel()[i] - T.ravel()[i], cal.std["T"][i]) for i in range(3)]
    rows.append(("baseline_mm", cal.baseline_mm - float(np.linalg.norm(T)), cal.std["baseline_mm"]))
    return cal, rows, [d.n_points for d in d0 + d1]


PLATE_CONFIG = """[images]
cam0 = "cam0.png"
cam1 = "cam1.png"
[cameras]
file = "{cameras}"
[geometry]
kind = "roi"
surface = "quadric"
polygon_px = {polygon}
elements = 150
"""


def shape_with(cameras_file: Path, folder: Path, polygon, specimen, true_cam0) -> dict:
    config = folder / f"{cameras_file.stem}.toml"
    config.write_text(PLATE_CONFIG.format(cameras=cameras_file.name, polygon=json.dumps(polygon)))
    out = folder / f"{cameras_file.stem}_out"
    if cli.main(["-q", "measure", str(config), "--out", str(out), "--overwrite"]) != 0:
        return dict(status="failed")
    (m,) = json.loads((out / "summary.json").read_text())["methods"]
    stem = m["mesh_file"].removesuffix(".vtu")
    vtu = meshio.read(out / m["mesh_file"])
    cam = read_cameras_json(out / f"{stem}_cameras.json")[0]
    X = (vtu.points @ cam.R.T + cam.tvec - true_cam0.tvec) @ true_cam0.R
    error = shape_error_to_surface(X, specimen) * 1e3
    return dict(status="ok", X=X, rms_um=float(np.sqrt(np.mean(error ** 2))),
                std_um=float(np.median(vtu.point_data["shape_std_mm"])) * 1e3)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--renderer", choices=("core", "riley", "both"), default="both")
    args = parser.parse_args(argv)
    print(f"# bench_calibration: {platform.node()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.2f}, {platform.python_version()}", flush=True)
    truth, poses = rig(), target_views.poses()
    specimen = target_specimen(target_views.DOTS)
    renderers = ("core", "riley") if args.renderer == "both" else (args.renderer,)
    recovered = {}
    for name in renderers:
        t0 = time.perf_counter()
        views = (core_views if name == "core" else riley_views)(specimen, truth, poses)
        render_s = time.perf_counter() - t0
        cal, rows, found = calibration_errors(views, truth)
        recovered[name] = cal.cameras
        worst = max(abs(e / s) for _, e, s in rows)
        print(f"\n## {name} renderer ({render_s:.0f} s): {sum(v.status == 'used' for v in cal.views)}"
              f" of {len(cal.views)} views, points found per image {min(found)}-{max(found)}, "
              f"reprojection RMS {cal.rms_px:.4f} px, largest error {worst:.2f} std", flush=True)
        print(f"{'parameter':12s} {'error':>12s} {'std':>10s} {'error/std':>10s}")
        for label, e, s in rows:
            print(f"{label:12s} {e:12.4g} {s:10.3g} {e / s:10.2f}")
    plate = twisted_plate(60.0, 40.0, corner_mm=0.5, speckle_mm=speckle_mm_for(truth[0], 4.0),
                          seed=3)
    images = render_stereo(plate, truth, supersample=3, noise_std=2.0, seed=1, progress=False)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for k, im in enumerate(images):
            cv2.imwrite(str(folder / f"cam{k}.png"), im.astype(np.uint8))
        xy = np.array([[-27, -18], [27, -18], [27, 18], [-27, 18]], float)
        polygon = np.round(truth[0].project(np.column_stack([xy, plate.height(xy[:, 0], xy[:, 1])])),
                           2).tolist()
        write_cameras_json(folder / "true.json", truth)
        runs = {"true": shape_with(folder / "true.json", folder, polygon, plate, truth[0])}
        for name, cams in recovered.items():
            # our calibration's world is camera 0's frame: put camera 0 where the truth's is
            moved = [c.with_extrinsics(np.concatenate(cv2.composeRT(
                truth[0].rvec.reshape(3, 1), truth[0].tvec.reshape(3, 1),
                c.rvec.reshape(3, 1), c.tvec.reshape(3, 1))[:2]).ravel()) for c in cams]
            write_cameras_json(folder / f"{name}.json", moved)
            runs[name] = shape_with(folder / f"{name}.json", folder, polygon, plate, truth[0])
    print("\n## a twisted plate measured with each calibration (georeg auto, kind = roi)")
    print(f"{'cameras':10s} {'RMS error (um)':>15s} {'median std (um)':>16s} "
          f"{'error minus the true rig's (um)':>32s}")
    for name, r in runs.items():
        if r["status"] != "ok":
            print(f"{name:10s} {'failed':>15s}")
            continue
        ref = runs["true"]
        # each run's specimen frame is its own (the ROI's fit): compare errors, not nodes
        diff = f"{r['rms_um'] - ref['rms_um']:+32.2f}" if name != "true" and ref["status"] == "ok" else ""
        print(f"{name:10s} {r['rms_um']:15.2f} {r['std_um']:16.2f} {diff}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
