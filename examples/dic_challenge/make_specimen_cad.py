"""Build the CAD of the Stereo DIC Challenge specimen's visible faces (STEP, named faces).

    python examples/dic_challenge/make_specimen_cad.py [--out data/dic_challenge_stereo/specimen.step]
        [--interim-iges interim.igs]

needs OpenCASCADE's Python binding (``cadquery-ocp``, the ``cad`` extra). The solid is the
union of the base plate (a 101.6 mm square, top face at z = 0, centred at the origin: the
world frame of ``specimen.toml``) and the raised features of ``specimen.toml`` (the block,
both half-cylinders, both wedge prisms), with the block's height taken from the block top of
``analysis.toml`` (6.36 mm, the laser's). The file holds one open shell of the union's
faces that the cameras can see, each named (STEP ``ADVANCED_FACE`` names through XCAF):

==========================  ========================================================
``base``                    the plate's top face, the five footprints trimmed out (inner wires)
``block_top``               the block's top face
``block_wall_xm`` ...       the block's four walls, by outward normal: ``xm`` (-x), ``xp``, ``ym``, ``yp``
``cylinder_h``, ``_v``      the half-cylinders' crests, +-40 degrees about the top (axes below the plate)
``prism_h_ym``, ``_yp``     the horizontal prism's slanted faces, by outward normal (-y, +y)
``prism_v_xm``, ``_xp``     the vertical prism's slanted faces, by outward normal (-x, +x)
``cylinder_h_flank_a`` ..   the bars' flanks, from the crest face down to the plate (a, b)
==========================  ========================================================

in this order (16 faces). The bars' end caps and the plate's sides and bottom are left out.
The faces share their edges (they come from one solid), so a reader can weld them. The file
is read back and each face's area checked against the hand formula (:func:`expected_areas`).
``--interim-iges`` also writes the analysis regions of ``analysis.toml`` as untrimmed IGES
B-splines for a ``georeg measure`` without the ``cad`` extra (see "interim IGES" below).
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from challenge.config import Feature, load_analysis                           # noqa: E402

logger = logging.getLogger("make_specimen_cad")

#: the plate's side (mm): the challenge's 4 inch plate (README, "Real images")
PLATE_MM = 101.6
#: how far the solids reach below the plate's top face (only the top faces are written)
BELOW_MM = 10.0
#: the faces written, in this order
FACE_NAMES = ("base", "block_top", "block_wall_xm", "block_wall_xp", "block_wall_ym", "block_wall_yp",
              "cylinder_h", "cylinder_v", "prism_h_ym", "prism_h_yp", "prism_v_xm", "prism_v_xp",
              "cylinder_h_flank_a", "cylinder_h_flank_b", "cylinder_v_flank_a", "cylinder_v_flank_b")
#: each bar's curved face is split along its length: a crest face of +-CREST_DEG about the
#: top (the arc both cameras see, as analysis.toml's [[bars]]) and two flank faces down to the plate
CREST_DEG = 40.0
DEFAULT_OUT = HERE.parent.parent / "data" / "dic_challenge_stereo" / "specimen.step"


def _pnt(x):
    from OCP.gp import gp_Pnt
    return gp_Pnt(*map(float, x))


def _vec(x):
    from OCP.gp import gp_Vec
    return gp_Vec(*map(float, x))


def _prism(polygon: np.ndarray, direction: np.ndarray):
    """The solid swept by a closed planar polygon (m, 3) along ``direction`` (3,)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakePolygon
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    wire = BRepBuilderAPI_MakePolygon()
    for p in polygon:
        wire.Add(_pnt(p))
    wire.Close()
    face = BRepBuilderAPI_MakeFace(wire.Wire(), True).Face()
    return BRepPrimAPI_MakePrism(face, _vec(direction)).Shape()


