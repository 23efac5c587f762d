"""Local validity of a displacement's nodes on renders with known truth.

The pair (tests/scenes.py ``twist_wave_pair``): the displacement tests' flat plate, then the
same paint twisted by 1 mm and wavy (up to 0.63 mm at the nodes), rendered independently.
Plain FE on a 1 mm mesh (4.4 px elements) diverges locally there (some nodes millimetres
off) while the global residual stays under the noise floor; on a coarse mesh, or with the
spline levels, it does not. "Bad" nodes: more than 10 times the median error and more than
20 um off. Figures: ``benchmarks/bench_validity.py``.
"""
import dataclasses

import numpy as np
import pytest

from fesdic_core.displacement.driver import (DisplacementSettings, displacement_reference,
                                             measure_displacement)
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.residual.validity import DEFAULT_MAX_INVALID_SHARE
from fesdic_core.synthetic.motion import RigidMotion

SCALES = DisplacementSettings(scales=(2, 1, 0))


def _measure(pair, mesh, solver=None, images=None, settings=SCALES):
    reference = displacement_reference(mesh, pair.reference, pair.cameras, settings)
    return measure_displacement(reference, pair.deformed if images is None else images, solver)


def _bad(m, truth):
    error = np.linalg.norm(m.U - truth, axis=1)
    return error, (error > 10 * np.median(error)) & (error > 0.02)


@pytest.mark.slow
def test_plain_fe_on_a_fine_mesh_flags_its_local_divergence(twist_wave_pair):
    """1 mm Q4 elements: the global residual is within the noise, but nodes end up
    millimetres off. The modified Gauss-Newton does not stagnate; the full one, run again
    from the start, reaches the residual's minimum ("no descent"), which holds the local
    divergence. The bad nodes are invalid but for a few whose residual is at the noise
    level, the invalid nodes are far off the valid ones, and with the renders' share
    (DEFAULT_MAX_INVALID_SHARE, 3 %) the frame fails on them."""
    mesh = rectangle_mesh(44.0, 30.0, 44, 30, family="Q4")
    strict = dataclasses.replace(SCALES, max_invalid_share=DEFAULT_MAX_INVALID_SHARE)
    m = _measure(twist_wave_pair, mesh, settings=strict)
    error, bad = _bad(m, twist_wave_pair.motion(mesh.nodes))
    assert bad.sum() >= 10 and error.max() > 1.0               # the divergence is there
    assert m.residual_percent < m.noise_percent                # ... under the global floor
    assert not m.ok and "not valid locally" in m.failure, m.failure
    assert np.sum(bad & m.valid) <= 0.2 * bad.sum()
    assert np.median(error[~m.valid]) > 5 * np.median(error[m.valid])
    assert m.validity.invalid_share > 0.02


@pytest.mark.slow
def test_a_coarse_fe_frame_keeps_its_nodes_valid(twist_wave_pair):
    """11 mm Q4 elements follow the twist (median error 8 um): the frame is ok, every node
    valid, each node's residual about half its local noise floor. (Slow: it renders the
    deformed pair.)"""
    mesh = rectangle_mesh(44.0, 30.0, 4, 3, family="Q4")
    m = _measure(twist_wave_pair, mesh)
    assert m.ok, m.failure
    assert m.valid.shape == (mesh.n_nodes,) and m.valid.dtype == bool
    assert m.valid.mean() >= 0.95
    assert np.all((m.residual_to_noise > 0.3) & (m.residual_to_noise < 0.8))


@pytest.mark.slow
def test_a_rigid_motion_on_a_finer_mesh_keeps_its_nodes_valid(twist_wave_pair):
    """A rigid motion on 2 mm Q4 elements (median error 10 um): ok, every node valid."""
    motion = RigidMotion((0.3, -0.2, 0.1), rvec=(0.0, 0.003, 0.002))
    images = twist_wave_pair.moved(motion)
    mesh = rectangle_mesh(44.0, 30.0, 22, 15, family="Q4")
    m = _measure(twist_wave_pair, mesh, images=images)
    error, bad = _bad(m, motion(mesh.nodes))
    assert m.ok, m.failure
    assert m.valid.mean() >= 0.95 and not np.any(bad & m.valid)


def test_nodes_over_the_background_are_invalid(twist_wave_pair):
    """A mesh 68 mm long on the 60 mm plate: its end nodes (4 mm beyond the plate) see the
    uniform background, have no texture and are invalid; with the renders' share of 3 % the
    frame fails, naming them (by default the share fails no frame:
    DISPLACEMENT_MAX_INVALID_SHARE)."""
    mesh = rectangle_mesh(68.0, 30.0, 17, 6, family="Q4")
    strict = dataclasses.replace(SCALES, max_invalid_share=DEFAULT_MAX_INVALID_SHARE)
    m = _measure(twist_wave_pair, mesh, images=twist_wave_pair.reference, settings=strict)
    beyond = np.abs(mesh.nodes[:, 0]) > 30.0
    assert beyond.sum() == 14
    assert not np.any(m.valid[beyond])
    assert np.all(m.validity.texture_ratio[beyond] < 2.0)
    assert not m.ok and "not valid locally" in m.failure and "the worst, node" in m.failure
    worst = int(np.nanargmax(np.where(m.valid, -np.inf, m.residual_to_noise)))
    assert f"node {worst} at" in m.failure


def test_the_invalid_share_is_a_checked_setting():
    with pytest.raises(ValueError, match="max_invalid_share must be a share in"):
        DisplacementSettings(max_invalid_share=1.5)
    with pytest.raises(ValueError, match="max_invalid_share"):
        DisplacementSettings(max_invalid_share="0.1")
    assert DisplacementSettings(max_invalid_share=1.0).max_invalid_share == 1.0


def test_a_looser_share_lets_the_frame_pass_with_its_nodes_still_flagged(twist_wave_pair):
    """The mesh over the background with max_invalid_share = 1: the frame passes its verdict
    (the global residual is within the noise) and still marks those nodes invalid."""
    mesh = rectangle_mesh(68.0, 30.0, 17, 6, family="Q4")
    settings = DisplacementSettings(scales=(0,), max_invalid_share=1.0)
    m = _measure(twist_wave_pair, mesh, images=twist_wave_pair.reference, settings=settings)
    assert m.ok, m.failure
    assert not np.any(m.valid[np.abs(mesh.nodes[:, 0]) > 30.0])
