"""STEP and trimmed/analytic IGES through OpenCASCADE (the optional ``cad`` extra).

A part's faces as the plugin's NURBS patches (Eqs. 11-12) with their trimming loops:

- the file is read by OpenCASCADE (``STEPControl_Reader`` / ``IGESControl_Reader``, lengths
  in mm); every face is converted to NURBS (``BRepBuilderAPI_NurbsConvert``: planes,
  cylinders, cones, surfaces of revolution, B-splines) and its ``Geom_BSplineSurface``
  (poles placed by the face's location, weights, knots with their multiplicities, degrees)
  becomes a :class:`~georeg_plugin.spline.patch.SplinePatch`. A periodic surface is made
  non-periodic (clamped, same geometry); a degree below 2 is elevated to 2 (a plane's
  degree 1: the spline levels of the paper are quadratic, and Q9 reproduces degree 2,
  Eq. 16). A reversed face (``TopAbs_REVERSED``) gets its ``u`` direction flipped, so that
  ``S_u x S_v`` is the face's outward normal;
- the trimming loops are the face's wires (outer first, then the holes), each edge's pcurve
  (``BRepAdaptor_Curve2d``, the parameterization of the converted surface) sampled densely,
  in the edge's orientation: closed polylines in the patch's ``(u, v)``;
- face names: the STEP/IGES entity's name when it has one, else ``face{k}`` (file order).

Errors name the file and the face: an unreadable file, a file without faces, a face the
kernel cannot convert to a B-spline surface, a degenerate surface.

:func:`kernel_triangles` triangulates every face inside its loops (``BRepMesh_IncrementalMesh``)
for ray casting.
"""
from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np

from georeg_plugin.errors import SplineFileError
from georeg_plugin.io.iges import _check_not_degenerate
from georeg_plugin.spline.patch import SplinePatch

logger = logging.getLogger(__name__)

__all__ = ["CadFace", "kernel_available", "read_kernel_faces", "kernel_triangles",
           "STEP_SUFFIXES", "IGES_SUFFIXES"]

STEP_SUFFIXES = (".step", ".stp")
IGES_SUFFIXES = (".igs", ".iges")
#: pcurve samples per edge (a straight pcurve: its two ends)
EDGE_SAMPLES = 256


def kernel_available() -> bool:
    """True when OpenCASCADE's Python bindings (``OCP``, the ``cad`` extra) import."""
    try:
        import OCP.STEPControl  # noqa: F401
    except ImportError:
        return False
    return True


@dataclasses.dataclass(frozen=True, eq=False)
class CadFace:
    """One face of a CAD part.

    Attributes
    ----------
    name : the entity's name, or ``face{k}``.
    patch : the face's untrimmed NURBS surface (mm), ``S_u x S_v`` along the outward normal.
    loops : closed polylines (k, 2) in the patch's ``(u, v)``: the outer loop, then the holes.
    trimmed : the loops cut the parameter box (False: the outer loop is the box's boundary
        and there is no hole).
    """

    name: str
    patch: SplinePatch
    loops: tuple
    trimmed: bool


def _quiet_kernel() -> None:
    """OpenCASCADE's messages below failures off (its readers print to stdout; ours log)."""
    from OCP.Message import Message, Message_Gravity
    for printer in Message.DefaultMessenger_s().Printers():
        printer.SetTraceLevel(Message_Gravity.Message_Fail)


def _read_shape(path: Path):
    """The file's shape and its reader (kept alive: its transfer results give the names)."""
    from OCP.IFSelect import IFSelect_RetDone
    _quiet_kernel()
    suffix = path.suffix.lower()
    if suffix in STEP_SUFFIXES:
        from OCP.STEPControl import STEPControl_Reader
        reader = STEPControl_Reader()
    elif suffix in IGES_SUFFIXES:
        from OCP.IGESControl import IGESControl_Reader
        reader = IGESControl_Reader()
    else:
        raise SplineFileError(f"{path}: not a STEP ({', '.join(STEP_SUFFIXES)}) or IGES "
                              f"({', '.join(IGES_SUFFIXES)}) file")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    status = reader.ReadFile(str(path))
    if status != IFSelect_RetDone:
        raise SplineFileError(f"{path}: unreadable {'STEP' if suffix in STEP_SUFFIXES else 'IGES'} "
                              f"file (OpenCASCADE status {status})")
    reader.TransferRoots()
    return reader.OneShape(), reader


