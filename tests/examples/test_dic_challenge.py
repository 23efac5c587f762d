"""The Stereo DIC Challenge example on the real stereo pair (examples/dic_challenge).

The specimen measured as one part from its CAD through ``georeg measure`` (in process,
:func:`georeg_app.cli.main`) on the pair downsampled by 2 (the core's pyramid,
:meth:`fesdic_core.imaging.image.Image.coarsen`) with the rig scaled to it (:meth:`Camera.scaled`),
image scales 2, 1, 0 (the full-resolution run's 3, 2, 1) and 2 spline levels (the plate's
finest 2 x 2 elements; ``specimen_part.toml`` has 4 levels, 8 x 8). With 3 levels, the
spline the full run uses at its scale 1, the fixed point at the half images' finest scale
does not stagnate (the poses drift 0.03-0.04 px per iteration, q 5 um, for 9 iterations and
more); with 2 it stagnates in 3 iterations: about 40 s. Then the example's analysis (``analyse_part.py``, ``analysis.toml``): block height,
base-plate flatness, bar radius and crest against the two INDEPENDENT references of the
challenge (README.md, "Real images: the Stereo DIC Challenge"; challenge/report.py LASER and
PYVALE): the laser scan and pyvale's subset DIC on this same pair. Tolerances come from the
references' own scatter, not from our output. Skipped without OpenCASCADE (the STEP part).
"""
import json
import sys
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

pytestmark = pytest.mark.slow         # the Stereo DIC Challenge's real pair

pytest.importorskip("OCP")

HERE = Path(__file__).resolve().parents[2] / "examples" / "dic_challenge"
sys.path.insert(0, str(HERE))

import analyse_part                                                  # noqa: E402
from challenge import analysis                                       # noqa: E402
from challenge.comparison import compare                             # noqa: E402
from challenge.report import LASER, PYVALE                           # noqa: E402
from fesdic_core.imaging.image import read_image                             # noqa: E402
from fesdic_core.cameras.rig import write_cameras_json                       # noqa: E402
from georeg_app import cli                                           # noqa: E402
from georeg_app.config.measure import load_config                            # noqa: E402
from georeg_app.inputs.cameras import load_cameras  # noqa: E402

PART = HERE / "specimen_part.toml"
#: spline levels of the half-resolution part (see the module docstring)
HALF_LEVELS = 2
#: The block height above the plate ring: laser 6.36 mm, pyvale 6.333 mm. The two independent
#: references differ by 0.027 mm, so nothing finer than 0.03 mm can be called agreement: a
#: height agrees with the references if it is within 0.03 mm of EACH of them.
HEIGHT_TOL_MM = 0.03
#: Base plate, README region: pyvale's RMS to the best-fit plane is 7.9 um, with a noise floor
#: of 3.6 um (its RMS to the best-fit quadric). Of pyvale's 7.9 um only the part above its own
#: noise is shape, so a second measurement agrees with it within +-3.6 um (pyvale's noise).
BASE_PLANE_TOL_UM = PYVALE["base_quadric_um"]
#: Crests of the bars above the plate ring: pyvale 6.21-6.22 mm, a height like the block's:
#: the same 0.03 mm scatter of the references applies.
PYVALE_CREST_MM = (6.21, 6.22)


def half_resolution_rig():
    """The pair downsampled by 2 and the rig posed as ``georeg measure`` poses it (pyvale's
    calibration, the landmarks of specimen_part.toml), then scaled to the half images."""
    config = load_config(PART)
    full = [read_image(config.images.cam0), read_image(config.images.cam1)]
    cameras = load_cameras(config.cameras, full)
    return config, full, cameras, [c.scaled(1) for c in cameras]


