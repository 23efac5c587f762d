"""pyxel-dic with and without the geometric-regularization plugin, on real images.

The open-hole composite pair and the Abaqus Q4 mesh of pyxel's example 1 (see
data/pyxel_composite/README.md). The mesh is a "legacy" mesh, not made from any
spline: the plugin locates its nodes on a flat B-spline rectangle covering the mesh by
point inversion, builds ``C_s`` at each level (Eq. 28), and the adapter hands
``B = C_s^T`` to pyxel's ``Correlate(..., Basis=B)``; pyxel itself is not modified.

- pyxel alone: ``MultiscaleInit`` (scales 3, 2, 1, pyxel's automatic Tikhonov length)
  then an unregularized ``Correlate`` on the full images, as pyxel's example does;
- pyxel + plugin: one ``Correlate`` per spline level, coarse to fine, each on its own
  image scale (the coarsest spline on the coarsest images, Fig. 5), no Tikhonov term.

Both use pyxel's pixel integration rule at every scale. Printed: the residual std (gray
levels) of every level at its own scale and at full scale, next to pyxel alone's final
field at the same scale; both fields; their difference; the wall times. With ``--out``
the figures and fields are written there, all or nothing: ``summary.json``,
``fields.csv`` and ``fields.vtu`` (nodal displacements in px, mesh in mm),
``displacement.png`` and ``residual.png``.

Needs the optional extra: ``python -m pip install -e ".[pyxel]"``. Run::

    python examples/pyxel_composite.py [--out pyxel_composite_out]
        [--levels 4 --scales 3,2,1,0 --elements 3,1]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import logging
import pathlib
import sys
import time

import numpy as np

from adapters import pyxel as pyxel_adapter

DATA = pathlib.Path(__file__).resolve().parents[1] / "data" / "pyxel_composite"
CAMERA_P = [-1.573863, 0.081188, 0.096383, 0.000095]  # pyxel's example 1 (rz, tx, ty, tz)


def load_case(data: pathlib.Path):
    """(f, g, mesh, camera) of pyxel's example 1."""
    pyxel = pyxel_adapter.import_pyxel()
    paths = [data / "zoom-0053_1.tif", data / "zoom-0070_1.tif", data / "abaqus_q4_m.inp"]
    for path in paths:
        if not path.is_file():
            raise FileNotFoundError(f"missing data file {path}")
    f = pyxel.Image(str(paths[0])).Load()
    g = pyxel.Image(str(paths[1])).Load()
    with contextlib.redirect_stdout(io.StringIO()):  # pyxel prints
        m = pyxel.ReadMesh(str(paths[2]))
        m.Connectivity()
    cam = pyxel.Camera(2)
    cam.set_p(CAMERA_P)
    return f, g, m, cam


def used_nodes(m) -> np.ndarray:
    """Indices of the nodes that carry displacement dofs."""
    return np.flatnonzero(np.asarray(m.conn)[:, 0] >= 0)


def displacement_px(m, cam, U: np.ndarray) -> np.ndarray:
    """Nodal displacements (n_used, 2) in pixels (pyxel's 2-D camera: tz = m / px)."""
    return m.DOF2Nodes(U)[used_nodes(m)] / cam.Get_pix2m()


def describe(name: str, u: np.ndarray) -> str:
    return (f"{name:>16s}: mean ({u[:, 0].mean():7.3f}, {u[:, 1].mean():7.3f}) px, "
            f"std ({u[:, 0].std():6.3f}, {u[:, 1].std():6.3f}) px, "
            f"range x [{u[:, 0].min():.2f}, {u[:, 0].max():.2f}], "
            f"y [{u[:, 1].min():.2f}, {u[:, 1].max():.2f}] px")


def difference_stats(u_a: np.ndarray, u_b: np.ndarray) -> dict:
    """Quantiles of ``|u_a - u_b|`` (px) and the RMS difference per component."""
    gap = np.linalg.norm(u_a - u_b, axis=1)
    q50, q90, q99 = np.quantile(gap, [0.5, 0.9, 0.99])
    rms = np.sqrt(np.mean((u_a - u_b) ** 2, axis=0))
    return {"median_px": float(q50), "q90_px": float(q90), "q99_px": float(q99),
            "max_px": float(gap.max()), "rms_x_px": float(rms[0]), "rms_y_px": float(rms[1])}


def _triangles(m) -> np.ndarray:
    """The Q4 (and T3) elements of ``m`` as triangles, for matplotlib."""
    tris = []
    for conn in m.e.values():
        conn = np.asarray(conn)
        if conn.shape[1] >= 4:  # quads: the corners are the first four nodes
            tris += [conn[:, [0, 1, 2]], conn[:, [0, 2, 3]]]
        else:
            tris.append(conn[:, :3])
    return np.concatenate(tris)