def _lateral(line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis vector (not unit) of a segment and the horizontal unit vector ``axis x z``."""
    axis = line[1] - line[0]
    lateral = np.cross(axis, [0.0, 0.0, 1.0])
    return axis, lateral / np.linalg.norm(lateral)


def feature_solid(f: Feature, block_height_mm: float):
    """The OpenCASCADE solid of a raised feature, reaching ``BELOW_MM`` under the plate."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir
    if f.kind == "box":
        foot = np.c_[np.asarray(f.footprint_mm, float), np.full(4, -BELOW_MM)]
        return _prism(foot, [0.0, 0.0, block_height_mm + BELOW_MM])
    line = np.asarray(f.line_mm, float)
    axis, lateral = _lateral(line)
    if f.kind == "half_cylinder":
        frame = gp_Ax2(_pnt(line[0]), gp_Dir(*axis))
        return BRepPrimAPI_MakeCylinder(frame, float(f.radius_mm), float(np.linalg.norm(axis))).Shape()
    # wedge: ridge at line_mm, slanted faces down to z = 0 at +-half_width, continued below
    ridge = line[0]
    reach = (ridge[2] + BELOW_MM) / ridge[2]
    feet = [ridge + reach * (np.r_[ridge[:2] + s * f.half_width_mm * lateral[:2], 0.0] - ridge)
            for s in (1.0, -1.0)]
    return _prism(np.array([ridge, *feet]), axis)


def specimen_solid(analysis_toml: Path):
    """The union of the plate and the features of the specimen that ``analysis_toml`` names
    (the block as high as its block top), coplanar pieces merged; and the features."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Fuse
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.ShapeUpgrade import ShapeUpgrade_UnifySameDomain
    from OCP.collections import List_TopoDS_Shape as TopTools_ListOfShape
    config = load_analysis(analysis_toml)
    specimen = config.specimen
    height = float(np.mean(np.asarray(config.block_top_mm)[:, 2]))
    h = PLATE_MM / 2
    plate = BRepPrimAPI_MakeBox(_pnt([-h, -h, -BELOW_MM]), _pnt([h, h, 0.0])).Shape()
    args, tools = TopTools_ListOfShape(), TopTools_ListOfShape()
    args.Append(plate)
    for f in specimen.features:
        tools.Append(feature_solid(f, height))
    fuse = BRepAlgoAPI_Fuse()
    fuse.SetArguments(args)
    fuse.SetTools(tools)
    fuse.Build()
    if not fuse.IsDone():
        raise RuntimeError("OpenCASCADE: the union of the plate and the features failed")
    unify = ShapeUpgrade_UnifySameDomain(fuse.Shape(), True, True, True)
    unify.Build()
    return unify.Shape(), specimen.features, height


def _faces(shape) -> list:
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS
    out, explorer = [], TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        out.append(TopoDS.Face(explorer.Current()))
        explorer.Next()
    return out


def face_probe(face) -> tuple[str, np.ndarray, np.ndarray]:
    """Surface type ("plane", "cylinder", ...), a point inside the face and its outward normal."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepGProp import BRepGProp, BRepGProp_Face
    from OCP.GeomAbs import GeomAbs_Cylinder, GeomAbs_Plane
    from OCP.GProp import GProp_GProps
    from OCP.gp import gp_Pnt, gp_Vec
    surface = BRepAdaptor_Surface(face)
    kind = {GeomAbs_Plane: "plane", GeomAbs_Cylinder: "cylinder"}.get(surface.GetType(), "other")
    u = 0.5 * (surface.FirstUParameter() + surface.LastUParameter())
    v = 0.5 * (surface.FirstVParameter() + surface.LastVParameter())
    p, n = gp_Pnt(), gp_Vec()
    BRepGProp_Face(face).Normal(u, v, p, n)          # oriented: outward for a solid's face
    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, props)
    c = props.CentreOfMass()
    normal = np.array([n.X(), n.Y(), n.Z()])
    return kind, np.array([c.X(), c.Y(), c.Z()]), normal / np.linalg.norm(normal)


