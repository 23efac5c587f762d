"""IGES 5.3 in and out: rational B-spline surfaces (entity 128) with their transformations.

The nominal shape of a part comes from its CAD as NURBS patches (sec. 3.1, Eqs. 11-12).
This module reads every untrimmed surface of an IGES file without a CAD kernel:

- entity 128 (rational B-spline surface, forms 0-9; polynomial or rational weights,
  PROP3; closed/periodic flags PROP1/2/4/5, unclamped knots and a parameter range
  ``[U0, U1] x [V0, V1]`` inside the knot range are clamped by knot insertion);
- entity 124 (transformation matrix ``x' = R x + T``), chained when a 124 points to
  another 124 (own matrix first, then the referenced one: IGES 5.3 sec. 3.2.2);
- entity 144 (trimmed surface) only when its outer boundary is the boundary of the
  parameter domain (``N1 = 0``) and it has no inner loop (``N2 = 0``): an untrimmed
  surface in fact, as OpenCASCADE (gmsh) writes every B-spline face;
- names from the entity's Name property (entity 406 form 15) or its DE label field.

Trimmed surfaces (143, 144 with loops) and analytic surfaces (108 plane, 118 ruled,
120 revolution, 122 tabulated cylinder, 140 offset, 190-198) are refused with an error
naming the file, the directory entry and the type: they need a CAD kernel (the optional
``cad`` extra). Points, curves, groups, colours and other non-surfaces are skipped.

File layout (fixed 80 columns): Start S, Global G, Directory Entry D (two lines of ten
8-column fields per entity), Parameter Data P (data in columns 1-64, the DE pointer in
65-72) and Terminate T; column 73 holds the section letter. The first IGES direction
(``S``, index ``i`` of ``W(i, j)``, varying fastest) is ``u``.
"""
from __future__ import annotations

import collections
import dataclasses
import logging
import os
import pathlib

import numpy as np

from georeg_plugin.errors import SplineFileError
from georeg_plugin.spline.bspline import _boehm_step
from georeg_plugin.spline.patch import SplinePatch

logger = logging.getLogger(__name__)

__all__ = ["IgesSurface", "read_iges_surfaces", "read_iges_surface_entity"]

#: IGES unit flag -> millimetres per unit (IGES 5.3, Global parameter 14)
IGES_UNITS_MM = {1: 25.4, 2: 1.0, 4: 304.8, 5: 1609344.0, 6: 1000.0, 7: 1.0e6,
                 8: 0.0254, 9: 1.0e-3, 10: 10.0, 11: 2.54e-5}
#: surfaces that need a CAD kernel (the ``cad`` extra)
KERNEL_SURFACES = {108: "plane", 114: "parametric spline surface", 118: "ruled surface",
                   120: "surface of revolution", 122: "tabulated cylinder",
                   140: "offset surface", 143: "bounded surface", 144: "trimmed surface",
                   186: "manifold solid B-rep", 190: "plane surface",
                   192: "right circular cylindrical surface", 194: "right circular conical "
                   "surface", 196: "spherical surface", 198: "toroidal surface",
                   510: "face", 514: "shell"}
_NEEDS_KERNEL = "needs a CAD kernel: install the optional 'cad' extra"


@dataclasses.dataclass(frozen=True, eq=False)
class IgesSurface:
    """One untrimmed surface of an IGES file.

    Attributes
    ----------
    directory_entry : DE index (sequence number of its first D line, odd) of the face:
        the entity 128, or the entity 144 that wraps it
    entity_type : 128, or 144 (an untrimmed trimmed surface)
    label : name (entity 406 form 15) or DE label, None when blank
    transform : (3, 4) ``[R | T]`` applied to the control points (T in mm), composed
        over the chain of entities 124
    patch : the surface in mm, transformation applied
    """

    directory_entry: int
    entity_type: int
    label: str | None
    transform: np.ndarray
    patch: SplinePatch


