"""Issue 10, item 4: geometric regularization with automatic levels is never worse than plain FE.

On each shape of a family with known truth (tests/scenes.py), the level search
(:func:`adapters.level_search.measure_auto_levels`, 3 start levels) is compared with the
core's plain FE and with Tikhonov at fixed lengths (5, 10, 20 mm), all on the same FE
mesh, images and settings; the error is the RMS distance of the measured nodes to the true
surface after the bounded rigid alignment (tests/shape_truth.py).

Cases: the demo's twisted open-hole plate with waviness (``small_demo_scene``, the NURBS
plate with a hole, 256 Q9 elements, scales (2, 1, 0)), and the family ``scenes.FAMILY``
(a 60 x 60 mm plate, 40 x 40 Q9 elements of 1.5 mm, 704 x 736 px, scales (1, 0)): flat,
and a 0.5 mm Gaussian bump of sigma = width / 2, / 5 and / 20 (30, 12 and 3 mm).

FE and Tikhonov run with ``uncertainty=False``: their shape and verdict do not depend on
it, and the FE's shape uncertainty inverts the 6561 x 6561 H densely (about 50 s here).
The level search needs it (its noise model).

Measured (um, this machine; georeg auto: chosen level / ladder, spline dofs):

=========== ======= ======= ======= ======= ===================
case          FE     T 5mm  T 10mm  T 20mm   georeg auto
=========== ======= ======= ======= ======= ===================
twisted      17.85    7.18   10.68   28.34   2.95 (1/4, 120)
flat         10.93    3.81    2.53    1.61   7.32 (0/5, 1764)
sigma W/2    10.42    3.59    3.95    8.80   7.30 (0/5, 1764)
sigma W/5     9.87    3.46    5.39    7.97   6.02 (0/5, 1764)
sigma W/20   10.93    5.44   11.23   22.02   7.32 (0/5, 1764)
=========== ======= ======= ======= ======= ===================

Never worse than FE: holds on every case. Not worse than the best fixed Tikhonov length:
holds on the twisted plate only (strict xfails below). On the flat plate and every bump the
search climbs to the spline of the FE mesh (Mallows' Cp gains 20 to 600 kappa per added
dof), the flat plate included, so it does not choose a finer level for the narrow bump
than for the flat plate either. The ladder of the 40 x 40 mesh also jumps from 8 x 8 knot
spans (100 dofs) to the mesh's 40 x 40 (1764): 16 does not divide 40.

Why the search climbs (benchmarks/bench_levels.py, column "misfit"): at the TRUE shape,
one FE step would lower the cost by b^T H^-1 b = 5.6 to 9.1 kappa per FE dof on these
renders, where images that differ from the truth by their noise only give 1 (the
definition of kappa). The renders integrate each pixel by 3 x 3 point samples of a 4 px
speckle (texels of 0.67 px); that leaves a systematic misfit, the FE mesh fits it (10.9 um
off a flat plate; 10.6 um without noise) and Cp counts it as shape (the twisted plate's
render, 500 x 333 px, has a misfit of 1.29: there the search stays on its start level). The
same scenes rendered
with 6 x 6 rays per pixel have a misfit of 1.25 to 1.4 on the flat plate and the 6 and 3 mm
bumps: the search then stops at level 1 (100 dofs) on the flat plate (0.73 um; Tikhonov
20 mm 0.33 um) and beats every Tikhonov length on the 6 and 3 mm bumps (2.10 um against
2.32 and 3.94 um), but not on the 30 and 12 mm bumps (6.22 against 3.10, 3.13 against 2.31),
whose misfit stays at 6.9 and 2.5 (not explained here; the broad bumps lift most of the plate
off the plane where the two views' sub-pixel phases are symmetric, which suggests the
interpolation bias of the image model).
The independent rasteriser riley-raster shows the same: aliased at this scale with 4 x 4
sub-pixels (misfit 7 to 10, same verdicts as here), near noise at the demo's scale (1.3 to
1.5 on the flat plate and the narrow bumps).

Time: 41 s wall, 68 s CPU on an idle 2-core machine (167 s wall under a load average of
about 9): four renders of 704 x 736 px and 25 measurements.
"""
from __future__ import annotations

import dataclasses

import pytest

import scenes
from adapters.fesdic_core import nominal_model
from adapters.level_search import measure_auto_levels
from fesdic_core.driver import MeasurementSettings, measure
from fesdic_core.tikhonov import TikhonovSolver
from georeg_plugin.geometries import plate_with_hole, rectangle
from shape_truth import bounded_shape_error, rms

TIKHONOV_MM = (5.0, 10.0, 20.0)
START_LEVELS = 3

#: case -> (divisor of the family, None for flat; "twisted" for the demo's plate)
CASES = {"twisted": "twisted", "flat": None, "sigma_W/2": 2, "sigma_W/5": 5, "sigma_W/20": 20}


