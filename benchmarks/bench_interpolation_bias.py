"""Benchmark: the sub-pixel interpolation bias of the image models (issue 13, "know the bias").

Truth, independent of every interpolant under test: a continuous random-dot speckle
texture ``T(x, y) = background + amplitude (1 - exp(-S))``, ``S = sum_d k exp(-|p - p_d|^2 /
(2 sigma^2))`` (Gaussian dots at Poisson-random centres, 50 % disc coverage, peak ``k = 2``
so overlapping dots saturate like paint), integrated over each pixel by 8 x 8 midpoint
supersampling (pixel-area integration). The speckle size ``d`` is the full width at half
maximum of an isolated dot in gray levels (``sigma = d / 3.18`` for ``k = 2``). The
deformed image is the same texture translated by ``s`` px in x, rendered the same way.

Measurement: a 1-D Gauss-Newton on the sum of squared differences
``sum_i (g(x_i + u, y_i) - f_i)^2`` over the pixel centres of the central region (a
``margin`` px border is left out), with the model's interpolant ``g`` and its x-derivative,
from the best integer shift of an integer search over -2..2 px; stopped when
``|du| < 1e-9`` px. The true answer is ``u = s``; ``u - s`` is the position error.

Image models (each optionally after a Gaussian prefilter ``sigma`` applied to BOTH images):

- ``bspline3``: the core's cubic B-spline, ``Image.from_array(..., prefilter_px=0)
  .evaluate_with_gradient`` (2-D evaluation, exact spline gradient); with a prefilter sigma
  this is the core's image model ``Image.from_array(..., prefilter_px=sigma)``.
- ``bspline5``: quintic B-spline, ``scipy.ndimage.spline_filter(order=5)`` then
  ``map_coordinates(order=5, prefilter=False)``; gradient by central finite differences of
  the spline with ``h = 1e-4`` px (error ~1e-9 gray level / px, far below any bias here).
- ``keys``: cubic convolution (Keys 1981, ``a = -0.5``), analytic derivative.
- ``bilinear``: the bad baseline (piecewise-linear in x, its one-sided slope).

``keys`` and ``bilinear`` are evaluated 1-D along the rows: every evaluation point has an
integer y (the translation is in x), where a separable 2-D interpolant is exactly the 1-D
interpolant of the row.

Noise: Gaussian noise of ``noise`` gray levels on both images, then rounding to 8 bits,
over ``seeds`` seeds (the same realisations for every model). Reported per model and
speckle size: max |bias| and RMS bias over s (noise-free), the RMS over s of the mean error
over seeds (the bias under noise: noise in the interpolated image adds a bias of its own,
proportional to the noise variance, which no averaging over pixels removes), the noise std
(std over seeds, RMS over s) and the total RMS error (over s and seeds, all together).

Run: ``python benchmarks/bench_interpolation_bias.py [--quick] [--plot docs/bias.png]``
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import ndimage, sparse

from fesdic_core.imaging.image import COMPILED_KERNEL, Image

BACKGROUND = 10.0            # gray level of the paint between the dots
AMPLITUDE = 230.0            # saturated dot: background + amplitude = 240
DOT_PEAK = 2.0               # k: S of an isolated dot at its centre
SUPERSAMPLE = 8              # sub-samples per pixel side (pixel-area integration)


def sigma_for_speckle(d: float, k: float = DOT_PEAK) -> float:
    """Gaussian sigma (px) of a dot whose gray-level profile ``1 - exp(-k g)`` has FWHM ``d`` px."""
    g_half = -np.log(1.0 - 0.5 * (1.0 - np.exp(-k))) / k      # g = exp(-r^2 / 2 sigma^2) at half max
    return float(d / (2.0 * np.sqrt(-2.0 * np.log(g_half))))


@dataclass(frozen=True)
class Speckle:
    """Dot centres (px, image coordinates: pixel centres at integers) and sigma (px)."""

    centres: np.ndarray          # (n, 2) = (x, y)
    sigma: float


def make_speckle(d: float, shape: tuple[int, int], seed: int = 0) -> Speckle:
    """Poisson random dots of FWHM ``d`` px covering ``shape`` (h, w) plus a border; 50 % disc coverage."""
    h, w = shape
    border = 4.0 * d + 2.0
    area = (w + 2 * border) * (h + 2 * border)
    rng = np.random.default_rng(seed)
    n = rng.poisson(np.log(2.0) * area / (np.pi * d * d / 4.0))     # 1 - exp(-n a / A) = 1/2
    centres = np.column_stack([rng.uniform(-border, w + border, n), rng.uniform(-border, h + border, n)])
    return Speckle(centres, sigma_for_speckle(d))


def _gauss_matrix(centres: np.ndarray, samples: np.ndarray, sigma: float) -> sparse.csr_matrix:
    """Sparse (n_dots, n_samples) matrix ``exp(-(s - c)^2 / 2 sigma^2)``, cut at 6 sigma."""
    r = 6.0 * sigma
    step = samples[1] - samples[0]
    lo = np.searchsorted(samples, centres - r)
    width = int(np.ceil(2 * r / step)) + 2
    raw = lo[:, None] + np.arange(width)
    cols = np.minimum(raw, len(samples) - 1)
    vals = np.exp(-0.5 * ((samples[cols] - centres[:, None]) / sigma) ** 2)
    vals[(np.abs(samples[cols] - centres[:, None]) > r) | (raw >= len(samples))] = 0.0
    rows = np.repeat(np.arange(len(centres)), width)
    m = sparse.coo_matrix((vals.ravel(), (rows, cols.ravel())), shape=(len(centres), len(samples)))
    return m.tocsr()


def render(speckle: Speckle, shape: tuple[int, int], shift_x: float = 0.0,
           supersample: int = SUPERSAMPLE) -> np.ndarray:
    """Pixel-area integrated image (h, w) of the texture translated by ``shift_x`` px in x.

    ``S`` is separable per dot, so ``S`` on the sub-sample grid is one sparse product
    ``Gy^T diag(k) Gx``; the saturation ``1 - exp(-S)`` is applied per sub-sample, then the
    ``supersample^2`` sub-samples of each pixel are averaged.
    """
    h, w = shape
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    xs = (np.arange(w)[:, None] + offsets).ravel()
    ys = (np.arange(h)[:, None] + offsets).ravel()
    gx = _gauss_matrix(speckle.centres[:, 0] + shift_x, xs, speckle.sigma)
    gy = _gauss_matrix(speckle.centres[:, 1], ys, speckle.sigma)
    s = (gy.T @ (gx.multiply(DOT_PEAK)).tocsr()).toarray()          # (h ss, w ss)
    t = BACKGROUND + AMPLITUDE * (1.0 - np.exp(-s))
    return t.reshape(h, supersample, w, supersample).mean(axis=(1, 3))


# ----------------------------------------------------------------------------- image models
#: an interpolant: (image (h, w), rows (n,), x (n,)) -> (value (n,), d value / dx (n,))
Evaluator = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def _model_bspline3(img: np.ndarray, rows: np.ndarray, cols0: np.ndarray) -> Callable:
    core = Image.from_array(img, prefilter_px=0.0)      # the bare spline: the prefilter is applied above

    def ev(u: float) -> tuple[np.ndarray, np.ndarray]:
        v, g = core.evaluate_with_gradient(np.column_stack([cols0 + u, rows]))
        return v, g[:, 0]
    return ev


def _model_bspline5(img: np.ndarray, rows: np.ndarray, cols0: np.ndarray) -> Callable:
    c = ndimage.spline_filter(img, order=5, output=np.float64, mode="mirror")
    hstep = 1e-4

    def at(x: np.ndarray) -> np.ndarray:
        return ndimage.map_coordinates(c, [rows, x], order=5, mode="mirror", prefilter=False)

    def ev(u: float) -> tuple[np.ndarray, np.ndarray]:
        x = cols0 + u
        return at(x), (at(x + hstep) - at(x - hstep)) / (2 * hstep)
    return ev


def _keys_weights(t: np.ndarray, a: float = -0.5) -> tuple[np.ndarray, np.ndarray]:
    """Keys cubic-convolution weights (n, 4) of nodes i-1..i+2 at i + t, and d/dt."""
    d = np.stack([1 + t, t, 1 - t, 2 - t], axis=1)                 # distances to the nodes
    sgn = np.array([1.0, 1.0, -1.0, -1.0])                         # d(distance)/dt
    near = d <= 1.0
    w = np.where(near, (a + 2) * d**3 - (a + 3) * d**2 + 1, a * d**3 - 5 * a * d**2 + 8 * a * d - 4 * a)
    dw = np.where(near, 3 * (a + 2) * d**2 - 2 * (a + 3) * d, 3 * a * d**2 - 10 * a * d + 8 * a) * sgn
    return w, dw


def _model_rows(kind: str) -> Callable:
    def build(img: np.ndarray, rows: np.ndarray, cols0: np.ndarray) -> Callable:
        ri = rows.astype(np.int64)

        def ev(u: float) -> tuple[np.ndarray, np.ndarray]:
            x = cols0 + u
            i = np.floor(x).astype(np.int64)
            t = x - i
            if kind == "bilinear":
                a, b = img[ri, i], img[ri, i + 1]
                return a + t * (b - a), b - a
            w, dw = _keys_weights(t)
            p = img[ri[:, None], i[:, None] + np.arange(-1, 3)]
            return (p * w).sum(axis=1), (p * dw).sum(axis=1)
        return ev
    return build


MODELS: dict[str, Callable] = {"bilinear": _model_rows("bilinear"), "keys": _model_rows("keys"),
                               "bspline3": _model_bspline3, "bspline5": _model_bspline5}


def measure_shift(f: np.ndarray, g: np.ndarray, model: str, prefilter: float = 0.0,
                  margin: int = 16, max_iter: int = 50) -> float:
    """Shift u (px, in x) with ``g(x + u) = f(x)``: 1-D Gauss-Newton on the SSD over the interior.

    ``prefilter`` > 0 smooths BOTH images with a Gaussian of that sigma (px) first.
    """
    if prefilter > 0:
        f = ndimage.gaussian_filter(f, prefilter)
        g = ndimage.gaussian_filter(g, prefilter)
    h, w = f.shape
    rr, cc = np.mgrid[margin:h - margin, margin:w - margin]
    rows, cols0 = rr.ravel().astype(float), cc.ravel().astype(float)
    ref = f[rr, cc].ravel()
    ev = MODELS[model](np.asarray(g, dtype=np.float64), rows, cols0)
    ints = np.arange(-2, 3)
    u = float(ints[np.argmin([np.sum((g[rr, cc + k] - f[rr, cc]) ** 2) for k in ints])])
    for _ in range(max_iter):
        v, dv = ev(u)
        du = -float(dv @ (v - ref)) / float(dv @ dv)
        u += du
        if abs(du) < 1e-9:
            break
    return u


def add_noise(img: np.ndarray, noise: float, rng: np.random.Generator) -> np.ndarray:
    """8-bit camera: ``img`` plus Gaussian noise of std ``noise``, rounded and clipped to 0..255."""
    return np.clip(np.round(img + rng.normal(0.0, noise, img.shape)), 0, 255)


def bias_curve(f: np.ndarray, shifted: dict[float, np.ndarray], model: str, prefilter: float,
               margin: int = 16) -> np.ndarray:
    """Position error ``u - s`` for each shift s of ``shifted`` (noise-free)."""
    return np.array([measure_shift(f, g, model, prefilter, margin) - s for s, g in shifted.items()])


def run_speckle(d: float, shape: tuple[int, int], margin: int, models: list[str], prefilters: list[float],
                s_bias: np.ndarray, s_noise: np.ndarray, noise: float, seeds: int
                ) -> tuple[str, list[dict], dict]:
    """All models and prefilters for one speckle size: (printed lines, table rows, bias curves)."""
    sp = make_speckle(d, shape, seed=int(10 * d))
    f = render(sp, shape)
    clean = {float(s): render(sp, shape, s) for s in np.union1d(s_bias, s_noise)}
    rng = np.random.default_rng(1234)
    noisy = [(float(s), add_noise(f, noise, rng), add_noise(clean[float(s)], noise, rng))
             for s in s_noise for _ in range(seeds)]
    lines = [f"\nspeckle {d:g} px (sigma {sp.sigma:.2f} px, {len(sp.centres)} dots), "
             f"gray levels {f.min():.0f}..{f.max():.0f}"]
    rows, curves = [], {}
    for model in models:
        for pf in prefilters:
            b = bias_curve(f, {float(s): clean[float(s)] for s in s_bias}, model, pf, margin)
            e = np.array([measure_shift(fn, gn, model, pf, margin) - s for s, fn, gn in noisy])
            e = e.reshape(len(s_noise), seeds)
            row = dict(d=d, model=model, prefilter=pf, max_bias=np.abs(b).max(),
                       rms_bias=np.sqrt(np.mean(b**2)), noisy_bias=np.sqrt(np.mean(e.mean(axis=1) ** 2)),
                       noise_std=np.sqrt(np.mean(e.std(axis=1, ddof=1) ** 2)), total=np.sqrt(np.mean(e**2)))
            rows.append(row)
            curves[(d, model, pf)] = b
            lines.append(f"  {model:9s} prefilter {pf:3.1f}: max|bias| {row['max_bias']:.4f}  RMS bias "
                         f"{row['rms_bias']:.4f}  RMS bias with noise {row['noisy_bias']:.4f}  noise std "
                         f"{row['noise_std']:.4f}  total RMS {row['total']:.4f} px")
    return "\n".join(lines), rows, curves


# ----------------------------------------------------------------------------- main
def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--size", type=int, default=256, help="image side (px)")
    p.add_argument("--speckles", default="3,4,5,8", help="speckle sizes d (px, FWHM)")
    p.add_argument("--step", type=float, default=0.05, help="shift step of the bias curve (px)")
    p.add_argument("--noise-step", type=float, default=0.1, help="shift step of the noise runs (px)")
    p.add_argument("--noise", type=float, default=2.0, help="noise std (gray levels)")
    p.add_argument("--seeds", type=int, default=8, help="noise realisations per shift")
    p.add_argument("--prefilters", default="0,0.5,0.7,0.9", help="Gaussian prefilter sigmas (px)")
    p.add_argument("--models", default="bilinear,keys,bspline3,bspline5")
    p.add_argument("--region", type=int, default=None,
                   help="side (px) of the central square measured (default: all but a 16 px border)")
    p.add_argument("--quick", action="store_true", help="coarse: step 0.1, noise step 0.25, 3 seeds")
    p.add_argument("--plot", default=None, help="save the bias curves to this PNG")
    args = p.parse_args()
    if args.quick:
        args.step, args.noise_step, args.seeds = 0.1, 0.25, 3
    t0 = time.perf_counter()
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"python {platform.python_version()}, compiled B-spline kernel: {COMPILED_KERNEL}")
    shape = (args.size, args.size)
    margin = 16 if args.region is None else (args.size - args.region) // 2
    if margin < 8:
        p.error("--region must leave a border of at least 8 px")
    speckles = [float(d) for d in args.speckles.split(",")]
    prefilters = [float(x) for x in args.prefilters.split(",")]
    models = args.models.split(",")
    s_bias = np.round(np.arange(0.0, 1.0 + 1e-9, args.step), 6)
    s_noise = np.round(np.arange(0.0, 1.0 + 1e-9, args.noise_step), 6)
    print(f"{args.size} x {args.size} px, 8x8 supersampled, GN over the central {args.size - 2 * margin} x {args.size - 2 * margin} px; "
          f"bias: s = 0..1 step {args.step}; noise {args.noise} GL, 8-bit, {args.seeds} seeds, "
          f"s step {args.noise_step}")
    jobs = [(d, shape, margin, models, prefilters, s_bias, s_noise, args.noise, args.seeds) for d in speckles]
    rows, curves = [], {}
    with ProcessPoolExecutor(max_workers=min(len(jobs), os.cpu_count() or 1)) as pool:
        for text, r, c in pool.map(run_speckle, *zip(*jobs)):
            print(text, flush=True)
            rows += r
            curves.update(c)
    print("\n| model | prefilter (px) | " + " | ".join(f"d = {d:g} px" for d in speckles) + " |")
    print("|---|---|" + "---|" * len(speckles))
    print("cells: max abs bias / RMS bias / RMS bias with noise / noise std / total RMS (px)")
    for model in models:
        for pf in prefilters:
            cells = []
            for d in speckles:
                r = next(r for r in rows if r["d"] == d and r["model"] == model and r["prefilter"] == pf)
                cells.append(f"{r['max_bias']:.4f} / {r['rms_bias']:.4f} / {r['noisy_bias']:.4f} / "
                             f"{r['noise_std']:.4f} / {r['total']:.4f}")
            print(f"| {model} | {pf:g} | " + " | ".join(cells) + " |")
    print()
    for d in speckles:
        best = min((r for r in rows if r["d"] == d), key=lambda r: r["total"])
        print(f"speckle {d:g} px: lowest total RMS {best['total']:.4f} px with {best['model']} "
              f"prefilter {best['prefilter']:g}")
    mean_total = {(m, pf): np.sqrt(np.mean([r["total"] ** 2 for r in rows if r["model"] == m and r["prefilter"] == pf]))
                  for m in models for pf in prefilters}
    (m, pf), v = min(mean_total.items(), key=lambda kv: kv[1])
    print(f"over speckles {args.speckles} px (RMS of the total RMS): best {m} prefilter {pf:g}: {v:.4f} px")
    print(f"elapsed {time.perf_counter() - t0:.0f} s")
    if args.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, axes = plt.subplots(1, len(speckles), figsize=(4 * len(speckles), 3.4), sharey=False)
        for ax, d in zip(np.atleast_1d(axes), speckles):
            for model in models:
                for pf in prefilters:
                    if pf not in (0.0, max(prefilters)):
                        continue
                    ax.plot(s_bias, curves[(d, model, pf)], ls="-" if pf == 0 else "--",
                            label=f"{model}" + (f" + G{pf:g}" if pf else ""))
            ax.axhline(0, color="k", lw=0.5)
            ax.set_title(f"speckle {d:g} px")
            ax.set_xlabel("true shift s (px)")
        np.atleast_1d(axes)[0].set_ylabel("bias u - s (px)")
        np.atleast_1d(axes)[-1].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=80)
        print(f"plot: {args.plot}")


if __name__ == "__main__":
    main()
