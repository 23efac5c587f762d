"""Write the reference CAD files of the `cad` extra's tests with OpenCASCADE's own writers.

An independent writer (OpenCASCADE's STEPControl_Writer / IGESControl_Writer, not our
``write_iges``) exports three parts; the tests read the committed files:

- ``box_fillet``: a 20 x 10 x 8 mm box whose vertical edge at x = 20, y = 10 is rounded
  with a 3 mm fillet (7 faces: 6 planes, one cylindrical fillet);
- ``cylinder``: a solid cylinder of radius 10 mm and height 20 mm along z (3 faces: the
  lateral cylinder, two discs trimmed by circles);
- ``panel``: one cylindrical face (the nominal of issue 11's panel scene, ``tests/scenes.py``
  ``CAD_PARTS``): radius 100 mm, axis along x at z = -100 mm, 50 mm long, 40 mm across,
  crest at z = 0 (an untrimmed face bounded by its parameter range);
- ``plate_hole``: one flat face at z = 0, 60 x 40 mm centred at the origin, with a round
  hole of radius 8 mm at the centre (a trimmed plane: outer loop and one hole).

Run from the repository root: ``python tests/data/cad/make_reference_cad.py``.
"""
import math
from pathlib import Path

from OCP.BRepBuilderAPI import (BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace,
                                BRepBuilderAPI_MakePolygon, BRepBuilderAPI_MakeWire)
from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox, BRepPrimAPI_MakeCylinder
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.GC import GC_MakeCircle
from OCP.gp import gp_Ax2, gp_Ax3, gp_Cylinder, gp_Dir, gp_Pln, gp_Pnt
from OCP.IFSelect import IFSelect_RetDone
from OCP.IGESControl import IGESControl_Controller, IGESControl_Writer
from OCP.Interface import Interface_Static
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer
from OCP.TopAbs import TopAbs_EDGE
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS

HERE = Path(__file__).resolve().parent
PLATE = dict(length_mm=60.0, width_mm=40.0, hole_radius_mm=8.0)


def box_fillet():
    box = BRepPrimAPI_MakeBox(20.0, 10.0, 8.0).Shape()
    fillet = BRepFilletAPI_MakeFillet(box)
    explorer = TopExp_Explorer(box, TopAbs_EDGE)
    while explorer.More():
        edge = TopoDS.Edge(explorer.Current())
        curve = BRepAdaptor_Curve(edge)
        p, q = curve.Value(curve.FirstParameter()), curve.Value(curve.LastParameter())
        if all(abs(t.X() - 20) < 1e-9 and abs(t.Y() - 10) < 1e-9 for t in (p, q)):
            fillet.Add(3.0, edge)
        explorer.Next()
    return fillet.Shape()


def cylinder():
    return BRepPrimAPI_MakeCylinder(10.0, 20.0).Shape()


def panel():
    radius, length, width = 100.0, 50.0, 40.0
    half = math.asin(0.5 * width / radius)
    axis = gp_Ax3(gp_Pnt(0, 0, -radius), gp_Dir(1, 0, 0), gp_Dir(0, 0, 1))  # u = 0 at +z
    return BRepBuilderAPI_MakeFace(gp_Cylinder(axis, radius), -half, half,
                                   -0.5 * length, 0.5 * length).Face()


def plate_hole():
    a, b, r = 0.5 * PLATE["length_mm"], 0.5 * PLATE["width_mm"], PLATE["hole_radius_mm"]
    outline = BRepBuilderAPI_MakePolygon(gp_Pnt(-a, -b, 0), gp_Pnt(a, -b, 0), gp_Pnt(a, b, 0),
                                         gp_Pnt(-a, b, 0), True).Wire()
    circle = GC_MakeCircle(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), r).Value()
    hole = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(circle).Edge()).Wire()
    hole.Reverse()                                      # an inner loop runs clockwise
    face = BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), outline)
    face.Add(hole)
    return face.Face()


def write(shape, name: str) -> None:
    Interface_Static.SetCVal_s("write.step.unit", "MM")
    step = STEPControl_Writer()
    step.Transfer(shape, STEPControl_AsIs)
    assert step.Write(str(HERE / f"{name}.step")) == IFSelect_RetDone
    IGESControl_Controller.Init_s()
    Interface_Static.SetIVal_s("write.iges.brep.mode", 0)   # faces as 144 trimmed surfaces
    iges = IGESControl_Writer("MM", 0)
    iges.AddShape(shape)
    iges.ComputeModel()
    assert iges.Write(str(HERE / f"{name}.igs"))


if __name__ == "__main__":
    for make in (box_fillet, cylinder, panel, plate_hole):
        write(make(), make.__name__)
        print("wrote", make.__name__)