def _faces(shape) -> list:
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS
    faces: list = []                                     # TopoDS_Face
    seen = set()
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        face = TopoDS.Face(explorer.Current())
        if hash(face) not in seen or not any(face.IsSame(f) for f in faces):
            seen.add(hash(face))
            faces.append(face)
        explorer.Next()
    return faces


def _name(reader, face) -> str | None:
    """The STEP/IGES entity's name of ``face``, or None."""
    try:
        entity = reader.WS().TransferReader().EntityFromShapeResult(face, 1)
    except Exception:                                   # noqa: BLE001 (no entity)
        return None
    if entity is None:
        return None
    for attr in ("Name", "NameValue"):
        if hasattr(entity, attr):
            try:
                text = getattr(entity, attr)().ToCString().strip()
            except Exception:                           # noqa: BLE001 (no name)
                continue
            if text:
                return text
    return None


def _array1(a) -> np.ndarray:
    return np.array([a.Value(i) for i in range(a.Lower(), a.Upper() + 1)], dtype=float)


def _bspline(face, where: str):
    """The face's surface as a non-periodic Geom_BSplineSurface of degree >= 2."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.GeomConvert import GeomConvert
    from OCP.TopoDS import TopoDS
    try:
        nurbs = TopoDS.Face(BRepBuilderAPI_NurbsConvert(face, True).Shape())
        surface = GeomConvert.SurfaceToBSplineSurface_s(BRep_Tool.Surface_s(nurbs))
    except Exception as err:                            # noqa: BLE001 (OCC failure)
        raise SplineFileError(f"{where}: not convertible to a B-spline surface ({err})") from None
    if surface.IsUPeriodic():
        surface.SetUNotPeriodic()
    if surface.IsVPeriodic():
        surface.SetVNotPeriodic()
    u0, u1, v0, v1 = surface.Bounds()
    surface.Segment(u0, u1, v0, v1)              # clamped (open) knots on the face's range
    surface.IncreaseDegree(max(2, surface.UDegree()), max(2, surface.VDegree()))
    return nurbs, surface


def _patch(surface) -> SplinePatch:
    nu, nv = surface.NbUPoles(), surface.NbVPoles()
    poles = np.array([[surface.Pole(i, j).Coord() for j in range(1, nv + 1)]
                      for i in range(1, nu + 1)])
    weights = np.array([[surface.Weight(i, j) for j in range(1, nv + 1)]
                        for i in range(1, nu + 1)])
    rational = not np.allclose(weights, weights.flat[0], rtol=1e-14, atol=0)
    return SplinePatch((surface.UDegree(), surface.VDegree()),
                       (_array1(surface.UKnotSequence()), _array1(surface.VKnotSequence())),
                       poles, weights if rational else None)


def _wire_polyline(wire, face) -> np.ndarray:
    """A wire's pcurves, in order and orientation, as one closed polyline (k, 2)."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve2d
    from OCP.BRepTools import BRepTools_WireExplorer
    from OCP.GeomAbs import GeomAbs_Line
    from OCP.TopAbs import TopAbs_REVERSED
    pieces = []
    explorer = BRepTools_WireExplorer(wire, face)
    while explorer.More():
        edge = explorer.Current()
        curve = BRepAdaptor_Curve2d(edge, face)
        n = 2 if curve.GetType() == GeomAbs_Line else EDGE_SAMPLES
        t = np.linspace(curve.FirstParameter(), curve.LastParameter(), n)
        if edge.Orientation() == TopAbs_REVERSED:
            t = t[::-1]
        pieces.append(np.array([curve.Value(float(s)).Coord() for s in t]))
        explorer.Next()
    return np.vstack(pieces)


def _loops(nurbs) -> list:
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS
    outer = BRepTools.OuterWire_s(nurbs)
    loops = [_wire_polyline(outer, nurbs)]
    explorer = TopExp_Explorer(nurbs, TopAbs_WIRE)
    while explorer.More():
        wire = TopoDS.Wire(explorer.Current())
        if not wire.IsSame(outer):
            loops.append(_wire_polyline(wire, nurbs))
        explorer.Next()
    return loops


