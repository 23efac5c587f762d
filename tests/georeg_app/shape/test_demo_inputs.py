"""georeg_app.shape.demo.demo_config: the demo's temporary inputs are removed after the run."""
import gc
import tempfile

import numpy as np

from fesdic_core.cameras.rig import read_cameras_json
from georeg_app.shape import demo


def _cheap_render(specimen, cams, **kwargs):
    """Stand-in for the 1 Mpx renderer (the rendering is not what is tested here)."""
    return [np.full((16, 24), 128.0) for _ in cams]


def test_demo_setup_leaves_no_folder_behind(tmp_path, monkeypatch):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    monkeypatch.setattr(demo, "render_stereo", _cheap_render)
    config, images, truth = demo.demo_config(tmp_path / "out")
    moved = config.with_output_dir(tmp_path / "elsewhere")          # a copy keeps the inputs
    del config
    gc.collect()
    assert _cameras_readable(moved)
    assert len(list(scratch.iterdir())) == 1 and moved.cameras.file.is_relative_to(scratch)
    del moved
    gc.collect()
    assert list(scratch.iterdir()) == []                            # the run's end: nothing left
    assert not (tmp_path / "out").exists() and not (tmp_path / "elsewhere").exists()


def _cameras_readable(config) -> bool:
    """The cameras file of the demo config reads back as a stereo pair."""
    return len(read_cameras_json(config.cameras.file)) == 2
