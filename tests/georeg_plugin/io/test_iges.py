"""IGES reader against an independent writer and reader (gmsh 4.15, OpenCASCADE 7.8).

gmsh writes every B-spline face as an entity 144 whose outer boundary is the parameter
domain (N1 = 0) around an entity 128: untrimmed in fact, read as such. gmsh's own
evaluation of the same file (``gmsh.model.getValue`` after ``gmsh.open``) is the truth.
"""
import logging

import numpy as np
import pytest
from numpy.testing import assert_allclose

from georeg_plugin.io.iges import read_iges_surface_entity, read_iges_surfaces
from georeg_plugin.io.spline_io import read_iges, write_iges
from georeg_plugin.spline.geometries import rectangle
from georeg_plugin.spline.patch import SplinePatch

gmsh = pytest.importorskip("gmsh")


@pytest.fixture
def occ():
    gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    yield gmsh.model.occ
    gmsh.finalize()


def _net(occ, nu=5, nv=4):
    return [occ.addPoint(10.0 * i, 8.0 * j, 3.0 * np.sin(i + 0.7 * j))
            for j in range(nv) for i in range(nu)]


def _gmsh_points(tag: int, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Random parameters in gmsh's parameter box of surface ``tag`` and gmsh's points."""
    lo, hi = gmsh.model.getParametrizationBounds(2, tag)
    uv = lo + rng.uniform(size=(n, 2)) * (hi - lo)
    return uv, np.reshape(gmsh.model.getValue(2, tag, uv.ravel()), (-1, 3))


def _kernel_surfaces(occ) -> dict:
    """Parameters and points of every surface of the current gmsh model."""
    occ.synchronize()
    rng = np.random.default_rng(1)
    return {t: _gmsh_points(t, 100, rng) for _, t in gmsh.model.getEntities(2)}


def test_gmsh_bspline_rational_and_bezier_surfaces_read_as_gmsh_evaluates_them(
        occ, tmp_path, caplog):
    rng = np.random.default_rng(0)
    a = occ.addBSplineSurface(_net(occ), 5, degreeU=3, degreeV=2)
    b = occ.addBSplineSurface(_net(occ), 5, degreeU=2, degreeV=3,
                              weights=list(rng.uniform(0.5, 2.0, 20)))
    occ.translate([(2, b)], 0.0, 0.0, 20.0)
    c = occ.addBezierSurface(_net(occ), 5)
    occ.rotate([(2, c)], 0, 0, 0, 1, 1, 0, 0.7)
    occ.translate([(2, c)], 60.0, 0.0, 0.0)
    before = _kernel_surfaces(occ)
    path = tmp_path / "three.igs"
    gmsh.write(str(path))
    with caplog.at_level(logging.INFO, logger="georeg_plugin.io.iges"):
        surfaces = read_iges_surfaces(path)
    assert "skipped 61 entities that are not surfaces (type 116 x60, type 402 x1)" \
        in caplog.text
    assert [s.entity_type for s in surfaces] == [144, 144, 144]
    assert [s.label for s in surfaces] == [None] * 3  # gmsh writes no names
    assert [s.patch.degrees for s in surfaces] == [(3, 2), (2, 3), (4, 3)]
    assert [s.patch.is_rational for s in surfaces] == [False, True, False]
    gmsh.clear()
    gmsh.open(str(path))  # gmsh reads the file back: same numbers, independent reader
    after = _kernel_surfaces(occ)
    for s, tag in zip(surfaces, (a, b, c)):
        lo, hi = gmsh.model.getParametrizationBounds(2, tag)
        assert_allclose(s.patch.bounds, [lo, hi], rtol=0, atol=1e-15)
        uv, x = after[tag]
        assert_allclose(s.patch.evaluate(uv), x, rtol=0, atol=1e-12)
        # against the model before writing: OpenCASCADE writes 10 significant digits
        uv, x = before[tag]
        assert_allclose(s.patch.evaluate(uv), x, rtol=0, atol=1e-8)


def test_gmsh_periodic_cylinder_base_surface_and_refusal_of_its_trimmed_face(occ, tmp_path):
    """convertToNURBS of a cylinder: a periodic 128 (PROP4 = 1, unclamped knots from
    -2 pi / 3, parameter range [0, 2 pi]) inside a 144 with a boundary loop (N1 = 1)."""
    occ.addCylinder(0, 0, 0, 0, 0, 10, 3)
    occ.synchronize()
    occ.convertToNURBS(gmsh.model.getEntities(3))
    occ.synchronize()
    path = tmp_path / "cylinder.igs"
    gmsh.write(str(path))
    with pytest.raises(ValueError) as err:
        read_iges_surfaces(path)
    message = str(err.value)
    assert str(path) in message and "3 surface(s) needs a CAD kernel" in message
    assert "entity 144 trimmed surface (directory entry 3, trimming loops on entity 128)" \
        in message and "'cad' extra" in message
    side = read_iges_surface_entity(path, 5)  # the lateral face's base surface
    assert side.patch.knots[0][0] == 0.0 and side.patch.degrees == (2, 1)
    gmsh.clear()
    gmsh.open(str(path))
    tags = [t for _, t in gmsh.model.getEntities(2)]
    rng = np.random.default_rng(2)
    uv, x = _gmsh_points(tags[0], 200, rng)
    assert_allclose(side.patch.bounds, [[0.0, 0.0], [2 * np.pi, 10.0]], rtol=0, atol=1e-9)
    assert_allclose(side.patch.evaluate(uv), x, rtol=0, atol=1e-12)
    assert_allclose(np.hypot(*side.patch.evaluate(uv)[:, :2].T), 3.0, rtol=1e-9)


@pytest.mark.parametrize("make, base", [
    (lambda occ: occ.addRectangle(0, 0, 0, 10, 5), "108"),
    (lambda occ: occ.addCylinder(0, 0, 0, 0, 0, 10, 3), "120")])
def test_gmsh_analytic_faces_are_refused_naming_file_entry_and_type(occ, tmp_path,
                                                                     make, base):
    make(occ)
    occ.synchronize()
    path = tmp_path / "analytic.igs"
    gmsh.write(str(path))
    with pytest.raises(ValueError, match=rf"analytic.igs: .* needs a CAD kernel: install "
                       rf"the optional 'cad' extra: entity 144 trimmed surface \(directory "
                       rf"entry \d+, trimming loops on entity {base}\)"):
        read_iges_surfaces(path)


def _wavy(shift: float = 0.0, rational: bool = True) -> SplinePatch:
    u = np.linspace(0, 1, 5)
    cp = np.stack(np.meshgrid(40 * u, 30 * np.linspace(0, 1, 4), indexing="ij"), axis=-1)
    z = 2 * np.sin(3 * cp[..., :1]) * np.cos(cp[..., 1:]) + shift
    w = 1 + 0.3 * np.add.outer(u, np.linspace(0, 1, 4)) if rational else None
    return SplinePatch((3, 2), (np.array([0, 0, 0, 0, .5, 1, 1, 1, 1.]),
                                np.array([0, 0, 0, .4, 1, 1, 1.])),
                       np.concatenate([cp, z], axis=-1), w)


def _rigid(axis, angle, t):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.cross(np.eye(3), axis)
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    return np.column_stack([R, t])


def test_several_surfaces_names_and_chained_transformations_round_trip(tmp_path):
    patches = [_wavy(), _wavy(5.0, rational=False), _wavy(-3.0)]
    M1, M2 = _rigid([1, 2, 3], 0.4, [5.0, -2.0, 1.0]), _rigid([0, 0, 1], -1.1, [0, 7, 0])
    path = tmp_path / "several.igs"
    write_iges(path, patches, names=["base plate", None, "crest"],
               transforms=[None, M1, [M1, M2]])
    surfaces = read_iges_surfaces(path)
    assert [s.label for s in surfaces] == ["base plate", "SURFACE", "crest"]
    assert [s.entity_type for s in surfaces] == [128] * 3
    # directory entries: 406 at 1, 128 at 3; 124 at 5, 128 at 7; 124 at 9, 11, 406 13, 128 15
    assert [s.directory_entry for s in surfaces] == [3, 7, 15]
    composed = M2[:, :3] @ M1 + np.column_stack([np.zeros((3, 3)), M2[:, 3]])
    rng = np.random.default_rng(3)
    uv = rng.uniform(size=(300, 2))
    for s, patch, M in zip(surfaces, patches, [np.eye(3, 4), M1, composed]):
        assert_allclose(s.transform, M, rtol=0, atol=1e-14)
        assert s.patch.is_rational == patch.is_rational
        x = patch.evaluate(uv) @ M[:, :3].T + M[:, 3]  # a rigid motion commutes with Eq. 11
        assert_allclose(s.patch.evaluate(uv), x, rtol=0, atol=1e-12)
    assert_allclose(read_iges(path, entity=2).control_points, surfaces[2].patch.control_points)


def test_single_transformation_read_as_gmsh_reads_it(occ, tmp_path):
    """One entity 124 (gmsh applies it; OpenCASCADE 7.8 ignores a 124 referenced by a 124,
    so the chain is checked against its composition in the round-trip test)."""
    M = _rigid([1, -1, 2], 0.9, [12.0, -4.0, 30.0])
    path = tmp_path / "placed.igs"
    write_iges(path, [_wavy()], transforms=[M])
    surface, = read_iges_surfaces(path)
    gmsh.open(str(path))
    tag, = [t for _, t in gmsh.model.getEntities(2)]
    uv, x = _gmsh_points(tag, 200, np.random.default_rng(4))
    assert_allclose(surface.patch.evaluate(uv), x, rtol=0, atol=1e-12)


def test_delimiters_hollerith_d_exponents_and_continuation_lines(tmp_path):
    """Global parameters 1-2 set other delimiters (here ``/`` and ``#``); reals in D
    notation; Hollerith strings holding delimiters; every entity 128 on several P lines."""
    path = tmp_path / "plain.igs"
    write_iges(path, [_wavy(2.5e-5), _wavy(1.0)], names=["a,b;c", "x"])
    other = []
    for line in path.read_text().split("\n"):
        width = {"G": 72, "P": 64}.get(line[72:73])
        if width:
            body = line[:width].replace(",", "/").replace(";", "#").replace("E", "D")
            line = body + line[width:]
        other.append(line)
    text = "\n".join(other).replace("5Ha/b#c", "5Ha,b;c")  # a Hollerith keeps its text
    assert text.startswith("2 rational") and "\n1H//1H#/13Hgeoreg spline/" in text
    assert "D-5/" in text and "5Ha,b;c#" in text
    path2 = tmp_path / "other.igs"
    path2.write_text(text)
    first, second = read_iges_surfaces(path), read_iges_surfaces(path2)
    assert [s.label for s in second] == ["a,b;c", "x"]
    for s, t in zip(first, second):
        assert_allclose(t.patch.control_points, s.patch.control_points, rtol=0, atol=0)
        assert_allclose(t.patch.weights, s.patch.weights, rtol=0, atol=0)
    assert_allclose(first[0].patch.control_points, _wavy(2.5e-5).control_points,
                    rtol=0, atol=0)


def test_degenerate_surfaces_are_refused_naming_file_and_entity(tmp_path):
    base = rectangle(60.0, 40.0)
    cp = base.control_points
    line = cp.copy()
    line[..., 1] = 0.0                                         # net on the x axis
    point = np.zeros_like(cp)                                  # net on one point
    curve = np.broadcast_to(np.stack([cp[:, 0, 0], np.zeros(len(cp)), cp[:, 0, 0] ** 2],
                                     axis=-1)[:, None], cp.shape)  # S(u, v) = c(u)
    for name, net, why in (("line", line, "collapsed to a line"),
                           ("point", point, "collapsed to a point"),
                           ("curve", curve, "of zero area")):
        path = tmp_path / f"{name}.igs"
        write_iges(path, [_wavy(), SplinePatch(base.degrees, base.knots, net)])
        with pytest.raises(ValueError, match=rf"{name}.igs: entity 128 \(directory "
                           rf"entry 3\): degenerate surface.*{why}"):
            read_iges_surfaces(path)


def test_bad_files_and_pointers_are_refused_naming_file_and_entity(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.igs"):
        read_iges_surfaces(tmp_path / "missing.igs")
    bad = tmp_path / "bad.igs"
    bad.write_text("solid cube\nendsolid\n")
    with pytest.raises(ValueError, match="bad.igs: line 1 is not an 80-column IGES record"):
        read_iges_surfaces(bad)
    path = tmp_path / "ok.igs"
    write_iges(path, [_wavy()], transforms=[np.eye(3, 4)])
    text = path.read_text()
    d = [line for line in text.split("\n") if line[72:73] == "D"]
    # the 128 (directory entry 3) points to a transformation at 99, then at itself
    for target, match in (("      99", r"entity 128 \(directory entry 3\) points to "
                                      r"directory entry 99"),
                          ("       3", r"entity 128 \(directory entry 3\): cycle in its "
                                      r"transformations \[3\]")):
        broken = tmp_path / "broken.igs"
        broken.write_text(text.replace(d[2], d[2][:48] + target + d[2][56:]))
        with pytest.raises(ValueError, match=r"broken.igs: " + match):
            read_iges_surfaces(broken)
    # a parameter that is not a number, in the entity 128
    p = [line for line in text.split("\n") if line[72:73] == "P" and int(line[64:72]) == 3]
    broken.write_text(text.replace(p[1], p[1][:2] + "x" + p[1][3:]))
    with pytest.raises(ValueError, match=r"broken.igs: entity 128 \(directory entry 3\): "
                       r"'.*x.*' is not a number"):
        read_iges_surfaces(broken)
    with pytest.raises(ValueError, match="ok.igs: directory entry 1 is entity 124, not "
                       "entity 128"):
        read_iges_surface_entity(path, 1)


def test_parameter_range_inside_the_knots_is_clamped_without_moving_the_surface(tmp_path):
    """U0 U1 V0 V1 narrower than the knots: the patch is the surface on that box (knots
    inserted to full multiplicity at its ends, Eq. 13), the same points as the original."""
    path = tmp_path / "box.igs"
    patch = _wavy()
    write_iges(path, [patch])
    text = path.read_text()
    assert text.count(",0.0,1.0,0.0,1.0;") == 1
    path.write_text(text.replace(",0.0,1.0,0.0,1.0;", ",0.3,0.9,0.1,0.4;"))
    surface, = read_iges_surfaces(path)
    assert_allclose(surface.patch.bounds, [[0.3, 0.1], [0.9, 0.4]], rtol=0, atol=0)
    assert surface.patch.shape == (5, 3) and surface.patch.is_rational  # spans 2 x 1
    uv = np.array([0.3, 0.1]) + np.random.default_rng(5).uniform(size=(300, 2)) * [0.6, 0.3]
    uv = np.vstack([uv, [[0.3, 0.1], [0.9, 0.4], [0.5, 0.4]]])
    assert_allclose(surface.patch.evaluate(uv), patch.evaluate(uv), rtol=0, atol=1e-12)
    path.write_text(text.replace(",0.0,1.0,0.0,1.0;", ",0.0,1.5,0.0,1.0;"))
    with pytest.raises(ValueError, match=r"box.igs: entity 128 \(directory entry 1\): "
                       r"parameter range \[0.0, 1.5\] in u is empty or outside"):
        read_iges_surfaces(path)