def name_faces(shape, features, height: float) -> dict:
    """The visible faces of the union by name (see the module docstring)."""
    by = {f.name: f for f in features}
    named = {}
    for face in _faces(shape):
        kind, centre, n = face_probe(face)
        name = None
        if kind == "plane" and n[2] > 0.999:
            name = "base" if abs(centre[2]) < 1e-6 else ("block_top" if abs(centre[2] - height) < 1e-6
                                                           else None)
        elif kind == "plane" and abs(n[2]) < 1e-9 and 0.0 < centre[2] < height:
            foot = np.asarray(by["block"].footprint_mm)
            if np.all(centre[:2] > foot.min(axis=0) - 1e-6) and np.all(centre[:2] < foot.max(axis=0) + 1e-6):
                k = int(np.argmax(np.abs(n[:2])))
                name = f"block_wall_{'xy'[k]}{'p' if n[k] > 0 else 'm'}"
        elif kind == "cylinder":
            name = min((f for f in features if f.kind == "half_cylinder"),
                       key=lambda f: np.linalg.norm(centre[:2] - np.mean(f.line_mm, axis=0)[:2])).name
        elif kind == "plane" and 0.1 < n[2] < 0.99:
            f = min((f for f in features if f.kind == "wedge"),
                    key=lambda f: np.linalg.norm(centre[:2] - np.mean(f.line_mm, axis=0)[:2]))
            k = int(np.argmax(np.abs(n[:2])))
            name = f"{f.name}_{'xy'[k]}{'p' if n[k] > 0 else 'm'}"
        if name is not None:
            if name in named:
                raise RuntimeError(f"two faces classified as {name!r}")
            named[name] = face
    missing = [n for n in FACE_NAMES if n not in named and "_flank_" not in n]
    if missing:
        raise RuntimeError(f"faces not found in the union: {missing}")
    return named


def write_step(path: Path, faces: dict) -> None:
    """One open shell of ``faces`` (name -> face) with its faces named, as STEP AP214."""
    from OCP.BRep import BRep_Builder
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.Interface import Interface_Static
    from OCP.STEPCAFControl import STEPCAFControl_Controller, STEPCAFControl_Writer
    from OCP.STEPControl import STEPControl_AsIs
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDocStd import TDocStd_Document
    from OCP.TopoDS import TopoDS_Shell
    from OCP.XCAFDoc import XCAFDoc_DocumentTool
    shell, builder = TopoDS_Shell(), BRep_Builder()
    builder.MakeShell(shell)
    for face in faces.values():
        builder.Add(shell, face)
    doc = TDocStd_Document(TCollection_ExtendedString("XmlOcaf"))
    tool = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
    label = tool.AddShape(shell, False)
    TDataStd_Name.Set_s(label, TCollection_ExtendedString("dic_challenge_specimen"))
    for name, face in faces.items():
        sub = tool.AddSubShape(label, face)
        TDataStd_Name.Set_s(sub, TCollection_ExtendedString(name))
    STEPCAFControl_Controller.Init_s()               # registers the parameters below
    Interface_Static.SetIVal_s("write.stepcaf.subshapes.name", 1)     # the faces' names
    Interface_Static.SetCVal_s("write.step.schema", "AP214IS")
    Interface_Static.SetCVal_s("write.step.unit", "MM")
    Interface_Static.SetCVal_s("write.step.product.name", "dic_challenge_specimen")
    writer = STEPCAFControl_Writer()
    writer.SetNameMode(True)
    if not writer.Transfer(doc, STEPControl_AsIs):
        raise RuntimeError("OpenCASCADE: STEP transfer failed")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    if writer.Write(str(tmp)) != IFSelect_RetDone:
        raise RuntimeError(f"{path}: OpenCASCADE could not write the STEP file")
    _strip_timestamp(tmp)
    tmp.replace(path)


def _strip_timestamp(path: Path) -> None:
    """A fixed FILE_NAME time stamp, so that rebuilding gives the same bytes."""
    import re
    text = path.read_text()
    text = re.sub(r"(FILE_NAME\('[^']*',)'[^']*'", r"\1'2026-01-01T00:00:00'", text, count=1)
    path.write_text(text)


def read_step_faces(path: Path) -> dict:
    """The named faces of a STEP file (name -> ``TopoDS_Face``), read back through XCAF."""
    from OCP.collections import Sequence_TDF_Label
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.Interface import Interface_Static
    from OCP.STEPCAFControl import STEPCAFControl_Controller, STEPCAFControl_Reader
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDocStd import TDocStd_Document
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopoDS import TopoDS
    from OCP.XCAFDoc import XCAFDoc_DocumentTool
    STEPCAFControl_Controller.Init_s()
    Interface_Static.SetIVal_s("read.stepcaf.subshapes.name", 1)
    reader = STEPCAFControl_Reader()
    reader.SetNameMode(True)
    if reader.ReadFile(str(path)) != IFSelect_RetDone:
        raise ValueError(f"{path}: OpenCASCADE could not read the STEP file")
    doc = TDocStd_Document(TCollection_ExtendedString("XmlOcaf"))
    if not reader.Transfer(doc):
        raise ValueError(f"{path}: OpenCASCADE could not transfer the STEP file")
    tool = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
    roots, faces = Sequence_TDF_Label(), {}
    tool.GetFreeShapes(roots)
    for i in range(1, roots.Length() + 1):
        subs = Sequence_TDF_Label()
        tool.GetSubShapes_s(roots.Value(i), subs)
        for j in range(1, subs.Length() + 1):
            label, name = subs.Value(j), TDataStd_Name()
            shape = tool.GetShape_s(label)
            if shape.ShapeType() == TopAbs_FACE and label.FindAttribute(TDataStd_Name.GetID_s(), name):
                faces[name.Get().ToExtString()] = TopoDS.Face(shape)
    return faces