def write_half_resolution_part(folder: Path, rig=None) -> Path:
    """specimen_part.toml on the half-resolution pair: images (float TIFF, the block means
    exactly), cameras JSON, one image scale fewer, ``HALF_LEVELS`` spline levels; ``rig``:
    what :func:`half_resolution_rig` returned (None: computed here)."""
    _, full, _, half = half_resolution_rig() if rig is None else rig
    for k, image in enumerate(full):
        cv2.imwrite(str(folder / f"cam{k}.tiff"), image.coarsen().values.astype(np.float32))
    write_cameras_json(folder / "cameras.json", half)
    doc = tomllib.loads(PART.read_text())
    geometry, method = doc["geometry"], doc["method"]
    geometry["file"] = str((PART.parent / geometry["file"]).resolve())
    method["scales"] -= 1                       # scales 2, 1, 0 of the half images: 3, 2, 1
    method["levels"] = HALF_LEVELS
    text = (f'[images]\ncam0 = {json.dumps(str(folder / "cam0.tiff"))}\n'
            f'cam1 = {json.dumps(str(folder / "cam1.tiff"))}\n'
            f'[cameras]\nfile = {json.dumps(str(folder / "cameras.json"))}\n')
    for name, table in (("geometry", geometry), ("method", method)):
        text += f"[{name}]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in table.items())
    path = folder / "part_half.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def rig():
    """:func:`half_resolution_rig`, once for the module (the pair read, the rig posed)."""
    return half_resolution_rig()


@pytest.fixture(scope="module")
def half_part(tmp_path_factory, rig):
    folder = tmp_path_factory.mktemp("dic_challenge_half")
    config = write_half_resolution_part(folder, rig)
    assert cli.main(["measure", str(config), "--out", str(folder / "out"), "--quiet"]) == 0
    part = analyse_part.load_part(folder / "out", config)
    return part, compare(part)