def displacement_figure(m, u_fe: np.ndarray, u_s: np.ndarray):
    """Maps of u_x, u_y (px) without and with the plugin, and their difference."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri

    used = used_nodes(m)
    full = np.full((len(m.n), 2, 2), np.nan)
    full[used, :, 0], full[used, :, 1] = u_fe, u_s
    xy = np.asarray(m.n)[:, :2] * 1e3  # mm
    tri = _triangles(m)
    tri = tri[np.all(np.isin(tri, used), axis=1)]
    mesh = mtri.Triangulation(xy[:, 0], xy[:, 1], tri)
    fig, axes = plt.subplots(2, 3, figsize=(15, 5.2), constrained_layout=True)
    for c, name in enumerate(("u_x", "u_y")):
        lo, hi = np.nanquantile(full[:, c, :], [0.005, 0.995])
        for k, title in enumerate(("pyxel alone", "pyxel + plugin")):
            pc = axes[c, k].tripcolor(mesh, full[:, c, k], shading="gouraud", vmin=lo, vmax=hi)
            axes[c, k].set_title(f"{name} (px), {title}")
            fig.colorbar(pc, ax=axes[c, k])
        diff = full[:, c, 1] - full[:, c, 0]
        bound = max(float(np.nanquantile(np.abs(diff), 0.99)), 1e-3)
        pc = axes[c, 2].tripcolor(mesh, diff, shading="gouraud", cmap="RdBu_r",
                                  vmin=-bound, vmax=bound)
        axes[c, 2].set_title(f"{name}: plugin - alone (px, 99% range)")
        fig.colorbar(pc, ax=axes[c, 2])
    for ax in axes.ravel():
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
    return fig


def residual_figure(host, U_fe: np.ndarray, U_s: np.ndarray):
    """Gray-level residual at the integration points of the full images, both fields."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f, g, m, cam, dic, H = host._scale(0)
    with contextlib.redirect_stdout(io.StringIO()):
        res = [dic.ComputeRES(g, m, cam, U) for U in (U_fe, U_s)]
    bound = 3.0 * max(float(np.std(r)) for r in res)
    fig, axes = plt.subplots(1, 2, figsize=(14, 3.4), constrained_layout=True)
    for ax, r, title in zip(axes, res, ("pyxel alone", "pyxel + plugin")):
        sc = ax.scatter(np.asarray(m.pgx) * 1e3, np.asarray(m.pgy) * 1e3, c=r, s=0.2,
                        cmap="RdBu_r", vmin=-bound, vmax=bound, rasterized=True)
        ax.set_title(f"residual (gray levels), {title}: std {np.std(r):.3f}")
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        fig.colorbar(sc, ax=ax)
    return fig


def write_outputs(out: pathlib.Path, m, cam, summary: dict, u_fe: np.ndarray,
                  u_s: np.ndarray, host, U_fe: np.ndarray, U_s: np.ndarray) -> list:
    """Write the summary, fields and figures to ``out``, all or nothing."""
    import matplotlib.pyplot as plt
    import meshio

    from georeg_app.shape.outputs import OutputWriter

    used = used_nodes(m)
    xy_mm = np.asarray(m.n)[:, :2] * 1e3
    rows = np.column_stack([used, xy_mm[used], u_fe, u_s, u_s - u_fe])
    header = ("node,x_mm,y_mm,ux_alone_px,uy_alone_px,ux_plugin_px,uy_plugin_px,"
              "dux_px,duy_px")
    buffer = io.StringIO()
    np.savetxt(buffer, rows, delimiter=",", header=header, comments="",
               fmt=["%d"] + ["%.6f"] * 8)
    full = {name: np.full((len(m.n), 2), np.nan)
            for name in ("u_alone_px", "u_plugin_px", "difference_px")}
    full["u_alone_px"][used], full["u_plugin_px"][used] = u_fe, u_s
    full["difference_px"][used] = u_s - u_fe
    cells = [(meshio_type, np.asarray(conn))
             for meshio_type, conn in ((_MESHIO.get(et), c) for et, c in m.e.items())
             if meshio_type is not None]
    points = np.c_[xy_mm, np.zeros(len(xy_mm))]
    with OutputWriter(out) as writer:
        writer.write_json("summary.json", summary)
        writer.write_text("fields.csv", buffer.getvalue())
        meshio.write(writer.path("fields.vtu"),
                     meshio.Mesh(points, cells, point_data=full))
        for name, fig in (("displacement.png", displacement_figure(m, u_fe, u_s)),
                          ("residual.png", residual_figure(host, U_fe, U_s))):
            fig.savefig(writer.path(name), dpi=110)
            plt.close(fig)
    return writer.published


