"""Calibration targets and their detection in one image.

A :class:`Target` is a planar grid of points in its own frame (``z = 0``, mm): the dots of a
dot grid or a circle grid, the inner corners of a checkerboard or of a ChArUco board. A
:class:`Detection` is the points of one image that were found, by index into
:meth:`Target.object_points`, with their sub-pixel positions. :func:`detect` runs the
detector of the target's kind: OpenCV's for boards and circle grids
(:mod:`~fesdic_core.cameras.targets.boards`), ours for dot grids with ring markers
(:mod:`~fesdic_core.cameras.targets.dot_grid`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fesdic_core.cameras.targets import boards, dot_grid

__all__ = ["TARGET_KINDS", "Target", "Detection", "detect"]

#: "dots": dark dots with ring markers (VIC-3D, DICe); "checkerboard": inner corners (OpenCV's
#: sector-based detector); "charuco": a ChArUco board; "circles" / "asymmetric_circles":
#: OpenCV's circle grids
TARGET_KINDS = ("dots", "checkerboard", "charuco", "circles", "asymmetric_circles")


@dataclass(frozen=True)
class Target:
    """A planar calibration target.

    Attributes
    ----------
    kind : one of :data:`TARGET_KINDS`.
    rows, columns : points per column and per row (dots and circles: dots; checkerboard:
        inner corners; charuco: squares).
    pitch_mm : distance between neighbouring points (charuco: the square's side). For an
        asymmetric circle grid, the distance between neighbouring dots of a row is
        ``2 * pitch_mm``.
    markers : "dots": the (column, row) grid positions of the ring markers, at least three
        and not collinear.
    dot_diameter_mm : "dots" and circle grids: the dots' diameter, for the correction of the
        perspective bias of their centres (None: no correction).
    marker_mm, dictionary : "charuco": the ArUco marker's side and OpenCV's dictionary name.
    """

    kind: str
    rows: int
    columns: int
    pitch_mm: float
    markers: tuple[tuple[int, int], ...] = ()
    dot_diameter_mm: float | None = None
    marker_mm: float | None = None
    dictionary: str = "DICT_4X4_50"

    def __post_init__(self) -> None:
        if self.kind not in TARGET_KINDS:
            raise ValueError(f"target kind must be one of {TARGET_KINDS}, got {self.kind!r}")
        for name in ("rows", "columns"):
            value = getattr(self, name)
            if not (isinstance(value, (int, np.integer)) and value >= 2):
                raise ValueError(f"target {name} must be an integer of at least 2, got {value!r}")
        if not (np.isfinite(self.pitch_mm) and self.pitch_mm > 0):
            raise ValueError(f"target pitch_mm must be a positive number, got {self.pitch_mm!r}")
        if self.kind == "dots":
            m = np.asarray(self.markers, float).reshape(-1, 2)
            if len(m) < 3:
                raise ValueError(f"a dot grid needs at least 3 ring markers, got {len(m)}")
            if np.any(m < 0) or np.any(m[:, 0] >= self.columns) or np.any(m[:, 1] >= self.rows):
                raise ValueError(f"target markers must be (column, row) inside the "
                                 f"{self.columns} x {self.rows} grid, got {m.tolist()}")
            a, b = m[1] - m[0], m[2] - m[0]
            if abs(a[0] * b[1] - a[1] * b[0]) < 1e-9:
                raise ValueError(f"target markers {m[:3].tolist()} are collinear: they cannot "
                                 "orient the grid")
        if self.kind == "charuco" and not (self.marker_mm and 0 < self.marker_mm < self.pitch_mm):
            raise ValueError(f"a charuco target needs 0 < marker_mm < pitch_mm, got "
                             f"{self.marker_mm!r}")
        if self.dot_diameter_mm is not None and not 0 < self.dot_diameter_mm < self.pitch_mm:
            raise ValueError(f"target dot_diameter_mm must lie in (0, pitch_mm), got "
                             f"{self.dot_diameter_mm!r}")

    @property
    def grid(self) -> np.ndarray:
        """(N, 2) the points' (column, row) grid positions, row-major (OpenCV's order)."""
        if self.kind == "charuco":
            c, r = np.meshgrid(np.arange(1, self.columns), np.arange(1, self.rows))
        else:
            c, r = np.meshgrid(np.arange(self.columns), np.arange(self.rows))
        return np.column_stack([c.ravel(), r.ravel()]).astype(float)

    def object_points(self) -> np.ndarray:
        """(N, 3) the points in the target's frame (mm, ``z = 0``), OpenCV's order."""
        g = self.grid
        if self.kind == "asymmetric_circles":
            x = (2.0 * g[:, 0] + g[:, 1] % 2) * self.pitch_mm
        else:
            x = g[:, 0] * self.pitch_mm
        return np.column_stack([x, g[:, 1] * self.pitch_mm, np.zeros(len(g))])

    @property
    def circular(self) -> bool:
        """Whether the points are centres of printed circles (with a perspective bias)."""
        return self.kind in ("dots", "circles", "asymmetric_circles")


@dataclass(frozen=True)
class Detection:
    """The target's points found in one image.

    ``ids`` (m,) index :meth:`Target.object_points`; ``px`` (m, 2) their sub-pixel positions
    (column, row); ``note`` says why nothing (or little) was found.
    """

    source: str
    image_size: tuple[int, int]
    ids: np.ndarray = field(repr=False)
    px: np.ndarray = field(repr=False)
    note: str = ""

    @property
    def n_points(self) -> int:
        return int(len(self.ids))


def detect(image: np.ndarray, target: Target, source: str = "") -> Detection:
    """Find ``target`` in the gray image ``image`` (h, w) (any dtype; 8-bit is used as is).

    Returns a :class:`Detection` (empty, with its ``note``, when the target is not found).
    """
    gray = np.asarray(image)
    if gray.ndim != 2:
        raise ValueError(f"{source or 'image'}: a calibration image must be gray (h, w), got "
                         f"shape {gray.shape}")
    if gray.dtype != np.uint8:
        lo, hi = float(np.min(gray)), float(np.max(gray))
        gray = np.clip((gray - lo) / max(hi - lo, 1e-12) * 255.0, 0, 255).astype(np.uint8)
    size = (gray.shape[1], gray.shape[0])
    if target.kind == "dots":
        blobs = dot_grid.find_blobs(gray)
        marker_xy = np.asarray(target.markers, float).reshape(-1, 2)
        ids, px, note = dot_grid.match_grid(blobs, target.grid, marker_xy)
    else:
        ids, px, note = boards.detect_board(gray, target)
    ids, px = np.asarray(ids, int), np.asarray(px, float).reshape(-1, 2)
    order = np.argsort(ids, kind="stable")
    return Detection(source=source, image_size=size, ids=ids[order], px=px[order], note=note)