def face_area(face) -> float:
    """Area of a face (mm^2), integrated by OpenCASCADE over its trimmed domain."""
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps
    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, props)
    return float(props.Mass())


def face_points(face, deflection_mm: float = 0.05) -> np.ndarray:
    """Points (n, 3) sampled inside a face's trimmed domain: the nodes of OpenCASCADE's
    triangulation of the face (``deflection_mm`` from the surface at most)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopLoc import TopLoc_Location
    BRepMesh_IncrementalMesh(face, deflection_mm, False, 0.2, False)
    location = TopLoc_Location()
    triangulation = BRep_Tool.Triangulation_s(face, location)
    transform = location.Transformation()
    points = [triangulation.Node(i).Transformed(transform) for i in range(1, triangulation.NbNodes() + 1)]
    return np.array([[p.X(), p.Y(), p.Z()] for p in points])


def distance_to_line(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance (n,) of points (n, 3) to the infinite line through the segment ``line`` (2, 3)."""
    a = np.asarray(line, float)
    d = (a[1] - a[0]) / np.linalg.norm(a[1] - a[0])
    arm = points - a[0]
    return np.linalg.norm(arm - np.outer(arm @ d, d), axis=1)


def expected_areas(features, height: float) -> dict:
    """The faces' areas (mm^2) from the features' dimensions, by hand (no CAD kernel)."""
    by = {f.name: f for f in features}
    out, footprints = {}, 0.0
    foot = np.asarray(by["block"].footprint_mm, float)
    x = 0.5 * np.sum(foot[:, 0] * np.roll(foot[:, 1], -1) - np.roll(foot[:, 0], -1) * foot[:, 1])
    out["block_top"] = abs(x)
    footprints += abs(x)
    for k, (a, b) in enumerate(zip(foot, np.roll(foot, -1, axis=0))):
        n = np.array([b[1] - a[1], a[0] - b[0]]) * np.sign(x)      # outward for a ccw polygon
        axis = int(np.argmax(np.abs(n)))
        out[f"block_wall_{'xy'[axis]}{'p' if n[axis] > 0 else 'm'}"] = np.linalg.norm(b - a) * height
    for f in features:
        if f.kind == "box":
            continue
        line = np.asarray(f.line_mm, float)
        length = float(np.linalg.norm(line[1] - line[0]))
        if f.kind == "half_cylinder":
            z0, r = float(line[0, 2]), float(f.radius_mm)
            half = np.arccos(-z0 / r)                   # from the crest down to z = 0
            crest = np.radians(CREST_DEG)
            out[f.name] = 2 * crest * r * length
            out[f"{f.name}_flank_a"] = out[f"{f.name}_flank_b"] = (half - crest) * r * length
            footprints += 2 * np.sqrt(r * r - z0 * z0) * length
        else:
            slant = np.hypot(f.half_width_mm, line[0, 2])
            lateral = _lateral(line)[1]
            k = int(np.argmax(np.abs(lateral[:2])))
            for s in (1.0, -1.0):
                out[f"{f.name}_{'xy'[k]}{'p' if s * lateral[k] > 0 else 'm'}"] = slant * length
            footprints += 2 * f.half_width_mm * length
    out["base"] = PLATE_MM ** 2 - footprints
    return {n: float(out[n]) for n in FACE_NAMES}