@dataclasses.dataclass(frozen=True)
class Outcome:
    errors_um: dict          # method -> RMS error (um)
    ok: dict                 # method -> Measurement.ok
    chosen: int              # the level the search chose (0 = the spline of the FE mesh)
    start: int
    n_levels: int
    dofs: int                # spline dofs of the chosen level

    @property
    def best_tikhonov(self) -> tuple[str, float]:
        return min(((k, v) for k, v in self.errors_um.items() if k.startswith("tikhonov")),
                   key=lambda kv: kv[1])

    def table(self) -> str:
        return ", ".join(f"{k} {v:.2f}" for k, v in self.errors_um.items()) + \
            f" um; level {self.chosen}/{self.n_levels} ({self.dofs} dofs)"


def _tikhonov_solvers(mesh) -> dict:
    solvers = {f"tikhonov {length:g} mm": TikhonovSolver(mesh, length) for length in TIKHONOV_MM}
    try:                                  # the length chosen from the data, where the core has it
        solvers["tikhonov auto"] = TikhonovSolver(mesh, "auto")
    except (TypeError, ValueError):
        pass
    return solvers


def _run(scene, model, settings: MeasurementSettings) -> Outcome:
    images, cameras, truth = scene.images, scene.cameras, scene.specimen
    geo, solver, search = measure_auto_levels(model, images, cameras, settings,
                                              start_levels=START_LEVELS)
    reference = dataclasses.replace(settings, uncertainty=False)
    runs = {"georeg auto": geo, "fe": measure(model.mesh, images, cameras, None, reference)}
    for name, tikhonov in _tikhonov_solvers(model.mesh).items():
        runs[name] = measure(model.mesh, images, cameras, tikhonov, reference)
    errors = {k: 1e3 * rms(bounded_shape_error(m.nodes, truth)) for k, m in runs.items()}
    return Outcome(errors, {k: m.ok for k, m in runs.items()}, search.chosen, search.start,
                   search.n_levels, int(solver.operator(search.chosen).shape[0]))


@pytest.fixture(scope="module")
def outcome(request, small_demo_scene, family_scenes):
    cache = {}

    def get(case: str) -> Outcome:
        if case not in cache:
            if CASES[case] == "twisted":
                model = nominal_model(plate_with_hole(100.0, 50.0, 14.0), 3, "Q9")
                cache[case] = _run(small_demo_scene, model, MeasurementSettings(scales=(2, 1, 0)))
            else:
                f = scenes.FAMILY
                model = nominal_model(rectangle(f["length_mm"], f["width_mm"]), f["elements"], "Q9")
                cache[case] = _run(family_scenes(CASES[case]), model,
                                   MeasurementSettings(scales=(1, 0)))
        return cache[case]
    return get


def _xfail(reason: str):
    return pytest.mark.xfail(strict=True, reason=reason)


@pytest.mark.parametrize("case", list(CASES))
def test_every_measurement_is_ok(outcome, case):
    result = outcome(case)
    assert all(result.ok.values()), result.ok


@pytest.mark.parametrize("case", list(CASES))
def test_automatic_level_is_not_worse_than_fe(outcome, case):
    result = outcome(case)
    assert result.errors_um["georeg auto"] <= result.errors_um["fe"], result.table()


_CLIMBS = ("the search climbs to the FE mesh's spline (level 0, 1764 dofs) and keeps its "
           "fit of image-model misfit: ")


@pytest.mark.parametrize("case", [
    "twisted",
    pytest.param("flat", marks=_xfail(_CLIMBS + "7.32 um against Tikhonov 20 mm's 1.61 um "
                                      "(fixed 2 levels: 1.74 um)")),
    pytest.param("sigma_W/2", marks=_xfail(_CLIMBS + "7.30 um against Tikhonov 5 mm's 3.59 um "
                                           "(fixed 3 levels: 2.47 um)")),
    pytest.param("sigma_W/5", marks=_xfail(_CLIMBS + "6.02 um against Tikhonov 5 mm's 3.46 um "
                                           "(fixed 4 levels: 3.17 um)")),
    pytest.param("sigma_W/20", marks=_xfail(_CLIMBS + "7.32 um against Tikhonov 5 mm's 5.44 um; "
                                            "the ladder has no level between 8 x 8 knot spans "
                                            "(100 dofs) and the FE mesh's 40 x 40 (1764)")),
])
def test_automatic_level_is_not_worse_than_the_best_fixed_tikhonov_length(outcome, case):
    result = outcome(case)
    name, best = result.best_tikhonov
    assert result.errors_um["georeg auto"] <= best, (name, result.table())


@_xfail("the flat plate's search also climbs to level 0 (Cp gain 21 kappa per dof from the "
        "36-dof start): the same level as for the narrow bump, not a coarser one")
def test_the_narrow_bump_gets_a_finer_level_than_the_flat_plate(outcome):
    flat, narrow = outcome("flat"), outcome("sigma_W/20")
    assert flat.start == narrow.start
    assert narrow.chosen < flat.chosen, (narrow.table(), flat.table())
