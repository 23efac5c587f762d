"""Spline output: a plain JSON layout and IGES 5.3 (entity 128), both read back.

The measured shape given "in terms of splines (thereby directly compatible with CAD
environments)" (sec. 3.3) is a ``SplinePatch``: degrees, knot vectors, control points
(mm) and weights.

JSON layout (``format`` "georeg-spline", ``version`` 1)::

    {"format": "georeg-spline", "version": 1,
     "degrees": [p, q],
     "knots": [[u_0, ..., u_{nu+p}], [v_0, ..., v_{nv+q}]],
     "control_points": [[[x, y, z], ... nv ...], ... nu ...],   # mm, [nu][nv][3]
     "weights": [[w, ... nv ...], ... nu ...] or null,          # null: B-spline
     "scalar_field": [[f, ... nv ...], ... nu ...]}             # optional, per control point

IGES: Rational B-Spline Surface entities (type 128, form 0), one per patch, optionally
named (entity 406 form 15) and placed by a chain of transformation matrices (entity 124),
in the fixed 80-column ASCII format of IGES 5.3: Start (S), Global (G), Directory Entry
(D, two lines of ten 8-column fields), Parameter Data (P: data in columns 1-64, the D
pointer in 65-72) and Terminate (T) sections; column 73 holds the section letter and
74-80 the sequence number. Units are mm (unit flag 2), parameter delimiter ``,`` and
record delimiter ``;``. The IGES first direction (``S``, index ``i`` of ``W(i, j)``,
varying fastest) is ``u``. Reading is :mod:`georeg_plugin.io.iges`.
"""
from __future__ import annotations

import datetime
import json
import logging
import os
import pathlib
import secrets

import numpy as np

from georeg_plugin.errors import SplineFileError
from georeg_plugin.io.iges import read_iges_surfaces
from georeg_plugin.spline.patch import SplinePatch

logger = logging.getLogger(__name__)

__all__ = ["write_spline_json", "read_spline_json", "read_scalar_field", "write_part_json",
           "read_part_json",
           "write_iges", "read_iges"]

FORMAT = "georeg-spline"
VERSION = 1


def _atomic_write_text(path: pathlib.Path, text: str, newline: str | None = None) -> None:
    """Write ``text`` to a new file beside ``path``, then ``os.replace`` it onto ``path``.

    The plugin does not import the core (whose ``fesdic_core.atomic`` does the same for any
    writer), so it keeps this one text writer of its own. The temporary file is created
    with mode 0666 and the kernel applies the umask, as for any new file (``mkstemp`` would
    give 0600); the umask itself is never read or changed.
    """
    path = pathlib.Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"{path}: folder {path.parent} does not exist")
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(8)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "w", encoding="ascii" if newline else "utf-8",
                       newline=newline) as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _weights_or_none(patch: SplinePatch) -> np.ndarray | None:
    """The weights (nu, nv) of a NURBS patch, None for a B-spline patch."""
    w = getattr(patch, "weights", None)
    return None if w is None else np.asarray(w, dtype=float)


# --------------------------------------------------------------------------- JSON
def _patch_doc(patch: SplinePatch, scalar_field=None, scalar_field_std=None,
               where: str = "") -> dict:
    """The JSON fields of one patch (layout in the module docstring)."""
    cp = np.asarray(patch.control_points, dtype=float)
    nu, nv = cp.shape[:2]
    w = _weights_or_none(patch)
    doc = {"degrees": [int(d) for d in patch.degrees],
           "knots": [np.asarray(k, dtype=float).tolist() for k in patch.knots],
           "control_points": cp.tolist(),
           "weights": None if w is None else w.tolist()}
    for name, field in (("scalar_field", scalar_field), ("scalar_field_std", scalar_field_std)):
        if field is not None:
            f = np.asarray(field, dtype=float)
            if f.size != nu * nv:
                raise ValueError(f"{where}{name} has {f.size} values, the patch has "
                                 f"{nu} x {nv} control points")
            doc[name] = f.reshape(nu, nv).tolist()
    return doc


