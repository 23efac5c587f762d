"""``[displacement] start`` of ``georeg track``: a large motion tracked from the feature start.

The rendered series of tests/series_data.py (0.225 mm/px, 4 px speckle) with one frame moved
by about 25 px: the reference folder's mesh (44 x 30 mm) stays on the 60 x 40 mm plate.
"""
import re

import numpy as np
import pytest

from fesdic_core.synthetic.motion import RigidMotion
from georeg_app import cli
from georeg_app.config.track import START_MODES, DisplacementConfig, load_track_config
from georeg_app.series.track import run_track
from series_data import write_series

#: 5 / -2 / 0.5 mm and 10 mrad about z: about 25 px in the images
MOTION = RigidMotion((5.0, -2.0, 0.5), rvec=(0.0, 0.0, 0.01))


@pytest.fixture(scope="module")
def large(tmp_path_factory):
    folder = tmp_path_factory.mktemp("large")
    _, mesh = write_series(folder, [MOTION], frames="frames")
    return folder, mesh


def _config(folder, displacement):
    path = folder / "track.toml"
    path.write_text('[images]\ncam0 = "ref_cam0.png"\ncam1 = "ref_cam1.png"\n'
                    '[series]\ncam0 = "frames/f*_cam0.png"\ncam1 = "frames/f*_cam1.png"\n'
                    f'[displacement]\n{displacement}\n[reference]\ndir = "shape_out"\n')
    return path


def test_start_defaults_to_features_and_is_checked(tmp_path, capsys):
    assert DisplacementConfig().start == "features" and START_MODES == ("features", "previous",
                                                                         "zero")
    _, _ = write_series(tmp_path, [None], frames="frames", supersample=1)
    config = load_track_config(_config(tmp_path, 'start = "zero"'))
    assert config.displacement.start == "zero"
    code = cli.main(["-q", "track", str(_config(tmp_path, 'start = "guess"')), "--out",
                     str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 1
    for name in ("[displacement]", "start", "guess", '"features"', '"previous"', '"zero"'):
        assert name in err, err


@pytest.mark.slow
def test_a_large_motion_is_tracked_from_the_feature_start_not_from_zero(large):
    """From zero the frame is not the truth (failed, or more than 1 mm off); from the
    feature start it is ok, within 3 um RMS in plane and 10 um out of plane (the bounds
    of the small motions' tests, twice theirs), and says where it started."""
    folder, mesh = large
    truth = MOTION(mesh.nodes)
    zero = run_track(load_track_config(_config(folder, 'start = "zero"'))).frames[0]
    assert zero.start == "zero"
    assert not zero.ok or np.sqrt(np.mean(np.sum((zero.U - truth) ** 2, axis=1))) > 1.0
    run = run_track(load_track_config(_config(folder, 'method = "fe"')))     # the default start
    frame = run.frames[0]
    assert frame.ok and frame.start == "features", frame.failure
    rms = np.sqrt(np.mean((frame.U - truth) ** 2, axis=0))
    assert np.all(rms[:2] < 3e-3) and rms[2] < 10e-3, f"{1e3 * rms} um"


@pytest.mark.slow
def test_an_incremental_frame_starts_from_the_previous_field_or_the_features(tmp_path, caplog):
    """A small motion (1.3 px), then the large one: the first frame starts from zero (its
    coarse residual within the noise, or its features within a pixel of the coarsest scale
    of zero); the second's features are 25 px from the first frame's field and lower the
    coarse residual, so it starts from them (the log says both residuals); both end on the
    truth."""
    small = RigidMotion((0.3, -0.2, 0.1))
    _, mesh = write_series(tmp_path, [small, MOTION], frames="frames")
    with caplog.at_level("INFO", logger="georeg_app.series.frames"):
        run = run_track(load_track_config(_config(tmp_path, 'incremental = true')))
    assert [f.ok for f in run.frames] == [True, True]
    assert [f.start for f in run.frames] == ["zero", "features"]
    messages = [r.getMessage() for r in caplog.records]
    assert any(m.startswith("frame 1 start: ") and ("of zero" in m or "no features needed" in m)
               for m in messages), messages
    line = next(m for m in messages if m.startswith("frame 2 start: features: "))
    found = re.search(r"([0-9.]+) px from previous, residual at scale 2 ([0-9.]+)% "
                      r"\(previous ([0-9.]+)%, noise floor [0-9.]+%\): starting from features",
                      line)
    assert found and float(found[1]) > 10.0 and float(found[2]) < float(found[3]), line
    for f, motion in zip(run.frames, (small, MOTION)):
        rms = np.sqrt(np.mean((f.U - motion(mesh.nodes)) ** 2, axis=0))
        assert np.all(rms[:2] < 3e-3) and rms[2] < 10e-3, f"{1e3 * rms} um"
