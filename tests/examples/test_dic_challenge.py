"""The Stereo DIC Challenge example on the real stereo pair (examples/dic_challenge).

End to end at coarse image scales (2, 1) on the base plate, the block top and the vertical
half-cylinder: block height, base-plate flatness, bar radius and crest against the two
INDEPENDENT references of the challenge (README.md, "Real images: the Stereo DIC Challenge";
challenge/report.py LASER and PYVALE): the laser scan and pyvale's subset DIC on this same
pair. Tolerances come from the references' own scatter, not from our output. The pieces
(configuration errors, occlusion by ray casting, the crop of the images, the figures of merit
on exact shapes) on their own.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parents[2] / "examples" / "dic_challenge"
sys.path.insert(0, str(HERE))

from challenge import analysis                                       # noqa: E402
from challenge.config import ConfigError, load_face                  # noqa: E402
from challenge.geometry import ConvexSolid, feature_solid, face_model  # noqa: E402
from challenge.measure import initial_cameras, load_images, measure_nominal  # noqa: E402
from challenge.pipeline import compare, run_challenge                # noqa: E402
from challenge.report import LASER, PYVALE                           # noqa: E402
from challenge.visibility import hidden_by                           # noqa: E402

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


@pytest.fixture(scope="module")
def coarse_run():
    run = run_challenge(HERE, ("base", "block_top", "cylinder_v"), scales=(2, 1))
    return run, compare(run)


def test_real_pair_block_height_agrees_with_laser_and_pyvale(coarse_run):
    """Block height within 0.03 mm of the laser's 6.36 mm and of pyvale's 6.333 mm.
    Measured at scales (2, 1): 6.335 mm."""
    _, c = coarse_run
    assert abs(c.block.height_mm - LASER["block_height_mm"]) <= HEIGHT_TOL_MM, c.block.height_mm
    assert abs(c.block.height_mm - PYVALE["block_height_mm"]) <= HEIGHT_TOL_MM, c.block.height_mm


def test_real_pair_base_flatness_agrees_with_pyvale(coarse_run):
    """Base plate (README region): RMS to a quadric below pyvale's noise floor (3.6 um), RMS to
    a plane within pyvale's noise (3.6 um) of pyvale's 7.9 um. Measured: 2.6 / 8.4 um."""
    _, c = coarse_run
    assert c.base_quadric_rms_mm * 1e3 < PYVALE["base_quadric_um"]
    assert abs(c.base_plane_rms_mm * 1e3 - PYVALE["base_plane_um"]) <= BASE_PLANE_TOL_UM


def test_real_pair_bar_radius_and_crest_lie_within_the_references(coarse_run):
    """Vertical bar: the references disagree on its radius (laser 6.38 mm, pyvale 6.157 mm,
    0.22 mm apart); a radius that agrees with the references lies between them, from either
    nominal (cylindrical, flat). Its crest above the plate ring is within 0.03 mm (the
    references' scatter on heights) of pyvale's 6.21-6.22 mm. Measured: radius 6.231 / 6.220 mm
    (cylindrical / flat nominal), crest 6.225 mm."""
    _, c = coarse_run
    bar = c.cylinders["cylinder_v"]
    lo, hi = sorted((LASER["radius_mm"]["cylinder_v"], PYVALE["radius_mm"]["cylinder_v"]))
    assert lo <= bar.fit.radius_mm <= hi, bar.fit.radius_mm
    assert lo <= bar.fit_flat.radius_mm <= hi, bar.fit_flat.radius_mm
    assert PYVALE_CREST_MM[0] - HEIGHT_TOL_MM <= bar.crest_above_ring_mm <= PYVALE_CREST_MM[1] + HEIGHT_TOL_MM


def test_real_pair_images_match_and_masks_and_frame_are_sane(coarse_run):
    """Not accuracy claims: sanity of the run (no reference exists for these)."""
    run, c = coarse_run
    # the images match: residual below 2.5 % of the dynamic range at scale 1 on the flat faces
    # (the bar: 2.30 % from its cylindrical nominal, 2.50 % from its flat one)
    assert c.residual_percent["base"] < 2.5 and c.residual_percent["block_top"] < 2.5
    # the block's solids mask the strips it hides from one camera, but not most of the plate
    assert 0.001 < c.masked_fraction["base"] < 0.05
    # every result is in the frame of the measured base plane (z = 0)
    base = run.results["base"].points_mm[run.results["base"].seen]
    assert abs(base[:, 2].mean()) < 1e-3


def test_crop_gives_the_same_surface():
    face = load_face(HERE / "block_top.toml")
    crop = (200, 800, 600, 560)                         # around the block, both views
    full = load_images(face.specimen)
    cams = initial_cameras(face.specimen, full)
    cropped = load_images(face.specimen, crop)
    cams_c = initial_cameras(face.specimen, cropped, crop)
    X = np.array([lm.xyz_mm for lm in face.specimen.landmarks])
    for a, b in zip(cams, cams_c):                      # same pose, pixels shifted by the crop
        np.testing.assert_allclose(b.project(X), a.project(X) - crop[:2], atol=1e-6)
    a = measure_nominal(face, face.nominals[0], full, cams, scales=(2, 1))
    b = measure_nominal(face, face.nominals[0], cropped, cams_c, scales=(2, 1))
    assert np.max(np.abs(a.nodes_mm - b.nodes_mm)) < 2e-3


def test_ray_casting_hides_the_strip_behind_a_box():
    box = ConvexSolid("box", np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]]),
                      np.array([-1, -1, -1, -1, -2, 0.0]), np.array([[-1, -1, 0], [1, 1, 2.0]]))
    camera = np.array([100.0, 0.0, 100.0])
    x = np.linspace(-5, 5, 1001)
    X = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    hidden = hidden_by(X, camera, box)
    # the ray from (x, 0, 0) grazes the top edge (-1, 0, 2) when x + 2 (100 - x) / 100 = -1;
    # points under the box (|x| <= 1) are inside it
    np.testing.assert_array_equal(hidden, (x >= -3.0 / 0.98 - 1e-9) & (x <= 1.0 + 1e-9))
    # points on the box's top face see the camera
    top = np.column_stack([x[np.abs(x) < 0.9], np.zeros(np.sum(np.abs(x) < 0.9)), np.full(np.sum(np.abs(x) < 0.9), 2.0 + 1e-9)])
    assert not hidden_by(top, camera, box).any()


def test_base_mesh_has_the_features_cut_out():
    face = load_face(HERE / "base.toml")
    nominal = face.nominals[0]
    solids = tuple(feature_solid(face.specimen.feature(h)) for h in nominal.holes)
    model = face_model(nominal, solids)
    for s in solids:
        assert not s.inflated(0.5).contains(model.mesh.nodes).any(), s.name
    assert model.uv.shape == (model.mesh.n_nodes, 2)


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
    # distance to the same cylinder sampled on a grid (0.2 mm x 0.8 deg), and to a copy
    # of radius r + 5 um: 0 and -5 um along the normal
    tg, ag = np.meshgrid(np.linspace(-20, 20, 201), np.radians(np.linspace(-40, 40, 101)))

    def surface(radius):
        return np.array([3.0, 40.0, -0.1]) + np.outer(tg.ravel(), axis) + radius * (
            np.outer(np.sin(ag.ravel()), lateral) + np.outer(np.cos(ag.ravel()), [0, 0, 1.0]))

    inner = (np.abs(t) < 19) & (np.abs(a) < np.radians(38))
    for offset in (0.0, 5e-3):
        d = analysis.surface_distance(P[inner], surface(r + offset), axis)
        assert np.isfinite(d).mean() > 0.8          # 0.5 mm lateral border excluded
        np.testing.assert_allclose(d[np.isfinite(d)], -offset, atol=2e-4)


def test_config_errors_name_the_file_and_key(tmp_path):
    text = (HERE / "block_top.toml").read_text().replace('specimen = "specimen.toml"',
                                                        f'specimen = "{HERE / "specimen.toml"}"')
    bad = tmp_path / "face.toml"
    bad.write_text(text.replace("levels = 3", "levels = 3\nlevles = 2"))
    with pytest.raises(ConfigError, match=r"face.toml: \[\[nominal\]\]\[0\] levles: unknown key \(did you mean levels"):
        load_face(bad)
    bad.write_text(text.replace("elements = [8, 8]", "elements = [6, 8]"))
    with pytest.raises(ConfigError, match="elements: .* multiples"):
        load_face(bad)
    bad.write_text(text.replace('kind = "quadrilateral"', 'kind = "sphere"'))
    with pytest.raises(ConfigError, match="kind: expected one of quadrilateral, cylinder"):
        load_face(bad)


def test_command_line_errors_exit_1_in_one_line_and_write_nothing(tmp_path, capsys):
    import runpy
    main = runpy.run_path(str(HERE / "run.py"), run_name="not_main")["main"]
    for argv, words in ((["--faces", "block_top"], "'base' is needed"),
                        (["--faces", "base,wing"], "unknown face(s) wing")):
        assert main(["--out", str(tmp_path / "out"), "--quiet", *argv]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("run.py: error: ") and words in err[0], err
        assert not (tmp_path / "out").exists()