def write_spline_json(path: str | os.PathLike, patch: SplinePatch,
                      scalar_field: np.ndarray | None = None,
                      scalar_field_std: np.ndarray | None = None) -> None:
    """Write a patch (and optionally one value per control point) as JSON, atomically.

    Parameters
    ----------
    path : output file.
    patch : SplinePatch with control points (nu, nv, 3) in mm.
    scalar_field : (nu, nv) or (nu * nv,), optional, e.g. the measured control values q_s.
    scalar_field_std : same shape, optional: the standard deviation of ``scalar_field``.
    """
    doc = {"format": FORMAT, "version": VERSION,
           **_patch_doc(patch, scalar_field, scalar_field_std)}
    _atomic_write_text(pathlib.Path(path), json.dumps(doc, indent=1) + "\n")
    logger.info("wrote spline %s (%d x %d control points)", path, *patch.control_points.shape[:2])


def write_part_json(path: str | os.PathLike, patches, names=None, scalar_fields=None,
                    scalar_field_stds=None) -> None:
    """Write the faces of a part as one JSON file, atomically: ``{"format", "version",
    "faces": [{"name", <the fields of one patch>}, ...]}`` (one entry per face, in order)."""
    patches = list(patches)
    k = len(patches)
    names = [None] * k if names is None else list(names)
    fields = [None] * k if scalar_fields is None else list(scalar_fields)
    stds = [None] * k if scalar_field_stds is None else list(scalar_field_stds)
    faces = [{"name": n, **_patch_doc(p, f, sd, f"face {i}: ")}
             for i, (p, n, f, sd) in enumerate(zip(patches, names, fields, stds))]
    doc = {"format": FORMAT, "version": VERSION, "faces": faces}
    _atomic_write_text(pathlib.Path(path), json.dumps(doc, indent=1) + "\n")
    logger.info("wrote %d spline faces %s", k, path)


def read_part_json(path: str | os.PathLike) -> list:
    """The faces (SplinePatch list) of a file of :func:`write_part_json` (or of
    :func:`write_spline_json`: one face)."""
    doc = _load_json(path)
    if "faces" not in doc:
        return [read_spline_json(path)]
    if not isinstance(doc["faces"], list) or not doc["faces"]:
        raise SplineFileError(f"{path}: field 'faces' must be a non-empty list")
    return [_patch_from_doc(face, f"{path} face {i}") for i, face in enumerate(doc["faces"])]


def _load_json(path: str | os.PathLike) -> dict:
    path = pathlib.Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"spline file {path} not found")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise SplineFileError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SplineFileError(f"{path}: field 'format' must be {FORMAT!r}")
    if doc.get("version") != VERSION:
        raise SplineFileError(f"{path}: field 'version' must be {VERSION}, "
                              f"got {doc.get('version')!r}")
    return doc


def _field(doc: dict, path, name: str, shape_hint: str) -> np.ndarray:
    if name not in doc:
        raise SplineFileError(f"{path}: field {name!r} is missing")
    try:
        return np.asarray(doc[name], dtype=float)
    except (TypeError, ValueError) as exc:
        raise SplineFileError(f"{path}: field {name!r} must be {shape_hint} ({exc})") from exc


def read_spline_json(path: str | os.PathLike) -> SplinePatch:
    """Read a patch written by ``write_spline_json`` (layout in the module docstring)."""
    return _patch_from_doc(_load_json(path), path)


def _patch_from_doc(doc: dict, path) -> SplinePatch:
    if not isinstance(doc, dict):
        raise SplineFileError(f"{path}: expected an object with the fields of a patch")
    degrees = _field(doc, path, "degrees", "[p, q]")
    if degrees.shape != (2,) or np.any(degrees != np.round(degrees)) or np.any(degrees < 1):
        raise SplineFileError(f"{path}: field 'degrees' must be two integers >= 1, "
                              f"got {doc['degrees']!r}")
    knots = doc.get("knots")
    if not isinstance(knots, list) or len(knots) != 2:
        raise SplineFileError(f"{path}: field 'knots' must hold two knot vectors")
    knots = tuple(_field({"knots": k}, path, "knots", "a list of numbers") for k in knots)
    cp = _field(doc, path, "control_points", "nested [nu][nv][3]")
    if cp.ndim != 3 or cp.shape[2] != 3:
        raise SplineFileError(f"{path}: field 'control_points' must be nested [nu][nv][3], "
                              f"got shape {cp.shape}")
    weights = None
    if doc.get("weights") is not None:
        weights = _field(doc, path, "weights", "nested [nu][nv]")
        if weights.shape != cp.shape[:2]:
            raise SplineFileError(f"{path}: field 'weights' has shape {weights.shape}, "
                                  f"expected {cp.shape[:2]}")
    try:
        return _make_patch(degrees.astype(int), knots, cp, weights)
    except ValueError as exc:
        raise SplineFileError(f"{path}: {exc}") from exc


