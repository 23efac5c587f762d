"""Tutorial: the operator projection of geometric regularization, on the smallest example.

Colantonio et al. (IJNME 2020, sections 2-3) regularize FE stereo-DIC shape measurement
without touching the FE-DIC code. The FE code assembles, at each Gauss-Newton step, the
system of its nodal shape correction ``q`` (Eq. 8, one scalar per node along the
normal, Remark 1):

    H_FE d = b_FE.

The plugin replaces the solve of this system by the same least-squares problem
restricted to a smooth spline space. All it needs is one sparse matrix ``C``
(n_spline x n_FE) that writes the spline basis functions as FE fields:

    R = C L                       (Eq. 16; spline basis R, FE Lagrange basis L)
    H_s = C H_FE C^T,  b_s = C b_FE          (Eqs. 18-20)
    d = C^T H_s^-1 b_s                       (Eq. 21: the step, back on the FE nodes)

This script walks through it on one flat B-spline patch, one spline level and a Q9 mesh
of 24 elements, with a real ``H_FE, b_FE`` assembled by the core (``fesdic_core``) on a
small rendered stereo pair of a twisted plate. It prints every quantity and checks every
identity it states; it exits with status 1 if one does not hold.

Run:  python examples/tutorial_operator_projection.py [--plot [FILE]]
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from adapters.fesdic_core import multilevel_for_mesh, nominal_model
from fesdic_core.atomic import atomic_path
from fesdic_core.fe.mesh import node_normals
from fesdic_core.fe.quadrature import pixel_quadrature
from fesdic_core.imaging.image import Image
from fesdic_core.residual.graylevel import gray_level_residual
from fesdic_core.shape.operators import shape_gauss_newton, shape_operators
from fesdic_core.solve.solvers import DirectSolver
from fesdic_core.synthetic.render import (demo_cameras, render_stereo, speckle_mm_for,
                                          true_normal_offset)
from fesdic_core.synthetic.specimen import twisted_plate
from georeg_plugin.levels.operators import extraction_operator
from georeg_plugin.levels.solver import GeometricRegularization
from georeg_plugin.spline.geometries import rectangle
from georeg_plugin.spline.refine import refine_to_elements, refine_uniform

LENGTH_MM, WIDTH_MM = 60.0, 40.0      # the plate, centred at the origin, nominal z = 0
FE_ELEMENTS = (6, 4)                  # Q9 elements along x and y
CORNER_MM = 1.0                       # twist z = k x y of the real plate at its corners
IMAGE_SIZE = (320, 240)               # px, two cameras 25 degrees apart


class Checks:
    """Identities stated by the tutorial: a value that must stay below (or above) a bound.

    ``values[name] = (value, bound, sense)``, ``sense`` "<=" or ">=".
    """

    def __init__(self) -> None:
        self.values: dict[str, tuple[float, float, str]] = {}

    def __call__(self, name: str, value: float, bound: float, what: str,
                 sense: str = "<=") -> None:
        self.values[name] = (float(value), float(bound), sense)
        status = "ok" if self.holds(name) else "FAILED"
        print(f"    [{status:>6s}] {what}: {value:.3g} ({sense} {bound:g})")

    def holds(self, name: str) -> bool:
        value, bound, sense = self.values[name]
        return value <= bound if sense == "<=" else value >= bound

    @property
    def failed(self) -> list[str]:
        return [name for name in self.values if not self.holds(name)]


def rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def quadratic_model(H: sps.spmatrix, b: np.ndarray, d: np.ndarray) -> float:
    """The Gauss-Newton model ``J(d) = 1/2 d^T H d - b^T d`` minimised by each step."""
    return 0.5 * float(d @ (H @ d)) - float(b @ d)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plot", nargs="?", const="tutorial_operator_projection.png",
                        default=None, metavar="FILE",
                        help="save a figure (mesh and control net, errors of both solutions)")
    args = parser.parse_args(argv)
    t_start = time.perf_counter()
    check = Checks()
    np.set_printoptions(precision=3, suppress=True, linewidth=100)

    # ------------------------------------------------------------------------------
    # 1. One spline level (section 3.1, Eq. 11).
    #    A flat B-spline rectangle, degree 2 in u (along x) and v (along y). One knot
    #    insertion in each direction gives 2 x 2 knot spans and 4 x 4 = 16 control
    #    points: the shape correction of this level is S(xi) = sum_J R_J(xi) q_J, 16
    #    unknowns, C1 across the inner knots.
    # ------------------------------------------------------------------------------
    print("1. The spline level: a flat B-spline patch (Eq. 11)")
    level, _ = refine_uniform(rectangle(LENGTH_MM, WIDTH_MM), 1)
    print(f"   degrees {level.degrees}, knots u {level.knots[0]}, v {level.knots[1]}")
    print(f"   {level.shape[0]} x {level.shape[1]} = {level.n_dofs} control points (spline dofs)")

    # ------------------------------------------------------------------------------
    # 2. The FE mesh made from the spline (Eqs. 13-15 and 17).
    #    Knot insertion refines the spline to one knot span per FE element without
    #    changing the surface: R_level = C_r R_fine (Eq. 13), x_fine = C_r^T x_level
    #    (Eq. 15). One Q9 element per knot span of the fine spline, its nine nodes at the
    #    Lagrange points of the span: x_FE = C_FE^T x_fine (Eq. 17), where C_FE holds the
    #    fine basis at the nodes. The adapter builds the same mesh for the core
    #    (adapters.fesdic_core.nominal_model) and keeps the parameters xi_I of each node.
    # ------------------------------------------------------------------------------
    print("\n2. The FE mesh made from the spline (Eq. 17)")
    fine, C_r = refine_to_elements(level, *FE_ELEMENTS)            # Eq. 13: R = C_r R_fine
    model = nominal_model(level, FE_ELEMENTS, "Q9")
    mesh, uv = model.mesh, model.uv
    conn = mesh.blocks[0].connectivity
    C_FE = extraction_operator(fine, uv)                           # (n_fine, n_FE)
    print(f"   fine spline {fine.shape[0]} x {fine.shape[1]} control points, C_r "
          f"{C_r.shape[0]} x {C_r.shape[1]}; FE mesh {len(conn)} Q9 elements, "
          f"{mesh.n_nodes} nodes")
    x_fine = fine.control_points.reshape(-1, 3)
    check("eq17_nodes", np.abs(C_FE.T @ x_fine - mesh.nodes).max(), 1e-10,
          "Eq. 17, |C_FE^T x_fine - x_FE| (mm)")
    check("eq15_geometry", np.abs(C_r.T @ level.control_points.reshape(-1, 3) - x_fine).max(),
          1e-10, "Eq. 15, |C_r^T x_level - x_fine| (mm)")

    # ------------------------------------------------------------------------------
    # 3. The operator C of the level (Eq. 28) and why row I of C^T is the spline basis
    #    at node I.
    #    Eq. 28 composes the bridges: C = C_r C_FE, so R_level = C L (Eqs. 13, 16).
    #    Evaluate this at FE node I: the Lagrange functions are nodal, L_K(xi_I) =
    #    delta_KI, hence R_J(xi_I) = C[J, I]. Column I of C (row I of C^T) is the level's
    #    basis at the parameters of node I (Remark 6, Eq. 26): the plugin builds C by
    #    evaluating the basis at the nodes, no Bezier extraction needed. Below, the
    #    plugin's C (node evaluation) is compared with the product form of Eq. 28, and
    #    R = C L is checked inside the elements, where L is the core's Q9 shape
    #    functions: every B-spline of the level IS a Q9 field (the spline space is a
    #    subspace of the C0 FE space), so a spline field is represented exactly.
    # ------------------------------------------------------------------------------
    print("\n3. The operator C (Eq. 28): row I of C^T = spline basis at node I")
    space = multilevel_for_mesh(model, 1)                          # one level
    C = space.operators[0]                                         # (n_spline, n_FE)
    print(f"   C is {C.shape[0]} x {C.shape[1]}, {C.nnz} non-zeros "
          f"({100 * C.nnz / np.prod(C.shape):.0f}% dense)")
    node = int(np.argmin(np.linalg.norm(mesh.nodes - [7.0, 4.0, 0.0], axis=1)))
    row = C.T[node].toarray().ravel()
    print(f"   node {node} at {mesh.nodes[node, :2]} mm, xi = {uv[node]}: row of C^T "
          f"(nonzero entries) {row[row != 0]}, sum {row.sum():.15f}")
    check("eq28_product_form", np.abs((C - C_r @ C_FE).toarray()).max(), 1e-12,
          "Eq. 28, |C (node evaluation) - C_r C_FE|")
    rng = np.random.default_rng(0)
    xi = rng.uniform(-1.0, 1.0, (7, 2))                            # 7 points per element
    L = mesh.blocks[0].family.shape_functions(xi)                  # (7, 9) Q9 functions
    uv_points = np.einsum("mk,ekd->emd", L, uv[conn])              # their parameters
    R = level.basis(uv_points.reshape(-1, 2)).toarray().reshape(len(conn), len(xi), -1)
    CL = np.einsum("mk,ekj->emj", L, C.T.toarray()[conn])          # (C L)^T at the points
    check("eq16_inside_elements", np.abs(R - CL).max(), 1e-12,
          "Eq. 16, |R(xi) - C L(xi)| at 7 random points of every element")
    check("partition_of_unity", np.abs(C.T @ np.ones(C.shape[0]) - 1.0).max(), 1e-12,
          "rows of C^T sum to 1 (a uniform offset is a spline field)")

    # ------------------------------------------------------------------------------
    # 4. A real FE system H_FE, b_FE (Eq. 8), assembled by the core.
    #    Two 320 x 240 px cameras see a speckled 60 x 40 mm plate twisted as
    #    z = k x y (1 mm at the corners); 2 gray levels of noise. The nominal mesh is flat
    #    (q = 0). The core's pixel quadrature, gray-level residual (Eq. 3, Remark 2) and
    #    shape operators give the Gauss-Newton system of the first step.
    # ------------------------------------------------------------------------------
    print("\n4. The FE system H_FE d = b_FE of the first Gauss-Newton step (Eq. 8)")
    cameras = demo_cameras(image_size=IMAGE_SIZE, field_mm=72.0)
    specimen = twisted_plate(LENGTH_MM, WIDTH_MM, corner_mm=CORNER_MM,
                             speckle_mm=speckle_mm_for(cameras[0], 4.0), seed=3)
    pictures = render_stereo(specimen, cameras, supersample=2, noise_std=2.0, seed=1,
                             progress=False)
    images = [Image.from_array(a, source=f"rendered cam{k}") for k, a in enumerate(pictures)]
    normals = node_normals(mesh)                                   # +z on the flat plate
    quad = pixel_quadrature(mesh, cameras)
    q0 = np.zeros(mesh.n_nodes)
    res = gray_level_residual(quad.points(mesh.nodes), quad, images, cameras, "element", "point")
    H, b = shape_operators(quad, normals, res)
    q_true = true_normal_offset(specimen, mesh.nodes, normals)     # = k x y at the nodes
    print(f"   {quad.n_points} integration points (~1 per pixel); residual at q = 0: "
          f"{res.std_percent:.2f}% of the dynamic range")
    print(f"   H_FE {H.shape[0]} x {H.shape[1]} ({H.nnz} non-zeros), |b_FE| = "
          f"{np.linalg.norm(b):.3g}; true correction: rms {rms(q_true):.3f} mm")
    check("H_symmetric", abs(H - H.T).max() / abs(H).max(), 1e-12, "H_FE symmetric")

    # ------------------------------------------------------------------------------
    # 5. The reduced system (Eqs. 18-20).
    #    H_s = C H_FE C^T is the Hessian of the same gray-level functional written in
    #    the 16 spline dofs (Eq. 18); b_s = C b_FE its gradient (Eq. 19). Nothing of the
    #    FE code changes: two sparse products.
    # ------------------------------------------------------------------------------
    print("\n5. The reduced system H_s = C H_FE C^T, b_s = C b_FE (Eqs. 18-19)")
    H_s = (C @ H @ C.T).toarray()
    b_s = C @ b
    eig = np.linalg.eigvalsh(H_s)
    print(f"   H_s {H_s.shape[0]} x {H_s.shape[1]}, eigenvalues in [{eig[0]:.3g}, "
          f"{eig[-1]:.3g}]: symmetric positive definite")
    check("H_s_positive", eig[0], 0.0, "smallest eigenvalue of H_s", ">=")

    # ------------------------------------------------------------------------------
    # 6. Solve and map back (Eq. 21): d_s = H_s^-1 b_s, d = C^T d_s.
    #    d is an FE nodal field (what the FE code expects from its solve) that lies in
    #    the range of C^T: a spline field of the level. The reduced residual vanishes,
    #    C (b - H d) = 0 (the FE residual b - H d does not), so d minimises the
    #    Gauss-Newton model J(d) = 1/2 d^T H d - b^T d over all spline fields. The
    #    plugin's solve hook (GeometricRegularization.solve, the StepSolver the core
    #    calls) returns exactly this d.
    # ------------------------------------------------------------------------------
    print("\n6. Solve and map back: d = C^T (C H C^T)^-1 C b (Eq. 21)")
    d_s = np.linalg.solve(H_s, b_s)
    d = C.T @ d_s
    hook = GeometricRegularization(space)
    print(f"   spline dofs d_s (mm along the normal):\n{d_s.reshape(level.shape)}")
    check("hook_equals_by_hand", np.abs(hook.solve(H, b, q0, 0) - d).max(), 1e-12,
          "plugin hook vs by-hand step (mm)")
    q_s_of_d = hook.control_values(d, 0)                           # least squares C^T q_s ~ d
    check("range_of_C_T", np.abs(C.T @ q_s_of_d - d).max() / np.abs(d).max(), 1e-10,
          "d in range(C^T): |C^T q_s - d| / |d|")
    fe_residual = np.linalg.norm(b - H @ d)
    check("reduced_residual", np.linalg.norm(C @ (b - H @ d)) / fe_residual, 1e-10,
          f"|C (b - H d)| / |b - H d| (|b - H d| = {fe_residual:.3g})")
    z = rng.standard_normal((20, C.shape[0])) * np.abs(d_s).max()
    gain = min(quadratic_model(H, b, d + C.T @ zk) - quadratic_model(H, b, d) for zk in z)
    check("minimum_over_splines", gain, 0.0,
          "min over 20 random spline fields z of J(d + C^T z) - J(d)", ">=")

    # ------------------------------------------------------------------------------
    # 7. Compared with the unregularized FE step d_FE = H_FE^-1 b_FE.
    #    d_FE minimises J over all 117 nodal fields, so J(d_FE) <= J(d); and d is the
    #    H-orthogonal projection of d_FE on the spline fields: C H (d_FE - d) = 0.
    #    The extra freedom of d_FE fits the image noise: against the true correction,
    #    the spline step is closer.
    # ------------------------------------------------------------------------------
    print("\n7. Compared with the unregularized FE step d_FE = H_FE^-1 b_FE")
    d_fe = spla.spsolve(sps.csc_matrix(H), b)
    check("fe_step_solves", np.linalg.norm(H @ d_fe - b) / np.linalg.norm(b), 1e-10,
          "|H d_FE - b| / |b|")
    check("h_orthogonal_projection",
          np.linalg.norm(C @ (H @ (d_fe - d))) / np.linalg.norm(H @ (d_fe - d)), 1e-10,
          "|C H (d_FE - d)| / |H (d_FE - d)|")
    J_fe, J_s = quadratic_model(H, b, d_fe), quadratic_model(H, b, d)
    check("fe_model_lower", J_fe - J_s, 0.0, f"J(d_FE) - J(d), with J(d_FE) = {J_fe:.4g}, "
          f"J(d) = {J_s:.4g}")
    err_step_fe, err_step_s = rms(d_fe - q_true), rms(d - q_true)
    print(f"   first step against the true correction (rms {rms(q_true):.3f} mm): "
          f"FE {1e3 * err_step_fe:.1f} um, spline {1e3 * err_step_s:.1f} um")

    # ------------------------------------------------------------------------------
    # 8. The B-spline case is exact.
    #    The true shape z = k x y is itself a spline field of this level: x is affine in
    #    u and y in v, so its control values are k x_J y_J (products of the control
    #    point coordinates). Mapped to the nodes by C^T, they give k x_I y_I exactly: the
    #    spline level loses nothing of this shape, the FE mesh only adds freedom.
    # ------------------------------------------------------------------------------
    print("\n8. A spline field is reproduced exactly at the FE nodes")
    k = CORNER_MM / (0.25 * LENGTH_MM * WIDTH_MM)
    x_level = level.control_points.reshape(-1, 3)
    q_s_true = k * x_level[:, 0] * x_level[:, 1]
    check("spline_field_exact", np.abs(C.T @ q_s_true - q_true).max(), 1e-9,
          "|C^T (k x_J y_J) - k x_I y_I| (mm)")

    # ------------------------------------------------------------------------------
    # 9. The whole Gauss-Newton loop of the core (Eq. 7), each step solved by a hook:
    #    the core's DirectSolver (unregularized FE) or the plugin's
    #    GeometricRegularization. Same images, same quadrature, same code. The FE
    #    solution reaches the lower gray-level residual (117 unknowns also fit the image
    #    noise); the spline solution is the closer one to the true shape.
    # ------------------------------------------------------------------------------
    print("\n9. Gauss-Newton to convergence, both hooks (fesdic_core.shape.operators.shape_gauss_newton)")
    runs = {}
    for name, solver in (("FE (DirectSolver)", DirectSolver()), ("spline (plugin hook)", hook)):
        run = shape_gauss_newton(mesh.nodes, normals, q0, quad, images, cameras, solver, 0)
        runs[name] = run
        print(f"   {name:21s}: {run.iterations} iterations, residual "
              f"{run.residual.std_percent:.3f}%, rms error {1e3 * rms(run.q - q_true):.1f} um, "
              f"max error {1e3 * np.abs(run.q - q_true).max():.1f} um")
    q_fe, q_spline = (r.q for r in runs.values())
    check("gn_spline_in_range", np.abs(C.T @ hook.control_values(q_spline, 0) - q_spline).max(),
          1e-10, "the converged spline shape is in range(C^T) (mm)")
    elapsed = time.perf_counter() - t_start
    print(f"\n{len(check.values) - len(check.failed)} of {len(check.values)} identities hold; "
          f"{elapsed:.1f} s")

    result = {"checks": check.values, "failed": check.failed,
              "n_fe": mesh.n_nodes, "n_spline": C.shape[0], "n_points": quad.n_points,
              "true_rms_mm": rms(q_true),
              "step_error_fe_mm": err_step_fe, "step_error_spline_mm": err_step_s,
              "gn_error_fe_mm": rms(q_fe - q_true), "gn_error_spline_mm": rms(q_spline - q_true),
              "gn_residual_fe_percent": runs["FE (DirectSolver)"].residual.std_percent,
              "gn_residual_spline_percent": runs["spline (plugin hook)"].residual.std_percent,
              "time_s": elapsed}
    if args.plot:
        save_figure(pathlib.Path(args.plot), mesh, level, q_fe - q_true, q_spline - q_true)
        print(f"figure written to {args.plot}")
    return result


def save_figure(path: pathlib.Path, mesh, level, err_fe: np.ndarray, err_spline: np.ndarray
                ) -> None:
    """Mesh and control net; errors (um) of the FE and spline shapes at the nodes."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri

    conn = mesh.blocks[0].connectivity
    xy = mesh.nodes[:, :2]
    fig, axes = plt.subplots(1, 3, figsize=(15, 3.8), constrained_layout=True)
    ax = axes[0]
    for e in conn:  # Q9 element edges through the corner nodes 0-1-2-3
        ring = xy[e[[0, 1, 2, 3, 0]]]
        ax.plot(ring[:, 0], ring[:, 1], color="0.6", lw=0.8)
    ax.plot(xy[:, 0], xy[:, 1], ".", color="0.3", ms=3)
    cp = level.control_points
    ax.plot(cp[..., 0], cp[..., 1], "-", color="C3", lw=0.8)
    ax.plot(cp[..., 0].T, cp[..., 1].T, "-", color="C3", lw=0.8)
    ax.plot(cp[..., 0].ravel(), cp[..., 1].ravel(), "s", color="C3", ms=5)
    ax.set_title(f"{len(xy)} FE nodes (dots), {level.n_dofs} spline dofs (control net)")
    triangles = np.concatenate([conn[:, [0, 1, 2]], conn[:, [0, 2, 3]]])
    tri = mtri.Triangulation(xy[:, 0], xy[:, 1], triangles)
    bound = 1e3 * max(np.abs(err_fe).max(), np.abs(err_spline).max())
    for ax, err, title in ((axes[1], err_fe, "FE (no regularization)"),
                           (axes[2], err_spline, "spline level (plugin)")):
        pc = ax.tripcolor(tri, 1e3 * err, shading="gouraud", cmap="RdBu_r",
                          vmin=-bound, vmax=bound)
        ax.set_title(f"error of q, {title} (um)")
        fig.colorbar(pc, ax=ax)
    for ax in axes:
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)


if __name__ == "__main__":
    sys.exit(1 if main()["failed"] else 0)