# --------------------------------------------------------------------------- interim IGES
# Until the `cad` extra reads STEP and trimmed faces, `georeg measure` reads untrimmed
# B-spline surfaces (IGES entity 128) only. This writes, through OpenCASCADE's IGES
# translator, the analysis regions as such surfaces: the block top (inset, analysis.toml's
# [block_top]), the bars' arcs about their crests (its [[bars]]), the prisms'
# four slanted faces (rectangles in the CAD: untrimmed already), and in place
# of the trimmed plate three rectangles of it free of features (INTERIM_BASE_MM): one that
# holds the README's flatness region and the east side of the block's ring, and one strip
# beside each bar that holds its ring (the plate 1.5..6 mm from its footprint).

#: x and y ranges (mm) of the plate's stand-ins: ``base`` from 1.5 mm east of the block and
#: 1.1 mm south of the vertical prism's end to the plate region's edges (analysis.toml [base]);
#: ``base_h`` between the horizontal prism and bar, ``base_v`` between the vertical prism
#: and bar (each at least 1.5 mm from a footprint)
INTERIM_BASE_MM = {"base": ((-10.0, 49.0), (-49.0, 1.0)), "base_h": ((-47.0, -4.0), (23.0, 31.5)),
                   "base_v": ((23.5, 32.9), (3.0, 46.0))}


def _biquadratic(face):
    """The face's surface as a B-spline of degree 2 in u and v (NURBS conversion, elevation),
    its natural normal ``S_u x S_v`` the face's outward one (u reversed for a reversed face)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.TopoDS import TopoDS
    converted = TopoDS.Face(BRepBuilderAPI_NurbsConvert(face, True).Shape())
    surface = BRep_Tool.Surface_s(converted)
    surface.IncreaseDegree(max(2, surface.UDegree()), max(2, surface.VDegree()))
    if converted.Orientation() == TopAbs_REVERSED:
        surface.UReverse()
    return surface


def interim_surfaces(folder: Path = HERE) -> dict:
    """Name -> untrimmed biquadratic B-spline surface of the analysis regions of
    ``folder/analysis.toml`` (the plate's stand-ins, the block top, the bars' arcs, the prisms)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Ax3, gp_Cylinder, gp_Dir, gp_Pln
    up, x = gp_Dir(0.0, 0.0, 1.0), gp_Dir(1.0, 0.0, 0.0)
    out = {name: _biquadratic(BRepBuilderAPI_MakeFace(gp_Pln(gp_Ax3(_pnt([0, 0, 0]), up, x)),
                                                       x0, x1, y0, y1).Face())
           for name, ((x0, x1), (y0, y1)) in INTERIM_BASE_MM.items()}
    config = load_analysis(folder / "analysis.toml")
    top = np.asarray(config.block_top_mm, float)
    lo, hi = top.min(axis=0), top.max(axis=0)
    out["block_top"] = _biquadratic(BRepBuilderAPI_MakeFace(
        gp_Pln(gp_Ax3(_pnt([0, 0, top[0, 2]]), up, x)), lo[0], hi[0], lo[1], hi[1]).Face())
    for n in config.bars:
        name = n.name
        line = np.asarray(n.axis_mm, float)
        axis = line[1] - line[0]
        frame = gp_Ax3(_pnt(line[0]), gp_Dir(*axis), up)          # u = 0 at the crest
        half = np.radians(n.arc_deg / 2)
        out[name] = _biquadratic(BRepBuilderAPI_MakeFace(gp_Cylinder(frame, float(n.radius_mm)), -half, half,
                                                         0.0, float(np.linalg.norm(axis))).Face())
    shape, features, height = specimen_solid(folder / "analysis.toml")
    for name, face in name_faces(shape, features, height).items():
        if name.startswith("prism"):                    # untrimmed rectangles already
            out[name] = _biquadratic(face)
    return out


def write_interim_iges(path: Path, surfaces: dict) -> None:
    """One IGES entity 128 per surface, named by an entity 406 form 15, in mm."""
    from OCP.GeomToIGES import GeomToIGES_GeomSurface
    from OCP.IGESBasic import IGESBasic_Name
    from OCP.IGESControl import IGESControl_Controller, IGESControl_Writer
    from OCP.TCollection import TCollection_HAsciiString
    IGESControl_Controller.Init_s()
    writer = IGESControl_Writer("MM", 0)
    convert = GeomToIGES_GeomSurface()
    convert.SetModel(writer.Model())
    for name, surface in surfaces.items():
        entity = convert.TransferSurface(surface, *surface.Bounds())
        label = IGESBasic_Name()
        label.Init(1, TCollection_HAsciiString(name))
        entity.AddProperty(label)
        if not writer.AddEntity(entity):
            raise RuntimeError(f"OpenCASCADE: cannot add the IGES entity of {name!r}")
    writer.ComputeModel()
    path.parent.mkdir(parents=True, exist_ok=True)
    if not writer.Write(str(path)):
        raise RuntimeError(f"{path}: OpenCASCADE could not write the IGES file")