def _flip_u(patch: SplinePatch, loops: list) -> tuple[SplinePatch, list]:
    """The same surface with ``u -> u_0 + u_end - u``: the normal ``S_u x S_v`` flips."""
    tu = patch.knots[0]
    a, b = tu[0], tu[-1]
    flipped = SplinePatch(patch.degrees, ((a + b - tu)[::-1], patch.knots[1]),
                          patch.control_points[::-1],
                          None if patch.weights is None else patch.weights[::-1])
    return flipped, [np.column_stack([a + b - loop[:, 0], loop[:, 1]]) for loop in loops]


def _is_trimmed(patch: SplinePatch, loops: list) -> bool:
    """True unless there is one loop and it runs along the boundary of the parameter box."""
    if len(loops) > 1:
        return True
    lo, hi = patch.bounds
    tol = 1e-7 * (hi - lo)
    uv = loops[0]
    on_box = np.any((np.abs(uv - lo) <= tol) | (np.abs(uv - hi) <= tol), axis=1)
    area = 0.5 * abs(np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1]))
    return not (np.all(on_box) and np.isclose(area, np.prod(hi - lo), rtol=1e-9))


def read_kernel_faces(path) -> list[CadFace]:
    """Every face of a STEP or IGES file as a NURBS patch with its trimming loops.

    Raises
    ------
    FileNotFoundError, ValueError
        Naming the file (and the face at fault): unreadable, no face, a face not
        convertible to a B-spline surface, a degenerate surface.
    """
    from OCP.TopAbs import TopAbs_REVERSED
    path = Path(path)
    shape, reader = _read_shape(path)
    faces = _faces(shape)
    if not faces:
        raise SplineFileError(f"{path}: no face (surface) in the file")
    out = []
    for k, face in enumerate(faces):
        name = _name(reader, face) or f"face{k}"
        where = f"{path}: face {k} ({name!r})"
        nurbs, surface = _bspline(face, where)
        try:
            patch = _patch(surface)
        except ValueError as err:
            raise SplineFileError(f"{where}: {err}") from None
        _check_not_degenerate(patch, where)
        loops = _loops(nurbs)
        if face.Orientation() == TopAbs_REVERSED:
            patch, loops = _flip_u(patch, loops)
        out.append(CadFace(name, patch, tuple(loops), _is_trimmed(patch, loops)))
    logger.info("%s: read %d face(s) through OpenCASCADE (%d trimmed)", path, len(out),
                sum(f.trimmed for f in out))
    return out


def kernel_triangles(path, deflection_mm: float = 0.01,
                     angle_rad: float = 0.1, only=None) -> np.ndarray:
    """A triangulation of every face of the file (or of the file-order indices ``only``)
    inside its loops, (m, 3, 3) mm.

    ``BRepMesh_IncrementalMesh`` with chord deviation ``deflection_mm`` (and angular
    deflection ``angle_rad``); triangles ordered so that their normal is the face's outward
    normal.
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.TopLoc import TopLoc_Location
    path = Path(path)
    shape, _ = _read_shape(path)
    BRepMesh_IncrementalMesh(shape, float(deflection_mm), False, float(angle_rad), True)
    out = []
    wanted = None if only is None else set(int(k) for k in only)
    for k, face in enumerate(_faces(shape)):
        if wanted is not None and k not in wanted:
            continue
        location = TopLoc_Location()
        mesh = BRep_Tool.Triangulation_s(face, location)
        if mesh is None:
            raise SplineFileError(f"{path}: face {k} could not be triangulated")
        transform = location.Transformation()
        nodes = np.array([mesh.Node(i).Transformed(transform).Coord()
                          for i in range(1, mesh.NbNodes() + 1)])
        tri = np.array([[mesh.Triangle(i).Value(j) for j in (1, 2, 3)]
                        for i in range(1, mesh.NbTriangles() + 1)]) - 1
        if face.Orientation() == TopAbs_REVERSED:
            tri = tri[:, ::-1]
        out.append(nodes[tri])
    return np.concatenate(out)
