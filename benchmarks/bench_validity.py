"""Benchmark: the local validity of a displacement's nodes (issue 27, item 2).

The scene of ``tests/fesdic_core/displacement/test_displacement.py`` (a 60 x 40 mm plate,
two cameras at 25 deg, 320 x 240 px over 72 mm, 4 px speckle, 2 gray levels of noise in
every image, independent seeds), the reference surface its central 44 x 30 mm. Pairs:

- ``twist``: the flat plate, then the same paint on the plate twisted by 1 mm at its corners
  and wavy (0.2 mm): u = (0, 0, k x y + 0.2 cos(pi x / 60) cos(pi y / 40)), up to 0.63 mm at
  the mesh's nodes, rendered independently (the deformed pair is a render of the twisted
  specimen, not a warp of the reference);
- ``rigid``, ``stretch``, ``bending``: the displacement tests' motions; the rigid one also on
  a mesh 68 mm long, whose ends lie 4 mm beyond the plate's, over the uniform background
  (its nodes there count as bad: nothing can be measured there).

Methods: plain FE on meshes from coarse (4 x 3 Q4, 11 mm elements) to fine (44 x 30 Q4, 1 mm
= 4.4 px elements: plain FE diverges locally there), FE and the spline levels (``georeg``, 2
levels) and Tikhonov (10 mm) on 24 x 16 Q9 (about the fine mesh's nodes). Printed per case: the
verdict, the share of invalid nodes, the nodes more than 10 times the median error and more
than 20 um off ("bad") and how many of them are valid, the error of the invalid and valid
nodes, and per check the worst value of the good nodes (error under 3 times the median) and
the bad nodes' range: the margins from which :mod:`fesdic_core.residual.validity`'s
thresholds are chosen.

Run: ``python benchmarks/bench_validity.py`` (about a minute).
"""
from __future__ import annotations

import time

import numpy as np

CASES_FE = (("FE 4x3 Q4", 4, 3, "Q4"), ("FE 11x8 Q4", 11, 8, "Q4"), ("FE 22x15 Q4", 22, 15, "Q4"),
            ("FE 44x30 Q4", 44, 30, "Q4"), ("FE 24x16 Q9", 24, 16, "Q9"))


def scene():
    from fesdic_core.imaging.image import Image
    from fesdic_core.synthetic.motion import BendingMotion, HeightMotion, RigidMotion, StretchMotion
    from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
    from fesdic_core.synthetic.specimen import flat_plate, twisted_plate
    cameras = demo_cameras(image_size=(320, 240), field_mm=72.0)
    speckle = speckle_mm_for(cameras[0], 4.0)
    plate = flat_plate(60.0, 40.0, speckle_mm=speckle, seed=3)
    twisted = twisted_plate(60.0, 40.0, corner_mm=1.0, waviness_mm=0.2, speckle_mm=speckle, seed=3)

    def images(arrays, tag):
        return tuple(Image.from_array(a, source=f"{tag} cam{k}") for k, a in enumerate(arrays))

    render = dict(supersample=3, noise_std=2.0, progress=False)
    pairs = {"reference": (images(render_stereo(plate, cameras, seed=1, **render), "reference"),
                           None),
             "twist": (images(render_stereo(twisted, cameras, seed=2, **render), "twist"),
                       HeightMotion(twisted.height))}
    for seed, (name, motion) in enumerate((("rigid", RigidMotion((0.3, -0.2, 0.1),
                                                                  rvec=(0.0, 0.003, 0.002))),
                                           ("stretch", StretchMotion(0.005)),
                                           ("bending", BendingMotion(0.5, 60.0))), start=3):
        pairs[name] = (images(render_stereo(plate, cameras, seed=seed, motion=motion, **render),
                              name), motion)
    return cameras, pairs