def bar_faces(f: Feature) -> dict:
    """A bar's curved face split along its length: ``name`` (the crest, +-``CREST_DEG``
    about the top), ``name_flank_a`` and ``_b`` (down to the plate, z = 0): faces of the
    exact cylinder over rectangles of its (angle, length) parameters, outward normals."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_CylindricalSurface
    from OCP.gp import gp_Ax3, gp_Dir
    line = np.asarray(f.line_mm, float)
    axis, _ = _lateral(line)
    unit = axis / np.linalg.norm(axis)
    up = np.array([0.0, 0.0, 1.0]) - unit[2] * unit
    up /= np.linalg.norm(up)
    x_dir = np.cross(up, unit)                     # y = axis x x = up: the crest at u = 90 deg
    frame = gp_Ax3(_pnt(line[0]), gp_Dir(*unit), gp_Dir(*x_dir))
    surface = Geom_CylindricalSurface(frame, float(f.radius_mm))
    r, z0, length = float(f.radius_mm), float(line[0, 2]), float(np.linalg.norm(axis))
    foot = np.arcsin(-z0 / r)                      # the angle where the cylinder meets z = 0
    c = np.radians(CREST_DEG)
    spans = {f.name: (np.pi / 2 - c, np.pi / 2 + c),
             f"{f.name}_flank_a": (foot, np.pi / 2 - c),
             f"{f.name}_flank_b": (np.pi / 2 + c, np.pi - foot)}
    return {name: BRepBuilderAPI_MakeFace(surface, float(u0), float(u1), 0.0, length, 1e-7).Face()
            for name, (u0, u1) in spans.items()}


def build(out: Path = DEFAULT_OUT) -> dict:
    """Build the union, name its visible faces (the bars split into crest and flanks), write
    ``out``; the named faces."""
    shape, features, height = specimen_solid(HERE / "analysis.toml")
    named = name_faces(shape, features, height)
    for f in features:
        if f.kind == "half_cylinder":
            named.update(bar_faces(f))
    faces = {n: named[n] for n in FACE_NAMES}
    write_step(out, faces)
    return faces


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="STEP file to write")
    p.add_argument("--interim-iges", type=Path, default=None,
                   help="also write the analysis regions as untrimmed IGES B-splines "
                        "(entity 128) to this file, for georeg measure before the cad extra")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
    try:
        from OCP.Message import Message, Message_Gravity
    except ImportError:
        print("make_specimen_cad.py: error: needs OpenCASCADE (pip install cadquery-ocp)", file=sys.stderr)
        return 1
    for printer in Message.DefaultMessenger_s().Printers():    # OpenCASCADE's own chatter off
        printer.SetTraceLevel(Message_Gravity.Message_Warning)
    faces = build(args.out)
    if args.interim_iges is not None:
        surfaces = interim_surfaces()
        write_interim_iges(args.interim_iges, surfaces)
        logger.info("wrote %s: %s", args.interim_iges, ", ".join(surfaces))
    logger.info("wrote %s: %d faces, %.1f kB", args.out, len(faces), args.out.stat().st_size / 1e3)
    back = read_step_faces(args.out)
    _, features, height = specimen_solid(HERE / "analysis.toml")
    expected = expected_areas(features, height)
    for name in FACE_NAMES:
        area = face_area(back[name]) if name in back else float("nan")
        logger.info("  %-14s area %9.3f mm^2 (by hand %9.3f, %+.1e relative)", name, area,
                    expected[name], area / expected[name] - 1)
    for f in features:
        if f.kind == "half_cylinder":
            r = distance_to_line(face_points(back[f.name]), f.line_mm)
            logger.info("  %-14s radius at %d sampled points: %.6f..%.6f mm (nominal %g)", f.name,
                        len(r), r.min(), r.max(), f.radius_mm)
    if list(back) != list(FACE_NAMES):
        logger.error("read back: faces %s, expected %s", list(back), list(FACE_NAMES))
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