def read_scalar_field(path: str | os.PathLike) -> np.ndarray | None:
    """The optional ``scalar_field`` (nu, nv) of a spline JSON file, or None."""
    doc = _load_json(path)
    if doc.get("scalar_field") is None:
        return None
    return _field(doc, path, "scalar_field", "nested [nu][nv]")


def _make_patch(degrees, knots, cp, weights) -> SplinePatch:
    """A SplinePatch; ``weights=None`` is a B-spline patch."""
    du, dv = (int(d) for d in degrees)
    ku, kv = (np.asarray(k, dtype=float) for k in knots)
    return SplinePatch(degrees=(du, dv), knots=(ku, kv),
                       control_points=np.asarray(cp, dtype=float),
                       weights=None if weights is None else np.asarray(weights, float))


# --------------------------------------------------------------------------- IGES
def _iges_real(x: float) -> str:
    """An IGES real: shortest round-trip digits, always a decimal point, exponent E."""
    s = repr(float(x))
    if "e" in s:
        mantissa, exponent = s.split("e")
        if "." not in mantissa:
            mantissa += ".0"
        s = f"{mantissa}E{int(exponent)}"
    return s


def _hollerith(s: str) -> str:
    return f"{len(s)}H{s}"


def _section(records: list[str], letter: str) -> list[str]:
    """Lines ``data(72) + letter + sequence(7)`` for the given 72-column records."""
    return [f"{r:<72.72}{letter}{i:7d}" for i, r in enumerate(records, start=1)]


def _pack(tokens: list[str], width: int) -> list[str]:
    """Tokens (each ending with its delimiter) packed into lines of at most ``width``."""
    lines, line = [], ""
    for t in tokens:
        if len(t) > width:
            raise ValueError(f"IGES parameter {t!r} is longer than {width} columns")
        if len(line) + len(t) > width:
            lines.append(line)
            line = ""
        line += t
    return lines + [line] if line else lines


def _entity_128(patch: SplinePatch, name_de: int | None) -> list:
    """Parameter data of entity 128: K1, K2, M1, M2, PROP1..5, knots S, T, weights,
    points, U0 U1 V0 V1, then (when named) no associativity and one property pointer."""
    cp = np.asarray(patch.control_points, dtype=float)
    nu, nv = cp.shape[:2]
    p, q = (int(d) for d in patch.degrees)
    ku, kv = (np.asarray(k, dtype=float) for k in patch.knots)
    w = _weights_or_none(patch)
    polynomial = w is None
    w = np.ones((nu, nv)) if w is None else w
    return ([128, nu - 1, nv - 1, p, q, 0, 0, int(polynomial), 0, 0]
            + ku.tolist() + kv.tolist()
            + w.ravel(order="F").tolist()                      # W(i, j), i fastest
            + cp.transpose(1, 0, 2).reshape(-1).tolist()       # X, Y, Z (i, j), i fastest
            + [ku[p], ku[-p - 1], kv[q], kv[-q - 1]]
            + ([] if name_de is None else [0, 1, name_de]))


def _entity_124(M, where: str) -> tuple[list, int]:
    """Parameter data and form of entity 124 ``[R | T]`` (form 0/1: R orthonormal)."""
    M = np.asarray(M, dtype=float)
    if M.shape != (3, 4) or not np.all(np.isfinite(M)):
        raise ValueError(f"{where}: expected a finite (3, 4) matrix [R | T], "
                         f"got shape {M.shape}")
    R = M[:, :3]
    if not np.allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-12):
        raise ValueError(f"{where}: R is not orthonormal (IGES entity 124 forms 0 and 1)")
    return [124] + M.ravel().tolist(), int(np.linalg.det(R) < 0)