def _method(label: str, nx: int, ny: int, family: str):
    from adapters.fesdic_core import nominal_model
    from fesdic_core.fe.mesh import rectangle_mesh
    from georeg_app.series.reference import displacement_solver
    from georeg_plugin.spline.geometries import rectangle
    if label.startswith("FE"):
        length = 68.0 if "edge" in label else 44.0       # 4 mm beyond the plate's ends
        return rectangle_mesh(length, 30.0, nx, ny, family=family), None
    model = nominal_model(rectangle(44.0, 30.0), (nx, ny), family)
    method = "georeg" if label.startswith("georeg") else "tikhonov"
    return model.mesh, displacement_solver(method, model.mesh, model, 10.0, 2)


def run(label, nx, ny, family, cameras, pairs, case):
    from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                                 measure_displacement)
    mesh, solver = _method(label, nx, ny, family)
    reference = displacement_reference(mesh, pairs["reference"][0], cameras,
                                       DisplacementSettings(scales=(2, 1, 0)))
    images, motion = pairs[case]
    t = time.perf_counter()
    m = measure_displacement(reference, images, solver)
    elapsed = time.perf_counter() - t
    error = np.linalg.norm(m.U - motion(mesh.nodes), axis=1)
    median = np.median(error)
    bad = (error > 10 * median) & (error > 0.02)
    if "edge" in label:                   # the nodes beyond the plate: nothing to measure there
        bad |= np.abs(mesh.nodes[:, 0]) > 30.0
    good = error < 3 * median
    v = m.validity
    invalid = ~v.valid
    verdict = "ok" if m.ok else "FAILED" + (" (local)" if "locally" in m.failure else "")
    err = lambda sel: (f"{1e3 * np.median(error[sel]):.0f} / {1e3 * error[sel].max():.0f}"
                       if sel.any() else "-")
    print(f"| {case} | {label} | {mesh.n_nodes} | {verdict} | {100 * invalid.mean():.1f} | "
          f"{bad.sum()} | {(bad & v.valid).sum()} | {1e3 * median:.1f} | {err(invalid)} | "
          f"{err(v.valid)} | {elapsed:.1f} |")
    relative = v.residual_to_noise / np.nanmedian(v.residual_to_noise)
    checks = {"residual/median": (relative, max), "texture": (v.texture_ratio, min),
              "conditioning": (v.conditioning, min), "neighbours": (v.neighbour_ratio, max)}
    return {name: (worst(values[good]), np.sort(values[bad]).round(2) if bad.any() else None)
            for name, (values, worst) in checks.items()}


def main() -> None:
    t = time.perf_counter()
    cameras, pairs = scene()
    print(f"rendered {len(pairs)} pairs in {time.perf_counter() - t:.0f} s\n")
    print("| pair | method | nodes | verdict | invalid (%) | bad | bad and valid | median error "
          "(um) | error of invalid nodes, median / max (um) | of valid nodes (um) | time (s) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    margins = []
    runs = [(case, *method) for case in ("twist",) for method in CASES_FE]
    runs += [("twist", "georeg 24x16 Q9", 24, 16, "Q9"), ("twist", "Tikhonov 24x16 Q9", 24, 16, "Q9")]
    runs += [(case, *method) for case in ("rigid", "stretch", "bending")
             for method in (CASES_FE[0], CASES_FE[2], ("georeg 24x16 Q9", 24, 16, "Q9"))]
    runs += [("rigid", "FE 17x6 Q4 over the edge", 17, 6, "Q4")]
    for case, label, nx, ny, family in runs:
        margins.append((case, label, run(label, nx, ny, family, cameras, pairs, case)))
    print("\nper check: the worst value of the good nodes (error < 3 x median); the bad nodes'")
    for case, label, checks in margins:
        print(f"{case:8s} {label:18s} " + "; ".join(
            f"{name} {good:.3g}" + ("" if bad is None else f" (bad {bad.min():.3g}-{bad.max():.3g})")
            for name, (good, bad) in checks.items()))


if __name__ == "__main__":
    main()