# --------------------------------------------------------------------------- parsing
def _split_params(text: str, pdelim: str, rdelim: str) -> list[str]:
    """Split free-format IGES parameters, honouring Hollerith strings ``nHxxx``."""
    out, i, n = [], 0, len(text)
    while i < n:
        j = i
        while j < n and text[j] == " ":
            j += 1
        k = j
        while k < n and text[k].isdigit():
            k += 1
        if k > j and k < n and text[k] in "Hh":  # Hollerith string
            length = int(text[j:k])
            out.append(text[k + 1:k + 1 + length])
            i = k + 1 + length
            while i < n and text[i] not in (pdelim, rdelim):
                i += 1
        else:
            i = j
            while i < n and text[i] not in (pdelim, rdelim):
                i += 1
            out.append(text[j:i].strip())
        if i >= n or text[i] == rdelim:
            break
        i += 1
    return out


def _float(token: str, where: str) -> float:
    """An IGES real or integer (``1.0D0`` exponents accepted); blank is 0."""
    try:
        return float(token.replace("D", "E").replace("d", "e")) if token else 0.0
    except ValueError as exc:
        raise SplineFileError(f"{where}: {token!r} is not a number") from exc


def _int(token: str, where: str) -> int:
    x = _float(token, where)
    if x != round(x):
        raise SplineFileError(f"{where}: {token!r} is not an integer")
    return int(x)


def _delimiters(g_text: str) -> tuple[str, str]:
    """Parameter and record delimiters: Global parameters 1 and 2 (default ``,`` ``;``)."""
    pdelim, i = ",", 0
    if g_text.startswith("1H"):
        pdelim, i = g_text[2], 3
    i += 1  # the delimiter after parameter 1
    rdelim = g_text[i + 2] if g_text[i:i + 2] == "1H" else ";"
    return pdelim, rdelim


@dataclasses.dataclass(frozen=True)
class _Entry:
    """The fields of one directory entry that the reader uses."""

    de: int
    type: int
    pointer: int
    transform: int
    line_count: int
    form: int
    label: str