def write_iges(path: str | os.PathLike, patches, names=None, transforms=None) -> None:
    """Write patches as an IGES 5.3 file of entities 128 (mm), atomically.

    Parameters
    ----------
    path : output file.
    patches : a SplinePatch, or a sequence of them (one entity 128 each).
    names : optional, one name per patch (or None): a Name property (entity 406 form 15)
        and the DE label (8 first characters).
    transforms : optional, per patch None, a (3, 4) ``[R | T]`` (mm), or a sequence of
        them applied in turn (a chain of entities 124, each pointing to the next); the
        control points are written untransformed.
    """
    path = pathlib.Path(path)
    patches = [patches] if isinstance(patches, SplinePatch) else list(patches)
    names = [None] * len(patches) if names is None else list(names)
    transforms = [None] * len(patches) if transforms is None else list(transforms)
    if not patches or len(names) != len(patches) or len(transforms) != len(patches):
        raise ValueError(f"{path}: {len(patches)} patches, {len(names)} names, "
                         f"{len(transforms)} transforms: need one each, at least one")
    # (type, form, transform DE, label, values, status)
    entities: list[tuple[int, int, int, str, list, str]] = []
    for k, (patch, name, chain) in enumerate(zip(patches, names, transforms)):
        if chain is not None and np.ndim(chain) == 2:
            chain = [chain]
        first = len(entities)
        for i, M in enumerate(chain or []):
            values, form = _entity_124(M, f"transforms[{k}][{i}]")
            nxt = 2 * (len(entities) + 1) + 1 if i + 1 < len(chain) else 0
            entities.append((124, form, nxt, "", values, "00000000"))
        t_de = 2 * first + 1 if chain else 0
        name_de = None
        if name is not None:
            name_de = 2 * len(entities) + 1
            entities.append((406, 15, 0, "", [406, 1, _hollerith(str(name))], "00000100"))
        entities.append((128, 0, t_de, (name or "SURFACE")[:8],
                         _entity_128(patch, name_de), "00000000"))
    d_records: list[str] = []
    p_lines: list[str] = []
    for k, (etype, form, t_de, label, values, status) in enumerate(entities):
        de = 2 * k + 1
        strings = [v if isinstance(v, str) else str(v) if isinstance(v, int)
                   else _iges_real(v) for v in values]
        records = _pack([s + "," for s in strings[:-1]] + [strings[-1] + ";"], 64)
        d_fields_1 = [etype, len(p_lines) + 1, 0, 0, 0, 0, t_de, 0]
        d_fields_2 = [etype, 0, 0, len(records), form]
        d_records += ["".join(f"{v:8d}" for v in d_fields_1) + status,
                      "".join(f"{v:8d}" for v in d_fields_2) + " " * 16
                      + f"{label:>8.8}{0:8d}"]
        p_lines += [f"{r:<64}{de:>8d}" for r in records]

    now = datetime.datetime.now().strftime("%Y%m%d.%H%M%S")
    extent = max(float(np.max(np.abs(p.control_points))) for p in patches)
    g_tokens = [_hollerith(","), _hollerith(";"), _hollerith("georeg spline"),
                _hollerith(path.name[:40]), _hollerith("georeg_plugin"),
                _hollerith("spline_io 1"), "32", "38", "6", "308", "15",
                _hollerith("georeg spline"), "1.0", "2", _hollerith("MM"), "1", "0.01",
                _hollerith(now), "1.0E-6", _iges_real(extent), _hollerith("georeg"),
                _hollerith("georeg"), "11", "0", _hollerith(now)]
    g_records = _pack([t + "," for t in g_tokens[:-1]] + [g_tokens[-1] + ";"], 72)
    s_records = [f"{len(patches)} rational B-spline surface(s) (entity 128) written by "
                 "georeg_plugin.", "Units mm."]
    sections = (_section(s_records, "S") + _section(g_records, "G")
                + _section(d_records, "D") + _section(p_lines, "P"))
    t_record = (f"S{len(s_records):7d}G{len(g_records):7d}"
                f"D{len(d_records):7d}P{len(p_lines):7d}")
    lines = sections + _section([t_record], "T")
    _atomic_write_text(path, "\n".join(lines) + "\n", newline="\n")
    logger.info("wrote IGES %s (%d surface(s))", path, len(patches))


def read_iges(path: str | os.PathLike, entity: int = 0) -> SplinePatch:
    """The ``entity``-th untrimmed surface of an IGES file, in mm, transformation applied.

    A thin wrapper of :func:`georeg_plugin.io.iges.read_iges_surfaces` (which refuses files
    with surfaces that need a CAD kernel).
    """
    surfaces = read_iges_surfaces(path)
    if len(surfaces) <= entity:
        raise SplineFileError(f"{path}: has {len(surfaces)} untrimmed surface(s) (entity 128), "
                              f"entity index {entity} requested")
    return surfaces[entity].patch