def test_half_resolution_rig_sees_as_the_pyramid(rig):
    """Pixel centres at integers: one 2x2 block mean maps x -> (x - 0.5) / 2, in the rig
    (Camera.scaled) as in the images (Image.coarsen): the scaled cameras project the landmarks
    where the full ones do, converted; the landmarks' picked pixels, converted, reproject as
    well at half resolution as they do at full resolution (half the px)."""
    config, full, cameras, half = rig
    X = np.array([lm.xyz_mm for lm in config.cameras.landmarks])
    picked = [np.array([getattr(lm, f"cam{k}_px") for lm in config.cameras.landmarks]) for k in (0, 1)]
    for k, (c, h) in enumerate(zip(cameras, half)):
        np.testing.assert_allclose(h.project(X), (c.project(X) - 0.5) / 2, atol=1e-9)
        assert h.image_size == tuple(s // 2 for s in c.image_size) == full[k].coarsen().shape[::-1]
        err_full = np.linalg.norm(c.project(X) - picked[k], axis=1)
        err_half = np.linalg.norm(h.project(X) - (picked[k] - 0.5) / 2, axis=1)
        np.testing.assert_allclose(err_half, err_full / 2, atol=1e-9)
    # the images: coarse pixel (i, j) is the mean of full pixels 2i, 2i + 1 (x) and 2j, 2j + 1
    # (y), centred at (2i + 0.5, 2j + 0.5): x -> (x - 0.5) / 2 again
    coarse = full[0].coarsen()
    assert coarse.values[100, 50] == pytest.approx(full[0].values[200:202, 100:102].mean(), abs=1e-12)


def test_real_pair_block_height_agrees_with_pyvale(half_part):
    """Block height within 0.03 mm of pyvale's 6.333 mm. Measured: 6.3285 mm."""
    _, c = half_part
    assert abs(c.block.height_mm - PYVALE["block_height_mm"]) <= HEIGHT_TOL_MM, c.block.height_mm


@pytest.mark.xfail(strict=True, reason="half resolution, 2 spline levels: 6.3285 mm, 0.0315 mm below "
                                       "the laser's 6.36 mm (the full-resolution part, 4 levels: 6.3378 mm)")
def test_real_pair_block_height_agrees_with_laser(half_part):
    """Block height within 0.03 mm of the laser's 6.36 mm (the two references differ by
    0.027 mm: a height agrees with them if it is within 0.03 mm of EACH)."""
    _, c = half_part
    assert abs(c.block.height_mm - LASER["block_height_mm"]) <= HEIGHT_TOL_MM, c.block.height_mm


def test_real_pair_base_flatness_agrees_with_pyvale(half_part):
    """Base plate (README region): RMS to a quadric below pyvale's noise floor (3.6 um), RMS to
    a plane within pyvale's noise (3.6 um) of pyvale's 7.9 um."""
    _, c = half_part
    assert c.base_quadric_rms_mm * 1e3 < PYVALE["base_quadric_um"], c.base_quadric_rms_mm
    assert abs(c.base_plane_rms_mm * 1e3 - PYVALE["base_plane_um"]) <= BASE_PLANE_TOL_UM, c.base_plane_rms_mm


def test_real_pair_bar_radius_and_crest_lie_within_the_references(half_part):
    """Vertical bar: the references disagree on its radius (laser 6.38 mm, pyvale 6.157 mm,
    0.22 mm apart); a radius that agrees with the references lies between them. Its crest
    above the plate ring is within 0.03 mm (the references' scatter on heights) of pyvale's
    6.21-6.22 mm."""
    _, c = half_part
    bar = c.cylinders["cylinder_v"]
    lo, hi = sorted((LASER["radius_mm"]["cylinder_v"], PYVALE["radius_mm"]["cylinder_v"]))
    assert lo <= bar.fit.radius_mm <= hi, bar.fit.radius_mm
    assert PYVALE_CREST_MM[0] - HEIGHT_TOL_MM <= bar.crest_above_ring_mm <= PYVALE_CREST_MM[1] + HEIGHT_TOL_MM, \
        bar.crest_above_ring_mm


def test_real_pair_images_match_and_masks_and_frame_are_sane(half_part):
    """Not accuracy claims: sanity of the run (no reference exists for these)."""
    part, _ = half_part
    # the images match: residual below 2.5 % of the dynamic range at full scale 1
    assert part.residual_percent < 2.5, part.residual_percent
    # the features hide strips of the plate from one camera, but not most of the plate
    assert 0.001 < part.masked_fraction["base"] < 0.05, part.masked_fraction
    # every face is in the frame of the measured base plane (z = 0)
    assert abs(part.points["base"][:, 2].mean()) < 1e-3
    assert not part.full_resolution                 # the time target is not checked on it


def test_figures_of_merit_on_exact_shapes():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-20, 20, (4000, 2))
    bowl = np.column_stack([xy, 1e-4 * xy[:, 0] ** 2 - 2e-4 * xy[:, 0] * xy[:, 1] + 0.01 * xy[:, 1]])
    assert analysis.rms(analysis.quadric_residuals(bowl)) < 1e-5      # 10 nm: tilt of the fit frame
    assert analysis.rms(analysis.plane_residuals(bowl)) > 1e-3
    # a tilted cylinder of radius 6.2 over 80 degrees of arc: radius, axis and crest recovered
    r, axis = 6.2, np.array([1.0, 0.02, 0.0]) / np.hypot(1.0, 0.02)
    t, a = rng.uniform(-20, 20, 5000), np.radians(rng.uniform(-40, 40, 5000))
    lateral = np.cross(axis, [0, 0, 1.0])
    P = np.array([3.0, 40.0, -0.1]) + np.outer(t, axis) + r * (np.outer(np.sin(a), lateral)
                                                               + np.outer(np.cos(a), [0, 0, 1.0]))
    fit = analysis.fit_cylinder(P, [1.0, 0.0, 0.0], 6.6)
    assert fit.radius_mm == pytest.approx(r, abs=1e-9)
    assert fit.crest_height_mm == pytest.approx(r - 0.1, abs=1e-9)
    assert fit.rms_mm < 1e-9
    imposed = analysis.fit_cylinder(P, axis, 6.6, radius=6.6)
    assert imposed.rms_mm > 1e-2