class _IgesFile:
    """Sections, delimiters, units and directory of one IGES file."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = path = pathlib.Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"IGES file {path} not found")
        sections: dict[str, list[str]] = {}
        for number, line in enumerate(path.read_text(encoding="latin-1").splitlines(), 1):
            if not line.strip():
                continue
            if len(line) < 73 or line[72] not in "SGDPTC":
                raise SplineFileError(f"{path}: line {number} is not an 80-column IGES record")
            sections.setdefault(line[72], []).append(line)
        if not sections.get("G") or not sections.get("D") or not sections.get("P"):
            raise SplineFileError(f"{path}: not an IGES file (missing G, D or P section)")
        g_text = "".join(line[:72] for line in sections["G"])
        self.pdelim, self.rdelim = _delimiters(g_text)
        g = _split_params(g_text, self.pdelim, self.rdelim)
        scale = _float(g[12], f"{path}: G field 13 (model space scale)") if len(g) > 12 \
            else 1.0
        unit = _int(g[13], f"{path}: G field 14 (unit flag)") if len(g) > 13 and g[13] \
            else 2
        if unit not in IGES_UNITS_MM:
            raise SplineFileError(f"{path}: G field 14 (unit flag) {unit} is not supported")
        self.to_mm = IGES_UNITS_MM[unit] / (scale or 1.0)
        self.p_lines = sections["P"]
        d = sections["D"]
        if len(d) % 2:
            raise SplineFileError(f"{path}: odd number of D lines ({len(d)})")
        self.entries: dict[int, _Entry] = {}
        for k in range(0, len(d), 2):
            a, b = d[k], d[k + 1]
            where = f"{path}: directory entry {k + 1}"
            self.entries[k + 1] = _Entry(
                de=k + 1, type=_int(a[0:8].strip(), where), pointer=_int(a[8:16].strip(), where),
                transform=_int(a[48:56].strip(), where), line_count=_int(b[24:32].strip(), where),
                form=_int(b[32:40].strip(), where), label=b[56:64].strip())

    def where(self, de: int) -> str:
        return f"{self.path}: entity {self.entries[de].type} (directory entry {de})"

    def entry(self, de: int, referrer: int) -> _Entry:
        if de not in self.entries:
            raise SplineFileError(f"{self.where(referrer)} points to directory entry {de}, "
                                  f"which does not exist")
        return self.entries[de]

    def params(self, de: int) -> list[str]:
        """The parameter tokens of an entity (continuation lines joined), type first."""
        e = self.entries[de]
        text = "".join(line[:64] for line in
                       self.p_lines[e.pointer - 1:e.pointer - 1 + e.line_count])
        tokens = _split_params(text, self.pdelim, self.rdelim)
        if not tokens or _float(tokens[0], self.where(de)) != e.type:
            raise SplineFileError(f"{self.where(de)}: parameter data starts with "
                                  f"{tokens[:1]!r}, not {e.type}")
        return tokens

    def transform(self, de: int) -> np.ndarray:
        """The (3, 4) ``[R | T]`` of the entity's chain of entities 124, T in file units."""
        M, seen, current = np.eye(4), [de], self.entries[de].transform
        while current:
            if current in seen:
                raise SplineFileError(f"{self.where(de)}: cycle in its transformations {seen}")
            t = self.entry(current, seen[-1])
            if t.type != 124:
                raise SplineFileError(f"{self.where(seen[-1])}: transformation pointer to "
                                      f"entity {t.type} (directory entry {current}), not 124")
            v = [_float(x, self.where(current)) for x in self.params(current)[1:13]]
            if len(v) != 12:
                raise SplineFileError(f"{self.where(current)}: 12 numbers expected")
            step = np.vstack([np.reshape(v, (3, 4)), [0, 0, 0, 1]])
            M = step @ M  # own matrix first, then the one it references
            seen.append(current)
            current = t.transform
        return M[:3]

    def name(self, de: int, tokens: list[str], n_params: int) -> str | None:
        """Name property (406 form 15) among the trailing pointers, else the DE label."""
        rest, where = tokens[n_params:], self.where(de)
        if rest:
            na = _int(rest[0], where)
            if len(rest) > na + 1:
                np_ = _int(rest[na + 1], where)
                for ptr in rest[na + 2:na + 2 + np_]:
                    e = self.entry(_int(ptr, where), de)
                    if e.type == 406 and e.form == 15:
                        return self.params(e.de)[2]
        return self.entries[de].label or None


# --------------------------------------------------------------------------- entity 128
def _clamp(knots: np.ndarray, p: int, P: np.ndarray, lo: float, hi: float):
    """Restrict a (possibly unclamped) B-spline to ``[lo, hi]`` with open knots.

    Boehm insertion brings ``lo`` and ``hi`` to multiplicity ``p`` (Eq. 13 leaves the
    curve unchanged), then the functions supported outside ``[lo, hi]`` are dropped.
    ``P`` (n, ...) holds homogeneous control points along this direction; the flag
    says whether knots were inserted or functions dropped.
    """
    t = knots.astype(float)
    if np.all(t[:p + 1] == lo) and np.all(t[-p - 1:] == hi):
        return t, P, False  # already open on [lo, hi]
    for x in (lo, hi):
        for _ in range(p - int(np.sum(t == x))):
            A, t = _boehm_step(t, p, float(x))
            P = np.tensordot(A.toarray(), P, axes=1)
    last_lo = int(np.flatnonzero(t == lo)[-1]) if p else int(np.searchsorted(t, lo, "right")) - 1
    first_hi = int(np.flatnonzero(t == hi)[0]) if p else int(np.searchsorted(t, hi, "left"))
    P = P[last_lo - p:first_hi]
    t = np.concatenate([[lo] * (p + 1), t[last_lo + 1:first_hi], [hi] * (p + 1)])
    return t, P, True


