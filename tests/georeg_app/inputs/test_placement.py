"""The nominal mesh against the specimen the calibrated rig triangulates (issue 22: a mesh
shifted by 0.5 mm along its normal was accepted silently)."""
import numpy as np
import pytest
from user_data import write_user_data

from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.fe.mesh_io import write_mesh
from fesdic_core.imaging.image import Image
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import Specimen
from georeg_app import cli
from georeg_app.inputs.placement import placement_check

pytestmark = pytest.mark.slow                  # a render and SIFT matches


@pytest.fixture(scope="module")
def flat(tmp_path_factory):
    cams = demo_cameras(image_size=(640, 480), field_mm=80.0)
    spec = Specimen(60.0, 40.0, speckle_mm=speckle_mm_for(cams[0], 4.0), seed=3)
    arrays = render_stereo(spec, cams, supersample=2, noise_std=2.0, seed=1, progress=False)
    return cams, arrays, write_user_data(tmp_path_factory.mktemp("placement"), arrays, cams)


def test_a_shifted_or_tilted_mesh_is_told_and_a_true_one_is_not(flat):
    cams, arrays, _ = flat
    images = [Image.from_array(a) for a in arrays]
    mesh = rectangle_mesh(50.0, 30.0, 10, 6, "Q9")
    true = placement_check(mesh, cams, images)
    assert true.agrees and abs(true.offset_mm) < 0.005 and true.tilt_deg < 0.05
    shifted = placement_check(mesh.with_nodes(mesh.nodes + [0.0, 0.0, 0.5]), cams, images)
    assert not shifted.agrees and abs(shifted.offset_mm + 0.5) < 0.005
    tilted = mesh.nodes.copy()
    tilted[:, 2] += 0.01 * tilted[:, 0]                            # 0.57 deg
    tilt = placement_check(mesh.with_nodes(tilted), cams, images)
    assert not tilt.agrees and abs(tilt.tilt_deg - np.degrees(np.arctan(0.01))) < 0.02


def test_measure_warns_when_the_mesh_is_off_the_specimen(flat, tmp_path, capsys):
    _, _, folder = flat
    mesh = rectangle_mesh(50.0, 30.0, 10, 6, "Q9")
    write_mesh(folder / "shifted.vtu", mesh.with_nodes(mesh.nodes + [0.0, 0.0, 0.5]))
    config = folder / "shifted.toml"
    config.write_text('[images]\ncam0 = "cam0.png"\ncam1 = "cam1.png"\n[cameras]\n'
                      'file = "cameras.json"\n[geometry]\nkind = "mesh"\nfile = "shifted.vtu"\n'
                      '[method]\nname = "fe"\nscales = 1\ncalibrate = false\n')
    cli.main(["measure", str(config), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert "placement check: the nominal mesh is not where the calibrated rig puts the " \
           "specimen" in err and "-500." in err, err[-2000:]