_MESHIO = {2: "triangle", 3: "quad", 9: "triangle6", 10: "quad9", 16: "quad8"}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=pathlib.Path, default=DATA)
    parser.add_argument("--out", type=pathlib.Path, default=None,
                        help="folder for summary.json, fields.csv/.vtu and the figures")
    parser.add_argument("--levels", type=int, default=4, help="spline levels")
    parser.add_argument("--scales", default="3,2,1,0",
                        help="image scale of each level, coarse to fine")
    parser.add_argument("--elements", default="3,1",
                        help="knot spans (u, v) of the coarsest spline (the mesh is 90 x 30 mm)")
    parser.add_argument("--degree", type=int, default=2)
    parser.add_argument("--integration", choices=pyxel_adapter.INTEGRATION_RULES,
                        default="pixel", help="pyxel integration rule of each scale")
    parser.add_argument("-v", "--verbose", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        scales = tuple(int(s) for s in args.scales.split(","))
        elements = tuple(int(s) for s in args.elements.split(","))
    except ValueError:
        parser.error(f"--scales and --elements take integers separated by commas, got "
                     f"{args.scales!r}, {args.elements!r}")
    if len(scales) != args.levels or len(elements) != 2:
        parser.error(f"--scales needs one scale per level ({args.levels}), "
                     f"--elements two numbers; got {args.scales!r}, {args.elements!r}")

    f, g, m, cam = load_case(args.data)
    n_elements = sum(len(e) for e in m.e.values())
    print(f"mesh: {len(m.n)} nodes, {n_elements} elements, {m.ndof} dofs; "
          f"images {f.pix.shape[1]} x {f.pix.shape[0]} px")

    t0 = time.perf_counter()
    U_fe, _ = pyxel_adapter.correlate_fe(f, g, m, cam, init_scales=(3, 2, 1),
                                         integration=args.integration)
    t_fe = time.perf_counter() - t0

    t0 = time.perf_counter()
    patch = pyxel_adapter.spline_for_mesh(m, degree=args.degree, elements=elements)
    U_s, _, history = pyxel_adapter.correlate_multilevel(
        f, g, m, cam, patch, args.levels, scales=scales, integration=args.integration)
    t_s = time.perf_counter() - t0

    # every residual with the same integration rule as the run at that scale
    host = pyxel_adapter.PyxelAdapter(f, g, m, cam, integration=args.integration)
    std_fe, std_s = host.residual_std(U_fe), host.residual_std(U_s)
    levels = []
    print("\nresidual std (gray levels), spline levels coarse to fine; 'alone' is pyxel "
          "alone's final field at the same scale:")
    print(f"  {'level':>5s} {'scale':>5s} {'dofs':>6s} {'iter':>4s} {'at scale':>9s} "
          f"{'alone':>7s} {'full scale':>10s}")
    for h in history:
        alone = host.residual_std(U_fe, h.image_scale)
        full = host.residual_std(h.U, 0)
        levels.append({"level": h.level, "image_scale": h.image_scale, "n_basis": h.n_basis,
                       "iterations": h.n_iterations, "residual_std": h.residual_std,
                       "residual_std_alone_same_scale": alone,
                       "residual_std_full_scale": full})
        print(f"  {h.level:5d} {h.image_scale:5d} {h.n_basis:6d} {h.n_iterations:4d} "
              f"{h.residual_std:9.3f} {alone:7.3f} {full:10.3f}")
    print(f"\nfull images: pyxel alone {std_fe:.3f} gray levels ({m.ndof} dofs, "
          f"{t_fe:.1f} s); with the plugin {std_s:.3f} gray levels "
          f"({history[-1].n_basis} spline dofs, {t_s:.1f} s)")
    u_fe, u_s = displacement_px(m, cam, U_fe), displacement_px(m, cam, U_s)
    print(describe("pyxel alone", u_fe))
    print(describe("pyxel + plugin", u_s))
    diff = difference_stats(u_s, u_fe)
    print(f"{'|difference|':>16s}: median {diff['median_px']:.3f} px, 90% "
          f"{diff['q90_px']:.3f} px, 99% {diff['q99_px']:.3f} px, max {diff['max_px']:.3f} px; "
          f"rms ({diff['rms_x_px']:.3f}, {diff['rms_y_px']:.3f}) px")

    summary = {"mesh": {"nodes": len(m.n), "elements": n_elements, "dofs": int(m.ndof)},
               "settings": {"levels": args.levels, "scales": list(scales),
                            "elements": list(elements), "degree": args.degree,
                            "integration": args.integration},
               "alone": {"residual_std": std_fe, "time_s": t_fe, "dofs": int(m.ndof)},
               "plugin": {"residual_std": std_s, "time_s": t_s,
                          "dofs": history[-1].n_basis, "levels": levels},
               "difference": diff}
    if args.out is not None:
        published = write_outputs(args.out, m, cam, summary, u_fe, u_s, host, U_fe, U_s)
        print(f"\nwrote {', '.join(p.name for p in published)} to {args.out}")
    return summary


if __name__ == "__main__":
    try:
        main()
    except (OSError, ValueError) as err:                # e.g. a missing data file: one line
        sys.exit(f"pyxel_composite.py: error: {err}")