def _check_not_degenerate(patch: SplinePatch, where: str) -> None:
    """Refuse a control net collapsed to a point or a line, or a surface of zero area."""
    x = patch.control_points.reshape(-1, 3)
    s = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
    if s[0] == 0 or s[1] <= 1e-9 * s[0]:
        raise SplineFileError(f"{where}: degenerate surface, its control net is collapsed to "
                              f"a {'point' if s[0] == 0 else 'line'}")
    su, sv = patch.sample_parameters(per_span=4)
    uv = np.stack(np.meshgrid(su, sv, indexing="ij"), axis=-1).reshape(-1, 2)
    Su, Sv = patch.derivatives(uv)
    jac = np.linalg.norm(np.cross(Su, Sv), axis=1)
    if np.max(jac) <= 1e-12 * s[0] ** 2:
        raise SplineFileError(f"{where}: degenerate surface of zero area")


def _surface_128(f: _IgesFile, de: int) -> tuple[SplinePatch, str | None]:
    """The patch of entity 128 at ``de`` (file units, no transformation) and its name."""
    where = f.where(de)
    tokens = f.params(de)
    k1, k2, m1, m2 = (_int(t, where) for t in tokens[1:5])
    prop = [_int(t, where) for t in tokens[5:10]]
    nu, nv = k1 + 1, k2 + 1
    sizes = [nu + m1 + 1, nv + m2 + 1, nu * nv, 3 * nu * nv, 4]
    n_params = 10 + sum(sizes)
    if min(nu, nv, m1 + 1, m2 + 1) < 1 or len(tokens) < n_params:
        raise SplineFileError(f"{where}: {len(tokens) - 10} numbers, {sum(sizes)} expected "
                              f"for K1={k1}, K2={k2}, M1={m1}, M2={m2}")
    values = np.array([_float(t, where) for t in tokens[10:n_params]])
    ku, kv, w, xyz, (u0, u1, v0, v1) = np.split(values, np.cumsum(sizes)[:-1])
    polynomial = prop[2] == 1
    w = np.ones(nu * nv) if polynomial else w
    if not np.all(w > 0):
        raise SplineFileError(f"{where}: weights must be > 0 (PROP3 = {prop[2]}: rational)")
    # homogeneous control points (w x, w), indexed [i, j] with i (u) fastest in the file
    cp = xyz.reshape(nv, nu, 3).transpose(1, 0, 2)
    w = w.reshape(nv, nu).T
    H = np.concatenate([cp * w[..., None], w[..., None]], axis=-1)
    for name, (t, p, lo, hi) in (("u", (ku, m1, u0, u1)), ("v", (kv, m2, v0, v1))):
        if not (t[p] - 1e-12 * abs(t[p]) <= lo < hi <= t[-p - 1] + 1e-12 * abs(t[-p - 1])):
            raise SplineFileError(f"{where}: parameter range [{lo}, {hi}] in {name} is empty "
                                  f"or outside the knots' range [{t[p]}, {t[-p - 1]}]")
    try:
        ku, H, in_u = _clamp(ku, m1, H, max(u0, ku[m1]), min(u1, ku[-m1 - 1]))
        kv, H, in_v = _clamp(kv, m2, H.transpose(1, 0, 2), max(v0, kv[m2]),
                             min(v1, kv[-m2 - 1]))
        H = H.transpose(1, 0, 2)
        if in_u or in_v:
            cp, w = H[..., :3] / H[..., 3:], H[..., 3]  # knots inserted
        patch = SplinePatch(degrees=(m1, m2), knots=(ku, kv), control_points=cp,
                            weights=None if polynomial else w)
    except ValueError as exc:
        raise SplineFileError(f"{where}: {exc}") from exc
    if prop[3] or prop[4]:
        logger.debug("%s: periodic (PROP4=%d, PROP5=%d), read on [%g, %g] x [%g, %g]",
                     where, prop[3], prop[4], u0, u1, v0, v1)
    return patch, f.name(de, tokens, n_params)


def _placed(f: _IgesFile, de: int, patch: SplinePatch, outer: int | None) -> tuple:
    """Apply the transformations of the 128 (and of the 144 wrapping it) and convert to mm."""
    M = np.vstack([f.transform(de), [0, 0, 0, 1]])
    if outer is not None:
        M = np.vstack([f.transform(outer), [0, 0, 0, 1]]) @ M
    M = M[:3] * np.array([1.0, 1.0, 1.0, f.to_mm])  # T in mm; R acts on mm points
    x = patch.control_points * f.to_mm
    placed = SplinePatch(degrees=patch.degrees, knots=patch.knots,
                         control_points=x @ M[:, :3].T + M[:, 3], weights=patch.weights)
    _check_not_degenerate(placed, f.where(outer or de))
    return M, placed


def read_iges_surface_entity(path: str | os.PathLike, directory_entry: int) -> IgesSurface:
    """The entity 128 at ``directory_entry`` alone, whatever refers to it.

    The untrimmed base surface of a trimmed face (its trimming loops ignored), with its
    own transformation only.
    """
    f = _IgesFile(path)
    e = f.entries.get(directory_entry)
    if e is None or e.type != 128:
        raise SplineFileError(f"{path}: directory entry {directory_entry} is "
                              f"{'absent' if e is None else f'entity {e.type}'}, not entity 128")
    patch, label = _surface_128(f, directory_entry)
    M, placed = _placed(f, directory_entry, patch, None)
    return IgesSurface(directory_entry, 128, label, M, placed)


def read_iges_surfaces(path: str | os.PathLike) -> list[IgesSurface]:
    """Every untrimmed B-spline surface of an IGES file, in directory order.

    Raises
    ------
    FileNotFoundError, ValueError
        Naming the file, and the directory entry and entity type at fault: a surface
        that needs a CAD kernel (trimmed or analytic), a degenerate surface, bad data.
    """
    f = _IgesFile(path)
    faces: list[tuple[int | None, int]] = []   # (entity 144 or None, its entity 128)
    refused: list[str] = []
    skipped: collections.Counter[int] = collections.Counter()
    wrapped = set()  # entities 128 reached through a 144 or 143
    for de, e in f.entries.items():
        if e.type == 144:
            tokens = f.params(de)
            pts, n1, n2 = (_int(t, f.where(de)) for t in tokens[1:4])
            base = f.entry(pts, de)
            wrapped.add(pts)
            if n1 == 0 and n2 == 0 and base.type == 128:
                faces.append((de, pts))
            else:
                why = "trimming loops" if n1 or n2 else "untrimmed"
                refused.append(f"entity 144 trimmed surface (directory entry {de}, {why} "
                               f"on entity {base.type})")
        elif e.type == 143:
            wrapped.add(_int(f.params(de)[2], f.where(de)))
            refused.append(f"entity 143 bounded surface (directory entry {de})")
    for de, e in f.entries.items():
        if e.type == 128 and de not in wrapped:
            faces.append((None, de))
        elif e.type in KERNEL_SURFACES and e.type not in (143, 144) and de not in wrapped:
            refused.append(f"entity {e.type} {KERNEL_SURFACES[e.type]} "
                           f"(directory entry {de})")
        elif e.type not in (128, 143, 144):
            skipped[e.type] += 1
    if refused:
        raise SplineFileError(f"{f.path}: {len(refused)} surface(s) {_NEEDS_KERNEL}: "
                              + "; ".join(refused))
    if skipped:
        logger.info("%s: skipped %d entities that are not surfaces (%s)", f.path,
                    sum(skipped.values()),
                    ", ".join(f"type {t} x{n}" for t, n in sorted(skipped.items())))
    surfaces = []
    for outer, de in sorted(faces, key=lambda od: od[0] or od[1]):
        patch, label = _surface_128(f, de)
        if outer is not None:
            outer_tokens = f.params(outer)
            label = f.name(outer, outer_tokens, 5) or label
        M, placed = _placed(f, de, patch, outer)
        surfaces.append(IgesSurface(outer or de, 144 if outer else 128, label, M, placed))
    if not surfaces:
        raise SplineFileError(f"{f.path}: no surface (entity 128) in the file")
    logger.info("%s: read %d surface(s)", f.path, len(surfaces))
    return surfaces
